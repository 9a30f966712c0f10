"""The default γ grids are written out as literals (run keys must not depend on the machine's
last digit); they must still be the geometric grids their docstrings describe."""

import numpy as np

from baselines import ADMM_GAMMAS, SDP_GAMMAS


def test_admm_grid_is_the_geometric_grid():
    np.testing.assert_allclose(ADMM_GAMMAS, np.geomspace(1e-6, 0.1, 10), rtol=1e-14, atol=0)
    assert all(isinstance(g, float) for g in ADMM_GAMMAS)


def test_sdp_grid_is_the_geometric_grid():
    np.testing.assert_allclose(SDP_GAMMAS, np.geomspace(1e-4, 1.0, 10), rtol=1e-14, atol=0)
    assert all(isinstance(g, float) for g in SDP_GAMMAS)
