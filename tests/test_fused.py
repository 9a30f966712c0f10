"""The fused (numba) GRNN engine against the torch engine, autograd and exact tanh.

The trainer-level checks (BPTT = autograd, stacked = single runs, mask respected,
divergence handling) run for both engines in tests/test_grnn.py.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from codesign import Instance, grnn, paper_instance
from codesign.learned import fused
from codesign.learned.engines import fused_unsupported, resolve_engine
from codesign.learned.trainer import selection_set
from codesign.learned.grnn_bptt import ModelSpec, _Problem, grnn_loss_and_grad, init_fwg
from compare.run.families.mass_spring import mass_spring_instance


@pytest.fixture(scope="module")
def inst():
    return paper_instance(3)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_tanh_is_within_one_unit_of_the_last_place_of_one(dtype):
    x = np.concatenate([np.linspace(-30, 30, 600_001), [0.0, -0.0, 1e-30, -1e-30, 1e30, -1e30]]).astype(dtype)
    z = x.copy()
    (fused.tanh64 if dtype == np.float64 else fused.tanh32)(z, *fused.tanh_constants(dtype))
    assert z.dtype == dtype
    error = np.abs(z.astype(float) - np.tanh(x.astype(float)))
    assert error.max() <= np.finfo(dtype).eps, error.max()
    np.testing.assert_array_equal(np.signbit(z[x != 0]), np.signbit(x[x != 0]))  # odd, sign kept
    special = np.array([np.nan, np.inf, -np.inf], dtype=dtype)
    (fused.tanh64 if dtype == np.float64 else fused.tanh32)(special, *fused.tanh_constants(dtype))
    assert np.isnan(special[0]) and special[1] == 1.0 and special[2] == -1.0


def _stack(specs):
    prob = _Problem(specs, torch.float64)
    params = [torch.tensor(np.stack([getattr(s, n) for s in specs])) for n in ("S0", "F0", "W0", "G0")]
    return prob, params


def _specs(inst):
    """Given support, frozen S, dense S with general Q and R, an unstable plant."""
    n = inst.n
    rng = np.random.default_rng(2)
    custom = Instance.from_matrices(inst.A, inst.B, Q=np.diag(rng.uniform(0.5, 2.0, n)), R=2.0 * np.eye(n),
                                    comm_adj=inst.comm_adj)
    unstable = paper_instance(4, a_norm=1.2)
    out = []
    for m, (instance, S0, mask) in enumerate([
        (inst, inst.gso, inst.comm_adj != 0),
        (inst, inst.gso, np.zeros((n, n), bool)),
        (custom, rng.random((n, n)), np.ones((n, n), bool)),
        (unstable, unstable.gso, unstable.comm_adj != 0),
    ]):
        F, W, G = init_fwg(np.random.default_rng([m, 3]), 5)
        out.append(ModelSpec(A=instance.A, B=instance.B, Q=instance.Q, R=instance.R, P=instance.P,
                             trace_P=instance.trace_P, S0=S0, mask=mask, F0=F, W0=W, G0=G, data_seed=m,
                             curve_x0=selection_set(instance, 10)))
    return out


@pytest.mark.parametrize("activation", ["tanh", "identity"])
@pytest.mark.parametrize("dense", [(0.5, 0.4), (2.0, 2.0), (-1.0, -1.0)], ids=["default", "patterns", "dense"])
def test_fused_cost_and_gradients_equal_the_torch_engine(inst, monkeypatch, activation, dense):
    """Every product path (S and [A B]' by pattern or dense) gives the torch engine's J and gradients."""
    monkeypatch.setattr(fused, "DENSE_S", dense[0])
    monkeypatch.setattr(fused, "DENSE_AB", dense[1])
    specs = _specs(inst)
    prob, (S, F, W, G) = _stack(specs)
    x0 = torch.tensor(np.random.default_rng(9).standard_normal((len(specs), 7, inst.n)))
    zero = torch.zeros(len(specs))
    J, grads = grnn_loss_and_grad(prob, S, F, W, G, x0, penalty=torch.zeros(len(specs), 4), beta=zero,
                                  horizon=inst.horizon, activation=activation)
    mask = np.stack([s.mask for s in specs])
    stack = fused.FusedStack(*(a.numpy() for a in (prob.A, prob.B, prob.Q, prob.R, prob.P)), S.numpy(), mask,
                             hidden=5, horizon=inst.horizon, batch=7, dtype=np.float64,
                             squash=activation == "tanh")
    x0_nodes = np.ascontiguousarray(x0.numpy().transpose(0, 2, 1))
    Jf, *gf = stack.loss_and_grad(S.numpy(), F.numpy(), W.numpy(), G.numpy(), x0_nodes)
    np.testing.assert_allclose(Jf / 7, J.numpy(), rtol=1e-12)
    expected = [grads[0].numpy() * mask] + [g.numpy() for g in grads[1:]]
    for got, want in zip(gf, expected):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    np.testing.assert_allclose(stack.costs(S.numpy(), F.numpy(), W.numpy(), G.numpy(), x0_nodes), Jf, rtol=1e-13)


def test_float32_fused_gradients_are_float32_and_close(inst):
    specs = _specs(inst)[:1]
    prob, params = _stack(specs)
    x0 = np.random.default_rng(1).standard_normal((1, inst.n, 20))
    stack64 = fused.FusedStack(*(a.numpy() for a in (prob.A, prob.B, prob.Q, prob.R, prob.P)), params[0].numpy(),
                               np.stack([specs[0].mask]), hidden=5, horizon=inst.horizon, batch=20,
                               dtype=np.float64, squash=True)
    stack32 = fused.FusedStack(*(a.numpy() for a in (prob.A, prob.B, prob.Q, prob.R, prob.P)), params[0].numpy(),
                               np.stack([specs[0].mask]), hidden=5, horizon=inst.horizon, batch=20,
                               dtype=np.float32, squash=True)
    out64 = stack64.loss_and_grad(*(p.numpy() for p in params), x0)
    out32 = stack32.loss_and_grad(*(p.numpy().astype(np.float32) for p in params), x0.astype(np.float32))
    for a, b in zip(out64, out32):
        assert b.dtype == np.float32
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-5 * np.abs(a).max())


def test_engine_resolution_and_bad_engines():
    two_states = fused_unsupported(states_per_node=2, inputs_per_node=1)
    assert fused_unsupported() is None
    assert resolve_engine("auto") == "fused"
    assert resolve_engine("auto", unsupported=two_states) == "torch"
    assert resolve_engine("torch", unsupported=fused_unsupported(states_per_node=3, inputs_per_node=2)) == "torch"
    assert resolve_engine("auto", nodes=100, support_density=1.0) == "torch"  # slower there
    assert resolve_engine("auto", nodes=100, support_density=0.1) == "fused"
    assert resolve_engine("auto", nodes=20, support_density=1.0) == "fused"
    assert resolve_engine("fused", nodes=100, support_density=1.0) == "fused"
    with pytest.raises(ValueError, match="engine 'fused' needs one state and one input per node, this model has 2 and 1"):
        resolve_engine("fused", unsupported=two_states)
    with pytest.raises(ValueError, match=r"engine 'fused' needs Q = R = I"):
        resolve_engine("fused", unsupported=fused_unsupported(unit_weights=False))
    with pytest.raises(ValueError, match="engine must be one of"):
        resolve_engine("numba")


def test_grnn_method_engines_agree_and_reject_what_they_cannot_run(inst):
    short = dict(steps=20, ensemble=1, stability_steps=20, curve_every=5)
    torch_design = grnn(inst, engine="torch", **short)
    fused_design = grnn(inst, engine="fused", **short)
    assert fused_design.status == torch_design.status == "optimal"
    np.testing.assert_allclose(fused_design.cost, torch_design.cost, rtol=1e-9)
    np.testing.assert_allclose(fused_design.extras["curve"]["cost"], torch_design.extras["curve"]["cost"], rtol=1e-9)
    with pytest.raises(ValueError, match="engine: expected 'torch' or 'fused' or 'auto', got str 'gpu'"):
        grnn(inst, engine="gpu", steps=1)
    chain = mass_spring_instance(4, horizon=10)  # two states per node
    with pytest.raises(ValueError, match="engine 'fused' needs one state and one input per node"):
        grnn(chain, engine="fused", steps=1)
    auto = grnn(chain, engine="auto", steps=5, ensemble=1, stability_steps=10, curve_size=10)
    assert auto.status in ("optimal", "diverged")

