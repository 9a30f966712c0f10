"""Sparse delayed static gains on node blocks: nodes with several states or inputs (the mass-spring chain).

u_i(t) = K_ii x_i(t) + sum_{j != i} K_ij x_j(t - 1) with K_ii node i's inputs by its own
states (no delay) and K_ij the block of node j's states, one step late; links are the
nonzero off-diagonal node blocks, penalized by their Frobenius norms.
"""

import importlib
import io

import numpy as np
import pytest

from baselines import decentralized
from baselines._sparse import GRAD_RTOL
from baselines.sparse_delayed import (
    DelayedStaticGain,
    delayed_closed_loop,
    delayed_gain_cost,
    delayed_gain_cost_and_grad,
    sparse_delayed,
)
from codesign import compare_exact_and_simulated, count_links, get_method
from codesign.controllers import controller_from_arrays
from codesign.evaluation import exact_cost, simulate, spectral_radius
from compare.run.families.mass_spring import mass_spring_instance
from references import augmented_delayed_reference  # tests/references.py

# `baselines.sparse_delayed` resolves to the function once a package imports it; the module by full name.
delayed_module = importlib.import_module("baselines.sparse_delayed")

GAMMAS = [0.0, 1e-5, 1e-4, 1e-3, 1e-2]


def _random_block_gain(instance, rng, scale=0.2):
    own = instance.block_mask()
    K_local = np.where(own, -0.3 + 0.1 * rng.standard_normal(own.shape), 0.0)
    K_delayed = np.where(own, 0.0, scale * rng.standard_normal(own.shape))
    return K_local, K_delayed


@pytest.fixture(scope="module")
def small():
    return mass_spring_instance(4, horizon=15)  # 8 states, 4 inputs, 4 nodes


@pytest.fixture(scope="module")
def chain():
    return mass_spring_instance(8)  # 16 states, 8 inputs, 8 nodes


@pytest.fixture(scope="module")
def path(chain):
    return sparse_delayed(chain, gammas=GAMMAS)


# -- cost and gradient with m != n ----------------------------------------------------------
def test_cost_and_gradient_match_the_augmented_recursion_with_fewer_inputs_than_states(small):
    assert (small.n, small.m, small.nodes) == (8, 4, 4) and not small.scalar_nodes
    K_local, K_delayed = _random_block_gain(small, np.random.default_rng(0))
    cost, g_local, g_delayed = delayed_gain_cost_and_grad(small, K_local, K_delayed)
    assert g_local.shape == g_delayed.shape == (4, 8)
    own = small.block_mask()
    assert not g_local[~own].any() and not g_delayed[own].any()
    ref_cost, ref_local, ref_delayed = augmented_delayed_reference(small, K_local, K_delayed)
    assert cost == pytest.approx(ref_cost, rel=1e-12)
    scale = max(np.abs(ref_local).max(), np.abs(ref_delayed).max())
    np.testing.assert_allclose(g_local[own], ref_local[own], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(g_delayed[~own], ref_delayed[~own], rtol=0, atol=1e-12 * scale)
    # The controller's closed-loop responses score the same gain to rounding.
    ctrl = DelayedStaticGain(K_local, K_delayed, small.state_nodes, small.input_nodes)
    assert exact_cost(small, ctrl) == pytest.approx(cost, rel=1e-12)


def test_gradient_matches_finite_differences_on_node_blocks(small):
    K_local, K_delayed = _random_block_gain(small, np.random.default_rng(1))
    cost, g_local, g_delayed = delayed_gain_cost_and_grad(small, K_local, K_delayed)
    own = small.block_mask()
    h = 1e-6
    for i in range(small.m):
        for j in range(small.n):
            local = bool(own[i, j])
            which = K_local if local else K_delayed
            plus, minus = which.copy(), which.copy()
            plus[i, j] += h
            minus[i, j] -= h
            up = delayed_gain_cost(small, plus, K_delayed) if local else delayed_gain_cost(small, K_local, plus)
            down = delayed_gain_cost(small, minus, K_delayed) if local else delayed_gain_cost(small, K_local, minus)
            grad = g_local if local else g_delayed
            assert (up - down) / (2 * h) == pytest.approx(grad[i, j], rel=1e-6, abs=1e-9 * cost), (i, j)
    # Entries that are not free are not read.
    assert delayed_gain_cost(small, K_local + np.where(own, 0.0, 5.0), K_delayed + np.where(own, 5.0, 0.0)) == cost


# -- the controller -----------------------------------------------------------------------
def test_block_controller_checks_its_blocks_counts_links_between_nodes_and_round_trips(small):
    K_local, K_delayed = _random_block_gain(small, np.random.default_rng(2), scale=0.05)
    K_delayed[small.expand_blocks(np.eye(4, k=2) + np.eye(4, k=-3) != 0)] = 0.0  # two fewer node blocks
    ctrl = DelayedStaticGain(K_local, K_delayed, small.state_nodes, small.input_nodes)
    assert (ctrl.n, ctrl.m) == (8, 4)
    assert ctrl.support.shape == (4, 4) and count_links(ctrl.support) == (12 - 3, 4)
    np.testing.assert_array_equal(ctrl.support, small.node_support((K_local != 0) | (K_delayed != 0)) != 0)
    # One step late: u(0) reads x(0) through K_local only, u(1) the neighbours' x(0).
    x0 = np.random.default_rng(3).standard_normal((2, 8))
    u0, state = ctrl.step(ctrl.reset(2), x0)
    np.testing.assert_array_equal(u0, x0 @ K_local.T)
    u1, _ = ctrl.step(state, np.zeros((2, 8)))
    np.testing.assert_array_equal(u1, x0 @ K_delayed.T)
    # Saved and loaded as the result store does (an .npz blob, no pickles).
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **ctrl.arrays())
    buffer.seek(0)
    with np.load(buffer, allow_pickle=False) as data:
        loaded = controller_from_arrays(ctrl.kind, {k: data[k] for k in data.files})
    assert np.array_equal(loaded.K_local, K_local) and np.array_equal(loaded.K_delayed, K_delayed)
    assert np.array_equal(loaded.state_nodes, small.state_nodes) and np.array_equal(loaded.input_nodes, small.input_nodes)
    assert exact_cost(small, loaded) == exact_cost(small, ctrl)
    # One state and one input per node: the arrays are the two gains, as before.
    assert set(DelayedStaticGain(np.eye(3), np.zeros((3, 3))).arrays()) == {"K_local", "K_delayed"}
    with pytest.raises(ValueError, match="outside each node's own block"):
        DelayedStaticGain(K_local + 1.0, K_delayed, small.state_nodes, small.input_nodes)
    with pytest.raises(ValueError, match="zero on each node's own block"):
        DelayedStaticGain(K_local, K_delayed + 1.0, small.state_nodes, small.input_nodes)
    with pytest.raises(ValueError, match="square matrix"):
        DelayedStaticGain(K_local, K_delayed)


# -- the group-l1 solve -------------------------------------------------------------------
def test_weighted_group_l1_solution_meets_its_optimality_conditions():
    inst = mass_spring_instance(6, horizon=20)
    own = inst.block_mask()
    diagonal = decentralized(inst)
    start = np.where(own, diagonal.controller.K, 0.0)
    dense = delayed_module.polish_delayed(inst, start, np.zeros((6, 12)), ~own)
    gamma = 1e-2  # plain group l1 from the dense gain: 24 of the 30 blocks stay
    threshold = gamma * (1.0 - np.eye(6))
    result = delayed_module._weighted_group_l1(inst, dense.local, dense.K_delayed, threshold, tol=1e-9,
                                               maxiter=2000)
    assert result.success, result.message
    _, g_local, g_delayed = delayed_gain_cost_and_grad(inst, result.local, result.K_delayed)
    norms, g_norms = inst.block_norms(result.K_delayed), inst.block_norms(g_delayed)
    off = ~np.eye(6, dtype=bool)
    zero, kept = off & (norms == 0), off & (norms > 0)
    assert zero.any() and kept.any()  # a proper subset of the blocks
    assert np.all(g_norms[zero] <= threshold[zero] * (1 + 1e-6))  # zero blocks: |g_ij| <= t_ij
    # Kept blocks: g_ij + t_ij K_ij / |K_ij| = 0; the local blocks: g = 0.
    direction = inst.expand_blocks(np.where(kept, threshold / np.where(kept, norms, 1.0), 0.0)) * result.K_delayed
    stationarity = (g_delayed + direction)[inst.expand_blocks(kept)]
    assert np.abs(stationarity).max() < 1e-8 and np.abs(g_local[own]).max() < 1e-8


# -- the path on the chain ------------------------------------------------------------------
def test_registered_for_node_blocks(chain):
    method = get_method("sparse_delayed")
    assert method.node_blocks and method.unsupported(chain, {}) is None
    designs = method(mass_spring_instance(6, horizon=20), gammas=[0.0, 1e-2])
    assert [d.method for d in designs] == ["sparse_delayed"] * 3
    assert all(d.status == "optimal" for d in designs)


def test_path_runs_from_dense_to_no_links(chain, path):
    N = chain.nodes
    assert [d.params["gamma"] for d in path] == [*GAMMAS, float("inf")]
    links = [d.links for d in path]
    assert links[0] == N * (N - 1) and links[-1] == 0, links
    assert all(b <= a for a, b in zip(links, links[1:])), links
    assert len(set(links)) >= 4, links  # intermediate patterns, not a jump from dense to none
    assert all(d.status == "optimal" for d in path), [d.message for d in path]
    assert all(d.self_loops == N for d in path)


def test_every_point_is_exact_stabilizing_and_polished_on_whole_blocks(chain, path):
    own = chain.block_mask()
    for design in path:
        ctrl = design.controller
        assert isinstance(ctrl, DelayedStaticGain) and ctrl.node_blocks
        assert design.info_model == "delayed" and design.cost_kind == "exact"
        assert ctrl.K_local.shape == ctrl.K_delayed.shape == (chain.m, chain.n)
        assert not ctrl.K_local[~own].any() and not ctrl.K_delayed[own].any()
        radius = spectral_radius(delayed_closed_loop(chain, ctrl.K_local, ctrl.K_delayed))
        assert radius < 1 and design.extras["spectral_radius"] == pytest.approx(radius, rel=1e-12)
        assert design.cost == exact_cost(chain, ctrl)
        assert design.cost == pytest.approx(delayed_gain_cost(chain, ctrl.K_local, ctrl.K_delayed), rel=1e-12)
        # Links counted between nodes: the nonzero off-diagonal node blocks.
        node_support = chain.node_support((ctrl.K_local != 0) | (ctrl.K_delayed != 0))
        assert (design.links, design.self_loops) == count_links(node_support) == count_links(ctrl.support)
        norms = chain.block_norms(ctrl.K_delayed)
        assert design.links == np.count_nonzero(norms)
        # Polished over the own blocks and every entry of the kept blocks.
        free = chain.expand_blocks(norms > 0)
        cost, g_local, g_delayed = delayed_gain_cost_and_grad(chain, ctrl.K_local, ctrl.K_delayed)
        masked = np.sqrt(np.sum(g_local[own] ** 2) + np.sum(g_delayed[free] ** 2))
        assert masked < GRAD_RTOL * cost
        assert design.extras["masked_grad_rel"] < GRAD_RTOL


def test_ends_against_lqr_and_decentralized(chain, path):
    dense, end = path[0], path[-1]
    assert dense.cost >= 1.0 - 1e-9  # LQR is optimal among causal controllers
    best = decentralized(chain)
    assert end.cost == pytest.approx(best.cost, rel=1e-12)
    assert np.array_equal(end.controller.K_local, best.controller.K)
    assert not end.controller.K_delayed.any() and end.extras["decentralized"]
    assert dense.cost < end.cost


def test_exact_cost_equals_simulation(chain, path):
    design = next(d for d in path if 0 < d.links < chain.nodes * (chain.nodes - 1))
    check = compare_exact_and_simulated(chain, design.controller)
    assert check["exact"] == design.cost
    assert abs(check["z"]) < 3, check
    np.testing.assert_allclose(check["control_variate"], check["exact"], rtol=1e-9)
    # From x(0) = e_j, j = 1..n, n times the mean simulated cost is the exact cost itself.
    basis = simulate(chain, design.controller, np.eye(chain.n)).cost * chain.n
    assert basis == pytest.approx(design.cost, rel=1e-12)
