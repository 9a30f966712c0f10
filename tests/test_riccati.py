"""The fast dense Riccati and Lyapunov solvers (codesign.riccati) against scipy and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from codesign.instances import paper_instance
from codesign.riccati import (
    LyapunovSolver,
    NoStabilizingSolutionError,
    dare_residual,
    solve_discrete_are,
    solve_discrete_lyapunov,
)

AGREEMENT = 1e-10  # relative Frobenius distance to scipy
RESIDUAL = 1e-13   # relative residual of our own solutions (measured: 1e-16 to 4e-15)


def relative(X, Y):
    return np.linalg.norm(X - Y) / np.linalg.norm(Y)


def random_dare(seed, n, m, *, radius=1.1, r_identity=False):
    """A well-conditioned random DARE: unstable A (spectral radius about ``radius``), dense B, Q and R."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A *= radius / np.max(np.abs(np.linalg.eigvals(A)))
    B = rng.standard_normal((n, m))
    C = rng.standard_normal((n, n))
    Q = C @ C.T / n + 0.1 * np.eye(n)
    D = rng.standard_normal((m, m))
    R = np.eye(m) if r_identity else D @ D.T / m + 0.5 * np.eye(m)
    return A, B, Q, R


def stable_matrix(seed, n, radius):
    """A non-normal (non-symmetric, complex eigenvalue pairs) matrix with the given spectral radius."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    return A * radius / np.max(np.abs(np.linalg.eigvals(A)))


# -- DARE ----------------------------------------------------------------------------------


@pytest.mark.parametrize("n, m, r_identity", [(12, 12, True), (30, 7, False), (45, 1, False), (60, 60, False)])
def test_dare_agrees_with_scipy_on_random_instances(n, m, r_identity):
    A, B, Q, R = random_dare(n + m, n, m, r_identity=r_identity)
    P, info = solve_discrete_are(A, B, Q, R, full_output=True)
    reference = scipy.linalg.solve_discrete_are(A, B, Q, R)
    assert relative(P, reference) <= AGREEMENT
    assert np.array_equal(P, P.T)
    assert info.method == "sda" and info.residual <= RESIDUAL
    assert dare_residual(A, B, Q, R, P) == pytest.approx(info.residual, rel=1e-6, abs=1e-18)


@pytest.mark.parametrize("n", [10, 20, 50, 100])
@pytest.mark.parametrize("a_norm", [0.995, 1.05])
def test_dare_agrees_with_scipy_on_paper_instances(n, a_norm):
    instance = paper_instance(1, n=n, a_norm=a_norm)  # instance.P is scipy's solution, symmetrized
    P, info = solve_discrete_are(instance.A, instance.B, instance.Q, instance.R, full_output=True)
    assert relative(P, instance.P) <= AGREEMENT
    # Every exact cost is divided by trace(P): it must move far less than the 1e-10 budget.
    assert abs(np.trace(P) - instance.trace_P) <= 1e-12 * instance.trace_P
    assert info.residual <= RESIDUAL


@pytest.mark.parametrize("a_norm", [0.995, 1.05])
def test_exact_costs_barely_move_when_the_terminal_cost_comes_from_the_fast_dare(a_norm):
    # What wiring the solver into the instance builders would do to the shipped exact costs.
    import dataclasses

    from codesign.evaluation import static_gain_cost

    for seed in range(3):
        instance = paper_instance(seed, n=20, a_norm=a_norm)
        fast = dataclasses.replace(instance, P=solve_discrete_are(instance.A, instance.B, instance.Q, instance.R))
        for K in (instance.K_lqr, np.diag(np.diag(instance.K_lqr)), np.zeros((20, 20))):
            today = static_gain_cost(instance, K)
            assert abs(static_gain_cost(fast, K) - today) <= 1e-12 * today
        assert static_gain_cost(fast, fast.K_lqr) == pytest.approx(1.0, abs=1e-12)


def test_dare_residual_is_that_of_the_equation():
    A, B, Q, R = random_dare(3, 15, 4)
    P = solve_discrete_are(A, B, Q, R)
    gain = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    equation = A.T @ P @ A - A.T @ P @ B @ gain + Q - P
    assert np.linalg.norm(equation) / np.linalg.norm(P) <= RESIDUAL
    assert np.max(np.abs(np.linalg.eigvals(A - B @ gain))) < 1
    # A wrong candidate has a large residual.
    assert dare_residual(A, B, Q, R, 1.01 * P) > 1e-3


@pytest.mark.parametrize("pole, reach", [(2.0, 1.0), (1.0001, 1.0), (1.0001, 1e-3), (3.0, 0.1)])
def test_dare_with_an_unobserved_unstable_mode_finds_the_stabilizing_solution(pole, reach):
    # Q does not see the unstable mode: the doubling alone leaves it uncontrolled, the
    # Newton fallback from the gain of Q + cI stabilizes it, as scipy does; a pole near 1
    # makes Newton's start slow (linear) but not its end, so it is not taken for one on the circle.
    A, B, Q, R = np.diag([pole, 0.5]), np.array([[reach], [1.0]]), np.diag([0.0, 1.0]), np.eye(1)
    P, info = solve_discrete_are(A, B, Q, R, full_output=True)
    assert info.method == "sda+newton"
    assert relative(P, scipy.linalg.solve_discrete_are(A, B, Q, R)) <= AGREEMENT
    gain = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    assert np.max(np.abs(np.linalg.eigvals(A - B @ gain))) == pytest.approx(1 / pole, rel=1e-9)


def test_dare_refuses_an_unstabilizable_pair():
    # Mode 2 is unstable and no input reaches it.
    A, B = np.diag([2.0, 0.5]), np.array([[0.0], [1.0]])
    with pytest.raises(NoStabilizingSolutionError, match="not stabilizable"):
        solve_discrete_are(A, B, np.eye(2), np.eye(1))


def test_dare_refuses_an_uncontrollable_mode_on_the_unit_circle():
    # A rotation that no input reaches: every gain leaves |lambda| = 1 (scipy returns a non-stabilizing P).
    c, s = np.cos(0.3), np.sin(0.3)
    A = scipy.linalg.block_diag([[c, -s], [s, c]], 0.5)
    B = np.array([[0.0], [0.0], [1.0]])
    with pytest.raises(NoStabilizingSolutionError, match="unit circle"):
        solve_discrete_are(A, B, np.eye(3), np.eye(1))


def test_dare_refuses_an_unobserved_mode_on_the_unit_circle():
    A, B, Q = np.diag([1.0, 0.5]), np.array([[1.0], [1.0]]), np.diag([0.0, 1.0])
    with pytest.raises(NoStabilizingSolutionError, match="unit circle"):
        solve_discrete_are(A, B, Q, np.eye(1))


def issue_49_dare(pole=1.2, *, b=(1.0, 0.5), delta=0.0):
    """Issue 49's reproduction: Q = c'c sees only the stable mode (0.5) of a rotated diag(pole, 0.5)."""
    t = 0.15
    U = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    A = U @ np.diag([pole, 0.5]) @ U.T
    c = np.array([[-np.sin(t), np.cos(t)]])
    return A, np.array(b, dtype=float).reshape(2, 1), c.T @ c + delta * np.eye(2), np.eye(1)


def test_dare_solves_issue_49s_reproduction():
    # Cholesky succeeds on this numerically singular Q, which used to skip the fallback and
    # report "no stabilizing solution"; scipy's closed loop has spectral radius 1 / 1.2.
    A, B, Q, R = issue_49_dare()
    scipy.linalg.cholesky(Q)  # no error: a plain Cholesky test calls it definite
    P, info = solve_discrete_are(A, B, Q, R, full_output=True)
    assert info.method == "sda+newton" and info.residual <= RESIDUAL
    assert relative(P, scipy.linalg.solve_discrete_are(A, B, Q, R)) <= AGREEMENT
    gain = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    assert np.max(np.abs(np.linalg.eigvals(A - B @ gain))) == pytest.approx(1 / 1.2, rel=1e-12)


@pytest.mark.parametrize("delta", [1e-14, 1e-12, 1e-9, 1e-6])
def test_dare_with_a_nearly_singular_q_agrees_with_scipy(delta):
    # Definite in exact arithmetic; the hidden mode is seen only through delta.
    A, B, Q, R = issue_49_dare(delta=delta)
    P, info = solve_discrete_are(A, B, Q, R, full_output=True)
    assert info.residual <= RESIDUAL
    assert relative(P, scipy.linalg.solve_discrete_are(A, B, Q, R)) <= 1e-9


def test_q_rank_test_is_rank_revealing():
    from codesign.riccati import _numerically_definite

    assert not _numerically_definite(issue_49_dare()[2])  # Cholesky passes on it (above)
    assert not _numerically_definite(np.diag([1.0, 1e-9]))  # relative tolerance 1e-8
    assert _numerically_definite(np.diag([1.0, 1e-7]))
    assert _numerically_definite(1e-30 * np.eye(3))  # relative, not absolute
    assert not _numerically_definite(np.zeros((3, 3)))
    assert not _numerically_definite(np.diag([1.0, -1e-3]))


def test_well_posed_problems_take_the_doubling_without_the_rank_test(monkeypatch):
    # The rank test and the fallback cost nothing where the doubling succeeds: a definite Q
    # and a clearly stable closed loop return the doubling's (unchanged) result.
    import codesign.riccati as riccati

    def forbidden(Q):
        raise AssertionError("the rank test ran on a well-posed problem")

    monkeypatch.setattr(riccati, "_numerically_definite", forbidden)
    for seed, (n, m) in enumerate([(12, 3), (30, 7), (45, 1)]):
        A, B, Q, R = random_dare(seed, n, m)
        P, info = solve_discrete_are(A, B, Q, R, full_output=True)
        assert info.method == "sda"
        assert relative(P, scipy.linalg.solve_discrete_are(A, B, Q, R)) <= AGREEMENT
    instance = paper_instance(1, n=50, a_norm=1.05)
    assert solve_discrete_are(instance.A, instance.B, instance.Q, instance.R, full_output=True)[1].method == "sda"


def test_dare_with_a_singular_q_still_refuses_what_has_no_stabilizing_solution():
    # Issue 49's system with its hidden mode on the unit circle (1 and -1), or nearly so
    # (1 + 1e-9 is the circle to working precision), and with B blind to the unstable mode.
    for pole in (1.0, -1.0, 1 + 1e-9):
        with pytest.raises(NoStabilizingSolutionError, match="unit circle"):
            solve_discrete_are(*issue_49_dare(pole))
    with pytest.raises(NoStabilizingSolutionError, match="not stabilizable"):
        solve_discrete_are(*issue_49_dare(b=(-np.sin(0.15), np.cos(0.15))))


def test_large_instances_with_a_hidden_unstable_mode_are_stabilizable(monkeypatch):
    # Instance.from_matrices takes this solver above FAST_DARE_ABOVE states; a user's Q = C'C
    # with an unstable mode that C does not see used to be called "not stabilizable".
    import codesign.instances as instances

    monkeypatch.setattr(instances, "FAST_DARE_ABOVE", 1)
    A, B, Q, R = issue_49_dare()
    instance = instances.Instance.from_matrices(A, B, Q=Q, input_nodes=[0])
    assert relative(instance.P, scipy.linalg.solve_discrete_are(A, B, Q, R)) <= AGREEMENT


@pytest.mark.parametrize("change, message", [
    (lambda a: {**a, "A": np.ones((3, 2))}, "A must be square"),
    (lambda a: {**a, "B": np.ones((2, 1))}, r"B must have shape \(3, any\)"),
    (lambda a: {**a, "Q": np.eye(2)}, r"Q must have shape \(3, 3\)"),
    (lambda a: {**a, "R": np.eye(2)}, r"R must have shape \(1, 1\)"),
    (lambda a: {**a, "A": np.full((3, 3), np.nan)}, "A has non-finite entries"),
    (lambda a: {**a, "Q": np.triu(np.ones((3, 3)))}, "Q must be symmetric"),
    (lambda a: {**a, "R": -np.eye(1)}, "R must be positive definite"),
    (lambda a: {**a, "B": np.ones((3, 1)) * 1j}, "B is complex"),
    (lambda a: {**a, "A": np.ones(3)}, "A must be a 2-D matrix"),
])
def test_dare_bad_input_is_named(change, message):
    good = {"A": 0.5 * np.eye(3), "B": np.ones((3, 1)), "Q": np.eye(3), "R": np.eye(1)}
    args = change(good)
    with pytest.raises(ValueError, match=message):
        solve_discrete_are(args["A"], args["B"], args["Q"], args["R"])


# -- Lyapunov ------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["auto", "smith", "schur"])
@pytest.mark.parametrize("transpose", [False, True])
@pytest.mark.parametrize("symmetric", [True, False])
def test_lyapunov_agrees_with_scipy(method, transpose, symmetric):
    n = 37  # odd, and above the direct block size, so the recursion splits around 2 x 2 blocks
    A = stable_matrix(5, n, 0.9)
    rng = np.random.default_rng(6)
    C = rng.standard_normal((n, n))
    Q = C @ C.T if symmetric else C
    X, info = solve_discrete_lyapunov(A, Q, transpose=transpose, method=method, full_output=True)
    reference = scipy.linalg.solve_discrete_lyapunov(A.T if transpose else A, Q)
    assert relative(X, reference) <= AGREEMENT
    assert info.method == ("schur" if method == "schur" else "smith")
    assert info.residual <= RESIDUAL
    if symmetric:
        assert np.array_equal(X, X.T)


def test_lyapunov_solver_reuses_its_schur_form():
    n = 50
    A = stable_matrix(7, n, 0.95)
    solver = LyapunovSolver(A)
    assert solver.spectral_radius == pytest.approx(0.95, rel=1e-12)
    rng = np.random.default_rng(8)
    for _ in range(3):
        Q = rng.standard_normal((n, n))
        Q = Q @ Q.T
        for transpose in (False, True):
            X = solver.solve(Q, transpose=transpose)
            reference = scipy.linalg.solve_discrete_lyapunov(A.T if transpose else A, Q)
            assert relative(X, reference) <= AGREEMENT


def test_lyapunov_gives_the_lqr_cost_to_go_of_a_paper_instance():
    # P = A_cl' P A_cl + Q + K'RK for the LQR gain: the transposed form the code base uses.
    instance = paper_instance(2, n=50)
    K = instance.K_lqr
    closed_loop = instance.A + instance.B @ K
    stage = instance.Q + K.T @ instance.R @ K
    for method in ("auto", "schur"):
        P = solve_discrete_lyapunov(closed_loop, stage, transpose=True, method=method)
        assert relative(P, instance.P) <= AGREEMENT
        assert relative(P, scipy.linalg.solve_discrete_lyapunov(closed_loop.T, stage)) <= AGREEMENT


def test_lyapunov_close_to_the_unit_circle_hands_over_to_schur():
    # Symmetric A = V diag(a) V' has the closed form X = V diag(1 / (1 - a^2)) V' for Q = I.
    n = 30
    rng = np.random.default_rng(9)
    V = np.linalg.qr(rng.standard_normal((n, n)))[0]
    a = rng.uniform(-0.9, 0.9, n)
    a[0] = 1 - 1e-6  # Smith would need 25 doublings, more than the 16 it is allowed
    X, info = solve_discrete_lyapunov((V * a) @ V.T, np.eye(n), full_output=True)
    assert info.method == "schur"
    assert info.residual <= RESIDUAL
    # Not well conditioned: the forward error is the residual times the condition 1 / (1 - rho^2) = 5e5.
    condition = 1 / (1 - a[0] ** 2)
    assert relative(X, (V / (1 - a**2)) @ V.T) <= 1e-14 * condition


@pytest.mark.parametrize("method", ["auto", "smith", "schur"])
def test_lyapunov_refuses_an_unstable_matrix(method):
    A = stable_matrix(10, 12, 1.05)
    with pytest.raises(NoStabilizingSolutionError, match="not stable"):
        solve_discrete_lyapunov(A, np.eye(12), method=method)


def test_lyapunov_solver_refuses_a_marginally_stable_matrix():
    with pytest.raises(NoStabilizingSolutionError, match=r"spectral radius 1 >= 1"):
        LyapunovSolver(np.diag([1.0, 0.3]))


@pytest.mark.parametrize("A, Q, kwargs, message", [
    (np.eye(2) * 0.5, np.eye(3), {}, r"Q must have shape \(2, 2\)"),
    (np.ones((2, 3)), np.eye(2), {}, "A must be square"),
    (np.diag([0.5, np.inf]), np.eye(2), {}, "A has non-finite entries"),
    (np.eye(2) * 0.5, np.eye(2), {"method": "qz"}, "method must be 'auto', 'smith' or 'schur'"),
])
def test_lyapunov_bad_input_is_named(A, Q, kwargs, message):
    with pytest.raises(ValueError, match=message):
        solve_discrete_lyapunov(A, Q, **kwargs)
