"""Sparse delayed static gains: u_i(t) = K_ii x_i(t) + sum_{j != i} K_ij x_j(t - 1)."""

import importlib
import io

import numpy as np
import pytest

from baselines import decentralized
from baselines._sparse import GRAD_RTOL
from baselines.sparse_delayed import (
    DELAYED_GAMMAS,
    DelayedStaticGain,
    delayed_closed_loop,
    delayed_gain_cost,
    delayed_gain_cost_and_grad,
    sparse_delayed,
)
from codesign.controllers import controller_from_arrays
from codesign.design import count_links
from codesign.evaluation import (
    exact_cost,
    simulate,
    spectral_radius,
    static_gain_cost_and_grad,
    validation_set,
)
from codesign.instances import paper_instance
from codesign.methods import registered_methods
from references import augmented_delayed_reference  # tests/references.py

# `baselines.sparse_delayed` resolves to the function once a package imports it; the module by full name.
delayed_module = importlib.import_module("baselines.sparse_delayed")

A_NORMS = (1.05, 0.995)
SIMULATION_DRAWS = 20_000


def _random_gain(n, rng, scale=0.2):
    K_local = np.diag(-0.5 + 0.1 * rng.standard_normal(n))
    K_delayed = scale * rng.standard_normal((n, n))
    np.fill_diagonal(K_delayed, 0.0)
    return K_local, K_delayed


# -- cost and gradient ---------------------------------------------------------------
def test_gradient_matches_finite_differences():
    inst = paper_instance(2, n=6, a_norm=1.05, horizon=15)
    n = inst.n
    K_local, K_delayed = _random_gain(n, np.random.default_rng(0))
    cost, g_local, g_delayed = delayed_gain_cost_and_grad(inst, K_local, K_delayed)
    assert np.count_nonzero(g_local - np.diag(np.diag(g_local))) == 0
    assert np.count_nonzero(np.diag(g_delayed)) == 0
    h = 1e-6
    for i in range(n):
        for j in range(n):
            # Free entries only: the diagonal of K_local, the off-diagonal of K_delayed.
            which, grad = (K_local, g_local) if i == j else (K_delayed, g_delayed)
            plus, minus = which.copy(), which.copy()
            plus[i, j] += h
            minus[i, j] -= h
            args = (plus, K_delayed) if i == j else (K_local, plus)
            args_minus = (minus, K_delayed) if i == j else (K_local, minus)
            fd = (delayed_gain_cost(inst, *args) - delayed_gain_cost(inst, *args_minus)) / (2 * h)
            assert fd == pytest.approx(grad[i, j], rel=1e-6, abs=1e-9 * cost), (i, j)


def test_cost_and_gradient_match_the_augmented_lyapunov_recursion():
    inst = paper_instance(1, n=8, a_norm=0.995, horizon=20)
    K_local, K_delayed = _random_gain(inst.n, np.random.default_rng(1))
    cost, g_local, g_delayed = delayed_gain_cost_and_grad(inst, K_local, K_delayed)
    ref_cost, ref_local, ref_delayed = augmented_delayed_reference(inst, K_local, K_delayed)
    assert cost == pytest.approx(ref_cost, rel=1e-12)
    scale = np.abs(ref_delayed).max()
    assert np.allclose(g_local, np.diag(np.diag(ref_local)), rtol=0, atol=1e-12 * scale)
    off = ~np.eye(inst.n, dtype=bool)
    assert np.allclose(g_delayed[off], ref_delayed[off], rtol=0, atol=1e-12 * scale)
    # The controller's closed-loop responses give the same exact cost.
    assert exact_cost(inst, DelayedStaticGain(K_local, K_delayed)) == pytest.approx(cost, rel=1e-12)


def test_no_delayed_term_is_the_static_gain():
    inst = paper_instance(0, n=8)
    K = np.diag(np.diag(inst.K_lqr))
    cost, g_local, g_delayed = delayed_gain_cost_and_grad(inst, K, np.zeros_like(K))
    static_cost, static_grad = static_gain_cost_and_grad(inst, K)
    assert cost == pytest.approx(static_cost, rel=1e-12)
    assert np.allclose(np.diag(g_local), np.diag(static_grad), rtol=1e-10, atol=1e-14)


# -- the controller -------------------------------------------------------------------
def test_controller_uses_own_state_now_and_neighbours_one_step_late():
    K_local = np.diag([1.0, 2.0, 3.0])
    K_delayed = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    ctrl = DelayedStaticGain(K_local, K_delayed)
    state = ctrl.reset(2)
    assert np.array_equal(state, np.zeros((2, 3)))
    x0 = np.array([[1.0, 1.0, 1.0], [0.0, 2.0, 0.0]])
    u0, state = ctrl.step(state, x0)
    assert np.array_equal(u0, x0 * [1.0, 2.0, 3.0])  # x(-1) = 0: local feedback only
    x1 = np.zeros((2, 3))
    u1, _ = ctrl.step(state, x1)
    assert np.array_equal(u1, x0 @ K_delayed.T)  # neighbours' x(0), one step late
    assert ctrl.support.tolist() == [[True, True, False], [False, True, False], [True, False, True]]
    assert count_links(ctrl.support) == (2, 3)
    with pytest.raises(ValueError, match="K_local must be diagonal"):
        DelayedStaticGain(np.ones((3, 3)), K_delayed)
    with pytest.raises(ValueError, match="zero diagonal"):
        DelayedStaticGain(K_local, np.eye(3))


def test_save_load_round_trip():
    inst = paper_instance(0, n=8)
    K_local, K_delayed = _random_gain(inst.n, np.random.default_rng(3), scale=0.05)
    ctrl = DelayedStaticGain(K_local, K_delayed)
    assert ctrl.kind == "delayed_static_gain"
    buffer = io.BytesIO()  # as the result store does: an .npz blob, no pickles
    np.savez_compressed(buffer, **ctrl.arrays())
    buffer.seek(0)
    with np.load(buffer, allow_pickle=False) as data:
        loaded = controller_from_arrays(ctrl.kind, {k: data[k] for k in data.files})
    assert isinstance(loaded, DelayedStaticGain)
    assert np.array_equal(loaded.K_local, K_local) and np.array_equal(loaded.K_delayed, K_delayed)
    assert exact_cost(inst, loaded) == exact_cost(inst, ctrl)
    x0 = validation_set(inst, 50)
    assert simulate(inst, loaded, x0).cost == simulate(inst, ctrl, x0).cost


# -- the path on paper instances ------------------------------------------------------
@pytest.fixture(scope="module", params=A_NORMS, ids=lambda a: f"a{a}")
def instance(request):
    return paper_instance(0, a_norm=request.param)


@pytest.fixture(scope="module")
def path(instance):
    return sparse_delayed(instance)


def test_path_runs_from_dense_to_no_links(instance, path):
    n = instance.n
    gammas = [d.params["gamma"] for d in path]
    assert gammas == [*DELAYED_GAMMAS, float("inf")]
    assert path[0].params["gamma"] == 0 and path[0].links == n * (n - 1)
    assert path[-1].links == 0
    assert all(d.status == "optimal" for d in path)
    links = [d.links for d in path]
    costs = [d.cost for d in path]
    # As γ grows: links never increase, and the cost never decreases by more than
    # 1e-12 (rounding) — on both instances the front is monotone.
    assert all(b <= a for a, b in zip(links, links[1:])), links
    assert all(b >= a - 1e-12 for a, b in zip(costs, costs[1:])), costs
    assert len(set(links)) >= 8  # many intermediate patterns, not a jump from dense to diagonal


def test_every_point_is_exact_stabilizing_and_polished(instance, path):
    off = ~np.eye(instance.n, dtype=bool)
    for design in path:
        ctrl = design.controller
        assert isinstance(ctrl, DelayedStaticGain)
        assert design.method == "sparse_delayed" and design.info_model == "delayed"
        assert design.cost_kind == "exact" and design.cost_stderr == 0
        assert {"gamma", "reweight", "eps_weight"} <= set(design.params)
        radius = spectral_radius(delayed_closed_loop(instance, ctrl.K_local, ctrl.K_delayed))
        assert radius < 1 and design.extras["spectral_radius"] == pytest.approx(radius, rel=1e-12)
        assert design.cost == exact_cost(instance, ctrl)
        assert design.cost == pytest.approx(delayed_gain_cost(instance, ctrl.K_local, ctrl.K_delayed), rel=1e-12)
        assert (design.links, design.self_loops) == count_links(ctrl.support)
        assert design.links == np.count_nonzero(ctrl.K_delayed[off])
        # Polished: the gradient over the free entries (diagonal of K_local, support of
        # K_delayed) is below 1e-6 of the cost, recomputed here and as recorded.
        cost, g_local, g_delayed = delayed_gain_cost_and_grad(instance, ctrl.K_local, ctrl.K_delayed)
        masked = np.sqrt(np.sum(np.diag(g_local) ** 2) + np.sum(g_delayed[ctrl.K_delayed != 0] ** 2))
        assert masked < GRAD_RTOL * cost
        assert design.extras["masked_grad_rel"] < GRAD_RTOL
        assert design.seconds > 0


def _simulated_designs(path):
    """The dense end, a middle pattern and the sparsest pattern with links (a 20,000-draw rollout is ~1-3 s)."""
    middle = next(d for d in path if d.links <= 60)
    sparsest = [d for d in path if d.links > 0][-1]
    return {"dense": path[0], "middle": middle, "sparsest": sparsest}


def test_exact_cost_equals_simulation(instance, path):
    x0 = validation_set(instance, SIMULATION_DRAWS)
    chosen = _simulated_designs(path)
    assert chosen["dense"].links > chosen["middle"].links > chosen["sparsest"].links > 0
    for name, design in chosen.items():
        rollout = simulate(instance, design.controller, x0)
        assert rollout.bounded
        z = (rollout.cost - design.cost) / rollout.stderr
        assert abs(z) < 3, (name, design.links, design.cost, rollout.cost, rollout.stderr)
    # With x(0) = e_j, j = 1..n, n times the mean simulated cost is the exact cost itself:
    # the controller's step() realizes the gain that the cost formula scores, at every point.
    for design in path:
        exact_from_basis = simulate(instance, design.controller, np.eye(instance.n)).cost * instance.n
        assert exact_from_basis == pytest.approx(design.cost, rel=1e-12)


def test_ends_against_lqr_and_decentralized(instance, path):
    dense, end = path[0], path[-1]
    assert dense.cost >= 1.0  # a delayed gain sees less than LQR
    best_diagonal = decentralized(instance)
    # The zero-link end is the decentralized gain itself: equal costs (to rounding).
    assert end.cost == pytest.approx(best_diagonal.cost, rel=1e-12)
    assert np.array_equal(end.controller.K_local, best_diagonal.controller.K)
    assert not end.controller.K_delayed.any()
    assert end.extras["decentralized"]
    assert dense.cost < end.cost


# -- hyperparameters, failures, reproducibility ------------------------------------------
def test_user_grid_and_reproducibility():
    inst = paper_instance(1, n=8)
    first = sparse_delayed(inst, gammas=[1e-3, 1e-4], diagonal_end=False)
    assert [d.params["gamma"] for d in first] == [1e-4, 1e-3]  # sorted, as a warm-started path needs
    assert first[0].links >= first[1].links > 0
    again = sparse_delayed(inst, gammas=[1e-4, 1e-3], diagonal_end=False, seed=5)
    for a, b in zip(first, again):
        assert a.cost == b.cost
        assert np.array_equal(a.controller.K_local, b.controller.K_local)
        assert np.array_equal(a.controller.K_delayed, b.controller.K_delayed)


@pytest.mark.parametrize("kwargs, match", [
    ({"gammas": [-1.0]}, "gammas"),
    ({"gammas": [float("nan")]}, "gammas"),
    ({"gammas": []}, "gammas"),
    ({"eps_weight": 0.0}, "eps_weight"),
    ({"tol": -1.0}, "tol"),
    ({"reweight": 0}, "reweight"),
    ({"maxiter": 0}, "maxiter"),
    ({"seed": -1}, "seed"),
])
def test_bad_hyperparameters_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        sparse_delayed(paper_instance(0, n=6), **kwargs)


def _unstable_second_polish(monkeypatch):
    """polish_delayed, but its second call leaves a destabilizing gain."""
    real = delayed_module.polish_delayed
    calls = []

    def unstable_second(instance, K_local, K_delayed, free=None, **kwargs):
        calls.append(1)
        result = real(instance, K_local, K_delayed, free, **kwargs)
        if len(calls) == 2:  # as if polishing had left a destabilizing gain
            result.K_delayed = np.where(result.K_delayed != 0, 50.0, 0.0)
        return result

    monkeypatch.setattr(delayed_module, "polish_delayed", unstable_second)


def test_a_destabilizing_gain_is_recorded_as_diverged(monkeypatch):
    inst = paper_instance(1, n=8)
    _unstable_second_polish(monkeypatch)
    # Only the path's own start: the stabilizing search's fallbacks are the next test's.
    monkeypatch.setattr(delayed_module, "pattern_starts", lambda decentral: [])
    monkeypatch.setattr(delayed_module, "local_starts", lambda instance: iter(()))
    first, second, third = sparse_delayed(inst, gammas=[0.0, 1e-4, 1e-3], diagonal_end=False)
    assert first.status == "optimal"
    assert second.status == "diverged" and second.controller is None and np.isnan(second.cost)
    assert "does not stabilize" in second.message and second.extras["spectral_radius"] >= 1
    assert second.info_model == "delayed" and second.links > 0
    assert third.status == "optimal" and third.extras["spectral_radius"] < 1


def test_the_stabilizing_search_goes_on_from_the_diagonal_gain(monkeypatch):
    inst = paper_instance(1, n=8)
    _unstable_second_polish(monkeypatch)
    first, second, third = sparse_delayed(inst, gammas=[0.0, 1e-4, 1e-3], diagonal_end=False)
    assert [d.status for d in (first, second, third)] == ["optimal"] * 3
    assert second.extras["polish_start"] == "decentralized" and second.extras["polish_starts"] == 2
    assert second.extras["spectral_radius"] < 1 and "polish_start" not in third.extras


def test_registered_method():
    m = registered_methods()["sparse_delayed"]
    assert {"gammas", "reweight", "eps_weight", "tol", "maxiter", "diagonal_end", "seed"} == set(m.hyperparameters)
    assert m.hyperparameters["reweight"].default == 3
    with pytest.raises(ValueError, match=r"params\.reweight: expected int"):
        m.check_params({"reweight": 1.5})
    designs = m(paper_instance(1, n=8, degree=4, a_norm=1.05, horizon=12), gammas=[0.0, 1e-2])
    assert [d.method for d in designs] == ["sparse_delayed"] * 3
    assert all(d.cost >= 1 for d in designs)


def test_no_stabilizing_diagonal_gain_is_a_recorded_end(monkeypatch):
    # As if the best diagonal gain did not stabilize: diagonal patterns are then polished
    # here like any other, and the γ = inf end is recorded as diverged, with a message.
    monkeypatch.setattr(delayed_module.DecentralizedCache, "usable", lambda self: None)
    inst = paper_instance(1, n=6)
    *path, end = sparse_delayed(inst, gammas=[0.0, 10.0])
    assert [d.status for d in path] == ["optimal", "optimal"]
    assert path[1].links == 0 and "decentralized" not in path[1].extras
    assert end.params["gamma"] == float("inf") and end.status == "diverged" and end.controller is None
    assert "no stabilizing diagonal gain" in end.message
