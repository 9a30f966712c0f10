"""Refit on a graph (baselines.refit): the best controller of each class on a given graph.

Checks that can fail: a polished design refit on its own graph costs no more than it;
the value of a graph never rises when links are added; SLS on the complete graph is
the SLS bound; at N = 3 the static refit of a budget's best pattern equals the
exhaustive search's cost and every refit of a random pattern reaches an independent
multi-start minimum; a graph no controller of the class can use is a recorded status.
"""

from __future__ import annotations

import numpy as np
import pytest

import compare.run.registry  # noqa: F401  (the built-ins)
from baselines import best_pattern, refit_design, sls, sparse_delayed
from codesign import get_method, paper_instance
from codesign.evaluation import spectral_radius, static_gain_cost_and_grad
from codesign.graphs import design_graph, graph_hash, graph_links, graph_text, parse_graph
from codesign.status import DIVERGED, INFEASIBLE, USABLE


@pytest.fixture(scope="module")
def small():
    return paper_instance(3, n=5, degree=2, a_norm=1.1, horizon=20)


@pytest.fixture(scope="module")
def delayed_path(small):
    return sparse_delayed(small, gammas=[0.0, 1e-3, 1e-2])


def test_graph_text_round_trips_and_names_bad_edges():
    rng = np.random.default_rng(0)
    adj = rng.random((6, 6)) < 0.4
    np.fill_diagonal(adj, False)
    text = graph_text(adj)
    assert np.array_equal(parse_graph(text, 6), adj)
    assert graph_hash(adj) == graph_hash(text) and graph_links(adj) == adj.sum()
    assert graph_text(np.eye(3)) == "" and not parse_graph("", 3).any()
    for bad, why in (("0-7", "outside"), ("2-2", "self-loop"), ("0-1,0-1", "twice"), ("0>1", "pairs")):
        with pytest.raises(ValueError, match=why):
            parse_graph(bad, 6)


def test_a_polished_delayed_design_refit_on_its_own_graph_costs_no_more(small, delayed_path):
    checked = 0
    for design in delayed_path:
        if design.status not in USABLE or design.links == 0:
            continue
        graph = design_graph(small, design)
        assert graph is not None and graph.sum() == design.links
        again = refit_design(small, graph, "delayed", starts=[design])
        assert again.status in USABLE and again.extras["graph"] == graph_hash(graph)
        assert again.cost <= design.cost * (1 + 1e-8), (design.links, design.cost, again.cost)
        assert again.links <= design.links
        checked += 1
    assert checked >= 1


def test_the_value_of_a_graph_never_rises_with_more_links(small):
    rng = np.random.default_rng(7)
    off = ~np.eye(small.nodes, dtype=bool)
    for _ in range(3):
        inner = (rng.random(off.shape) < 0.3) & off
        outer = inner | ((rng.random(off.shape) < 0.3) & off)
        for controller in ("delayed", "instantaneous"):
            v_inner = refit_design(small, inner, controller)
            # The larger graph's search also starts from the smaller graph's refit: a gain on a subgraph is
            # a gain on the graph, so its value can only be lower.
            v_outer = refit_design(small, outer, controller, starts=[v_inner])
            assert v_inner.status in USABLE and v_outer.status in USABLE
            assert v_outer.cost <= v_inner.cost * (1 + 1e-9), (controller, v_inner.cost, v_outer.cost)


def test_sls_refit_is_monotone_on_graphs_that_contain_the_plant_graph(small):
    plant = (small.plant_adj != 0) & ~np.eye(small.nodes, dtype=bool)
    rng = np.random.default_rng(3)
    extra = (rng.random(plant.shape) < 0.5) & ~np.eye(small.nodes, dtype=bool)
    on_plant, on_more = refit_design(small, plant, "sls"), refit_design(small, plant | extra, "sls")
    assert on_plant.status in USABLE and on_more.status in USABLE and on_plant.extras["qi"]
    # Convex: the larger feasible set's optimum is no higher (to the solver's tolerance, 1e-6 relative).
    assert on_more.cost <= on_plant.cost * (1 + 1e-6)


def test_sls_refit_on_the_complete_graph_is_the_sls_bound(small):
    complete = ~np.eye(small.nodes, dtype=bool)
    refit = refit_design(small, complete, "sls")
    bound = sls(small, graph="complete")
    assert refit.status in USABLE and refit.method == "refit" and refit.info_model == "delayed"
    assert refit.cost == pytest.approx(bound.cost, rel=1e-9)


def test_sls_refit_on_a_graph_below_the_plant_graph_is_recorded_infeasible(small):
    sparse = np.zeros((small.nodes, small.nodes), dtype=bool)
    sparse[0, 1] = True
    design = refit_design(small, sparse, "sls")
    assert design.status == INFEASIBLE and not np.isfinite(design.cost)
    assert "known without solving" in design.message and design.extras["solved"] is False
    solved = sls(small, comm_adj=sparse | np.eye(small.nodes, dtype=bool))  # the QP agrees: no such SLS
    assert solved.status == INFEASIBLE


def _multistart_minimum(instance, mask, starts: int, seed: int) -> float:
    """An independent reference: L-BFGS from random stabilizing gains on the mask, the lowest stable minimum."""
    import scipy.optimize

    rng = np.random.default_rng(seed)
    index = np.nonzero(mask)
    best = np.inf
    for _ in range(starts):
        K0 = np.where(mask, instance.K_lqr * rng.uniform(0.0, 1.2) + rng.normal(0, 0.2, mask.shape), 0.0)

        def fun(theta):
            K = np.zeros(mask.shape)
            K[index] = theta
            cost, grad = static_gain_cost_and_grad(instance, K)
            return (cost, grad[index]) if np.isfinite(cost) else (np.inf, np.zeros_like(theta))

        res = scipy.optimize.minimize(fun, K0[index], jac=True, method="L-BFGS-B", options={"gtol": 1e-10})
        K = np.zeros(mask.shape)
        K[index] = res.x
        if spectral_radius(instance.A + instance.B @ K) < 1 and res.fun < best:
            best = float(res.fun)
    return best


@pytest.mark.parametrize("n", [3, pytest.param(4, marks=pytest.mark.slow)])  # N = 4: best_pattern's 4096 patterns
def test_static_refits_equal_exhaustive_references(n):
    """On every pattern best_pattern finds best for its link count, the refit on that graph costs what the
    exhaustive search found (it starts there, so it may only polish); on random graphs, no more than an
    independent multistart L-BFGS reference."""
    inst = paper_instance(0, n=n, degree=2, a_norm=1.1, horizon=20)
    for best in best_pattern(inst):
        graph = design_graph(inst, best)
        refit = refit_design(inst, graph, "instantaneous", starts=[best])
        assert refit.status in USABLE
        assert refit.cost == pytest.approx(best.cost, rel=1e-7), best.params
    rng = np.random.default_rng(11)
    for _ in range(4):
        graph = (rng.random((n, n)) < 0.5) & ~np.eye(n, dtype=bool)
        refit = refit_design(inst, graph, "instantaneous")
        reference = _multistart_minimum(inst, graph | np.eye(n, dtype=bool), starts=12, seed=int(rng.integers(1e6)))
        assert refit.cost <= reference * (1 + 1e-7), (graph_text(graph), refit.cost, reference)


def test_a_graph_no_static_gain_stabilizes_is_a_recorded_status():
    # Node 0 is unstable and only node 1's input moves it: with no link node 1 cannot see it, so no gain
    # on the empty graph stabilizes the plant (which is stabilizable, through the link 1 <- 0).
    from codesign import Instance

    inst = Instance.from_matrices(np.array([[2.0, 0.0], [0.0, 0.5]]), np.array([[0.0, 1.0], [0.0, 0.0]]),
                                  horizon=20)
    empty = np.zeros((2, 2), dtype=bool)
    for controller in ("delayed", "instantaneous"):
        design = refit_design(inst, empty, controller)
        assert design.status == DIVERGED and not np.isfinite(design.cost), (controller, design.status)
        assert design.extras["graph_links"] == 0 and "stabiliz" in design.message
    linked = refit_design(inst, parse_graph("1-0", 2), "instantaneous")
    assert linked.status in USABLE and linked.extras["spectral_radius"] < 1


def test_the_grnn_refit_keeps_its_start_where_training_does_not_improve(small, delayed_path):
    design = next(d for d in delayed_path if d.status in USABLE and d.links > 0)
    graph = design_graph(small, design)
    start = refit_design(small, graph, "delayed", starts=[design])
    linear = refit_design(small, graph, "grnn", starts=[design], activation="identity", steps=30, ensemble=1,
                          dtype="float64")
    assert linear.status in USABLE and linear.method == "refit" and linear.info_model == "delayed"
    assert linear.extras["start_cost"] == pytest.approx(start.cost, rel=1e-12)
    assert linear.cost <= start.cost * (1 + 1e-9)  # exact costs: trained below the start, or the start kept
    assert linear.links <= graph.sum()  # S is held to the graph's support


def test_the_registered_method_checks_its_settings(small):
    method = get_method("refit")
    with pytest.raises(ValueError, match="graph"):
        method.check_params({"graph": "0 to 1"})
    with pytest.raises(ValueError, match="grnn"):
        method(small, graph="0-1", controller="delayed", steps=10)
    (design,) = method(small, graph="0-1,1-0", controller="delayed")
    assert design.method == "refit" and design.params["graph"] == "0-1,1-0" and design.extras["graph_links"] == 2
