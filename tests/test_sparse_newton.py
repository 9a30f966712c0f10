"""The proximal Newton ℓ1 path: optimality of its weighted solves, and the same designs as ADMM."""

import importlib

import numpy as np
import pytest
import scipy.linalg

from baselines import sparse_admm, sparse_newton
from codesign import paper_instance
from codesign.status import USABLE
from references import static_gain_response_cost  # tests/references.py

newton_module = importlib.import_module("baselines.sparse_newton")
admm_module = importlib.import_module("baselines.sparse_admm")


@pytest.fixture(scope="module")
def paper12():
    return paper_instance(3, n=12)


def _scipy_gradient(instance, K):
    """∇ of trace(P_K) / trace(P) by scipy's Lyapunov solver, apart from the path's doubling."""
    Acl = instance.A + instance.B @ K
    P = scipy.linalg.solve_discrete_lyapunov(Acl.T, instance.Q + K.T @ instance.R @ K)
    L = scipy.linalg.solve_discrete_lyapunov(Acl, np.eye(instance.n))
    return 2.0 * (instance.R @ K + instance.B.T @ P @ Acl) @ L / instance.trace_P


def test_a_weighted_solve_meets_the_l1_optimality_conditions(paper12):
    """At the solution of min J/trace(P) + γ Σ_{i≠j} |K_ij|: ∇ = -γ sign(K) on the support, |∇| <= γ off it,
    to ``tol`` x γ (the stopping rule), with ∇ from scipy's Lyapunov solver rather than the path's doubling."""
    gamma, tol = 1e-3, 1e-6
    (design,) = sparse_newton(paper12, gammas=[gamma], reweight=1, polish=False, diagonal_end=False, tol=tol)
    assert design.status in USABLE and 0 < design.links < paper12.n * (paper12.n - 1)
    assert design.extras["newton_converged"]
    _assert_optimal(paper12, np.asarray(design.controller.K), gamma, tol)


def _assert_optimal(instance, K, gamma, tol):
    grad = _scipy_gradient(instance, K)
    off = ~np.eye(instance.n, dtype=bool)
    support, zero = off & (K != 0), off & (K == 0)
    slack = tol * gamma + 1e-12 * np.abs(grad).max()  # the two gradients' round-off apart
    np.testing.assert_allclose(grad[support], -gamma * np.sign(K[support]), rtol=0, atol=slack)
    np.testing.assert_allclose(np.diag(grad), 0.0, atol=slack)
    assert np.abs(grad[zero]).max() <= gamma + slack


def test_patterns_are_those_of_admm_run_to_convergence(paper12, monkeypatch):
    """ADMM at its default 1 % residual stops a few entries short; run tight, it meets the Newton path."""
    gammas = [1e-4, 1e-3]
    newton = sparse_newton(paper12, gammas=gammas, polish=False, diagonal_end=False)
    monkeypatch.setattr(admm_module, "_REL_TOL", 1e-6)
    admm = sparse_admm(paper12, gammas=gammas, polish=False, diagonal_end=False, tol=1e-9, kstep_tol=1e-8,
                       maxiter=20000)
    for a, b in zip(admm, newton, strict=True):
        assert a.extras["admm_converged"]
        assert a.links > 0
        np.testing.assert_array_equal(np.asarray(a.controller.K) != 0, np.asarray(b.controller.K) != 0)


def test_the_default_path_matches_admm_where_the_patterns_agree():
    """Paper N = 20: same pattern at 4 of 10 γ, the others at most 3 entries (or 3 %) apart; same pattern, same cost."""
    instance = paper_instance(0, n=20)
    admm, newton = sparse_admm(instance), sparse_newton(instance)
    assert [d.params["gamma"] for d in admm] == [d.params["gamma"] for d in newton]
    same = 0
    for a, b in zip(admm, newton, strict=True):
        assert a.status in USABLE and b.status in USABLE
        pa, pb = np.asarray(a.controller.K) != 0, np.asarray(b.controller.K) != 0
        apart = int((pa ^ pb).sum())
        assert apart <= max(3, 0.03 * max(a.links, b.links)), (a.params, a.links, b.links)
        if apart == 0:
            same += 1
            assert abs(a.cost - b.cost) <= 1e-8 * a.cost
    assert same >= 4


def test_the_working_set_product_equals_the_dense_one():
    """Above STRUCTURED_ABOVE states (R + B'PB) E L is taken on the working set through sparse products."""
    rng = np.random.default_rng(0)
    n = 260
    X = rng.standard_normal((n, n))
    Rm, L = X @ X.T / n + np.eye(n), np.cov(rng.standard_normal((n, 3 * n)))
    offsets = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    rows, cols = np.nonzero(offsets <= 3)
    curvature = newton_module._Curvature(Rm, L, rows, cols, (n, n))
    assert not curvature.dense
    e = rng.standard_normal(len(rows))
    E = np.zeros((n, n))
    E[rows, cols] = e
    expected = (Rm @ E @ L)[rows, cols]
    np.testing.assert_allclose(curvature.apply(e), expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_bad_input_is_refused_by_name(paper12):
    with pytest.raises(ValueError, match="start gain does not stabilize"):
        sparse_newton(paper12, start=np.zeros((12, 12)) + 10.0)
    with pytest.raises(ValueError, match="tol must be a positive number"):
        sparse_newton(paper12, tol=0.0)
    with pytest.raises(ValueError, match="gammas must be non-negative"):
        sparse_newton(paper12, gammas=[-1.0])


def test_node_blocks_meet_the_group_optimality_conditions_and_admm():
    """Nodes with two states (the mass-spring chain): the group-ℓ1 conditions per node block against scipy's
    gradient, and the same node patterns as ADMM at every γ of the default grid."""
    from compare.run.families.mass_spring import mass_spring_instance

    instance = mass_spring_instance(6)
    assert not instance.scalar_nodes
    gamma, tol = 0.03, 1e-6  # plain group ℓ1 keeps 14 of the 30 links here
    (design,) = sparse_newton(instance, gammas=[gamma], reweight=1, polish=False, diagonal_end=False, tol=tol)
    assert design.extras["newton_converged"] and 0 < design.links < 30
    K = np.asarray(design.controller.K)
    grad = _scipy_gradient(instance, K)
    norms = instance.block_norms(K)
    own = np.eye(instance.nodes, dtype=bool)
    slack = tol * gamma + 1e-12 * np.abs(grad).max()
    with np.errstate(divide="ignore", invalid="ignore"):
        toward = np.where(instance.expand_blocks(norms) > 0, K * instance.expand_blocks(gamma / norms), 0.0)
    on = instance.block_norms(grad + np.where(instance.expand_blocks(own), 0.0, toward))
    assert on[(norms > 0) & ~own].max() <= slack and on[own].max() <= slack
    assert instance.block_norms(grad)[(norms == 0) & ~own].max() <= gamma + slack
    for a, b in zip(sparse_admm(instance, polish=False), sparse_newton(instance, polish=False), strict=True):
        np.testing.assert_array_equal(instance.node_support(a.controller.K) != 0,
                                      instance.node_support(b.controller.K) != 0)


@pytest.mark.slow
def test_a_thousand_nodes_optimality_and_exact_cost():
    """N = 1000 (the working set's sparse products): the ℓ1 optimality conditions of one weighted
    solve against scipy's gradients, and the polished design's cost against forward responses."""
    instance = paper_instance(0, n=1000, connect="bridge")
    gamma = 1e-6
    (raw,) = sparse_newton(instance, gammas=[gamma], reweight=1, polish=False, diagonal_end=False, tol=1e-4)
    assert raw.extras["newton_converged"] and 0 < raw.links < 0.1 * instance.n * (instance.n - 1)
    _assert_optimal(instance, np.asarray(raw.controller.K), gamma, 1e-4)
    (design,) = sparse_newton(instance, gammas=[gamma], reweight=1, diagonal_end=False)
    assert design.status in USABLE
    assert design.cost == pytest.approx(static_gain_response_cost(instance, np.asarray(design.controller.K)),
                                        rel=1e-8)
