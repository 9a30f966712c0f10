"""GCNN baseline (Gama & Sojoudi 2021) as the paper benchmarked it."""

from __future__ import annotations

import numpy as np
import pytest

from baselines import GCNNController, gcnn, gcnn_batch
from codesign import Instance, controller_from_arrays, paper_instance, simulate
from compare.run.registry import get_method
from references import gcnn_cost_autograd  # tests/references.py


@pytest.fixture(scope="module")
def inst():
    return paper_instance(2)


def test_gcnn_has_192_parameters_and_reports_instantaneous_links(inst):
    design = gcnn(inst, steps=20, ensemble=1, stability_steps=40)
    assert design.controller.n_parameters == 192
    assert design.extras["n_parameters"] == 192
    assert design.controller.H.shape == (5, 32) and design.controller.w.shape == (32,)
    assert design.info_model == "instantaneous"
    assert design.links == int(np.sum(inst.comm_adj != 0)) - inst.n
    assert design.status == "optimal" and design.cost_kind == "simulated" and design.cost_stderr > 0
    curve = design.extras["curve"]
    assert curve["step"] == [0, 10, 20] and curve["cost"][-1] < curve["cost"][0]


def test_gcnn_controller_is_the_filter_bank(inst):
    rng = np.random.default_rng(0)
    H, w = rng.standard_normal((5, 32)) / 3, rng.standard_normal(32) / 6
    c = GCNNController(inst.gso, H, w)
    x = rng.standard_normal((3, inst.n))
    z = sum(np.einsum("ij,bj->bi", np.linalg.matrix_power(inst.gso, k), x)[:, :, None] * H[k] for k in range(5))
    u, _ = c.step(None, x)
    np.testing.assert_allclose(u, np.tanh(z) @ w, atol=1e-13)
    # Linearization at the origin: small signals see the gain sum_k (H_k . w) S^k. At 1e-5 (the
    # scale of local_cost_form is 1e-4) the cubic term of tanh is 1e-10 of the signal, and the
    # controller's 2 sigmoid(2 z) - 1 arithmetic, accurate to 1e-16 absolute, 1e-10 of it too.
    small = 1e-5 * x
    np.testing.assert_allclose(c.step(None, small)[0], small @ c.linear_gain().T, rtol=1e-6, atol=1e-20)
    again = controller_from_arrays("gcnn", c.arrays())
    assert simulate(inst, again).cost == simulate(inst, c).cost


def test_stacked_gcnn_equals_single_runs(inst):
    other = paper_instance(5, a_norm=1.05)
    together = gcnn_batch([(inst, {"steps": 8, "ensemble": 1, "stability_steps": 0, "seed": 1}),
                           (other, {"steps": 8, "ensemble": 1, "stability_steps": 0, "seed": 2})])
    alone = gcnn(other, steps=8, ensemble=1, stability_steps=0, seed=2)
    np.testing.assert_allclose(together[1].controller.H, alone.controller.H, rtol=1e-9, atol=1e-13)
    assert together[1].params == alone.params == {"seed": 2, "steps": 8, "ensemble": 1, "stability_steps": 0}


def test_registered_with_batch_hook(inst):
    method = get_method("gcnn")
    assert method.label == "GCNN"
    assert method.batch is not None and "training_curve" in method.produces
    out = method.run_batch([(inst, {"steps": 4, "ensemble": 1, "stability_steps": 0})])
    assert len(out) == 1 and out[0][0].method == "gcnn"


def test_bad_input_raises(inst):
    with pytest.raises(ValueError, match="steps"):
        gcnn(inst, steps=0)
    with pytest.raises(ValueError, match="decay"):
        gcnn(inst, decay=1.5)


def test_hand_written_bptt_matches_autograd(inst):
    import torch

    gm = __import__("codesign.learned.gcnn_bptt", fromlist=["_"])
    insts = [inst, paper_instance(6, a_norm=1.05)]
    rng = np.random.default_rng(3)

    def stack(arrays):
        return torch.tensor(np.stack(arrays))

    S, A_t, B_t, P = (stack([getattr(i, k) if k != "A" else i.A for i in insts]) for k in ("gso", "A", "B", "P"))
    A_t, B_t = A_t.transpose(1, 2).contiguous(), B_t.transpose(1, 2).contiguous()
    H = torch.tensor(rng.standard_normal((2, 5, 32)) / 3)
    w = torch.tensor(rng.standard_normal((2, 32)) / 6)
    x0 = torch.tensor(rng.standard_normal((2, 7, inst.n)))
    Hl, wl = H.clone().requires_grad_(True), w.clone().requires_grad_(True)
    reference = gcnn_cost_autograd(S, Hl, wl, A_t, B_t, P, x0, inst.horizon) / 7
    reference.sum().backward()
    loss, (dH, dw) = gm._loss_and_grad(S, H, w, A_t, B_t, P, x0, inst.horizon)
    np.testing.assert_allclose(loss.numpy(), reference.detach().numpy(), rtol=1e-12)
    np.testing.assert_allclose(dH.numpy(), Hl.grad.numpy(), rtol=0, atol=1e-11 * Hl.grad.abs().max().item())
    np.testing.assert_allclose(dw.numpy(), wl.grad.numpy(), rtol=0, atol=1e-11 * wl.grad.abs().max().item())


@pytest.mark.parametrize("dtype, rtol", [("float64", 1e-12), ("float32", 1e-3)])
def test_fused_engine_equals_the_torch_path(dtype, rtol):
    """The compiled GCNN pass gives the torch path's loss, gradients and curve costs (to rounding)."""
    import torch

    from codesign.learned.gcnn import ensemble_member, parse_job
    from codesign.learned.gcnn_bptt import GCNNStack

    insts = [paper_instance(s, n=10, degree=4, horizon=12, a_norm=1.05) for s in range(3)]
    jobs = [parse_job(i, dict(dtype=dtype, ensemble=1, steps=5, batch=6, curve_size=9)) for i in insts]
    assert {job.engine for job in jobs} == {"fused"}  # "auto" on the paper's setting
    members = [ensemble_member(job, 0) for job in jobs]
    loop = jobs[0].settings.loop(12)
    torch_path, fused = GCNNStack(members, loop, engine="torch"), GCNNStack(members, loop, engine="fused")
    rng = np.random.default_rng(0)
    x0 = torch.tensor(rng.standard_normal((3, 6, 10)), dtype=getattr(torch, dtype))
    (loss_t, grads_t), (loss_f, grads_f) = torch_path.loss_and_grad(x0), fused.loss_and_grad(x0)
    np.testing.assert_allclose(loss_f.numpy(), loss_t.numpy(), rtol=rtol)
    for gt, gf in zip(grads_t, grads_f):
        assert gt.shape == gf.shape
        np.testing.assert_allclose(gf.numpy(), gt.numpy(), rtol=rtol, atol=rtol * float(gt.abs().max()))
    xc = torch.tensor(rng.standard_normal((3, 9, 10)), dtype=x0.dtype)
    np.testing.assert_allclose(fused.curve_cost(xc).numpy(), torch_path.curve_cost(xc).numpy(), rtol=rtol)


def test_gcnn_engines_agree_and_fused_refuses_node_blocks():
    from compare.run.families.mass_spring import mass_spring_instance

    inst = paper_instance(4, n=8, degree=4, horizon=12)  # the method-contract test's kernel shapes
    short = dict(steps=15, ensemble=1, stability_steps=0, curve_size=10, curve_every=5)
    by_torch, by_fused = gcnn(inst, engine="torch", **short), gcnn(inst, engine="fused", **short)
    assert by_torch.status == by_fused.status == "optimal"
    np.testing.assert_allclose(by_fused.extras["curve"]["cost"], by_torch.extras["curve"]["cost"], rtol=1e-9)
    np.testing.assert_allclose(by_fused.cost, by_torch.cost, rtol=1e-9)
    with pytest.raises(ValueError, match="engine 'fused' needs one state and one input per node"):
        gcnn(mass_spring_instance(3), engine="fused", **short)


def test_auto_takes_the_fused_gcnn_only_where_it_is_faster():
    from codesign.learned.gcnn import parse_job
    from compare.run.families.mass_spring import mass_spring_instance

    assert parse_job(paper_instance(0, n=20), {}).engine == "fused"
    assert parse_job(paper_instance(0, n=40, degree=6), {}).engine == "torch"  # dense loops do not unroll
    assert parse_job(paper_instance(0, n=40, degree=6), {"engine": "fused"}).engine == "fused"
    assert parse_job(mass_spring_instance(3), {}).engine == "torch"  # node blocks
    paper = paper_instance(0, n=20)
    weighted = Instance.from_matrices(paper.A, paper.B, Q=2.0 * paper.Q, comm_adj=paper.comm_adj)
    assert parse_job(weighted, {}).engine == "torch"  # the fused kernel assumes Q = R = I
    with pytest.raises(ValueError, match=r"engine 'fused' needs Q = R = I; use engine 'torch' or 'auto'"):
        parse_job(weighted, {"engine": "fused"})
