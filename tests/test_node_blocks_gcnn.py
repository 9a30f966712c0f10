"""The GCNN on nodes with several states and inputs (node blocks), and its reduction to the paper's model."""

from __future__ import annotations

import io
import sys

import numpy as np
import pytest

import compare.run.registry  # noqa: F401  (the built-ins)
from baselines import GCNNController, gcnn, gcnn_batch
from codesign import Instance, controller_from_arrays, get_method, paper_instance, simulate
from codesign.design import count_links
from codesign.evaluation import validation_set
from compare.run.families.mass_spring import mass_spring_instance
from references import gcnn_block_cost_autograd  # tests/references.py

FAST = dict(steps=20, ensemble=1, stability_steps=0, curve_size=20)


def gm():
    return sys.modules["codesign.learned.gcnn_bptt"]


@pytest.fixture(scope="module")
def chain():
    return mass_spring_instance(6)


@pytest.fixture(scope="module")
def design(chain):
    return gcnn(chain, **FAST)


def _reference_actions(S, H, w, state_nodes, input_nodes, x):
    """The node-block GCNN written out entry by entry (independent of the controller's code)."""
    K, p, F = H.shape
    N = S.shape[0]
    u = np.zeros((x.shape[0], len(input_nodes)))
    for b in range(x.shape[0]):
        X = np.zeros((N, p))
        for k, node in enumerate(state_nodes):
            X[node, sum(1 for j in range(k) if state_nodes[j] == node)] = x[b, k]
        Z = sum(np.linalg.matrix_power(S, k) @ X @ H[k] for k in range(K))  # (N, F)
        Y = np.tanh(Z) @ w  # (N, q)
        for a, node in enumerate(input_nodes):
            u[b, a] = Y[node, sum(1 for j in range(a) if input_nodes[j] == node)]
    return u


def test_gcnn_trains_on_the_mass_spring_chain(chain, design):
    assert get_method("gcnn").node_blocks
    assert design.status == "optimal", design.message
    assert np.isfinite(design.cost) and design.cost >= 1.0 - 10 * design.cost_stderr
    assert design.cost_kind == "simulated" and design.cost_stderr > 0
    c = design.controller
    # p = 2 states (position, velocity) and q = 1 input per node.
    assert c.H.shape == (5, 2, 32) and c.w.shape == (32, 1)
    assert design.extras["n_parameters"] == c.n_parameters == 5 * 2 * 32 + 32
    np.testing.assert_array_equal(c.state_nodes, chain.state_nodes)
    np.testing.assert_array_equal(c.input_nodes, chain.input_nodes)
    # Links between nodes: the given graph the filter shifts over (the chain), as on the paper's family.
    assert (design.links, design.self_loops) == count_links(chain.comm_adj) == (10, 6)
    assert c.support.shape == (chain.nodes, chain.nodes) and count_links(c.support) == count_links(chain.comm_adj)
    assert design.info_model == "instantaneous"
    curve = design.extras["curve"]
    assert curve["step"] == [0, 10, 20] and curve["cost"][-1] < curve["cost"][0]
    # Through the registry too (no recorded "failed" design on node blocks).
    (again,) = get_method("gcnn")(chain, **FAST)
    assert again.status == "optimal" and again.cost == design.cost


def test_block_controller_is_the_padded_filter_bank(chain, design):
    c = design.controller
    x = np.random.default_rng(0).standard_normal((4, chain.n))
    u, _ = c.step(None, x)
    assert u.shape == (4, chain.m)
    np.testing.assert_allclose(u, _reference_actions(c.S, c.H, c.w, chain.state_nodes, chain.input_nodes, x),
                               rtol=0, atol=1e-13)
    small = 1e-8 * x
    gain = c.linear_gain()
    assert gain.shape == (chain.m, chain.n)
    np.testing.assert_allclose(c.step(None, small)[0], small @ gain.T, rtol=1e-6, atol=1e-20)


def test_uneven_blocks_are_padded():
    # Node 0: 2 states, 1 input; node 1: 1 state, no input; node 2: 3 states, 2 inputs.
    rng = np.random.default_rng(4)
    state_nodes, input_nodes = [0, 2, 0, 1, 2, 2], [2, 0, 2]
    S = np.array([[1.0, 1, 0], [1, 1, 1], [0, 1, 1]]) / 2.5
    H, w = rng.standard_normal((5, 3, 8)) / 3, rng.standard_normal((8, 2)) / 3
    c = GCNNController(S, H, w, state_nodes, input_nodes)
    x = rng.standard_normal((5, 6))
    np.testing.assert_allclose(c.step(None, x)[0], _reference_actions(S, H, w, state_nodes, input_nodes, x),
                               rtol=0, atol=1e-13)
    small = 1e-8 * x
    np.testing.assert_allclose(c.step(None, small)[0], small @ c.linear_gain().T, rtol=1e-6, atol=1e-20)
    with pytest.raises(ValueError, match="more than the 2 channels"):
        GCNNController(S, H[:, :2], w, state_nodes, input_nodes)
    # And it trains: p = 3, q = 2 on an instance with such nodes (any R).
    A = np.diag(rng.uniform(0.8, 1.05, 6))
    A[1, 4] = A[3, 0] = 0.1
    B = np.eye(6)[:, [1, 0, 4]]
    inst = Instance.from_matrices(A, B, R=2 * np.eye(3), state_nodes=state_nodes, input_nodes=input_nodes,
                                  comm_adj=S != 0, horizon=10)
    d = gcnn(inst, steps=10, ensemble=2, stability_steps=20, curve_size=20)
    assert d.status == "optimal" and d.controller.H.shape == (5, 3, 32) and d.controller.w.shape == (32, 2)


def test_controller_round_trips_through_arrays(chain, design):
    c = design.controller
    arrays = c.arrays()
    assert set(arrays) == {"S", "H", "w", "state_nodes", "input_nodes"}
    # As the result store saves them: an npz without pickles.
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **{k: np.asarray(v) for k, v in arrays.items()})
    with np.load(io.BytesIO(buffer.getvalue()), allow_pickle=False) as data:
        loaded = {k: data[k] for k in data.files}
    back = controller_from_arrays("gcnn", loaded)
    x = validation_set(chain)[:50]
    np.testing.assert_array_equal(back.step(None, x)[0], c.step(None, x)[0])
    np.testing.assert_array_equal(back.linear_gain(), c.linear_gain())
    assert back.n_parameters == c.n_parameters
    # The paper's model keeps its three arrays.
    scalar = GCNNController(np.eye(3) / 2, np.ones((5, 4)), np.ones(4))
    assert set(scalar.arrays()) == {"S", "H", "w"}


def test_simulated_cost_agrees_with_the_design(chain, design):
    same = simulate(chain, design.controller)
    assert same.cost == design.cost and same.stderr == design.cost_stderr
    other = simulate(chain, design.controller, validation_set(chain, seed=12345), control_variates=True)
    assert abs(other.cost - design.cost) <= 3 * np.hypot(other.stderr, design.cost_stderr)


def test_same_seed_same_numbers(chain, design):
    twice = gcnn(chain, **FAST)
    np.testing.assert_array_equal(twice.controller.H, design.controller.H)
    np.testing.assert_array_equal(twice.controller.w, design.controller.w)
    assert twice.cost == design.cost and twice.extras["curve"] == design.extras["curve"]
    other = gcnn(chain, seed=1, **FAST)
    assert not np.array_equal(other.controller.H, design.controller.H)


def test_stacks_of_blocks_and_scalar_instances_equal_single_runs(chain):
    paper = paper_instance(2, n=8)
    settings = dict(steps=6, ensemble=1, stability_steps=0, curve_size=20)
    together = gcnn_batch([(paper, dict(settings, seed=1)), (chain, dict(settings, seed=2)),
                           (mass_spring_instance(6, seed=1), dict(settings, seed=3))])
    alone = [gcnn(paper, seed=1, **settings), gcnn(chain, seed=2, **settings)]
    assert together[0].controller.H.shape == (5, 32)
    for a, b in zip(together, alone):
        np.testing.assert_allclose(a.controller.H, b.controller.H, rtol=1e-9, atol=1e-13)
        np.testing.assert_allclose(a.cost, b.cost, rtol=1e-9)


def test_general_formula_reduces_to_the_scalar_one():
    inst = paper_instance(2, n=10)
    rng = np.random.default_rng(1)
    H, w = rng.standard_normal((5, 32)) / 3, rng.standard_normal(32) / 6
    scalar = GCNNController(inst.gso, H, w)
    general = GCNNController(inst.gso, H[:, None, :], w[:, None], np.arange(10), np.arange(10))
    assert general.blocks and not scalar.blocks and general.n_parameters == scalar.n_parameters == 192
    x = rng.standard_normal((6, 10))
    np.testing.assert_allclose(general.step(None, x)[0], scalar.step(None, x)[0], rtol=0, atol=1e-13)
    np.testing.assert_allclose(general.linear_gain(), scalar.linear_gain(), rtol=0, atol=1e-14)
    # The initialization draws the same numbers in both shapes.
    Hs, ws = gm().gcnn_init(np.random.default_rng([0, 0, 22]), 5, 32)
    assert Hs.shape == (5, 1, 32) and ws.shape == (32, 1)
    Hg, wg = gm().gcnn_init(np.random.default_rng([0, 0, 22]), 5, 32, 1, 1)
    np.testing.assert_array_equal(Hs, Hg)
    np.testing.assert_array_equal(ws, wg)
    legacy = np.random.default_rng([0, 0, 22])
    np.testing.assert_array_equal(Hs.reshape(5, 32), legacy.uniform(-1.0, 1.0, (5, 32)) / np.sqrt(5))
    np.testing.assert_array_equal(ws.reshape(32), legacy.uniform(-1.0, 1.0, 32) / np.sqrt(32))


def test_block_loss_reduces_to_the_hand_written_one():
    import torch

    insts = [paper_instance(2, n=8), paper_instance(6, n=8, a_norm=1.05)]
    rng = np.random.default_rng(3)

    def stack(arrays):
        return torch.tensor(np.stack(arrays))

    S = stack([i.gso for i in insts])
    A_t, B_t = stack([i.A.T for i in insts]), stack([i.B.T for i in insts])
    P, Q = stack([i.P for i in insts]), stack([i.Q for i in insts])
    E = stack([np.eye(8)] * 2)
    H = torch.tensor(rng.standard_normal((2, 5, 32)) / 3)
    w = torch.tensor(rng.standard_normal((2, 32)) / 6)
    x0 = torch.tensor(rng.standard_normal((2, 7, 8)))
    loss, (dH, dw) = gm()._loss_and_grad(S, H, w, A_t, B_t, P, x0, 12)
    Hl = H.unsqueeze(2).clone().requires_grad_(True)
    wl = w.unsqueeze(2).clone().requires_grad_(True)
    J = gcnn_block_cost_autograd(S, Hl, wl, E, E, A_t, B_t, Q, Q, P, x0, 12) / 7
    J.sum().backward()
    np.testing.assert_allclose(J.detach().numpy(), loss.numpy(), rtol=1e-12)
    np.testing.assert_allclose(Hl.grad[:, :, 0].numpy(), dH.numpy(), rtol=0, atol=1e-11 * dH.abs().max().item())
    np.testing.assert_allclose(wl.grad[:, :, 0].numpy(), dw.numpy(), rtol=0, atol=1e-11 * dw.abs().max().item())


def test_one_state_per_node_with_other_costs_trains_on_the_autograd_path():
    base = paper_instance(2, n=6, horizon=10)
    inst = Instance.from_matrices(base.A, base.B, R=3 * np.eye(6), comm_adj=base.comm_adj, horizon=10)
    assert inst.scalar_nodes and gm().node_layout(inst) == (6, 6, 1, 1) and gm().node_layout(base) is None
    d = gcnn(inst, steps=10, ensemble=1, stability_steps=0, curve_size=20)
    assert d.status == "optimal" and d.controller.H.shape == (5, 32) and d.controller.w.shape == (32,)
    assert set(d.controller.arrays()) == {"S", "H", "w"}


@pytest.mark.parametrize("uneven", [False, True])
def test_block_bptt_matches_autograd(chain, uneven):
    import torch

    if uneven:
        rng = np.random.default_rng(8)
        A = np.diag(rng.uniform(0.8, 1.05, 6))
        A[1, 4] = A[3, 0] = 0.1
        Q = np.eye(6) + 0.3 * (np.eye(6, k=1) + np.eye(6, k=-1))
        inst = Instance.from_matrices(A, np.eye(6)[:, [1, 0, 4]], Q=Q, R=2 * np.eye(3), horizon=9,
                                      state_nodes=[0, 2, 0, 1, 2, 2], input_nodes=[2, 0, 2],
                                      comm_adj=np.ones((3, 3)))
    else:
        inst = chain
    _, N, p, q = gm().node_layout(inst)
    rng = np.random.default_rng(3)

    def stack(arrays):
        return torch.tensor(np.stack(arrays))

    insts = [inst, inst]
    S = stack([i.gso for i in insts])
    A_t, B_t = stack([i.A.T for i in insts]), stack([i.B.T for i in insts])
    Q, R, P = (stack([getattr(i, k) for i in insts]) for k in "QRP")
    Ex = stack([gm().scatter(i.state_nodes, N, p) for i in insts])
    Eu = stack([gm().scatter(i.input_nodes, N, q).T for i in insts])
    L = stack([gm().tap_map(i.gso, i.state_nodes, 5, p) for i in insts])
    H = torch.tensor(rng.standard_normal((2, 5, p, 32)) / 3)
    w = torch.tensor(rng.standard_normal((2, 32, q)) / 6)
    x0 = torch.tensor(rng.standard_normal((2, 7, inst.n)))
    T = 12
    Hl, wl = H.clone().requires_grad_(True), w.clone().requires_grad_(True)
    reference = gcnn_block_cost_autograd(S, Hl, wl, Ex, Eu, A_t, B_t, Q, R, P, x0, T) / 7
    reference.sum().backward()
    loss, (dH, dw) = gm()._block_loss_and_grad(L, H, w, Eu, A_t, B_t, Q, R, P, x0, T)
    np.testing.assert_allclose(loss.numpy(), reference.detach().numpy(), rtol=1e-12)
    np.testing.assert_allclose(dH.numpy(), Hl.grad.numpy(), rtol=0, atol=1e-11 * Hl.grad.abs().max().item())
    np.testing.assert_allclose(dw.numpy(), wl.grad.numpy(), rtol=0, atol=1e-11 * wl.grad.abs().max().item())
    forward, _ = gm()._block_forward(L, H, w, Eu, A_t, B_t, Q, R, P, x0, T, keep=False)
    np.testing.assert_allclose(forward.numpy() / 7, reference.detach().numpy(), rtol=1e-12)
