"""The GRNN with a per-node readout (issue #50): u_i = Z_i G_i, on the torch engine, the controller and the method."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from codesign import Instance, compare_exact_and_simulated, controller_from_arrays, get_method, grnn, paper_instance
from codesign.evaluation import impulse_responses
from codesign.learned.engines import fused_unsupported, resolve_engine
from codesign.learned.grnn import GRNNController, LinearGRNNController, _padded_problem
from codesign.learned.grnn_bptt import (GRNNStack, ModelSpec, _Problem, grnn_loss_and_grad,
                                        init_fwg, train_grnn)
from codesign.learned.trainer import selection_set
from compare.run.families.mass_spring import mass_spring_instance
from references import grnn_loss_autograd  # tests/references.py

SHORT = dict(steps=20, ensemble=1, stability_steps=30, curve_size=20)


@pytest.fixture(scope="module")
def inst():
    return paper_instance(3)


def _spec(instance, m, *, hidden=4, per_node=True, G_noise=0.3, **kw):
    """A spec in the padded layout; with ``per_node`` each node's G is the shared draw plus noise."""
    padded = _padded_problem(instance)
    rng = np.random.default_rng([m, 7])
    F, W, G = init_fwg(rng, hidden, padded["p"], padded["q"])
    if per_node:
        G = np.repeat(G[None], instance.nodes, axis=0) + G_noise * rng.standard_normal((instance.nodes,) + G.shape)
    return ModelSpec(A=padded["A"], B=padded["B"], Q=padded["Q"], R=padded["R"], P=padded["P"],
                     trace_P=instance.trace_P, S0=instance.gso, mask=instance.comm_adj != 0, F0=F, W0=W, G0=G,
                     data_seed=[m, 0], curve_x0=padded["embed"](selection_set(instance, 10)),
                     state_index=padded["state_index"], **kw)


def _assert_matches_autograd(specs, x0, *, horizon, activation):
    prob = _Problem(specs, torch.float64)
    tensors = [torch.tensor(np.stack([getattr(s, name) for s in specs])) for name in ("S0", "F0", "W0", "G0")]
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    penalty = torch.tensor([s.penalty for s in specs])
    beta = torch.tensor([s.beta for s in specs])
    leaves = [t.clone().requires_grad_(True) for t in tensors]
    reference = grnn_loss_autograd(prob, *leaves, x0, penalty=penalty, beta=beta, horizon=horizon,
                                   activation=activation, per_node=True)
    reference.sum().backward()
    loss, grads = grnn_loss_and_grad(prob, *tensors, x0, penalty=penalty, beta=beta, horizon=horizon,
                                     activation=activation, readout="per_node")
    np.testing.assert_allclose(loss.numpy(), reference.detach().numpy(), rtol=1e-12)
    for leaf, grad in zip(leaves, grads):
        assert grad.shape == leaf.shape
        np.testing.assert_allclose(grad.numpy(), leaf.grad.numpy(), rtol=0, atol=1e-11 * leaf.grad.abs().max().item())


@pytest.mark.parametrize("activation", ["tanh", "identity"])
def test_per_node_bptt_matches_autograd(inst, activation):
    """Loss and all four gradients (G's per node) equal autograd's, with a general Q, R and a dense S."""
    rng = np.random.default_rng(0)
    custom = Instance.from_matrices(inst.A, inst.B, Q=np.diag(rng.uniform(0.5, 2.0, inst.n)), R=2.0 * np.eye(inst.n),
                                    comm_adj=inst.comm_adj)
    specs = [_spec(inst, 0, beta=0.3), _spec(custom, 1, penalty=(1.0, 0.5, 0.7, 2.0))]
    specs[1].S0, specs[1].mask = rng.random((inst.n, inst.n)), np.ones((inst.n, inst.n), bool)
    assert np.shape(specs[0].G0) == (inst.n, 4)
    _assert_matches_autograd(specs, rng.standard_normal((2, 6, inst.n)), horizon=inst.horizon, activation=activation)


@pytest.mark.parametrize("activation", ["tanh", "identity"])
def test_per_node_bptt_matches_autograd_on_uneven_blocks(uneven, activation):
    """p = 3 states and q = 2 inputs per node after padding, G (N, h, q): every gradient equals autograd's."""
    specs = [_spec(uneven, 0, beta=0.2), _spec(uneven, 1, penalty=(1.0, 0.5, 0.7, 2.0))]
    assert np.shape(specs[0].G0) == (4, 4, 2)
    rng = np.random.default_rng(1)
    x0 = np.zeros((2, 5, 12))
    x0[:, :, specs[0].state_index] = rng.standard_normal((2, 5, 8))
    _assert_matches_autograd(specs, x0, horizon=uneven.horizon, activation=activation)


def test_equal_readouts_are_the_shared_model(inst):
    """With G_i = g at every node the per-node loss is the shared one, and dG_i sums to the shared dG."""
    shared = _spec(inst, 0, per_node=False)
    prob = _Problem([shared], torch.float64)
    S, F, W, G = (torch.tensor(np.asarray(getattr(shared, k))[None]) for k in ("S0", "F0", "W0", "G0"))
    x0 = torch.tensor(np.random.default_rng(3).standard_normal((1, 5, inst.n)))
    zero, beta = torch.zeros(1, 4, dtype=torch.float64), torch.zeros(1, dtype=torch.float64)
    loss, grads = grnn_loss_and_grad(prob, S, F, W, G, x0, penalty=zero, beta=beta, horizon=inst.horizon)
    Gn = G[:, None].repeat(1, inst.n, 1)
    loss_n, grads_n = grnn_loss_and_grad(prob, S, F, W, Gn, x0, penalty=zero, beta=beta, horizon=inst.horizon,
                                         readout="per_node")
    np.testing.assert_allclose(loss_n.numpy(), loss.numpy(), rtol=1e-13)
    for a, b in zip(grads_n[:3], grads[:3]):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(grads_n[3].sum(1).numpy(), grads[3].numpy(), rtol=1e-11)


def test_controller_with_a_per_node_readout(inst):
    """The controller reads node i with G[i]; equal rows are the shared controller; arrays round-trip."""
    rng = np.random.default_rng(1)
    h, n = 3, inst.n
    F, W, g = rng.random(h), rng.random((h, h)) / 3, rng.random(h) / 3
    G = g + 0.1 * rng.standard_normal((n, h))
    c = GRNNController(inst.gso, F, W, G)
    assert c.readout == "per_node" and GRNNController(inst.gso, F, W, g).readout == "shared"
    x = rng.standard_normal((4, n))
    Z = np.zeros((4, n, h))
    state = c.reset(4)
    for _ in range(3):
        Z = np.tanh(np.einsum("ij,bjk->bik", c.S, Z @ W) + x[:, :, None] * F)
        u, state = c.step(state, x)
        np.testing.assert_allclose(u, np.einsum("bik,ik->bi", Z, G), atol=1e-14)
        x = x @ inst.A.T + u @ inst.B.T
    same = GRNNController(inst.gso, F, W, np.tile(g, (n, 1)))
    shared = GRNNController(inst.gso, F, W, g)
    x = rng.standard_normal((5, n))
    np.testing.assert_allclose(same.step(same.reset(5), x)[0], shared.step(shared.reset(5), x)[0], atol=1e-15)
    again = controller_from_arrays("grnn", c.arrays())
    np.testing.assert_array_equal(again.G, c.G)
    assert again.readout == "per_node"
    assert c.rollout(inst, x, 5) is None  # the compiled rollout reads one G: the step loop runs


def test_per_node_readout_on_a_sparse_s_above_the_structured_size():
    """Above STRUCTURED_ABOVE nodes S acts by its CSR on a node-major state: G[i] still reads node i."""
    rng = np.random.default_rng(4)
    n, h = 250, 3
    S = (rng.random((n, n)) < 0.02) * rng.random((n, n)) * 0.1
    F, W, G = rng.random(h), rng.random((h, h)) / 3, rng.standard_normal((n, h))
    c = GRNNController(S, F, W, G)
    assert c._S_op is not None and c.readout == "per_node"
    state, Z = c.reset(4), np.zeros((4, n, h))
    for _ in range(3):
        x = rng.standard_normal((4, n))
        Z = np.tanh(np.einsum("ij,bjk->bik", S, Z @ W) + x[:, :, None] * F)
        u, state = c.step(state, x)
        np.testing.assert_allclose(u, np.einsum("bik,ik->bi", Z, G), atol=1e-13)


def test_linear_per_node_closed_loop_is_exact(inst, uneven):
    """The linearized closed loop (dense and sparse) reproduces the responses, and the exact cost the simulation."""
    rng = np.random.default_rng(2)
    for instance, h in ((inst, 3), (uneven, 4)):
        padded = _padded_problem(instance)
        p, q, N = padded["p"], padded["q"], instance.nodes
        F = rng.random((p, h)) / 2 if p > 1 else rng.random(h) / 2
        G = -rng.random((N, h, q)) / 2 if q > 1 else -rng.random((N, h)) / 2
        nodes = {} if instance.scalar_nodes else dict(state_nodes=instance.state_nodes,
                                                       input_nodes=instance.input_nodes)
        c = LinearGRNNController(instance.gso * 0.5, F, rng.random((h, h)) / 3, G, **nodes)
        assert c.readout == "per_node"
        phi_x, _ = impulse_responses(instance, c, 6)
        Mcl = c.linearized_closed_loop(instance)
        if instance.scalar_nodes:
            np.testing.assert_allclose(c.linearized_closed_loop(instance, sparse=True).toarray(), Mcl, atol=1e-15)
        z = np.zeros((Mcl.shape[0], instance.n))
        z[:instance.n] = np.eye(instance.n)
        for _ in range(6):
            z = Mcl @ z
        np.testing.assert_allclose(z[:instance.n], phi_x[6], atol=1e-12)
        check = compare_exact_and_simulated(instance, c)
        assert abs(check["control_variate"] - check["exact"]) < 1e-8 * check["exact"]


def test_a_per_node_readout_does_not_transfer_to_another_size(inst):
    """A per-node G names its nodes: on an S of another size the controller refuses it in one line."""
    rng = np.random.default_rng(3)
    with pytest.raises(ValueError, match=r"per node \(7, h\)"):
        GRNNController(np.eye(7), rng.random(3), rng.random((3, 3)), rng.random((inst.n, 3)))


def test_engine_rule_for_per_node(inst):
    """auto takes torch; an explicit fused is a one-line error naming the setting and the engine."""
    per_node = fused_unsupported(readout="per_node")
    assert resolve_engine("auto", unsupported=per_node) == "torch"
    assert resolve_engine("auto", unsupported=fused_unsupported()) == "fused"
    with pytest.raises(ValueError, match="engine 'fused' supports readout 'shared' only, got readout 'per_node'"):
        resolve_engine("fused", unsupported=per_node)
    with pytest.raises(ValueError, match="engine 'fused' supports readout 'shared' only"):
        grnn(inst, readout="per_node", engine="fused", steps=1)
    with pytest.raises(ValueError, match="readout"):
        grnn(inst, readout="nodes", steps=1)
    with pytest.raises(ValueError, match=r"readout 'per_node' needs G0 of shape \(20, 4, 1\) or \(20, 4\)"):
        train_grnn([_spec(inst, 0, per_node=False)], steps=1, horizon=inst.horizon, readout="per_node")
    assert GRNNStack.engine_for([_spec(inst, 0).member()], "auto", readout="per_node") == "torch"


def test_the_setting_is_one_more_hyperparameter():
    """readout is in every GRNN method's table with its choices, default shared (not in a default run's params)."""
    for name in ("grnn", "grnn_dense", "grnn_fixed", "grnn_sparse"):
        hyper = get_method(name).hyperparameters["readout"]
        assert hyper.default == "shared"
        hyper.check("per_node", "readout")
        with pytest.raises(ValueError, match="readout"):
            hyper.check("each", "readout")


@pytest.mark.parametrize("variant", ["given", "sparse"])
def test_per_node_designs_train_and_score(inst, variant):
    """Tanh and linear per-node designs: G (N, h) per node, the setting in params, the linear one scored exactly."""
    kw = dict(beta=1.0, l1_hops=2) if variant == "sparse" else {}
    tanh = grnn(inst, variant=variant, readout="per_node", **SHORT, **kw)
    assert tanh.status == "optimal" and tanh.params["readout"] == "per_node"
    assert tanh.controller.G.shape == (inst.n, 5) and tanh.cost_kind == "simulated"
    linear = grnn(inst, variant=variant, readout="per_node", activation="identity", **SHORT, **kw)
    assert linear.cost_kind == "exact" and linear.controller.readout == "per_node"
    shared = grnn(inst, variant=variant, **dict(SHORT, curve_size=100), **kw)  # the fused kernels other tests compile
    assert "readout" not in shared.params and shared.controller.readout == "shared"


def test_per_node_on_node_blocks_trains():
    """Mass-spring nodes (two states, one input): G (N, h, 1) per node, scored exactly when linear."""
    chain = mass_spring_instance(5, horizon=15)
    design = grnn(chain, readout="per_node", activation="identity", **SHORT)
    assert design.status == "optimal" and design.controller.G.shape == (5, 5, 1)
    assert design.controller.readout == "per_node" and design.cost_kind == "exact"
