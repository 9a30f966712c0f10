"""Localized SLS: column by column, against the joint QP of `sls`, locality, feasibility and the realization."""

import importlib

import numpy as np
import pytest

from baselines import sls, sls_local
from codesign import Instance, hop_distances, paper_instance, response_cost
from baselines.sls import topology

sls_local_module = importlib.import_module("baselines.sls_local")


@pytest.fixture(scope="module")
def inst():
    return paper_instance(0)


@pytest.fixture(scope="module")
def line():
    """50 nodes of the paper family: the plant graph's diameter (7 here) exceeds the localities tested."""
    return paper_instance(2, n=50, horizon=20)


@pytest.mark.parametrize("kwargs", [{}, {"fir": 10}, {"horizon": 30}, {"act_delay": 0}, {"speed": 3.0, "graph": "given"}, {"speed": 2.0, "graph": "given"}])
def test_whole_graph_locality_is_the_joint_qp(inst, kwargs):
    """With the locality at the diameter, the columns' exact KKT solves give the cvxpy QP's design."""
    local = sls_local(inst, locality=inst.nodes, **kwargs)
    joint = sls(inst, **kwargs)
    assert local.status == joint.status
    if joint.status == "infeasible":  # at speed 2 information is slower than the plant on the given graph
        assert kwargs.get("speed") == 2.0 and "column 0 (node 0)" in local.message
        return
    assert joint.status == "optimal"
    assert local.cost == pytest.approx(joint.cost, rel=1e-7)  # Clarabel's tolerance
    assert (local.links, local.self_loops) == (joint.links, joint.self_loops)
    assert local.info_model == "delayed"


def test_maps_are_local_and_cost_grows_as_locality_shrinks(line):
    dist = hop_distances(topology(line, "plant"))
    assert dist.max() >= 5
    assert sls_local(line, locality=1, fir=8).status == "infeasible"  # 32 of 50 columns, residuals ~1e-2
    costs = []
    for d in (2, 3, 4, int(dist.max())):
        design = sls_local(line, locality=d, fir=8)
        assert design.status == "optimal", design.message
        X, U = design.controller.phi_x, design.controller.phi_u
        far = dist > d
        assert not np.any(X[:, far]) and not np.any(U[:, far])
        costs.append(design.cost)
    assert all(a >= b - 1e-12 for a, b in zip(costs, costs[1:]))
    assert costs[0] > costs[-1] * (1 + 1e-3)  # locality 2 really costs something here (1.0399 against 1.0344)
    assert costs[-1] == pytest.approx(sls(line, fir=8).cost, rel=1e-7)


def test_designed_maps_are_the_realized_closed_loop(line):
    """Scored on its designed maps: the SLS realization reproduces them (dynamics met to rounding)."""
    for kwargs in ({"fir": 6}, {}, {"horizon": 12}):
        design = sls_local(line, locality=2, **kwargs)
        assert design.extras["dynamics_residual"] < 1e-12
        realized = response_cost(line, *design.controller.closed_loop_responses(line))
        assert design.cost == pytest.approx(realized, rel=1e-10)


def test_rank_deficient_columns_are_solved_exactly(line):
    """Localized columns have redundant boundary rows; regularized KKT + refinement meets them to rounding."""
    design = sls_local(line, locality=2, fir=8)
    assert design.extras["dynamics_residual"] < 1e-12
    assert design.extras["largest_column"] < line.n * 9  # a column is a neighbourhood, not the network


def test_infeasible_locality_is_a_status_naming_the_node():
    """Each node drives only itself on a coupled chain. With a step of delay, x(1) already holds the
    neighbours' states, which spread one hop further each step, out of reach of every input allowed
    there: infeasible at every locality below the diameter. Acting at once (act_delay 0), one hop suffices."""
    n = 6
    A = 0.9 * (np.eye(n) + 0.3 * np.eye(n, k=1) + 0.3 * np.eye(n, k=-1))
    chain = Instance.from_matrices(A, np.eye(n), horizon=8, name="chain")
    design = sls_local(chain, locality=0)
    assert design.status == "infeasible"
    assert "column 0 (node 0) (and 5 other column(s)) cannot meet 0-hop locality" in design.message
    assert design.extras["infeasible_columns"] == 6
    assert design.controller is None and np.isnan(design.cost)
    assert [sls_local(chain, locality=d).extras["infeasible_columns"] for d in range(1, 6)] == [6, 6, 4, 2, 0]
    assert sls_local(chain, locality=0, act_delay=0).status == "infeasible"
    assert sls_local(chain, locality=1, act_delay=0).status == "optimal"


def test_bad_inputs_raise(inst):
    for kwargs, match in (({"locality": -1}, "locality"), ({"fir": 0}, "fir"), ({"fir": 5, "horizon": 5}, "either"),
                          ({"speed": 0.0}, "speed"), ({"graph": "nope"}, "unknown graph")):
        with pytest.raises(ValueError, match=match):
            sls_local(inst, **kwargs)


def test_node_blocks_match_the_joint_qp():
    """Two states and one input per node (mass-spring): columns follow the nodes' hop distances."""
    from compare.run.families.mass_spring import mass_spring_instance

    chain = mass_spring_instance(5, seed=0, horizon=10)
    local = sls_local(chain, locality=chain.nodes, fir=6)
    joint = sls(chain, fir=6)
    assert local.status == joint.status == "optimal"
    assert local.cost == pytest.approx(joint.cost, rel=1e-7)


@pytest.mark.slow
def test_a_thousand_nodes_cost_agrees_with_the_realized_closed_loop():
    """N = 1000 (about 3 minutes): the designed maps' cost against the SLS realization rolled out on the plant."""
    big = paper_instance(0, n=1000, connect="bridge")
    design = sls_local(big, locality=3, fir=10)
    assert design.status == "optimal", design.message
    assert design.extras["dynamics_residual"] < 1e-12
    realized = response_cost(big, *design.controller.closed_loop_responses(big))
    assert design.cost == pytest.approx(realized, rel=1e-8)
    assert 1.0 < design.cost < 1.02  # 1.0068 on seed 0: 3 hops cost 0.7 % over centralized LQR
