"""Stability in the plant's own time, a search that does not hang on the horizon, and the start scaling (issue 60).

The stand-in for lqrsp's New England model (not redistributable): a continuous-time stable
plant of 8 nodes with 2 states and 1 input each, one slow rotational mode (eigenvalues
-5e-6 ± 0.6j 1/s) among ordinary ones (-0.2 to -2 1/s), held by zero-order hold at
dt = 0.01 and 0.05. Its open-loop radius is 1 - 5e-8 (1 - 2.5e-7): stable, and unstable
by a fixed margin 1 - 1e-6. At horizon 50 the finite-horizon cost barely sees the slow
mode, and on seeds 1 and 3 every start's minimum lets it drift just outside the circle
(radius 1.00025 and 1.0021, "no stabilizing diagonal gain found from 9 starts" before).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.signal import cont2discrete

from baselines import decentralized, polish_gain
from baselines.stabilizing import (_within, horizon_free_gain, is_stable, local_starts, lyapunov_cost_and_grad,
                                   stability_tol, unstable_note)
from codesign import Instance, paper_instance, spectral_radius, static_gain_cost
from codesign.status import STABILITY_FRACTION, STABILITY_TOL, USABLE

SLOW = -5e-6  # 1/s


def slow_mode_system(dt, *, seed=0, nodes=8, horizon=50):
    """The stand-in: ``nodes`` nodes of 2 states and 1 input, one slow rotational mode, ZOH at ``dt``."""
    rng = np.random.default_rng(seed)
    n = 2 * nodes
    blocks = [np.array([[SLOW, 0.6], [-0.6, SLOW]])]
    for _ in range(1, nodes):
        s, w = -rng.uniform(0.2, 2.0), rng.uniform(0.5, 5.0)
        blocks.append(np.array([[s, w], [-w, s]]))
    V = np.eye(n) + 0.3 * rng.standard_normal((n, n))
    Ac = V @ scipy.linalg.block_diag(*blocks) @ np.linalg.inv(V)
    Bc = np.zeros((n, nodes))
    Bc[2 * np.arange(nodes) + 1, np.arange(nodes)] = 1.0
    A, B, *_ = cont2discrete((Ac, Bc, np.eye(n), np.zeros((n, nodes))), dt, method="zoh")
    return Instance.from_matrices(A, B, horizon=horizon, state_nodes=np.repeat(np.arange(nodes), 2),
                                  input_nodes=np.arange(nodes))


# -- the rule ---------------------------------------------------------------------------------


@pytest.mark.parametrize("dt", [0.01, 0.05])
def test_the_margin_is_a_tenth_of_the_plants_own_slowest_decay(dt):
    inst = slow_mode_system(dt)
    decay = 1 - np.exp(SLOW * dt)  # 5e-8 at dt = 0.01: the slow mode's decay per step
    assert 1 - inst.open_loop_radius == pytest.approx(decay, rel=1e-6)
    assert stability_tol(inst) == pytest.approx(STABILITY_FRACTION * decay, rel=1e-6)
    # The plant itself is stable in its own time, not by the fixed margin.
    assert is_stable(inst.open_loop_radius, inst) and not is_stable(inst.open_loop_radius)
    assert not is_stable(1 - 0.5 * STABILITY_FRACTION * decay, inst)
    assert not is_stable(1.0, inst) and not is_stable(float("nan"), inst)
    assert f"not below 1 - {stability_tol(inst):g}" in unstable_note(1.0, instance=inst)


def test_the_verdict_on_a_slow_plant_does_not_depend_on_the_sampling_time():
    # The same plant, and the same closed-loop decay in continuous time, at two sampling times.
    fine, coarse = slow_mode_system(0.01), slow_mode_system(0.05)
    assert stability_tol(coarse) / stability_tol(fine) == pytest.approx(5.0, rel=1e-5)
    for rate in (0.5 * STABILITY_FRACTION * SLOW, 2 * STABILITY_FRACTION * SLOW):  # 1/s: slower, faster
        verdicts = {is_stable(np.exp(rate * dt), inst) for dt, inst in ((0.01, fine), (0.05, coarse))}
        assert verdicts == {rate < STABILITY_FRACTION * SLOW}


def test_plants_without_a_slow_decay_keep_the_fixed_margin():
    assert stability_tol(None) == STABILITY_TOL == 1e-6
    assert stability_tol(paper_instance(0, n=20, a_norm=0.995)) == STABILITY_TOL  # every mode decays fast
    assert stability_tol(paper_instance(0, n=20, a_norm=1.05)) == STABILITY_TOL
    assert stability_tol(np.diag([1.3, 1.1])) == STABILITY_TOL  # nothing decays
    # An undamped mode on the circle (rounding puts it at 1 - 1e-15) gives no time scale.
    c, s = np.cos(0.3), np.sin(0.3)
    assert stability_tol(scipy.linalg.block_diag([[c, -s], [s, c]], 0.5)) == STABILITY_TOL
    assert stability_tol(np.diag([1 - 1e-9, 0.5])) == STABILITY_TOL  # decay below STABILITY_RESOLVED
    # An unstable plant with a slow stable mode: that mode sets the margin.
    assert stability_tol(np.diag([1.2, 1 - 5e-8])) == pytest.approx(5e-9, rel=1e-6)
    # The fixed margin's verdicts stand: the plant is looked at only for radii in [1 - 1e-6, 1).
    inst = paper_instance(0, n=20)
    assert is_stable(1 - 2e-6, None) and not is_stable(1 - 5e-7, inst) and not is_stable(1 - 5e-7)


# -- the search does not depend on the horizon ----------------------------------------------


@pytest.mark.parametrize("dt, seed", [(0.01, 1), (0.01, 3), (0.01, 0), (0.05, 1)])
def test_the_slow_mode_stand_in_gets_a_stabilizing_diagonal_gain_at_horizon_50(dt, seed):
    inst = slow_mode_system(dt, seed=seed)
    assert inst.horizon == 50
    d = decentralized(inst)
    assert d.status in USABLE, d.message
    K = d.controller.K
    assert np.array_equal(K != 0, inst.block_mask() & (K != 0))  # diagonal (own blocks): no link
    assert d.links == 0
    radius = spectral_radius(inst.A + inst.B @ K)
    assert radius == pytest.approx(d.extras["spectral_radius"], rel=1e-12)
    assert is_stable(radius, inst) and radius < 1 - 1e-4  # stable by the fixed margin too, a hundredfold
    assert d.cost == pytest.approx(static_gain_cost(inst, K), rel=1e-12)
    if d.extras["search_start"] == "horizon-free":
        # Every start's finite-horizon minimum was unstable; the message says so.
        assert d.status == "inaccurate" and "infinite-horizon cost" in d.message
    again = decentralized(inst)
    assert np.array_equal(again.controller.K, K)  # reproducible


def test_where_the_horizon_cost_cannot_see_the_slow_mode_the_search_goes_horizon_free():
    inst = slow_mode_system(0.01, seed=1)
    mask = inst.block_mask()
    # Each start's minimum of the horizon-50 cost lets the slow mode out of the circle.
    for name, K in local_starts(inst):
        result = polish_gain(inst, np.where(mask, K, 0.0), mask)
        radius = spectral_radius(inst.A + inst.B @ result.K)
        assert 1 < radius < np.exp(1 / inst.horizon), (name, radius)  # grows less than e-fold over 50 steps
        break  # one start shows it (the test above runs the whole search)
    d = decentralized(inst)
    assert d.extras["search_start"] == "horizon-free" and d.status == "inaccurate"
    assert "do not stabilize" in d.message and "1.00025" in d.message
    # Its cost is a finite-horizon cost like any other (a little above the unstable minimum's).
    assert 2.0 < d.cost < 2.6


def test_horizon_free_gain_from_an_unstable_start():
    inst = slow_mode_system(0.01, seed=3)
    mask = inst.block_mask()
    start = np.where(mask, inst.K_lqr, 0.0) * 3.0  # far outside
    assert spectral_radius(inst.A + inst.B @ start) > 1
    K, radius, rounds, _ = horizon_free_gain(inst, mask, start)
    assert rounds >= 2 and is_stable(radius, inst) and radius == spectral_radius(inst.A + inst.B @ K)
    assert np.all(K[~mask] == 0)
    # No stabilizing diagonal gain on paper_instance(6, n=4, degree=2, a_norm=1.2): none is made up.
    hopeless = paper_instance(6, n=4, degree=2, a_norm=1.2)
    assert horizon_free_gain(hopeless, hopeless.block_mask(), np.zeros((4, 4))) is None


def test_a_visible_instability_does_not_start_the_horizon_free_search():
    # Radius 1.17 grows 2000-fold over 50 steps: the horizon sees it, the verdict stands.
    d = decentralized(paper_instance(6, n=4, degree=2, a_norm=1.2))
    assert d.status == "diverged" and d.extras["search_start"] != "horizon-free"


def test_the_lyapunov_cost_and_its_gradient():
    inst = paper_instance(3, n=6, degree=2, a_norm=1.05)
    # The LQR gain's infinite-horizon cost is trace(P): 1 normalized.
    assert lyapunov_cost_and_grad(inst, inst.K_lqr)[0] == pytest.approx(1.0, rel=1e-10)
    assert np.linalg.norm(lyapunov_cost_and_grad(inst, inst.K_lqr)[1]) < 1e-8  # its minimum
    mask = inst.block_mask()
    K = 0.9 * decentralized(inst).controller.K  # a stabilizing gain on the own blocks, not a minimum
    for discount in (1.0, 1.3):
        cost, grad = lyapunov_cost_and_grad(inst, K, mask, discount=discount)
        assert np.all(grad[~mask] == 0)
        direction = np.where(mask, np.random.default_rng(0).standard_normal(K.shape), 0.0)
        h = 1e-6
        plus = lyapunov_cost_and_grad(inst, K + h * direction, discount=discount)[0]
        minus = lyapunov_cost_and_grad(inst, K - h * direction, discount=discount)[0]
        assert (plus - minus) / (2 * h) == pytest.approx(np.sum(grad * direction), rel=1e-6)
    # Finite only below the discount.
    assert lyapunov_cost_and_grad(inst, np.zeros((6, 6)))[0] == np.inf  # open loop radius 1.05
    assert np.isfinite(lyapunov_cost_and_grad(inst, np.zeros((6, 6)), discount=1.06)[0])


# -- the start scaling ------------------------------------------------------------------------


def test_random_starts_work_where_the_lqr_diagonal_is_far_outside():
    # The LQR diagonal's closed loop has radius 1.846 here, against max(1, rho(A)) + 0.1 = 1.3:
    # halving toward it never met that limit, and all six random starts were the base's copies
    # (7.2911, from the deadbeat start). 37 of 40 plain random starts reach 4.4108 (radius 0.819).
    inst = paper_instance(25, n=4, degree=2, a_norm=1.2)
    mask = inst.block_mask()
    assert spectral_radius(inst.A + inst.B @ np.where(mask, inst.K_lqr, 0.0)) > inst.open_loop_radius + 0.5
    d = decentralized(inst)
    assert d.status == "optimal" and d.cost == pytest.approx(4.4108, rel=0.01)
    assert d.extras["spectral_radius"] == pytest.approx(0.819, abs=1e-3)
    again = decentralized(inst)
    assert again.cost == d.cost and np.array_equal(again.controller.K, d.controller.K)


def test_starts_that_met_the_first_limit_are_as_before():
    # The halving against max(1, rho(A)) + 0.1, the rule before: unchanged wherever it succeeds.
    inst = paper_instance(0, n=20, a_norm=1.05)
    mask = inst.block_mask()
    base = np.where(mask, inst.K_lqr, 0.0)
    step = np.where(mask, np.random.default_rng(1).standard_normal(mask.shape), 0.0) * 3.0
    limit = max(1.0, inst.open_loop_radius) + 0.1
    before = step
    for _ in range(10):
        if spectral_radius(inst.A + inst.B @ (base + before)) <= limit:
            break
        before = before / 2.0
    assert spectral_radius(inst.A + inst.B @ (base + before)) <= limit
    assert np.array_equal(_within(inst, base, step), base + before)
