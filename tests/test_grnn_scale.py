"""GRNNs at a thousand nodes: sparse rollouts and linearization, the l1 stage on a few hops, size limits.

Above STRUCTURED_ABOVE states a GRNN's S, and the plant's A, B, Q, R, are multiplied on
their supports when the rollouts score it, and its linearized closed loop's spectral
radius comes from ARPACK on a sparse matrix. At small sizes the thresholds are lowered
to force that path, and the results are compared with the dense path that every
shipped report was computed with.
"""

from types import SimpleNamespace

import importlib

import numpy as np
import pytest

import baselines  # noqa: F401  (registers the GRNN methods)
from codesign import evaluation
from codesign.evaluation import exact_cost, local_cost_form, simulate, spectral_radius, validation_set
from codesign.instances import hop_distances, paper_instance
from codesign.methods import get_method

grnn_module = importlib.import_module("codesign.learned.grnn")
grnn_controller = importlib.import_module("codesign.learned.grnn_controller")
GRNNController, LinearGRNNController = grnn_module.GRNNController, grnn_module.LinearGRNNController


@pytest.fixture(scope="module")
def inst():
    return paper_instance(5, n=24, horizon=20)


def _parameters(inst, seed=0):
    rng = np.random.default_rng(seed)
    S = np.where(inst.comm_adj != 0, 0.3 * rng.random(inst.comm_adj.shape), 0.0) + 0.2 * np.eye(inst.n)
    return S, 0.5 * rng.random(5), 0.3 * rng.random((5, 5)), -0.3 * rng.random(5)


def _structured(monkeypatch):
    """Every size takes the structured path, and every matrix is multiplied as CSR."""
    monkeypatch.setattr(evaluation, "STRUCTURED_ABOVE", 0)
    monkeypatch.setattr(grnn_controller, "STRUCTURED_ABOVE", 0)
    monkeypatch.setattr(evaluation, "SPARSE_DENSITY", 1.0)


@pytest.mark.parametrize("kind", [GRNNController, LinearGRNNController])
def test_sparse_rollouts_equal_the_dense_ones(inst, monkeypatch, kind):
    S, F, W, G = _parameters(inst)
    dense = kind(S, F, W, G)
    x0 = validation_set(inst, 300)
    before = simulate(inst, dense, x0)
    form_before = local_cost_form(inst, dense)
    _structured(monkeypatch)
    sparse = kind(S, F, W, G)
    assert sparse._S_op is not None and dense._S_op is None
    assert sparse.reset(7).shape == (inst.n, 5, 7)  # node-major hidden state
    after = simulate(inst, sparse, x0)
    np.testing.assert_allclose(after.costs, before.costs, rtol=1e-12)
    assert after.bounded == before.bounded and after.max_state == pytest.approx(before.max_state, rel=1e-12)
    np.testing.assert_allclose(local_cost_form(inst, sparse), form_before, rtol=1e-10, atol=1e-14)


def test_sparse_linearization_has_the_dense_spectral_radius(inst):
    S, F, W, G = _parameters(inst, seed=3)
    controller = GRNNController(S, F, W, G)
    dense = controller.linearized_closed_loop(inst)
    sparse = controller.linearized_closed_loop(inst, sparse=True)
    np.testing.assert_allclose(sparse.toarray(), dense, rtol=0, atol=1e-15)
    assert spectral_radius(sparse) == pytest.approx(spectral_radius(dense), rel=1e-10)


def test_a_sparse_linear_grnn_scores_its_exact_cost(inst, monkeypatch):
    """The linear GRNN's rollout on the structured path against its closed form (impulse responses)."""
    S, F, W, G = _parameters(inst, seed=1)
    _structured(monkeypatch)
    controller = LinearGRNNController(S, 0.2 * F, 0.5 * W, 0.2 * G)
    x0 = np.eye(inst.n) * np.sqrt(inst.n)  # E[x x'] = I over these rows
    rollout = simulate(inst, controller, x0)
    assert rollout.plain_cost == pytest.approx(exact_cost(inst, controller), rel=1e-10)


def test_the_l1_stage_trains_only_within_l1_hops(inst):
    grnn = grnn_module.grnn
    design = grnn(inst, variant="sparse", beta=0.3, l1_hops=2, steps=40, ensemble=1, curve_every=0,
                  stability_steps=0)
    assert design.params["l1_hops"] == 2
    candidates = hop_distances(inst.comm_adj) <= 2
    assert not np.all(candidates)  # the test means something: some pairs are out of reach
    assert not np.any(design.controller.S[~candidates])
    assert design.extras["l1_links"] <= np.count_nonzero(candidates & ~np.eye(inst.n, dtype=bool))
    again = grnn(inst, variant="sparse", beta=0.3, l1_hops=2, steps=40, ensemble=1, curve_every=0,
                 stability_steps=0)
    assert again.cost == design.cost and again.links == design.links  # reproducible


def test_l1_hops_is_a_co_design_setting_only(inst):
    with pytest.raises(ValueError, match="l1_hops"):
        get_method("grnn").check_params({"l1_hops": 2})
    with pytest.raises(ValueError, match="l1_hops"):
        get_method("grnn_sparse").check_params({"l1_hops": 0})


def test_size_limits_say_what_runs_where():
    """GRNN-Sparse's dense l1 stage stops at 500 states; on a few hops, and GRNN on its graph, at 1000."""
    big = SimpleNamespace(n=800, scalar_nodes=True)
    sparse = get_method("grnn_sparse")
    refused = sparse.unsupported(big, {"beta": 1.0})
    assert refused is not None and refused[0].extras["size_guard"]
    assert "at most 500 here" in refused[0].message and "l1_hops" in refused[0].message
    assert sparse.unsupported(big, {"beta": 1.0, "l1_hops": 3}) is None
    assert get_method("grnn").unsupported(big, {}) is None
    assert "at most 500" in get_method("grnn_dense").unsupported(big, {})[0].message
    huge = SimpleNamespace(n=1001, scalar_nodes=True)
    assert "(at most 1000):" in sparse.unsupported(huge, {"l1_hops": 3})[0].message


def test_the_local_cost_form_carries_the_control_variates_at_large_n(inst, monkeypatch):
    """Too few draws for the squares: x0'Px0 alone, and a fixed form M joins as x0'Mx0 - tr M (unbiased)."""
    from codesign import estimators

    monkeypatch.setattr(estimators, "LARGE_ABOVE", 0)
    rng = np.random.default_rng(2)
    L = rng.standard_normal((inst.n, inst.n)) / inst.n
    M = L @ L.T + np.eye(inst.n)
    x0 = rng.standard_normal((60, inst.n))
    costs = np.einsum("bi,ij,bj->b", x0, M, x0)
    cost, stderr, name = estimators.control_variate_estimate(inst, x0, costs)
    assert name.startswith("control variates: x0'Px0,")  # 25 coefficients would not fit on 54 rows
    with_form, form_stderr, form_name = estimators.control_variate_estimate(inst, x0, costs, M)
    assert "the local cost form" in form_name
    assert with_form == pytest.approx(np.trace(M), rel=1e-10) and form_stderr < 1e-8 * stderr


def test_node_blocks_keep_the_dense_limits():
    from codesign.instances import Instance

    blocks = SimpleNamespace(n=800, scalar_nodes=False)
    assert "at most 500 here" in get_method("grnn").unsupported(blocks, {})[0].message
    assert "at most 500 here" in get_method("grnn_sparse").unsupported(blocks, {"l1_hops": 2})[0].message
    rng = np.random.default_rng(0)
    A = np.diag(rng.uniform(0.5, 0.9, 8))
    two_per_node = Instance.from_matrices(A, np.eye(8), horizon=5, state_nodes=np.arange(8) // 2,
                                          input_nodes=np.arange(8) // 2)
    assert get_method("gcnn").size_limit(two_per_node, {})[0] == 300


def test_sparse_gcnn_bptt_equals_the_dense_one(inst):
    """The GCNN's hand-written BPTT with block-diagonal CSR products against the dense one (checked by autograd)."""
    import torch

    gm = importlib.import_module("codesign.learned.gcnn_bptt")
    rng = np.random.default_rng(4)
    insts = [inst, paper_instance(6, n=24, horizon=20)]
    H = torch.tensor(rng.uniform(-0.5, 0.5, (2, 5, 32)))
    w = torch.tensor(rng.uniform(-0.3, 0.3, (2, 32)))
    x0 = torch.tensor(rng.standard_normal((2, 7, 24)))
    S, A_t, B_t, P = (torch.tensor(np.stack([f(i) for i in insts]))
                      for f in (lambda i: i.gso, lambda i: i.A.T, lambda i: i.B.T, lambda i: i.P))
    dense_loss, dense_grads = gm._loss_and_grad(S, H, w, A_t, B_t, P, x0, 20)
    products = gm._SparseProducts([i.gso for i in insts], [i.A for i in insts], [i.B for i in insts], np.float64)
    loss, grads = gm._loss_and_grad(None, H, w, None, None, P, x0, 20, products=products)
    np.testing.assert_allclose(loss.numpy(), dense_loss.numpy(), rtol=1e-12)
    for sparse_grad, dense_grad in zip(grads, dense_grads):
        np.testing.assert_allclose(sparse_grad.numpy(), dense_grad.numpy(), rtol=1e-10, atol=1e-12)


def test_sparse_gcnn_rollouts_equal_the_dense_ones(inst, monkeypatch):
    gcnn_module = importlib.import_module("codesign.learned.gcnn")
    rng = np.random.default_rng(5)
    H, w = rng.uniform(-0.5, 0.5, (5, 32)), rng.uniform(-0.3, 0.3, 32)
    x0 = validation_set(inst, 200)
    before = simulate(inst, gcnn_module.GCNNController(inst.gso, H, w), x0)
    _structured(monkeypatch)
    monkeypatch.setattr(gcnn_module, "STRUCTURED_ABOVE", 0)
    controller = gcnn_module.GCNNController(inst.gso, H, w)
    assert controller._sparse_S is not None
    np.testing.assert_allclose(simulate(inst, controller, x0).costs, before.costs, rtol=1e-12)


@pytest.mark.parametrize("n, horizon", [(300, 30), pytest.param(1000, 50, marks=pytest.mark.slow)])
def test_a_linear_grnn_at_scale_costs_what_its_closed_loop_says(n, horizon):
    """At a real size on the structured path (CSR S, A, B): the rollout against the dense closed-loop recursion.

    At N = 1000 (slow: about two minutes, 1.5 GB) the dense recursion multiplies the
    6000 x 6000 closed loop 50 times, independently of the sparse products it checks.
    """
    big = paper_instance(1, n=n, connect="bridge", horizon=horizon)
    S, F, W, G = _parameters(big, seed=2)
    controller = LinearGRNNController(S, 0.2 * F, 0.5 * W, 0.2 * G)
    assert controller._S_op is not None  # n > STRUCTURED_ABOVE
    n, h = big.n, controller.hidden
    M = controller.linearized_closed_loop(big)  # dense (n + n h)^2: the exact closed loop of a linear GRNN
    Gm = np.kron(np.eye(n), controller.G.reshape(1, h))
    X = np.vstack([np.eye(n), np.zeros((n * h, n))])  # responses to x(0) = e_j, Z(0) = 0
    cost = 0.0
    for _ in range(big.horizon):
        x, u = X[:n], Gm @ (M[n:] @ X)
        cost += np.sum(x * (big.Q @ x)) + np.sum(u * (big.R @ u))
        X = M @ X
    cost += np.sum(X[:n] * (big.P @ X[:n]))
    rollout = simulate(big, controller, np.sqrt(n) * np.eye(n))  # E[x x'] = I over these rows
    assert rollout.plain_cost == pytest.approx(cost / big.trace_P, rel=1e-10)


def test_large_fused_models_train_alone_to_the_same_bits_as_stacked(inst, monkeypatch):
    """Above SPREAD_ABOVE states (lowered here), train_jobs trains fused-engine models one per stack
    (so that a dask cluster can spread them): every parameter and curve equals the stacked training's."""
    from codesign.learned import trainer

    insts = [inst, paper_instance(6, n=24, horizon=20)]
    parsed = [grnn_module._parse(instance, dict(variant=variant, seed=0, steps=3, ensemble=2,
                                                **({"l1_hops": 2, "beta": 0.3} if variant == "sparse" else {})))
              for instance in insts for variant in ("given", "sparse")]

    def train():
        jobs = [grnn_module._training(job, grnn_module._first_stage_specs(job)) for job in parsed]
        return trainer.train_jobs(jobs, stack_size=128)[0]

    calls = []
    real = trainer.train_stack
    monkeypatch.setattr(trainer, "train_stack", lambda model, members, *a, **k: calls.append(len(members))
                        or real(model, members, *a, **k))
    monkeypatch.setattr(trainer, "SPREAD_ABOVE", 10)
    alone = train()
    assert set(calls) == {1}
    calls.clear()
    monkeypatch.setattr(trainer, "SPREAD_ABOVE", 10**9)
    stacked = train()
    assert max(calls) > 1
    for job_alone, job_stacked in zip(alone, stacked):
        for a, b in zip(job_alone, job_stacked):
            for name in "SFWG":
                np.testing.assert_array_equal(a.params[name], b.params[name])
            assert a.curve_cost == b.curve_cost
