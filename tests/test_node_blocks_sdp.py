"""The ℓ1 SDP on nodes with several states and inputs: block-diagonal X, group penalty on node blocks."""

import numpy as np
import pytest
import scipy.linalg

import compare.run.registry  # noqa: F401  (the built-ins)
from baselines._sparse import GRAD_RTOL, pattern_of
from baselines.sparse_sdp import SparseSDP
from codesign import get_method, static_gain_cost_and_grad
from codesign.design import count_links
from codesign.evaluation import spectral_radius
from compare.run.families.mass_spring import mass_spring_instance

#: On the 8-mass chain (gamma_max about 0.237) these give 36, 32, 28, 24 and 0 links.
#: The path is not monotone everywhere: gamma = 3e-3 gives 40 links, more than 1e-3's 36.
GAMMAS = [1e-3, 1e-2, 3e-2, 1e-1, 3e-1]


@pytest.fixture(scope="module")
def chain():
    return mass_spring_instance(8)


@pytest.fixture(scope="module")
def path(chain):
    return get_method("sparse_sdp")(chain, gammas=GAMMAS)


def test_sdp_is_registered_for_node_blocks(chain):
    assert get_method("sparse_sdp").node_blocks
    assert get_method("sparse_sdp").unsupported(chain, {}) is None


def test_path_runs_from_many_links_to_none(chain, path):
    assert [d.params["gamma"] for d in path] == GAMMAS + [float("inf")]
    links = [d.links for d in path]
    assert links[0] >= 30 and links[-2] == 0 and links[-1] == 0
    assert links == sorted(links, reverse=True)
    costs = [d.cost for d in path]
    assert costs[0] < 1.001 and costs[-1] == pytest.approx(get_method("decentralized")(chain)[0].cost, rel=1e-9)


def test_path_designs_are_stabilizing_polished_and_counted_by_node(chain, path):
    for d in path:
        assert d.status == "optimal" or (d.status == "inaccurate" and d.message), (d.status, d.message)
        assert d.self_loops == chain.nodes
        K = np.asarray(d.controller.K)
        assert K.shape == (chain.m, chain.n)
        assert spectral_radius(chain.A + chain.B @ K) < 1
        assert d.links == count_links(chain.node_support(K))[0]
        cost, grad = static_gain_cost_and_grad(chain, K)
        assert d.cost == pytest.approx(cost, rel=1e-12)
        assert np.linalg.norm(grad[pattern_of(K, chain)]) < GRAD_RTOL * cost
        if d.params["gamma"] < float("inf"):
            assert d.extras["solver"] == "CLARABEL" and d.extras["iterations"] > 0
            # The block-diagonal X still bounds the cost from above (loosely: about 2.6 at small γ).
            assert d.extras["sdp_bound"] >= d.cost


def test_gain_is_y_times_inverse_block_x_and_bound_is_certified(chain):
    sdp = SparseSDP(chain, solver="clarabel")  # a certificate to 1e-6 needs the interior-point solve
    result = sdp.solve(1e-2)
    assert result["status"] == "optimal"
    X, Y, K = result["X"], result["Y"], result["K"]
    # X is block-diagonal by node and K = -Y X^-1 keeps Y's node blocks.
    same_node = chain.state_nodes[:, None] == chain.state_nodes[None, :]
    assert np.all(X[~same_node] == 0) and np.allclose(X, X.T)
    np.testing.assert_allclose(K, -Y @ np.linalg.inv(X), atol=1e-10 * np.abs(K).max())
    # The certificate A_cl X A_cl' + I <= X holds, and the bound dominates trace(P_K).
    Acl = chain.A + chain.B @ K
    assert np.linalg.eigvalsh(X - Acl @ X @ Acl.T - np.eye(chain.n)).min() > -1e-6 * np.abs(X).max()
    P_K = scipy.linalg.solve_discrete_lyapunov(Acl.T, chain.Q + K.T @ chain.R @ K)
    assert result["bound"] >= np.trace(P_K) * (1 - 1e-7)
    # The objective is the smooth bound plus the group penalty on the off-diagonal node blocks.
    norms = chain.block_norms(Y)
    np.fill_diagonal(norms, 0.0)
    assert sdp.problem.value == pytest.approx(result["bound"] + 1e-2 * chain.trace_P * norms.sum(), rel=1e-6)


def test_gamma_max_is_exact_on_node_blocks():
    chain = mass_spring_instance(6)
    sdp = SparseSDP(chain, solver="clarabel")
    top = sdp.gamma_max()
    off = ~np.eye(chain.nodes, dtype=bool)
    below, above = sdp.solve(0.97 * top), sdp.solve(1.03 * top)
    for result, (low, high) in ((below, (1e-3, 1.0)), (above, (0.0, 1e-6))):
        norms = chain.block_norms(result["Y"])
        assert low < norms[off].max() / norms.max() < high


def test_threshold_zeroes_whole_node_blocks(chain):
    sdp = SparseSDP(chain)
    Y = np.ones((chain.m, chain.n))
    Y[0, chain.state_nodes == 1] = 1e-6  # node 0 reading node 1: a small block
    small = sdp.small_entries(Y, 1e-4)
    np.testing.assert_array_equal(small, chain.expand_blocks(np.eye(chain.nodes, k=1) * (np.arange(8) == 0)[:, None]))


@pytest.mark.parametrize("solver, why", [("clarabel", "user_limit"), ("scs", "iteration limit")])
def test_failed_solves_are_recorded_statuses(chain, solver, why):
    (design,) = get_method("sparse_sdp")(chain, gammas=[1e-2], max_iter=2, solver=solver, diagonal_end=False)
    assert design.status == "failed" and design.controller is None and why in design.message


def test_nodes_of_mixed_sizes_and_a_node_without_inputs():
    """One-state nodes take the quadratic-over-linear term; a node with no input has no row blocks."""
    from codesign import Instance

    rng = np.random.default_rng(0)
    inst = Instance.from_matrices(0.4 * rng.standard_normal((6, 6)), rng.standard_normal((6, 3)),
                                  state_nodes=[0, 0, 1, 2, 2, 2], input_nodes=[0, 2, 2], horizon=20)
    top = SparseSDP(inst, solver="clarabel").gamma_max()
    designs = get_method("sparse_sdp")(inst, gammas=[1e-4, 0.5 * top, 2 * top])
    assert [d.links for d in designs] == [4, 3, 0, 0]  # 4: nodes 0 and 2 each read both others
    for d in designs:
        assert d.status == "optimal" and d.self_loops == 2, d.message  # node 1 has no input
        assert d.links == count_links(inst.node_support(np.asarray(d.controller.K)))[0]


def test_a_singular_lyapunov_block_is_a_recorded_failure(chain, monkeypatch):
    def singular(self):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(SparseSDP, "_block_solution", singular)
    (design,) = get_method("sparse_sdp")(chain, gammas=[1e-2])
    assert design.status == "failed" and design.controller is None and "no usable gain" in design.message
