"""Sparse static gains: ℓ1 ADMM (lqrsp) and ℓ1 SDP paths, truncated LQR, polishing."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from baselines import decentralized, sparse_admm, sparse_sdp, truncated_lqr
from baselines._sparse import GRAD_RTOL, pattern_of
from baselines.sparse_admm import admm_gamma_max
from baselines.sparse_sdp import SparseSDP
from baselines.truncation import truncation_mask
from codesign.design import count_links
from codesign.evaluation import spectral_radius, static_gain_cost, static_gain_cost_and_grad
from codesign.instances import Instance, paper_instance

A_NORMS = (0.995, 1.05)
METHODS = {"sparse_admm": sparse_admm, "sparse_sdp": sparse_sdp}


@pytest.fixture(scope="module", params=A_NORMS, ids=lambda a: f"a{a}")
def instance(request):
    return paper_instance(0, a_norm=request.param)


@pytest.fixture(scope="module")
def paths(instance):
    """Default-grid paths of both methods on one paper instance, computed once."""
    return {name: method(instance) for name, method in METHODS.items()}


def _front(designs):
    """(links, cost) of the usable designs."""
    return [(d.links, d.cost) for d in designs if d.status == "optimal"]


@pytest.mark.parametrize("name", METHODS)
def test_dense_end_is_lqr(instance, paths, name):
    first = paths[name][0]
    n = instance.n
    assert first.status == "optimal"
    assert first.cost <= 1.0 + 1e-3
    assert first.links >= 0.9 * n * (n - 1)


@pytest.mark.parametrize("name", METHODS)
def test_sparse_end_is_decentralized(instance, paths, name):
    last = paths[name][-1]
    K = last.controller.K
    assert last.status == "optimal"
    assert last.links == 0
    assert np.count_nonzero(K - np.diag(np.diag(K))) == 0
    assert spectral_radius(instance.A + instance.B @ K) < 1
    best_diagonal = decentralized(instance)
    assert last.cost == pytest.approx(best_diagonal.cost, rel=1e-9)


@pytest.mark.parametrize("name", METHODS)
def test_links_fall_and_cost_rises(paths, name):
    front = _front(paths[name])
    assert len(front) == len(paths[name])
    links = [links for links, _ in front]
    costs = [cost for _, cost in front]
    assert all(b <= a for a, b in zip(links, links[1:])), links
    assert all(b >= a - 1e-12 for a, b in zip(costs, costs[1:])), costs
    assert links[0] > links[-1]


@pytest.mark.parametrize("name", METHODS)
def test_every_point_is_exact_stable_and_polished(instance, paths, name):
    gammas = []
    for design in paths[name]:
        K = design.controller.K
        gammas.append(design.params["gamma"])
        assert design.method == name
        assert design.info_model == "instantaneous"
        assert design.cost_kind == "exact" and design.cost_stderr == 0
        assert spectral_radius(instance.A + instance.B @ K) < 1
        assert design.cost == static_gain_cost(instance, K)
        assert (design.links, design.self_loops) == count_links(K)
        cost, grad = static_gain_cost_and_grad(instance, K)
        assert np.linalg.norm(grad[pattern_of(K)]) < GRAD_RTOL * cost
        assert design.seconds > 0
    assert gammas == sorted(gammas) and len(set(gammas)) == len(gammas)


def test_extras_record_the_solver(paths):
    for design in paths["sparse_sdp"]:
        extras = design.extras
        if design.params["gamma"] == float("inf"):
            assert extras["decentralized"] and design.links == 0
            continue
        assert extras["solver"] == "SCS"
        assert extras["solver_status"] == "optimal"
        assert extras["iterations"] > 0 and extras["solve_time"] > 0
        # The diagonal-X SDP bounds the infinite-horizon cost of K = Y X^-1 from above.
        assert extras["sdp_bound"] >= 1.0
    for design in paths["sparse_admm"]:
        assert design.params["rho"] == 100.0 and design.params["reweight"] == 3
        if design.params["gamma"] < float("inf"):
            assert design.extras["solver"] == "admm"
            assert design.extras["admm_iterations"] > 0


#: "Matches": the ADMM front may exceed truncation by this relative amount. On the
#: dense end both polish near-identical patterns to costs that differ in the 6th
#: digit (worst seen on seeds 0-9, both a_norms: 9e-5 relative, at 28 links).
MATCH_RTOL = 1e-4


def _check_admm_front_against_truncation(instance, admm_designs):
    admm = _front(admm_designs)
    counts = sorted({links for links, _ in admm})
    truncated = {d.params["links"]: d for d in truncated_lqr(instance, links=counts)}
    strictly_better = 0
    for count in counts:
        best_admm = min(cost for links, cost in admm if links <= count)
        assert truncated[count].status == "optimal"
        assert best_admm <= truncated[count].cost * (1 + MATCH_RTOL), (count, best_admm, truncated[count].cost)
        strictly_better += best_admm < truncated[count].cost * (1 - MATCH_RTOL)
    return strictly_better


#: Known exceptions to "the ADMM front matches or beats truncation" on the paper
#: family, seeds 0-29 at both a_norms (60 instances, the same on every machine since
#: the generator fixes the basis of repeated eigenvalues): (a_norm, seed) -> what
#: happens. Both are heuristics for a combinatorial problem, and each misses on 3 of 60.
ADMM_LOSES_TO_TRUNCATION = {
    (1.05, 0): "reweighted l1's 4-link point is 5.7e-3 above truncation's (1.228790 against 1.221838)",
    (1.05, 7): "reweighted l1's 12-link point is 3.7e-4 above truncation's (1.052235 against 1.051850)",
    (0.995, 27): "reweighted l1's 8-link point is 1.5e-4 above truncation's (1.051423 against 1.051269)",
}
PLAIN_L1_LOSES_TO_TRUNCATION = {
    (0.995, 0): "plain l1's 4-link point is 3.7e-3 above truncation's (1.165078 against 1.160730)",
    (0.995, 2): "plain l1's 58-link point is 1.4e-4 above truncation's (1.010573 against 1.010433)",
    (0.995, 14): "plain l1's 12-link point is 6.1e-4 above truncation's (1.111692 against 1.111017)",
}


def _expect_known_loss(request, instance, known_losses=ADMM_LOSES_TO_TRUNCATION):
    known = known_losses.get((instance.spec["a_norm"], instance.spec["seed"]))
    if known:
        request.applymarker(pytest.mark.xfail(strict=True, raises=AssertionError, reason=known))


def test_admm_matches_or_beats_truncated_lqr(instance, paths, request):
    _expect_known_loss(request, instance)
    _check_admm_front_against_truncation(instance, paths["sparse_admm"])


def test_plain_l1_admm_matches_or_beats_truncated_lqr(instance, request):
    _expect_known_loss(request, instance, PLAIN_L1_LOSES_TO_TRUNCATION)
    _check_admm_front_against_truncation(instance, sparse_admm(instance, reweight=1))


def test_admm_gamma_max_gives_the_diagonal_gain():
    inst = paper_instance(3, n=10)
    top = admm_gamma_max(inst)
    below, above = sparse_admm(inst, gammas=[0.05 * top, top], reweight=1, diagonal_end=False)
    assert below.links > 0
    assert above.links == 0


def test_sdp_gamma_max_is_exact():
    inst = paper_instance(2, n=8, a_norm=1.05)
    sdp = SparseSDP(inst, solver="clarabel")  # exactness needs the interior-point solve
    top = sdp.gamma_max()
    off = ~np.eye(inst.n, dtype=bool)
    below, above = sdp.solve(0.97 * top), sdp.solve(1.03 * top)
    assert np.abs(below["Y"][off]).max() > 1e-3 * np.abs(below["Y"]).max()
    assert np.abs(above["Y"][off]).max() < 1e-6 * np.abs(above["Y"]).max()


@pytest.mark.parametrize("solver", ["clarabel", "scs"])
def test_sdp_screens_gammas_beyond_a_certified_diagonal_point(solver):
    """Once a γ's solution is diagonal, its dual certifies every larger γ: no solve, same designs."""
    inst = paper_instance(2, n=8, a_norm=1.05)
    top = SparseSDP(inst, solver="clarabel").gamma_max()
    gammas = [0.3 * top, 1.5 * top, 3 * top, 10 * top]
    screened = sparse_sdp(inst, gammas=gammas, solver=solver)
    solved = sparse_sdp(inst, gammas=gammas, solver=solver, screen=False)
    assert [d.links for d in screened] == [d.links for d in solved]
    assert screened[0].links > 0 and screened[1].links == 0
    assert [bool(d.extras.get("screened")) for d in screened] == [False, False, True, True, False]
    # The certificate read at 1.5 gamma_max is gamma_max itself, to the solves' accuracy (gamma_max's own
    # solve at weight 1e6 agrees to 3e-5 with Clarabel's at 1.5 gamma_max; SCS's dual carries eps = 1e-5).
    assert screened[1].extras["diagonal_certificate"] == pytest.approx(top, rel=1e-4 if solver == "clarabel" else 1e-3)
    for a, b in zip(screened, solved):
        assert a.status == b.status == "optimal" and a.params == b.params
        assert a.cost == pytest.approx(b.cost, rel=1e-12)
    assert all(d.extras["iterations"] == 0 and d.extras["screened_by_gamma"] == gammas[1] for d in screened[2:4])


def test_sdp_gain_is_y_over_x_with_evaluator_sign():
    inst = paper_instance(1, n=8)
    result = SparseSDP(inst, solver="clarabel").solve(0.0)
    K = result["K"]
    assert np.allclose(K, -result["Y"] @ np.diag(1.0 / result["x"]))
    # u = K x with the sign included: the SDP certificate A_cl X A_cl' + I <= X holds.
    Acl = inst.A + inst.B @ K
    X = np.diag(result["x"])
    assert np.linalg.eigvalsh(X - Acl @ X @ Acl.T - np.eye(inst.n)).min() > -1e-6
    # X bounds the covariance sum L, so the SDP objective bounds trace(P_K) from above.
    P_K = scipy.linalg.solve_discrete_lyapunov(Acl.T, inst.Q + K.T @ inst.R @ K)
    assert result["bound"] >= np.trace(P_K) * (1 - 1e-7)
    assert spectral_radius(Acl) < 1


def test_truncation_mask_keeps_diagonal_and_largest_entries():
    rng = np.random.default_rng(0)
    K = rng.standard_normal((6, 6))
    mask = truncation_mask(K, 7)
    assert mask.diagonal().all()
    off = ~np.eye(6, dtype=bool)
    assert mask[off].sum() == 7
    assert np.abs(K[off & mask]).min() >= np.abs(K[off & ~mask]).max()
    with pytest.raises(ValueError, match="links"):
        truncation_mask(K, 31)


def test_truncated_lqr_path():
    inst = paper_instance(0, n=8)
    designs = truncated_lqr(inst, links=[56, 10, 0])
    assert [d.links for d in designs] == [56, 10, 0]
    assert designs[0].cost == pytest.approx(1.0, abs=1e-9)  # nothing truncated: LQR
    assert designs[-1].cost == pytest.approx(decentralized(inst).cost, rel=1e-12)
    assert designs[0].cost <= designs[1].cost <= designs[2].cost
    with pytest.raises(ValueError, match="links"):
        truncated_lqr(inst, links=[-1])


@pytest.mark.parametrize("name", METHODS)
@pytest.mark.parametrize("gammas", [[-1.0, 1.0], [float("nan")], []])
def test_bad_gammas_raise(name, gammas):
    inst = paper_instance(0, n=6)
    with pytest.raises(ValueError, match="gammas"):
        METHODS[name](inst, gammas=gammas)


def test_admm_rejects_non_stabilizing_start():
    inst = paper_instance(0, n=6, a_norm=1.05)
    with pytest.raises(ValueError, match="does not stabilize"):
        sparse_admm(inst, gammas=[0.1], start=np.zeros((6, 6)).tolist())
    with pytest.raises(ValueError, match="start"):
        sparse_admm(inst, gammas=[0.1], start=np.zeros((5, 5)).tolist())
    with pytest.raises(ValueError, match="rho"):
        sparse_admm(inst, gammas=[0.1], rho=-1.0)


def _no_diagonal_certificate():
    # Node 0 has no actuator and x0(t+1) = x0(t) + x1(t): stabilizable through node 1,
    # but row 0 of A_cl is fixed at [1, 1], so no diagonal X gives A_cl X A_cl' + I <= X.
    return Instance.from_matrices([[1.0, 1.0], [-0.5, 0.0]], np.diag([0.0, 1.0]), horizon=20)


def test_infeasible_sdp_is_a_recorded_status():
    inst = _no_diagonal_certificate()
    designs = sparse_sdp(inst, gammas=[0.1, 1.0])
    assert [d.status for d in designs] == ["infeasible", "infeasible"]
    assert all(np.isnan(d.cost) and d.controller is None for d in designs)
    assert all(d.extras["solver_status"] == "infeasible" for d in designs)
    assert [d.params["gamma"] for d in designs] == [0.1, 1.0]
    # The default grid: every point recorded as infeasible, and no diagonal end is
    # added to a path that never produced a gain.
    default = sparse_sdp(inst)
    assert len(default) == 10 and all(d.status == "infeasible" for d in default)
    with pytest.raises(RuntimeError, match="diagonal SDP"):
        SparseSDP(inst).gamma_max()
    # The ADMM needs no diagonal certificate and designs stabilizing gains here.
    assert all(d.status == "optimal" for d in sparse_admm(inst, gammas=[1e-3, 1.0]))


@pytest.mark.parametrize("solver, why", [("clarabel", "user_limit"), ("scs", "iteration limit (2)")])
def test_sdp_iteration_limit_is_a_recorded_failure(solver, why):
    inst = paper_instance(0, n=6)
    (design,) = sparse_sdp(inst, gammas=[0.01], max_iter=2, solver=solver, diagonal_end=False)
    assert design.status == "failed" and design.controller is None
    assert why in design.message
    if solver == "clarabel":
        assert design.extras["solver_status"] == "user_limit"


def test_sdp_rejects_unknown_solver_and_bad_eps():
    inst = paper_instance(0, n=6)
    with pytest.raises(ValueError, match="unknown SDP solver 'mosek'"):
        sparse_sdp(inst, solver="mosek")
    for bad in (0.0, -1e-5, 1.0, True):
        with pytest.raises(ValueError, match="eps"):
            sparse_sdp(inst, eps=bad)


def _same_designs(fast, reference):
    """Pattern by pattern; polished costs on the same pattern agree to rounding."""
    assert [d.params for d in fast] == [d.params for d in reference]
    for f, r in zip(fast, reference):
        assert f.status == r.status == "optimal", (f.message, r.message)
        np.testing.assert_array_equal(pattern_of(np.asarray(f.controller.K)), pattern_of(np.asarray(r.controller.K)))
        assert f.cost == pytest.approx(r.cost, rel=1e-9)


def test_scs_path_reaches_clarabels_designs():
    """The default SCS solve gives the reference (Clarabel) patterns, hence the same polished gains.

    On this instance every point agrees. Elsewhere a pattern can differ in an entry that
    the SDP puts within a few percent of the threshold (2 of 80 points on N = 20 paper
    instances, seeds 0-3, both norms: relative |Y_ij| 1.02e-4 and 1.05e-4 by Clarabel,
    9.2e-5 and 9.9e-5 by SCS, objectives equal to 1e-9): the SDP does not determine
    such an entry more finely than about 1e-5 of max |Y|.
    """
    inst = paper_instance(2, n=20, a_norm=1.05)
    scs = sparse_sdp(inst)
    assert all(d.extras["solver"] == "SCS" for d in scs[:-1])
    _same_designs(scs, sparse_sdp(inst, solver="clarabel"))


@pytest.mark.slow
def test_scs_reaches_clarabels_designs_at_n50():
    inst = paper_instance(0, n=50, a_norm=0.995)
    gammas = [1e-3, 3e-2]
    _same_designs(sparse_sdp(inst, gammas=gammas), sparse_sdp(inst, gammas=gammas, solver="clarabel"))


def test_sdp_size_guard_fails_fast_with_a_reason():
    inst = paper_instance(0, n=6)
    designs = sparse_sdp(inst, gammas=[1e-3, 0.1], max_states=5)
    assert [d.status for d in designs] == ["failed", "failed"]  # no diagonal end without a usable point
    assert [d.params["gamma"] for d in designs] == [1e-3, 0.1]
    assert all("6 states" in d.message and "max_states = 5" in d.message for d in designs)
    assert all(d.extras["size_guard"] and d.controller is None for d in designs)
    # At the limit the path is solved as usual.
    assert all(d.status == "optimal" for d in sparse_sdp(inst, gammas=[1e-3], max_states=6))
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="max_states"):
            sparse_sdp(inst, gammas=[1e-3], max_states=bad)


def test_unpolished_points_are_exact_too():
    inst = paper_instance(1, n=8)
    designs = sparse_admm(inst, gammas=[1e-4, 1e-3], polish=False, diagonal_end=False)
    assert len(designs) == 2
    for design in designs:
        assert design.cost == static_gain_cost(inst, design.controller.K)
        assert design.extras["polish_iterations"] == 0


@pytest.mark.parametrize("name", METHODS)
def test_user_grid_is_closed_by_the_diagonal_gain(name):
    inst = paper_instance(1, n=8)
    designs = METHODS[name](inst, gammas=[1e-4, 1e-3])
    assert [d.params["gamma"] for d in designs] == [1e-4, 1e-3, float("inf")]
    assert designs[1].links > 0
    end = designs[-1]
    assert end.links == 0 and end.status == "optimal" and end.extras["decentralized"]
    assert end.cost == pytest.approx(decentralized(inst).cost, rel=1e-12)


def test_registry_and_preset():
    from compare.run.registry import get_method

    preset = Path(__file__).resolve().parents[1] / "compare" / "run" / "presets" / "baselines-small.toml"
    spec = tomllib.loads(preset.read_text())
    assert spec["name"] == "baselines-small"
    names = [entry["method"] for entry in spec["methods"]]
    assert {"lqr", "sparse_admm", "sparse_sdp"} <= set(names)
    for entry in spec["methods"]:
        get_method(entry["method"]).check_params(entry.get("params", {}))
    admm = get_method("sparse_admm")
    assert {"gammas", "reweight", "rho", "polish"} <= set(admm.hyperparameters)
    assert {"gammas", "polish", "threshold"} <= set(get_method("sparse_sdp").hyperparameters)
    with pytest.raises(ValueError, match="rho"):
        admm.check_params({"rho": "big"})


@pytest.mark.slow
@pytest.mark.parametrize("a_norm", A_NORMS)
@pytest.mark.parametrize("seed", range(1, 30))
@pytest.mark.parametrize("reweight", [3, 1], ids=["reweighted", "plain"])
def test_paper_scale_admm_front_against_truncation(reweight, seed, a_norm, request):
    inst = paper_instance(seed, a_norm=a_norm)
    _expect_known_loss(request, inst, ADMM_LOSES_TO_TRUNCATION if reweight > 1 else PLAIN_L1_LOSES_TO_TRUNCATION)
    _check_admm_front_against_truncation(inst, sparse_admm(inst, reweight=reweight))


@pytest.mark.slow
@pytest.mark.parametrize("a_norm", A_NORMS)
@pytest.mark.parametrize("seed", range(1, 5))
def test_paper_scale_paths(seed, a_norm):
    inst = paper_instance(seed, a_norm=a_norm)
    for name, method in METHODS.items():
        designs = method(inst)
        assert all(d.status == "optimal" for d in designs), name
        assert designs[0].cost <= 1 + 1e-3 and designs[-1].links == 0
        links = [d.links for d in designs]
        costs = [d.cost for d in designs]
        assert all(b <= a for a, b in zip(links, links[1:])), (name, links)
        assert all(b >= a - 1e-12 for a, b in zip(costs, costs[1:])), (name, costs)


@pytest.mark.parametrize("path", ["sparse_admm", "sparse_newton"])
def test_an_l1_path_keeps_the_previous_gain_when_a_gamma_fails(path, monkeypatch):
    import importlib

    import baselines

    from codesign.design import Design

    # The path (shared by the l1 solvers) lives in baselines._sparse.
    path_module = importlib.import_module("baselines._sparse")

    inst = paper_instance(1, n=8)
    real = path_module.design_on_pattern
    calls = []

    def failing_second(instance, method, params, K, **kwargs):
        calls.append(params["gamma"])
        if len(calls) == 2:  # as if polishing had left a destabilizing gain
            return Design.failure(method, params, "diverged", "gain does not stabilize",
                                  info_model="instantaneous")
        return real(instance, method, params, K, **kwargs)

    monkeypatch.setattr(path_module, "design_on_pattern", failing_second)
    method = getattr(baselines, path)
    first, second, third = method(inst, gammas=[1e-4, 1e-3, 1e-2], diagonal_end=False)
    assert second.status == "optimal" and second.extras["fallback"]
    assert "previous gamma" in second.message and second.params["gamma"] == 1e-3
    assert (second.links, second.cost) == (first.links, first.cost)
    assert not third.extras["fallback"] and third.status == "optimal"

    calls.clear()
    monkeypatch.setattr(path_module, "design_on_pattern",
                        lambda instance, method, params, K, **kw: Design.failure(
                            method, params, "diverged", "gain does not stabilize", info_model="instantaneous"))
    (only,) = method(inst, gammas=[1e-4])
    assert only.status == "diverged" and np.isnan(only.cost)


@pytest.mark.parametrize("name", ["sparse_admm", "sparse_newton"])
def test_a_paths_design_seconds_add_up_to_no_more_than_its_wall_time(name):
    """The γ → ∞ end point used to carry the diagonal gain's seconds a γ's timer had already counted."""
    import time

    import baselines

    instance = paper_instance(1, n=6, a_norm=1.05)
    start = time.perf_counter()
    designs = getattr(baselines, name)(instance, gammas=[1e-2, 1.0])
    wall = time.perf_counter() - start
    assert designs[-1].params["gamma"] == float("inf")
    assert sum(d.seconds for d in designs) <= wall
