"""SLS under delay constraints, its realization, the FIR variant and the QI check."""

import functools
import importlib

import cvxpy
import numpy as np
import pytest

import baselines
from baselines import (
    SLSController,
    is_quadratically_invariant,
    sls,
    sls_topologies,
    topology,
)
from codesign import (
    SOLVER_STATUS,
    Instance,
    compare_exact_and_simulated,
    controller_from_arrays,
    hop_distances,
    paper_instance,
    response_cost,
    simulate,
    solver_status,
    static_gain_cost,
    vet_solver_cost,
)
from compare.run.registry import get_method

# The package exports the function ``sls``, which hides the module of the same name.
sls_module = importlib.import_module("baselines.sls")


@pytest.fixture(scope="module")
def inst():
    return paper_instance(0)


@pytest.fixture(scope="module")
def family(inst):
    return {d.params["graph"]: d for d in sls_topologies(inst)}


@pytest.fixture(scope="module")
def fir(inst):
    return sls(inst, fir=15)


@pytest.fixture(scope="module")
def small():
    """A 6-node chain whose plant couples neighbours; given graph = the plant."""
    rng = np.random.default_rng(4)
    n = 6
    chain = np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1)
    A = 1.1 * chain * rng.uniform(0.3, 0.6, (n, n))
    B = np.eye(n) + 0.2 * np.eye(n, k=1)
    return Instance.from_matrices(A, B, horizon=12, name="chain")


# -- the QP ----------------------------------------------------------------------
def test_unconstrained_returns_trace_p(inst):
    design = sls(inst, graph="complete", act_delay=0)
    assert design.status == "optimal"
    assert abs(design.cost - 1.0) < 1e-6
    assert design.links == inst.n * (inst.n - 1)


def test_plant_graph_feasible_and_qi(inst, family):
    design = family["plant"]
    assert design.status == "optimal", design.message
    assert design.extras["qi"] is True
    assert is_quadratically_invariant(inst, topology(inst, "plant")).qi
    off_diagonal = inst.plant_adj.sum() - np.trace(inst.plant_adj)
    assert design.links == off_diagonal
    assert design.info_model == "delayed"
    assert design.cost >= 1.0 - 1e-9


def test_given_graph_infeasible_with_violating_pair(inst, family):
    design = family["given"]
    assert design.status == "infeasible"
    assert np.isnan(design.cost) and design.controller is None
    assert design.links == inst.comm_adj.sum() - np.trace(inst.comm_adj)
    qi = is_quadratically_invariant(inst, inst.comm_adj)
    assert not qi.qi
    i, j = qi.pair
    assert f"node {i}" in design.message and f"node {j}" in design.message
    assert design.extras["qi_pair"] == [i, j]
    # The pair is at least two hops apart on the given graph but one plant step apart.
    assert hop_distances(inst.comm_adj)[i, j] >= 2
    assert qi.transmission > qi.propagation


def test_cost_does_not_increase_with_denser_graph(inst, family):
    order = ["plant", "plant^2", "plant^3", "complete"]
    costs = [family[name].cost for name in order]
    links = [family[name].links for name in order]
    assert all(family[name].status == "optimal" for name in order)
    assert links == sorted(links)
    for sparse, dense in zip(costs, costs[1:]):
        assert dense <= sparse + 1e-7 * sparse
    # Every design keeps the settings the report groups by.
    for name, design in family.items():
        assert design.params["graph"] == name
        assert {"speed", "act_delay", "horizon", "fir"} <= set(design.params)


def test_graphs_with_the_same_edges_are_solved_once(inst, family, monkeypatch):
    """plant^2, plant^3 and complete coincide on this instance: one QP, the same design to the bit."""
    distinct = {topology(inst, name).tobytes() for name in family}
    assert len(distinct) < len(family)  # else this test checks nothing
    solves = []
    solve = sls_module._solve_qp
    monkeypatch.setattr(sls_module, "_solve_qp", lambda *a, **k: solves.append(1) or solve(*a, **k))
    again = {d.params["graph"]: d for d in sls_topologies(inst)}
    assert len(solves) == len(distinct)
    for name, design in again.items():
        alone = sls(inst, graph=name)
        assert (design.status, design.links) == (alone.status, alone.links)
        assert design.cost == alone.cost or (np.isnan(design.cost) and np.isnan(alone.cost))
        assert design.params == alone.params
        first = design.extras.get("same_graph_as")
        if first is not None:
            assert np.array_equal(topology(inst, first), topology(inst, name)) and first != name
            np.testing.assert_array_equal(design.controller.phi_x, alone.controller.phi_x)


def test_given_graph_at_plant_speed_is_qi_and_feasible(inst):
    # The plant is the 3-hop closure of the given graph: three hops per step is as fast.
    assert is_quadratically_invariant(inst, inst.comm_adj, speed=3).qi
    design = sls(inst, graph="given", speed=3)
    assert design.status == "optimal", design.message
    assert design.links == inst.comm_adj.sum() - np.trace(inst.comm_adj)


def test_supports_respect_delays(inst, family):
    design = family["plant"]
    dist = hop_distances(topology(inst, "plant"))
    ctrl = design.controller
    for k in range(1, ctrl.length + 1):
        allowed = dist <= k - 1  # act_delay = 1, speed = 1
        assert np.all(ctrl.phi_u[k - 1][~allowed] == 0)
        assert np.all(ctrl.phi_x[k - 1][~allowed] == 0)


def test_shorter_horizon_scored_on_instance_horizon(small):
    full = sls(small)
    short = sls(small, horizon=4)
    assert full.status == short.status == "optimal"
    phi_x, phi_u = short.controller.closed_loop_responses(small)
    assert phi_x.shape[0] == small.horizon + 1
    assert short.cost == pytest.approx(response_cost(small, phi_x, phi_u), rel=1e-12)
    assert short.cost >= full.cost - 1e-9
    assert short.params["horizon"] == 4 and short.params["fir"] is None


# -- the realization -------------------------------------------------------------
def test_simulation_reproduces_exact_cost(inst, family):
    check = compare_exact_and_simulated(inst, family["plant"].controller)
    assert check["exact"] == pytest.approx(family["plant"].cost, rel=1e-12)
    assert abs(check["z"]) < 3


@pytest.mark.parametrize("noise_std", [0.3, 1.0])
def test_noisy_simulation_matches_prediction(inst, family, noise_std):
    ctrl = family["plant"].controller
    predicted = ctrl.predicted_cost(inst, noise_std=noise_std)
    assert predicted > family["plant"].cost
    rollout = simulate(inst, ctrl, noise_std=noise_std, seed=11)
    assert abs(rollout.cost - predicted) < 3 * rollout.stderr


def test_noise_prediction_agrees_with_static_gain_formula(inst):
    K = inst.K_lqr
    Acl = inst.A + inst.B @ K
    phi_x = np.stack([np.linalg.matrix_power(Acl, t) for t in range(inst.horizon + 1)])
    phi_u = np.einsum("ij,tjk->tik", K, phi_x[:-1])
    for noise_std in (0.0, 0.4):
        assert response_cost(inst, phi_x, phi_u, noise_std=noise_std) == pytest.approx(
            static_gain_cost(inst, K, noise_std=noise_std), rel=1e-10
        )


def test_realization_is_feedback_on_measured_state(inst, family):
    """The innovation δ(t) is the disturbance that entered x(t), recovered from measurements."""
    ctrl = family["plant"].controller
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, inst.n))
    state = ctrl.reset(3)
    disturbance = x
    for _ in range(8):
        u, state = ctrl.step(state, x)
        np.testing.assert_allclose(state[:, : inst.n], disturbance, atol=1e-9)
        disturbance = rng.standard_normal(x.shape)
        x = x @ inst.A.T + u @ inst.B.T + disturbance
    # Model mismatch changes the inputs: they depend on measured x, not only on x(0).
    x0 = rng.standard_normal((1, inst.n))
    runs = []
    for A in (inst.A, 0.9 * inst.A):
        x, state, inputs = x0, ctrl.reset(1), []
        for _ in range(4):
            u, state = ctrl.step(state, x)
            inputs.append(u)
            x = x @ A.T + u @ inst.B.T
        runs.append(np.concatenate(inputs))
    assert np.allclose(runs[0][0], runs[1][0])
    assert not np.allclose(runs[0][1:], runs[1][1:])


def test_controller_arrays_round_trip(inst, family):
    ctrl = family["plant"].controller
    rebuilt = controller_from_arrays(ctrl.kind, ctrl.arrays())
    assert isinstance(rebuilt, SLSController)
    x0 = np.random.default_rng(1).standard_normal((4, inst.n))
    assert simulate(inst, rebuilt, x0).cost == simulate(inst, ctrl, x0).cost
    with pytest.raises(ValueError, match="phi_x"):
        SLSController(ctrl.phi_x[:-1], ctrl.phi_u)


# -- FIR variant --------------------------------------------------------------------
def test_fir_is_exact_and_stationary(inst, fir):
    assert fir.status == "optimal", fir.message
    assert fir.params["fir"] == 15 and fir.params["horizon"] is None
    phi_x, phi_u = fir.controller.closed_loop_responses(inst)
    assert fir.cost == pytest.approx(response_cost(inst, phi_x, phi_u), rel=1e-12)
    assert fir.cost == pytest.approx(fir.extras["objective"], rel=1e-6)
    # Finite impulse response: nothing left after F steps.
    assert np.max(np.abs(phi_x[15:])) < 1e-8 and np.max(np.abs(phi_u[15:])) < 1e-8


def test_fir_bounded_over_long_noisy_rollout(inst, fir):
    rollout = simulate(inst, fir.controller, steps=500, noise_std=0.5, seed=2)
    assert rollout.bounded
    # Stationary: the state stays at the noise level, nowhere near the bound.
    assert rollout.max_state < 50


def test_fir_too_short_is_infeasible_not_an_exception(inst):
    design = sls(inst, fir=1)
    assert design.status == "infeasible"
    assert "too short" in design.message
    assert design.params["fir"] == 1


# -- statuses and inputs ------------------------------------------------------------
def test_solver_trouble_is_a_status(inst, monkeypatch):
    monkeypatch.setattr(
        sls_module, "_solve_qp", lambda *a, **k: (None, None, {"solver_status": "optimal_inaccurate"})
    )
    design = sls(inst)
    assert design.status == "failed" and "optimal_inaccurate" in design.message
    assert np.isnan(design.cost) and design.links > 0

    T, n = inst.horizon, inst.n
    X, U = np.zeros((T + 1, n, n)), np.zeros((T, n, n))
    X[0] = np.eye(n)
    absurd = {"solver_status": "optimal", "objective": 1e29, "residual": 0.0}
    monkeypatch.setattr(sls_module, "_solve_qp", lambda *a, **k: (X, U, absurd))
    design = sls(inst)
    assert design.status == "failed" and "absurd" in design.message and np.isnan(design.cost)

    def broken(*a, **k):
        raise cvxpy.error.SolverError("boom")

    monkeypatch.undo()
    monkeypatch.setattr(cvxpy.Problem, "solve", broken)
    design = sls(inst)
    assert design.status == "failed" and "boom" in design.message


def test_one_status_policy():
    assert SOLVER_STATUS == {"optimal": "optimal", "optimal_inaccurate": "inaccurate",
                             "infeasible": "infeasible", "infeasible_inaccurate": "infeasible"}
    assert solver_status("optimal_inaccurate") == "inaccurate"
    assert [solver_status(raw) for raw in ("user_limit", "solver_error", "unbounded", None)] == ["failed"] * 4
    assert vet_solver_cost("inaccurate", 1.5 * (1 + 1e-4), 1.5) == ("inaccurate", "")
    status, why = vet_solver_cost("inaccurate", 1e29, 1.5)
    assert status == "failed" and "disagrees" in why
    assert vet_solver_cost("inaccurate", 1.5, float("inf"))[0] == "failed"
    assert vet_solver_cost("optimal", 1.5 * (1 + 1e-4), 1.5, rtol=1e-5)[0] == "failed"
    assert vet_solver_cost("infeasible", float("nan"), float("nan")) == ("infeasible", "")


def test_inaccurate_solve_kept_only_when_the_realized_cost_agrees(small, monkeypatch):
    exact = {label: sls(small, **kwargs) for label, kwargs in
             (("finite", {}), ("short", {"horizon": 8}), ("fir", {"fir": 15}))}
    solve = sls_module._solve_qp

    def inaccurate(*args, raw="optimal_inaccurate", shift=0.0, **kwargs):
        X, U, info = solve(*args, **kwargs)
        return X, U, {**info, "solver_status": raw, "objective": info["objective"] * (1 + shift)}

    monkeypatch.setattr(sls_module, "_solve_qp", inaccurate)
    # "short" and "fir" are checked on the QP's own horizon, the others on the benchmark cost.
    for label, kwargs in (("finite", {}), ("short", {"horizon": 8}), ("fir", {"fir": 15})):
        design = sls(small, **kwargs)
        assert design.status == "inaccurate" and "optimal_inaccurate" in design.message, label
        assert design.cost == exact[label].cost and design.extras["realized_objective_gap"] < 1e-7
    # Within codesign.INACCURATE_RTOL an inaccurate solve is kept; an optimal one is not.
    monkeypatch.setattr(sls_module, "_solve_qp", functools.partial(inaccurate, shift=1e-4))
    assert sls(small).status == "inaccurate"
    monkeypatch.setattr(sls_module, "_solve_qp", functools.partial(inaccurate, raw="optimal", shift=1e-4))
    assert sls(small).status == "failed"
    monkeypatch.setattr(sls_module, "_solve_qp", functools.partial(inaccurate, shift=1e-2))
    for kwargs in ({}, {"horizon": 8}, {"fir": 15}):
        design = sls(small, **kwargs)
        assert design.status == "failed" and np.isnan(design.cost)
        assert "optimal_inaccurate" in design.message and "disagrees" in design.message


def test_bad_inputs_raise(inst):
    with pytest.raises(ValueError, match="speed"):
        sls(inst, speed=0)
    with pytest.raises(ValueError, match="act_delay"):
        sls(inst, act_delay=-1)
    with pytest.raises(ValueError, match="not both"):
        sls(inst, horizon=10, fir=10)
    with pytest.raises(ValueError, match="unknown graph"):
        sls(inst, graph="ring")
    with pytest.raises(ValueError, match="comm_adj"):
        sls(inst, comm_adj=np.ones((3, 3)))
    with pytest.raises(ValueError, match="comm_adj"):
        is_quadratically_invariant(inst, np.ones((3, 3)))
    with pytest.raises(ValueError, match="graphs"):
        sls_topologies(inst, graphs=[])


def test_custom_graph_and_closures(inst, small):
    design = sls(small, comm_adj=np.ones((small.n, small.n)))
    assert design.params["graph"] == "custom" and design.status == "optimal"
    closure = topology(inst, "plant^2")
    assert np.all(closure >= topology(inst, "plant"))
    np.testing.assert_array_equal(topology(inst, "given^3") != 0, hop_distances(inst.comm_adj) <= 3)


def test_qi_on_unreachable_pair(small):
    # Nobody talks: every pair the plant connects (in any number of steps) is a violation.
    result = is_quadratically_invariant(small, np.eye(small.n))
    assert not result.qi and result.transmission == -1 and "never" in result.reason
    reachable = np.isfinite(hop_distances(small.plant_adj)).sum() - small.n
    assert result.violations == reachable


def test_registered(inst):
    for name in ("sls", "sls_topologies"):
        method = get_method(name)
        assert method.design in (baselines.sls, baselines.sls_topologies)
    get_method("sls").check_params({"graph": "plant^2", "speed": 3, "act_delay": 1, "fir": 20})
    with pytest.raises(ValueError):
        get_method("sls").check_params({"grpah": "plant"})


def test_fir_costs_bound_the_finite_horizon_cost(small):
    finite = sls(small)
    designs = {F: sls(small, fir=F) for F in (6, 9, 12)}
    assert designs[12].status == "optimal", designs[12].message
    costs = [designs[F].cost for F in (6, 9, 12) if designs[F].status == "optimal"]
    # FIR maps with F <= T are feasible for the finite-horizon QP; longer FIRs contain shorter ones.
    assert all(c >= finite.cost - 1e-9 for c in costs)
    assert all(b <= a + 1e-9 for a, b in zip(costs, costs[1:]))


# -- paper scale ------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("a_norm", [0.995, 1.05])
def test_paper_family_facts(a_norm):
    for seed in range(5):
        instance = paper_instance(seed, a_norm=a_norm)
        designs = {d.params["graph"]: d for d in sls_topologies(instance)}
        assert designs["given"].status == "infeasible"
        assert not is_quadratically_invariant(instance, instance.comm_adj).qi
        assert designs["plant"].status == "optimal" and designs["plant"].extras["qi"]
        costs = [designs[g].cost for g in ("plant", "plant^2", "plant^3", "complete")]
        assert all(b <= a * (1 + 1e-7) for a, b in zip(costs, costs[1:]))
        fir = sls(instance, fir=20)
        assert fir.cost >= designs["plant"].cost - 1e-7
        assert simulate(instance, fir.controller, steps=500, noise_std=1.0, seed=seed).bounded


@pytest.mark.slow
def test_n100_fir_completes():
    instance = paper_instance(0, n=100)
    design = sls(instance, fir=15)
    assert design.status == "optimal", design.message
    assert 1.0 - 1e-9 <= design.cost < 2.0


def test_a_qp_too_large_is_refused_at_once_naming_the_way_out(inst, monkeypatch):
    """The variable count is known before anything is built; past MAX_QP_VARIABLES the run is a failed design."""
    for kwargs in ({}, {"fir": 10}, {"graph": "complete"}):
        adj = topology(inst, kwargs.get("graph", "plant"))
        counted = sls_module._variable_count(inst, hop_distances(adj), kwargs.get("fir", inst.horizon), speed=1.0,
                                             act_delay=1, fir="fir" in kwargs)
        assert counted == sls(inst, **kwargs).extras["variables"]
    monkeypatch.setattr(sls_module, "MAX_QP_VARIABLES", 1000)
    design = sls(inst)
    assert design.status == "failed" and design.extras["size_guard"]
    assert "the joint SLS QP would have 39,392 variables on 20 states, above MAX_QP_VARIABLES = 1,000" in design.message
    assert "sls_local" in design.message and design.seconds < 1
