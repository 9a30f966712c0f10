"""The structured path of a static gain's exact cost and gradient (above STRUCTURED_ABOVE states).

At small sizes the threshold is lowered to force the structured path (and the density
threshold raised, so that the closed loop of a sparse gain is multiplied as CSR), and the
results are compared with the dense formulas; at the default threshold the dense formulas
must give the very same bits as before the structured path existed.
"""

import numpy as np
import pytest

from baselines import polish as polish_module
from baselines.polish import polish_gain
from codesign import evaluation
from codesign.evaluation import static_gain_cost, static_gain_cost_and_grad
from codesign.instances import FAST_DARE_ABOVE, Instance, paper_instance
from references import static_gain_response_cost  # tests/references.py


@pytest.fixture(scope="module")
def paper100():
    return paper_instance(4, n=100, horizon=20)


@pytest.fixture(scope="module")
def blocks():
    """Non-symmetric sparse A, two states per node, fewer inputs than states (m != n)."""
    rng = np.random.default_rng(7)
    n, m = 80, 30
    A = np.where(rng.random((n, n)) < 0.05, rng.standard_normal((n, n)), 0.0)
    A *= 1.02 / np.max(np.abs(np.linalg.eigvals(A)))
    B = np.where(rng.random((n, m)) < 0.1, rng.standard_normal((n, m)), 0.0)
    B[2 * np.arange(m), np.arange(m)] = 1.0
    return Instance.from_matrices(A, B, Q=np.diag(rng.uniform(0.5, 2.0, n)), R=np.diag(rng.uniform(0.5, 2.0, m)),
                                  horizon=15, state_nodes=np.arange(n) // 2, input_nodes=np.arange(m) + 10)


def _gains(instance):
    """(name, gain, mask): decentralized-like, on a sparse pattern, and dense."""
    K = instance.K_lqr
    diagonal = instance.block_mask()
    nearest = np.argsort(-np.abs(K), axis=1)[:, :5]
    pattern = np.zeros(K.shape, dtype=bool)
    np.put_along_axis(pattern, nearest, True, axis=1)
    pattern |= diagonal
    dense = 0.8 * K + 0.01 * np.random.default_rng(3).standard_normal(K.shape)
    return [("diagonal", K * diagonal, diagonal), ("pattern", np.where(pattern, K, 0.0), pattern),
            ("dense", dense, pattern)]


def test_threshold_is_the_fast_dare_threshold():
    assert evaluation.STRUCTURED_ABOVE == FAST_DARE_ABOVE == 200


@pytest.mark.parametrize("which", ["paper100", "blocks"])
def test_structured_cost_and_gradient_match_the_dense_formulas(which, request, monkeypatch):
    instance = request.getfixturevalue(which)
    expected = {}
    for name, K, _ in _gains(instance):
        expected[name] = (static_gain_cost(instance, K), static_gain_cost(instance, K, noise_std=0.3),
                          static_gain_cost_and_grad(instance, K)[1])
    monkeypatch.setattr(evaluation, "STRUCTURED_ABOVE", 10)
    monkeypatch.setattr(evaluation, "SPARSE_DENSITY", 0.5)
    for name, K, mask in _gains(instance):
        cost, noisy, grad = expected[name]
        loop = evaluation._ClosedLoop(instance, K)
        # The sparse gains take CSR closed loops, the dense one the dense fallback.
        assert isinstance(loop.acl, np.ndarray) == (name == "dense"), name
        assert static_gain_cost(instance, K) == pytest.approx(cost, rel=1e-12, abs=0)
        assert static_gain_cost(instance, K, noise_std=0.3) == pytest.approx(noisy, rel=1e-12, abs=0)
        scale = np.abs(grad[mask]).max()
        masked_cost, masked = static_gain_cost_and_grad(instance, K, mask=mask)
        assert masked_cost == pytest.approx(cost, rel=1e-12, abs=0)
        np.testing.assert_allclose(masked[mask], grad[mask], rtol=1e-10, atol=1e-10 * scale, err_msg=name)
        assert not masked[~mask].any()
        full_cost, full = static_gain_cost_and_grad(instance, K)
        assert full_cost == pytest.approx(cost, rel=1e-12, abs=0)
        np.testing.assert_allclose(full, grad, rtol=1e-10, atol=1e-10 * np.abs(grad).max(), err_msg=name)


@pytest.mark.parametrize("fraction", [0.0, 1.0])
def test_masked_product_blocks_and_full_product_agree(fraction, monkeypatch):
    """Both ways of :class:`MaskedProduct` (row blocks, or the full product) give the masked ``sum M_t S_t``."""
    monkeypatch.setattr(evaluation, "_MASK_DENSE_FRACTION", fraction)
    rng = np.random.default_rng(1)
    m, n = 37, 50
    mask = rng.random((m, n)) < 0.08
    mask[5] = False  # a row with no free entry
    product = evaluation.MaskedProduct(mask)
    assert product.full == (fraction == 0.0)
    total = np.zeros((m, n))
    for _ in range(3):
        M = rng.standard_normal((m, n))
        S = rng.standard_normal((n, n))
        S = S + S.T
        product.add(M, S)
        total += M @ S
    result = product.result()
    np.testing.assert_allclose(result[mask], total[mask], rtol=1e-13, atol=1e-13 * np.abs(total).max())
    assert not result[~mask].any()


def test_a_local_pattern_in_scrambled_order_takes_row_blocks():
    """Reverse Cuthill-McKee finds the band of a banded pattern whatever the numbering of the nodes."""
    n = 300
    offsets = np.subtract.outer(np.arange(n), np.arange(n))
    order = np.random.default_rng(2).permutation(n)
    mask = (np.abs(offsets) <= 2)[np.ix_(order, order)]
    product = evaluation.MaskedProduct(mask)
    assert not product.full
    assert sum(len(rows) * len(cols) for rows, cols, _, _ in product.blocks) < 0.1 * mask.size


def test_mask_of_the_wrong_shape_is_refused(paper100):
    with pytest.raises(ValueError, match="mask shape"):
        static_gain_cost_and_grad(paper100, np.zeros((100, 100)), mask=np.ones((100, 99), dtype=bool))


def _old_cost_to_go(instance, K):
    """The dense recursion as it was before the structured path, copied verbatim."""
    Acl = instance.A + instance.B @ K
    stage = instance.Q + K.T @ instance.R @ K
    Ps = [None] * (instance.horizon + 1)
    Ps[-1] = instance.P
    for t in range(instance.horizon - 1, -1, -1):
        Ps[t] = stage + Acl.T @ Ps[t + 1] @ Acl
    return Ps, Acl


def _old_cost(instance, K, noise_std=0.0):
    Ps, _ = _old_cost_to_go(instance, K)
    total = np.trace(Ps[0]) + noise_std**2 * sum(np.trace(Pt) for Pt in Ps[1:])
    return float(total / instance.trace_P)


def _old_cost_and_grad(instance, K):
    Ps, Acl = _old_cost_to_go(instance, K)
    grad = np.zeros_like(K)
    sigma = np.eye(instance.n)
    RK = instance.R @ K
    for t in range(instance.horizon):
        grad += (RK + instance.B.T @ Ps[t + 1] @ Acl) @ sigma
        sigma = Acl @ sigma @ Acl.T
    scale = instance.trace_P
    return float(np.trace(Ps[0]) / scale), 2.0 * grad / scale


def test_response_cost_above_the_threshold_takes_blas_products_and_agrees(monkeypatch):
    """Response maps (SLS) are scored through BLAS products above the threshold, einsum at and below."""
    from codesign.evaluation import response_cost

    instance = paper_instance(3, n=60, horizon=20)
    rng = np.random.default_rng(0)
    X, U = rng.standard_normal((21, 60, 60)), rng.standard_normal((20, 60, 60))
    small = [response_cost(instance, X, U, noise_std=s) for s in (0.0, 0.3)]
    stage = np.einsum("tij,ik,tkj->t", X[:20], instance.Q, X[:20]) + np.einsum("tij,ik,tkj->t", U, instance.R, U)
    assert small[0] == (stage.sum() + np.einsum("ij,ik,kj->", X[20], instance.P, X[20])) / instance.trace_P
    calls = []
    monkeypatch.setattr(evaluation, "STRUCTURED_ABOVE", 10)
    monkeypatch.setattr(evaluation, "_einsum_traces", lambda *a: calls.append(1))
    large = [response_cost(instance, X, U, noise_std=s) for s in (0.0, 0.3)]
    assert not calls
    assert large == pytest.approx(small, rel=1e-13)


def test_small_instances_give_the_same_bits_as_before():
    """At and below STRUCTURED_ABOVE the shipped reports' numbers are reproduced to the last digit."""
    instance = paper_instance(2)
    assert instance.n == 20 <= evaluation.STRUCTURED_ABOVE
    for _, K, mask in _gains(instance):
        for noise in (0.0, 0.3):
            assert static_gain_cost(instance, K, noise_std=noise) == _old_cost(instance, K, noise)
        cost, grad = _old_cost_and_grad(instance, K)
        new_cost, new_grad = static_gain_cost_and_grad(instance, K)
        assert new_cost == cost and np.array_equal(new_grad, grad)
        masked_cost, masked = static_gain_cost_and_grad(instance, K, mask=mask)
        assert masked_cost == cost and np.array_equal(masked[mask], grad[mask]) and not masked[~mask].any()


def test_polishing_a_small_instance_is_unchanged(monkeypatch):
    """polish_gain passes its mask; at n <= 200 L-BFGS sees the very numbers of the full gradient."""
    instance = paper_instance(2)
    _, K, mask = _gains(instance)[1]
    new = polish_gain(instance, K, mask)

    def full_gradient(instance, K, mask=None):
        return _old_cost_and_grad(instance, K)

    monkeypatch.setattr(polish_module, "static_gain_cost_and_grad", full_gradient)
    old = polish_gain(instance, K, mask)
    assert np.array_equal(new.K, old.K) and new.cost == old.cost and new.grad_norm == old.grad_norm
    assert new.iterations == old.iterations


def test_structured_polish_reaches_the_dense_optimum(paper100, monkeypatch):
    """The decentralized polish on the structured path ends at the dense path's optimum."""
    mask = paper100.block_mask()
    K0 = paper100.K_lqr * mask
    dense = polish_gain(paper100, K0, mask)
    monkeypatch.setattr(evaluation, "STRUCTURED_ABOVE", 10)
    monkeypatch.setattr(evaluation, "SPARSE_DENSITY", 0.5)
    structured = polish_gain(paper100, K0, mask)
    assert structured.cost == pytest.approx(dense.cost, rel=1e-10)
    assert structured.grad_norm < 1e-6 * structured.cost


@pytest.mark.slow
def test_paper_scale_costs_match_an_independent_computation():
    """N = 1000: the structured costs of the diagonal and LQR gains against forward responses."""
    instance = paper_instance(0, n=1000, connect="bridge")
    assert instance.n > evaluation.STRUCTURED_ABOVE
    diagonal = np.diag(np.diag(instance.K_lqr))
    lqr = np.array(instance.K_lqr)
    for K in (diagonal, lqr):
        assert static_gain_cost(instance, K) == pytest.approx(static_gain_response_cost(instance, K), rel=1e-8)
    # With the DARE's P as terminal cost, LQR's cost-to-go is P at every step: exactly 1, and
    # the noise adds noise_std^2 trace(P) per step, T steps.
    assert static_gain_cost(instance, lqr) == pytest.approx(1.0, abs=1e-9)
    assert static_gain_cost(instance, lqr, noise_std=0.3) == pytest.approx(1.0 + 0.09 * instance.horizon, rel=1e-9)
    assert static_gain_cost_and_grad(instance, lqr, mask=instance.block_mask())[0] == pytest.approx(1.0, abs=1e-9)
    # The masked gradient of the diagonal gain against the dense formulas (about 10 s).
    mask = instance.block_mask()
    cost, grad = static_gain_cost_and_grad(instance, diagonal, mask=mask)
    dense_cost, dense_grad = _old_cost_and_grad(instance, diagonal)
    assert cost == pytest.approx(dense_cost, rel=1e-12)
    np.testing.assert_allclose(grad[mask], dense_grad[mask], rtol=1e-10, atol=1e-10 * np.abs(dense_grad[mask]).max())
