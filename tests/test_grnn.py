"""GRNN controller, batched trainer and co-design variants (small M, few steps)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from codesign import (
    Instance,
    compare_exact_and_simulated,
    controller_from_arrays,
    grnn,
    grnn_batch,
    paper_instance,
    simulate,
)
from codesign.learned.grnn import GRNNController, LinearGRNNController
from codesign.learned.grnn_bptt import ModelSpec, init_fwg, train_grnn
from codesign.learned.trainer import clip_coefficients, selection_set
from references import assert_bptt_matches_autograd  # tests/references.py


@pytest.fixture(scope="module")
def inst():
    return paper_instance(3)


@pytest.fixture(scope="module")
def unstable():
    return paper_instance(4, a_norm=1.05)


def _spec(instance, m, *, mask=None, S0=None, lr=0.02, beta=0.0, penalty=(2.0, 2.0, 0.0, 2.0)):
    F, W, G = init_fwg(np.random.default_rng([m, 7]), 5)
    return ModelSpec(
        A=instance.A, B=instance.B, Q=instance.Q, R=instance.R, P=instance.P, trace_P=instance.trace_P,
        S0=instance.gso if S0 is None else S0, mask=instance.comm_adj != 0 if mask is None else mask,
        F0=F, W0=W, G0=G, data_seed=[m, 0], curve_x0=selection_set(instance, 10), lr=lr, beta=beta,
        penalty=penalty,
    )


@pytest.mark.parametrize("engine", ["torch", "fused"])
@pytest.mark.parametrize("activation", ["tanh", "identity"])
def test_hand_written_bptt_matches_autograd(inst, unstable, activation, engine):
    """Loss and all four gradients of the hand-written BPTT equal autograd's, with a general Q, R."""
    rng = np.random.default_rng(0)
    Q = np.diag(rng.uniform(0.5, 2.0, inst.n))
    custom = Instance.from_matrices(inst.A, inst.B, Q=Q, R=2.0 * np.eye(inst.n), comm_adj=inst.comm_adj)
    specs = [_spec(inst, 0, beta=0.3), _spec(unstable, 1, penalty=(1.0, 0.5, 0.7, 2.0)),
             _spec(custom, 2, S0=rng.random((inst.n, inst.n)), mask=np.ones((inst.n, inst.n), bool))]
    assert_bptt_matches_autograd(specs, rng.standard_normal((3, 6, inst.n)), horizon=inst.horizon,
                                 activation=activation, engine=engine)


@pytest.mark.parametrize("engine", ["torch", "fused"])
def test_support_is_respected_exactly(inst, engine):
    """Off the mask S stays exactly zero (given support) or exactly at S0 (frozen S)."""
    n = inst.n
    given = _spec(inst, 0)
    frozen = _spec(inst, 1, mask=np.zeros((n, n), bool))
    results = train_grnn([given, frozen], steps=15, curve_every=5, engine=engine)
    off = inst.comm_adj == 0
    assert np.all(results[0].params["S"][off] == 0.0)
    assert np.any(results[0].params["S"][~off] != inst.gso[~off])  # the support did train
    np.testing.assert_array_equal(results[1].params["S"], inst.gso)


@pytest.mark.parametrize("engine", ["torch", "fused"])
def test_stacked_run_equals_single_runs(inst, unstable, engine):
    """A stack of M models gives the parameters of M separate runs with the same seeds."""
    n = inst.n
    specs = [_spec(inst, 0), _spec(unstable, 1, lr=0.03),
             _spec(inst, 2, S0=np.full((n, n), 1.0 / n), mask=np.ones((n, n), bool), beta=0.5)]
    stacked = train_grnn(specs, steps=12, curve_every=4, engine=engine)
    for spec, together in zip(specs, stacked):
        alone = train_grnn([spec], steps=12, curve_every=4, engine=engine)[0]
        for name in ("S", "F", "W", "G"):
            np.testing.assert_allclose(together.params[name], alone.params[name], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(together.curve_cost, alone.curve_cost, rtol=1e-9)


def test_l1_stage_sparsifies_more_with_larger_beta(inst):
    """More entries of S fall below the threshold as beta grows."""
    n = inst.n
    dense = np.random.default_rng(5).random((n, n))
    dense /= dense.sum(axis=1, keepdims=True)
    betas = (0.0, 1.0, 10.0)
    specs = [_spec(inst, 0, S0=dense, mask=np.ones((n, n), bool), lr=0.03, beta=b, penalty=(2.0, 2.0, 0.0, 0.0))
             for b in betas]
    results = train_grnn(specs, steps=60, curve_every=0)
    small = [int(np.sum(np.abs(r.params["S"]) < 4e-3)) for r in results]
    assert small[0] < small[1] < small[2], small


@pytest.mark.parametrize("engine", ["torch", "fused"])
def test_diverging_model_is_flagged_and_others_continue(inst, engine):
    """A model whose loss overflows is recorded as diverged; the rest of the stack trains normally."""
    n = inst.n
    wild = Instance.from_matrices(1e4 * np.eye(n), np.eye(n), comm_adj=inst.comm_adj)
    specs = [_spec(inst, 0), _spec(wild, 1), _spec(inst, 2)]
    results = train_grnn(specs, steps=10, curve_every=5, engine=engine)
    assert [r.diverged for r in results] == [False, True, False]
    assert results[1].diverged_at == 0
    alone = train_grnn([specs[2]], steps=10, curve_every=5, engine=engine)[0]
    np.testing.assert_allclose(results[2].params["S"], alone.params["S"], rtol=1e-9, atol=1e-12)
    assert all(np.isfinite(results[0].curve_cost))


@pytest.mark.parametrize("engine", ["torch", "fused"])
def test_all_members_diverged_is_a_recorded_status(inst, engine):
    n = inst.n
    wild = Instance.from_matrices(1e4 * np.eye(n), np.eye(n), comm_adj=inst.comm_adj)
    design = grnn(wild, steps=3, ensemble=2, stability_steps=0, engine=engine)
    assert design.status == "diverged" and np.isnan(design.cost)
    assert "diverged" in design.message


def test_grnn_controller_matches_the_recurrence_and_round_trips(inst):
    rng = np.random.default_rng(1)
    c = GRNNController(inst.gso, rng.random(5), rng.random((5, 5)) / 5, rng.random(5) / 5)
    x = rng.standard_normal((4, inst.n))
    Z = np.zeros((4, inst.n, 5))
    state = c.reset(4)
    for _ in range(3):
        Z = np.tanh(np.einsum("ij,bjk->bik", c.S, Z @ c.W) + x[:, :, None] * c.F)
        u_ref = Z @ c.G
        u, state = c.step(state, x)
        np.testing.assert_allclose(u, u_ref, atol=1e-14)
        x = x @ inst.A.T + u @ inst.B.T
    again = controller_from_arrays("grnn", c.arrays())
    np.testing.assert_array_equal(again.S, c.S)
    assert simulate(inst, again).cost == simulate(inst, c).cost


def test_linearization_predicts_small_signal_rollout(inst):
    """The linearized closed loop in (x, Z) matches a rollout from a tiny x(0)."""
    rng = np.random.default_rng(2)
    c = GRNNController(inst.gso * (inst.comm_adj != 0), rng.random(5), rng.random((5, 5)) / 3, -rng.random(5))
    L = c.linearized_closed_loop(inst)
    x = 1e-7 * rng.standard_normal(inst.n)
    state = np.zeros(inst.n * 5)
    xs = np.concatenate([x, state])
    xb, zb = x[None, :], c.reset(1)
    for _ in range(5):
        u, zb = c.step(zb, xb)
        xb = xb @ inst.A.T + u @ inst.B.T
        xs = L @ xs
    np.testing.assert_allclose(xb[0], xs[: inst.n], rtol=1e-6, atol=1e-16)


def test_variants_links_and_extras(inst):
    designs = grnn_batch([
        (inst, {"variant": v, "steps": 30, "ensemble": 1, "stability_steps": 50, "curve_every": 10})
        for v in ("given", "dense", "fixed", "sparse")
    ])
    given, dense, fixed, sparse = designs
    links = int(np.sum(inst.comm_adj != 0)) - inst.n
    assert (given.links, given.self_loops) == (links, inst.n)
    assert (fixed.links, fixed.self_loops) == (links, inst.n)
    assert (dense.links, dense.self_loops) == (inst.n * (inst.n - 1), inst.n)
    assert sparse.params["beta"] == 1.0  # the paper's Table 1 value for a_norm 0.995
    assert sparse.links + sparse.self_loops == sparse.extras["l1_links"] + sparse.extras["l1_self_loops"]
    for d in designs:
        assert d.status == "optimal" and d.info_model == "delayed" and d.cost_kind == "simulated"
        assert d.cost >= 1.0 - 4 * d.cost_stderr and d.cost_stderr > 0
        assert d.extras["curve"]["step"] == [0, 10, 20, 30]
        assert d.extras["curve"]["cost"][-1] < d.extras["curve"]["cost"][0]
        assert d.extras["spectral_radius"] > 0 and isinstance(d.extras["bounded"], bool)


def test_bad_input_raises(inst):
    with pytest.raises(ValueError, match="variant"):
        grnn(inst, variant="banana")
    with pytest.raises(ValueError, match="beta"):
        grnn(inst, variant="given", beta=1.0)
    with pytest.raises(ValueError, match="a_norm"):
        grnn(paper_instance(0, a_norm=1.2), variant="sparse", steps=1)
    with pytest.raises(ValueError, match="steps"):
        grnn(inst, steps=0)
    with pytest.raises(ValueError, match="dtype"):
        grnn(inst, dtype="float16")


@pytest.mark.parametrize("name", ["grnn", "grnn_dense", "grnn_fixed"])
def test_co_design_settings_are_rejected_by_the_other_variants(inst, name):
    from compare.run.registry import get_method

    method = get_method(name)
    for key in ("beta", "l1_lr", "threshold", "refine_ensemble"):
        assert key not in method.hyperparameters
        with pytest.raises(ValueError, match=f"params.{key}: unknown hyperparameter"):
            method.check_params({key: 1})
    with pytest.raises(ValueError, match="params.threshold: unknown hyperparameter"):
        method(inst, threshold=0.1, steps=1)
    with pytest.raises(ValueError, match="params.threshold: unknown hyperparameter"):
        method.run_batch([(inst, {"threshold": 0.1, "steps": 1})])
    assert "threshold" in get_method("grnn_sparse").hyperparameters


@pytest.mark.slow
def test_float32_reaches_the_float64_median_cost():
    """Paper-scale: median final cost over instances agrees within 1 % between float32 and float64."""
    instances = [paper_instance(seed, a_norm=a) for seed in range(6) for a in (0.995, 1.05)]
    costs = {}
    for dtype in ("float64", "float32"):
        designs = grnn_batch([(i, {"variant": "given", "dtype": dtype, "ensemble": 1}) for i in instances])
        costs[dtype] = np.median([d.cost for d in designs])
    assert abs(costs["float32"] / costs["float64"] - 1) < 0.01, costs


def _augmented_cost(instance, controller) -> float:
    """Finite-horizon cost of a linear GRNN by covariance propagation of its closed loop on (x, vec Z)."""
    n, h = instance.n, controller.hidden
    Acl = controller.linearized_closed_loop(instance)  # exact for the identity activation
    # u(t) = G Z(t+1) = Gm (Kzx x(t) + Kzz z(t)): the bottom block row of Acl, read out by Gm.
    Gm = np.kron(np.eye(n), controller.G.reshape(1, h))
    K = Gm @ Acl[n:]
    Sigma = np.zeros((n + n * h, n + n * h))
    Sigma[:n, :n] = np.eye(n)
    total = 0.0
    for _ in range(instance.horizon):
        total += np.trace(instance.Q @ Sigma[:n, :n]) + np.trace(instance.R @ K @ Sigma @ K.T)
        Sigma = Acl @ Sigma @ Acl.T
    total += np.trace(instance.P @ Sigma[:n, :n])
    return total / instance.trace_P


@pytest.mark.parametrize("variant,beta", [("given", None), ("dense", None), ("fixed", None), ("sparse", 0.5)])
def test_linear_grnn_is_scored_exactly(unstable, variant, beta):
    """The identity activation gives a linear controller: exact cost, equal to an independent closed form."""
    design = grnn(unstable, variant=variant, beta=beta, activation="identity", steps=40, ensemble=1,
                  stability_steps=0)
    assert design.status == "optimal", design.message
    assert isinstance(design.controller, LinearGRNNController)
    assert design.cost_kind == "exact" and design.cost_stderr == 0.0
    assert design.params["activation"] == "identity"
    np.testing.assert_allclose(design.cost, _augmented_cost(unstable, design.controller), rtol=1e-9)
    # The rollout simulator agrees: plain mean within 3 standard errors, control variates to rounding.
    check = compare_exact_and_simulated(unstable, design.controller)
    assert abs(check["z"]) < 3
    np.testing.assert_allclose(check["control_variate"], design.cost, rtol=1e-9)
    stored = controller_from_arrays(design.controller.kind, design.controller.arrays())
    assert isinstance(stored, LinearGRNNController)
    assert design.extras["bounded"] == (design.extras["spectral_radius"] < 1)


def test_linear_grnn_differs_from_the_tanh_grnn_only_by_the_activation(inst):
    """Same seeds, same initial parameters: the first curve point differs (σ differs), the links match the given graph."""
    kwargs = dict(steps=5, ensemble=1, curve_every=1, stability_steps=0)
    tanh, linear = grnn(inst, **kwargs), grnn(inst, activation="identity", **kwargs)
    assert tanh.links == linear.links
    assert tanh.extras["curve"]["cost"][0] != linear.extras["curve"]["cost"][0]
    x = np.random.default_rng(0).standard_normal((3, inst.n))
    ctrl = linear.controller
    state = ctrl.reset(3)
    _, Z = ctrl.step(state, x)
    np.testing.assert_allclose(Z, ctrl.F[:, None, None] * x[None])  # Z(1) = x(0) F, no squashing; (h, batch, N)


def test_gradient_norm_is_finite_for_huge_float32_gradients():
    """A linear GRNN on an unstable plant starts with gradients ~1e22 whose squares overflow float32."""
    grads = [torch.full((2, 3, 3), 1e22, dtype=torch.float32), torch.full((2, 4), -1e22, dtype=torch.float32)]
    grads[0][1] = 0.0
    grads[1][1] = 0.0
    norm, coef = clip_coefficients(grads, 10.0)
    np.testing.assert_allclose(norm.numpy(), [1e22 * np.sqrt(13), 0.0], rtol=1e-6)
    np.testing.assert_allclose(coef.numpy(), [10.0 / (1e22 * np.sqrt(13)), 1.0], rtol=1e-5)


def test_unknown_activation_is_a_clear_error(inst):
    with pytest.raises(ValueError, match="activation: expected 'tanh' or 'identity', got str 'relu'"):
        grnn(inst, activation="relu", steps=1)

