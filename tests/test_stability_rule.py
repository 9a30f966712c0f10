"""One stability rule for every static design, and the stabilizing search behind it (baselines.stabilizing)."""

from __future__ import annotations

import numpy as np
import pytest

from baselines import decentralized, polish_gain
from baselines._sparse import gain_design
from baselines.sparse_delayed import delayed_gain_design as delayed_design
from baselines.stabilizing import STABILITY_TOL, is_stable, local_starts, stability_tol
from codesign import Instance, get_method, paper_instance, registered_methods, spectral_radius
from codesign.status import DIVERGED, USABLE

#: Every built-in method whose designs are static gains (u = K x, or the delayed gain on its
#: augmented loop), with settings that keep the test short; autonomous is the reference
#: "no control" cost, exempt from the rule (tests/test_baselines_lqr.py).
STATIC = {
    "lqr": [{}],
    "decentralized": [{}],
    "sparse_admm": [{}],
    "sparse_newton": [{}],
    "sparse_sdp": [{}],
    "truncated_lqr": [{}],
    "sparse_budget": [{"links": [12, 6, 2, 1, 0]}, {"links": [12, 6, 2, 1, 0], "info_model": "delayed"}],
    "best_pattern": [{"links": [0, 1, 2, 12]}, {"links": [0, 1, 2, 12], "info_model": "delayed"}],
    "sparse_delayed": [{}],
    "refit": [{"graph": "0-1,1-2,3-0", "controller": "delayed"},
              {"graph": "0-1,1-2,3-0", "controller": "instantaneous"}],
}
#: The GRNN methods are registered by baselines/grnn.py (the trainer with its warm starts' static designs).
NOT_STATIC = {"autonomous", "sls", "sls_topologies", "sls_local", "grnn", "grnn_dense", "grnn_fixed", "grnn_sparse"}


def unstable(seed):
    """N = 4 with an unstable open loop, where one L-BFGS run from the LQR diagonal stops unstable."""
    return paper_instance(seed, n=4, degree=2, a_norm=1.2)


def closed_loop_radius(instance, controller) -> float:
    if hasattr(controller, "closed_loop"):  # the delayed gain: its augmented loop
        return spectral_radius(controller.closed_loop(instance))
    return spectral_radius(instance.A + instance.B @ controller.K)


def test_the_rule_is_one_named_margin():
    assert STABILITY_TOL == 1e-6
    assert is_stable(1 - 2 * STABILITY_TOL) and not is_stable(1 - STABILITY_TOL) and not is_stable(1.0)
    assert not is_stable(float("nan")) and not is_stable(float("inf"))
    # In the plant's own time it is the same margin wherever the plant has no slow mode
    # (tests/test_stabilizing_search.py has the slow ones).
    inst = unstable(1)
    assert stability_tol(inst) == stability_tol() == STABILITY_TOL
    assert is_stable(1 - 2 * STABILITY_TOL, inst) and not is_stable(1 - STABILITY_TOL, inst)


def test_a_gain_within_the_margin_of_the_unit_circle_is_diverged():
    inst = Instance.from_matrices(np.diag([1.1, 0.5]), np.eye(2), horizon=10)
    barely = np.diag([-(0.1 + STABILITY_TOL / 2), 0.0])  # closed-loop radius 1 - 5e-7: stable, but not by the rule
    design = gain_design(inst, "x", {}, barely, seconds=0.0, extras={}, polished=False)
    assert design.status == DIVERGED and design.controller is None and "1 - 1e-06" in design.message
    assert gain_design(inst, "x", {}, np.diag([-0.2, 0.0]), seconds=0.0, extras={}, polished=False).status == "optimal"
    delayed = delayed_design(inst, {}, np.diag(barely).copy(), np.zeros((2, 2)), extras={})
    assert delayed.status == DIVERGED and "augmented closed loop" in delayed.message


@pytest.mark.parametrize("seed, best", [(1, 13.99), (2, 3.31), (4, 5.43)])
def test_the_diagonal_gain_is_the_best_stabilizing_one_found(seed, best):
    # One L-BFGS run from the LQR diagonal stops at an unstable local minimum here (58.5 at
    # radius 1.02 on seed 1); 40 random starts found these stabilizing gains.
    d = decentralized(unstable(seed))
    assert d.status == "optimal" and d.cost == pytest.approx(best, rel=0.01)
    assert is_stable(d.extras["spectral_radius"]) and d.extras["search_starts"] > 1
    assert d.extras["spectral_radius"] == pytest.approx(closed_loop_radius(unstable(seed), d.controller), rel=1e-12)
    again = decentralized(unstable(seed))  # the random starts are seeded
    assert again.cost == d.cost and np.array_equal(again.controller.K, d.controller.K)


def test_no_stabilizing_diagonal_gain_is_diverged_with_its_radius():
    # No diagonal gain stabilizes this one (Nelder-Mead on the radius bottoms out at 1.165).
    d = decentralized(unstable(6))
    assert d.status == DIVERGED and d.controller is None and np.isnan(d.cost)
    assert "no stabilizing diagonal gain found from" in d.message and "spectral radius" in d.message
    assert d.extras["spectral_radius"] > 1


def test_where_the_first_start_stabilizes_its_minimum_is_kept_to_the_last_digit():
    inst = paper_instance(0, n=20, a_norm=1.05)
    mask = inst.block_mask()
    first = polish_gain(inst, np.where(mask, inst.K_lqr, 0.0), mask)
    d = decentralized(inst)
    assert d.cost == first.cost and np.array_equal(d.controller.K, first.K)
    assert d.extras["search_start"] == "lqr_diagonal" and d.extras["search_starts"] == 9  # 3 fixed, 6 random
    assert decentralized(inst, start="zero").extras["search_start"] == "zero"


def test_large_instances_draw_fewer_random_starts():
    names = [name for name, _ in local_starts(paper_instance(0, n=60))]
    assert names == ["lqr_diagonal", "zero", "deadbeat", "random 1", "random 2"]


def test_the_static_list_covers_every_built_in_static_method():
    built_in = {name for name, m in registered_methods().items()
                if any(module.startswith("baselines.") for module in m.modules)}
    assert built_in == set(STATIC) | NOT_STATIC


@pytest.fixture(scope="module", params=[1, 2, 4])
def designs(request):
    inst = unstable(request.param)
    found = {}
    for name, settings in STATIC.items():
        for params in settings:
            found[(name, params.get("info_model", params.get("controller", "")))] = get_method(name)(inst, **params)
    return inst, found


def test_every_usable_static_design_has_a_stable_closed_loop(designs):
    inst, found = designs
    for key, ds in found.items():
        for d in ds:
            if d.status in USABLE:
                radius = closed_loop_radius(inst, d.controller)
                assert is_stable(radius), (key, d.params, d.status, radius)
            else:
                assert d.controller is None and np.isnan(d.cost), (key, d.params, d.status)
    # A stabilizing diagonal gain exists on these seeds, and every pattern frees the diagonal: no
    # design is diverged for want of a stabilizing start, and none with no link costs more than it.
    diagonal = found[("decentralized", "")][0]
    for key, ds in found.items():
        for d in ds:
            if key[0] != "lqr":
                assert d.status in USABLE, (key, d.params, d.status, d.message)
            if d.links == 0:
                assert d.cost <= diagonal.cost * (1 + 1e-6), (key, d.params, d.cost, diagonal.cost)
