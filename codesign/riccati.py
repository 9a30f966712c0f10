"""Fast dense solvers for the discrete algebraic Riccati and Lyapunov (Stein) equations.

scipy's :func:`scipy.linalg.solve_discrete_are` builds a 2n x 2n (here 3n x 3n)
matrix pencil and reduces it by the QZ algorithm, and
:func:`scipy.linalg.solve_discrete_lyapunov` maps the equation to a continuous one
and calls a real Schur form and LAPACK's unblocked ``trsyl``. At n = 1000 these
take minutes, while the equations need about 10^10-10^11 flops, seconds of
matrix products on one core. The solvers here use only n x n LU factors,
triangular solves and matrix products:

- :func:`solve_discrete_are`: ``P = A'PA - A'PB (R + B'PB)^{-1} B'PA + Q`` by the
  structure-preserving doubling algorithm (SDA; Chu, Fan & Lin 2005), quadratically
  convergent at the rate of ``rho(A_cl)^(2^k)``: about 17 n^3 flops a step and 6-7
  steps on the paper's family (18 where rho(A_cl) = 0.9999); then, when the residual
  is not yet at rounding level, Newton-Kleinman corrections in defect form. With
  ``check=True`` the returned P is certified: small residual and a closed loop
  ``A + BK`` whose repeated squares fall below norm 1/2 (so its spectral radius is
  below 1). The doubling follows the Riccati difference equation, so a mode that a
  singular Q does not see is left uncontrolled (or its dual iterate overflows to NaN);
  wherever the doubling fails (diverges, does not converge, is not stabilizing or
  keeps a large residual) and Q is not numerically definite (smallest eigenvalue at
  most 1e-8 times the largest: a rank-revealing test, run only then), Newton-Kleinman
  from the stabilizing gain of ``Q + cI`` finds the stabilizing solution. The error
  then means that none exists: (A, B) is not stabilizable, or a mode that Q does not
  see lies on the unit circle (with a singular Q, within about 1e-6 of it). The doubling
  inverts R (``G = B R^{-1} B'``): where R is nearly singular at the problem's scale and
  that path fails, scipy's QZ solver, which keeps R in its pencil, gives the candidate,
  accepted only once refined and certified like ours (it then costs the QZ's minutes at
  n = 1000, paid only by such problems).
- :func:`solve_discrete_lyapunov`: ``X = A X A' + Q`` (or ``X = A'XA + Q`` with
  ``transpose=True``) by Smith's squared iteration (6 n^3 flops a doubling), whose
  convergence also certifies that A is stable. The rule: Smith first (about 2.6
  matrix products a doubling, 9-11 doublings on the paper family's closed loops, and
  a residual at 1e-16 where the Schur method's is 1e-14); when it has not converged
  within :data:`SMITH_MAX_DOUBLINGS` = 16 doublings (spectral radius above about
  0.9997), where it would cost more than the Schur form and one triangular solve
  (about 38 products at n = 1000), the Schur method finishes, and its eigenvalues
  decide whether A is stable at all.
- :class:`LyapunovSolver`: one real Schur form ``A = U T U'``, then each
  ``solve(Q)`` is a recursive blocked solve of the triangular Stein equation
  (Jonsson & Kagstrom's recursion, matrix products down to 8 x 8 blocks) and four
  products: the choice where A is fixed and Q changes (the cost-to-go and the
  covariance of one closed loop, or many right-hand sides).

Errors: malformed input raises :class:`ValueError` with a one-line message; an
equation without a stabilizing (convergent) solution raises
:class:`NoStabilizingSolutionError`, also a :class:`ValueError`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "SMITH_MAX_DOUBLINGS",
    "LyapunovSolver",
    "NoStabilizingSolutionError",
    "SolveInfo",
    "dare_residual",
    "solve_discrete_are",
    "solve_discrete_lyapunov",
]

#: Doublings Smith's iteration may take before the Schur method takes over. It converges
#: within 16 when ||A^(2^15)||_F^2 <= 1e-9: whenever rho(A) < 1 - 3.2e-4 (barring extreme
#: non-normality). 16 doublings cost about 42 n x n products at n = 1000, the Schur form and
#: one triangular solve about 38 (measured on one core, random non-symmetric A).
SMITH_MAX_DOUBLINGS = 16
_SMITH_TOL = 1e-9        # ||A^(2^(k+1))||_F bound: the remaining series is below 1e-18 of X
_SMITH_GROWTH = 1e30     # ||A^(2^k)||_F above this: leave it to the Schur form's eigenvalues
_SDA_MAX_STEPS = 50      # A_cl^(2^50): beyond it rounding (2^k eps) blurs decay and the unit circle
_SDA_TOL = 1e-13         # relative change of H_k that ends the doubling
_SDA_OVERFLOW = 1e150    # ||H_k||_F beyond this: the doubling diverges
_REFINE_RTOL = 1e-14     # relative residual the Newton corrections aim for
_MAX_REFINEMENTS = 3     # Newton corrections after the doubling (one is the rule, when any)
_MAX_NEWTON = 50         # Newton-Kleinman steps from a stabilizing gain (semidefinite Q fallback)
_DEFINITE_RTOL = 1e-8    # Q is numerically definite when lambda_min(Q) > 1e-8 lambda_max(Q)
_MARGIN_SQUARINGS = 20   # with Q singular, a closed loop must halve within 2^20 steps: rho < 1 - 7e-7
_ROUNDING_RTOL = 1e-10   # below this residual a Newton step that does not reduce it is rounding
_LINEAR_EVIDENCE_RTOL = 1e-12  # Newton's residual ratios count as linear convergence only above this residual
_ROUNDING_STEP_ULPS = 1000     # ... and only for steps above this many ulps of ||P||_F
_CHECK_RTOL = 1e-8       # relative residual above which no solution is reported
_ILL_R_RTOL = 1e-8       # R is ill-conditioned for the doubling below lambda_min(R) = 1e-8 x the problem's scale
_CERTIFY_SQUARINGS = 40  # squarings of A_cl allowed: 2^40 eps keeps the rounding drift below 1e-3
_CERTIFY_NORM = 0.5      # ||A_cl^(2^k)||_F below this certifies rho(A_cl) < 1 despite that drift
_BASE = 8                # block size at which the triangular Stein solve is done directly


class NoStabilizingSolutionError(ValueError):
    """The equation has no stabilizing solution (or none was found to working precision)."""


class SolveInfo(NamedTuple):
    """How a solution was found.

    Attributes
    ----------
    residual : float
        Relative residual ``||F(X)||_F / ||X||_F`` of the returned solution (always
        computed for the DARE; NaN for a Lyapunov solve with ``check=False``).
    method : str
        ``"sda"`` (doubling), ``"sda+newton"`` (Newton-Kleinman from the gain of
        ``Q + cI``, where the doubling failed on a numerically singular Q), ``"qz"``
        (scipy's QZ solution, refined and certified, where the doubling failed on a
        nearly singular R), ``"smith"`` or ``"schur"``.
    steps : int
        Doubling steps (SDA or Smith); 0 for the Schur method.
    refinements : int
        Newton steps applied after the doubling (DARE only).
    """

    residual: float
    method: str
    steps: int
    refinements: int = 0


# -- input checks ---------------------------------------------------------------------------


def _matrix(label: str, value, rows: int | None = None, cols: int | None = None) -> np.ndarray:
    """A finite real 2-D float array of the given shape, or a one-line ValueError."""
    raw = np.asarray(value)
    if np.iscomplexobj(raw):
        raise ValueError(f"{label} is complex; these solvers take real matrices")
    try:
        M = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{label} must be a numeric matrix") from None
    if M.ndim != 2:
        raise ValueError(f"{label} must be a 2-D matrix, got {M.ndim} dimension(s)")
    if (rows is not None and M.shape[0] != rows) or (cols is not None and M.shape[1] != cols):
        want = (rows if rows is not None else "any", cols if cols is not None else "any")
        raise ValueError(f"{label} must have shape ({want[0]}, {want[1]}), got {M.shape}")
    if M.size == 0:
        raise ValueError(f"{label} is empty (shape {M.shape})")
    if not np.all(np.isfinite(M)):
        raise ValueError(f"{label} has non-finite entries (NaN or inf)")
    return M


def _square(label: str, value, size: int | None = None) -> np.ndarray:
    M = _matrix(label, value)
    if M.shape[0] != M.shape[1]:
        raise ValueError(f"{label} must be square, got shape {M.shape}")
    if size is not None and M.shape[0] != size:
        raise ValueError(f"{label} must have shape {(size, size)}, got {M.shape}")
    return M


def _symmetric(label: str, M: np.ndarray) -> np.ndarray:
    """M made exactly symmetric, if it is symmetric to 1e-10 of its largest entry."""
    scale = max(float(np.abs(M).max()), 1e-300)
    if np.abs(M - M.T).max() > 1e-10 * scale:
        raise ValueError(f"{label} must be symmetric (largest asymmetry {np.abs(M - M.T).max():.3g})")
    return (M + M.T) / 2


def _sym(M: np.ndarray) -> np.ndarray:
    return (M + M.T) / 2


def _relative(F: np.ndarray, X: np.ndarray) -> float:
    return float(np.linalg.norm(F) / max(np.linalg.norm(X), np.finfo(float).tiny))


# -- the Riccati equation -------------------------------------------------------------------


def dare_residual(A, B, Q, R, P) -> float:
    """Relative residual of a candidate DARE solution.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
        Symmetric.
    R : array_like, shape (m, m)
        Symmetric positive definite.
    P : array_like, shape (n, n)
        Candidate solution.

    Returns
    -------
    float
        ``||A'PA - A'PB (R + B'PB)^{-1} B'PA + Q - P||_F / ||P||_F``.

    Raises
    ------
    ValueError
        Shapes or non-finite entries.
    """
    A, B, Q, R = _dare_inputs(A, B, Q, R)
    P = _square("P", P, A.shape[0])
    return _defect(A, B, Q, R, _sym(P))[3]


def _dare_inputs(A, B, Q, R):
    A = _square("A", A)
    n = A.shape[0]
    B = _matrix("B", B, rows=n)
    Q = _symmetric("Q", _square("Q", Q, n))
    R = _symmetric("R", _square("R", R, B.shape[1]))
    return A, B, Q, R


def _defect(A, B, Q, R, P):
    """(F, K, A_cl, relative residual): the DARE residual F(P) at P with its optimal gain u = Kx."""
    import scipy.linalg

    PA = P @ A
    PB = P @ B
    BtPA = PB.T @ A
    try:
        factor = scipy.linalg.cho_factor(R + B.T @ PB, check_finite=False)
    except np.linalg.LinAlgError:
        raise NoStabilizingSolutionError("R + B'PB is not positive definite at the computed P: "
                                         "no stabilizing solution was found") from None
    K = -scipy.linalg.cho_solve(factor, BtPA, check_finite=False)
    F = _sym(Q + A.T @ PA + BtPA.T @ K - P)
    return F, K, A + B @ K, _relative(F, P)


def _sda_step(A, G, H, identity):
    """One doubling step: (A_{k+1}, G_{k+1}, H_{k+1}), or None where W = I + G_k H_k is singular.

    W is never singular while G_k and H_k are semidefinite; an exactly singular LU
    factor means the iterates have overflowed (LAPACK's ``getrf`` is called directly,
    as :func:`scipy.linalg.lu_factor` does, without its warning).
    """
    import scipy.linalg
    from scipy.linalg import lapack

    n = A.shape[0]
    W = identity + G @ H
    lu, piv, info = lapack.dgetrf(W, overwrite_a=True)
    if info != 0:
        return None
    solved = scipy.linalg.lu_solve((lu, piv), np.hstack([A, G]), check_finite=False)
    WA, WG = solved[:, :n], solved[:, n:]
    return A @ WA, _sym(G + A @ WG @ A.T), _sym(H + A.T @ (H @ WA))


def _sda(A, G, H, max_steps: int):
    """Structure-preserving doubling: H_k -> the stabilizing solution. Returns (H, steps).

    A_{k+1} = A_k W^{-1} A_k, G_{k+1} = G_k + A_k W^{-1} G_k A_k',
    H_{k+1} = H_k + A_k' H_k W^{-1} A_k with W = I + G_k H_k, which is never singular
    for G_k, H_k positive semidefinite; A_k decays like A_cl^(2^k).
    """
    identity = np.eye(A.shape[0])
    previous = np.inf
    for step in range(1, max_steps + 1):
        with np.errstate(over="ignore", invalid="ignore"):  # divergence is detected just below
            stepped = _sda_step(A, G, H, identity)
            if stepped is None:
                size = np.inf
            else:
                A, G, H_next = stepped
                size = np.linalg.norm(H_next)
        if not np.isfinite(size) or size > _SDA_OVERFLOW:
            raise NoStabilizingSolutionError(
                f"no stabilizing solution: the doubling diverges (||H|| = {size:.3g} after {step} steps); "
                "(A, B) is not stabilizable")
        change = np.linalg.norm(H_next - H) / max(size, np.finfo(float).tiny)
        H = H_next
        if change <= _SDA_TOL:
            return H, step
        # Quadratic regime: the next change is about change^3 / previous^2; stop when it is
        # below rounding (the residual check and the Newton corrections cover a misjudgment).
        if change < 1e-8 and change < previous and change**3 / previous**2 < 1e-18:
            return H, step
        previous = change
    raise NoStabilizingSolutionError(
        f"no stabilizing solution detected: the doubling did not converge in {max_steps} steps "
        "(eigenvalues on the unit circle: (A, B) not stabilizable or (Q, A) with unobservable "
        "modes on the unit circle)")


def _certify_stable(M: np.ndarray) -> int:
    """Raise unless some ||M^(2^k)||_F, k <= 40, is below 1/2 (then rho(M) < 1); return that k.

    Squaring in floating point drifts by about 2^k eps, which can make the powers
    of a matrix with an eigenvalue on the unit circle decay after 50 squarings; 40
    squarings and the margin 1/2 keep the certificate honest. It accepts spectral
    radii up to about 1 - 1e-11; k is about log2(0.69 / (1 - rho(M))).
    """
    size = np.linalg.norm(M)
    with np.errstate(over="ignore", invalid="ignore"):
        for squarings in range(_CERTIFY_SQUARINGS + 1):
            if squarings:
                M = M @ M
                size = np.linalg.norm(M)
            if size < _CERTIFY_NORM:
                return squarings
            if not np.isfinite(size) or size > _SMITH_GROWTH:
                break
    raise NoStabilizingSolutionError(
        f"no stabilizing solution: the closed loop A + BK of the computed P is not stable "
        f"(||A_cl^(2^{squarings})||_F = {size:.3g} does not decay)")


def _newton(A, B, Q, R, state, max_steps: int, *, from_far: bool):
    """Newton-Kleinman steps D = A_cl' D A_cl + F(P), P <- P + D, from ``state = (P, F, K, A_cl, residual)``.

    Each step needs A_cl stable: :func:`solve_discrete_lyapunov` checks it (Smith's
    powers decay, or the Schur form's eigenvalues). Returns ``(state, steps,
    certified)`` where ``certified`` says whether the returned state's own closed
    loop passed that check: ``""`` (not checked), ``"smith"`` (Smith's iteration
    converged: spectral radius below about 1 - 3e-4) or ``"schur"`` (below 1, by the
    Schur form's eigenvalues). ``from_far``: the start is a stabilizing gain far from
    the solution, where Newton's residual need not fall monotonically; otherwise
    a step that does not lower the residual ends the refinement (rounding level).

    Linear convergence is judged only on steps above rounding: a ratio of successive
    residuals counts as evidence only where the residual before the step is above
    :data:`_LINEAR_EVIDENCE_RTOL` (1e-12) and the step itself above
    :data:`_ROUNDING_STEP_ULPS` (1000) ulps of P. A limit on the unit circle shows
    itself long before that: its residual falls about fourfold a step while the error,
    and so the step, only halves, so at a residual of 1e-12 its steps are still about
    1e-6 of P. Below, the residual's moves are rounding, whose ratios can fall anywhere
    (issue 60 saw 3e-5, 3.4e-8, 4.6e-14, 1.3e-14, 4.7e-15; tests/test_riccati_fuzz.py has
    2.2e-10, 7.8e-14, 5.8e-14, 6.8e-15: the ratios 0.74 and 0.12 of its last two steps were
    taken for linear convergence, on a problem scipy solves to 2.5e-11).
    """
    certified = ""
    ratios = []
    ulp = np.finfo(float).eps
    for step in range(max_steps):
        P, F, _, Acl, residual = state
        if residual <= _REFINE_RTOL:
            if from_far and len(ratios) >= 2 and all(0.1 <= r <= 0.9 for r in ratios[-2:]):
                # Newton converges quadratically to a stabilizing solution; steadily linear
                # convergence (the residual divided by about 4 a step) means its limit has a
                # closed-loop eigenvalue on the unit circle, which it approaches.
                raise NoStabilizingSolutionError(
                    "no stabilizing solution: Newton's iteration converges only linearly, to a closed loop "
                    "on the unit circle (an unobservable mode of (Q, A) on the unit circle)")
            return state, step, certified
        try:
            correction, solved = solve_discrete_lyapunov(Acl, F, transpose=True, check=False, full_output=True)
        except NoStabilizingSolutionError:
            if from_far and step == 0:
                # The start is the optimal gain of a definite cost Q + cI: it stabilizes if any gain does.
                raise NoStabilizingSolutionError(
                    "no stabilizing solution: the optimal gain for the definite cost Q + cI does not "
                    "stabilize; (A, B) is not stabilizable") from None
            if from_far:
                raise NoStabilizingSolutionError(
                    "no stabilizing solution: Newton's closed loop reaches the unit circle "
                    "(an unobservable mode of (Q, A) on the unit circle)") from None
            return state, step, ""
        P_next = _sym(P + correction)
        trial = _defect(A, B, Q, R, P_next)
        if not trial[3] < residual and (residual <= _ROUNDING_RTOL or not from_far):
            return state, step, solved.method  # rounding level: keep the certified point
        if residual > _LINEAR_EVIDENCE_RTOL and (np.linalg.norm(correction)
                                                 > _ROUNDING_STEP_ULPS * ulp * np.linalg.norm(P_next)):
            ratios.append(trial[3] / residual)
        state, certified = (P_next,) + trial, ""
    if from_far and state[4] > _CHECK_RTOL:
        raise NoStabilizingSolutionError(
            f"no stabilizing solution detected: Newton's iteration did not converge in {max_steps} steps "
            "(an unobservable mode of (Q, A) on the unit circle)")
    return state, max_steps, certified


def _numerically_definite(Q: np.ndarray) -> bool:
    """Whether Q's smallest eigenvalue exceeds :data:`_DEFINITE_RTOL` (1e-8) times its largest.

    A rank-revealing test (symmetric eigenvalues; about 6 n x n products at n = 1000,
    spent only once the doubling has failed). A Cholesky factorization is no such
    test: it succeeds on a numerically singular Q = C'C, whose eigenvalues at rounding
    level come out positive as often as not. Below the ratio 1e-8 a mode may be seen
    by Q only through an eigenvalue that the doubling cannot resolve (its dual iterate
    G_k grows along that mode like 1 / lambda_min(Q), and W = I + G_k H_k loses as
    many digits), so the doubling's failure is no proof that no stabilizing solution exists.
    """
    eigenvalues = np.linalg.eigvalsh(Q)
    return bool(eigenvalues[0] > _DEFINITE_RTOL * max(float(eigenvalues[-1]), 0.0))


def _certified_state(A, B, Q, R, state, certified, singular):
    """``state`` if its closed loop is stable and its residual at most 1e-8, else NoStabilizingSolutionError.

    ``certified``: what :func:`_newton` already checked (``""``: nothing, then
    :func:`_certify_stable` does). ``singular()``: whether Q is not numerically
    definite; then a closed loop that needs more than :data:`_MARGIN_SQUARINGS` = 20
    squarings to halve (spectral radius above about 1 - 7e-7) is refused: with a
    singular Q a mode that Q does not see may sit on the unit circle, and rounding
    moves such a closed-loop eigenvalue to 1 - 1e-8 or so (the pencil's double
    eigenvalue splits by about sqrt(eps)), where it cannot be told from a stable one.
    """
    squarings = None if certified else _certify_stable(state[3])
    if not state[4] <= _CHECK_RTOL:
        raise NoStabilizingSolutionError(
            f"no stabilizing solution detected: the relative residual stays at {state[4]:.3g}")
    near = certified == "schur" if squarings is None else squarings > _MARGIN_SQUARINGS
    if near and singular():
        if squarings is None:
            squarings = _certify_stable(state[3])
        if squarings > _MARGIN_SQUARINGS:
            raise NoStabilizingSolutionError(
                f"no stabilizing solution detected: with a singular Q the closed loop's powers take "
                f"2^{squarings} steps to halve (spectral radius within about 1e-6 of 1), which is "
                "taken for an unobservable mode of (Q, A) on the unit circle")
    return state


def _from_detectable_problem(A, B, Q, R, G, max_steps):
    """Stabilizing solution when (Q, A) may not be detectable: Newton from the gain of Q + cI.

    The doubling follows the Riccati difference equation from Q, which leaves an
    unobserved unstable mode uncontrolled (it costs nothing over any finite
    horizon); with Q + cI every mode is observed, so its solution's gain is
    stabilizing, and Newton-Kleinman from a stabilizing gain converges to the
    stabilizing solution of the given Q wherever that exists (and, where an
    unobserved mode sits on the unit circle, only linearly, which :func:`_newton`
    reports). Q + cI is definite and well conditioned (c >= ||Q||_F / sqrt(n)), so
    a divergence of its doubling means that (A, B) is not stabilizable. Returns
    ``(state, steps, newton_steps)`` with a certified state.
    """
    n = A.shape[0]
    c = max(float(np.linalg.norm(Q)) / np.sqrt(n), 1.0)
    P_shifted, steps = _sda(A, G, Q + c * np.eye(n), max_steps)
    state = (P_shifted,) + _defect(A, B, Q, R, P_shifted)
    state, newton_steps, certified = _newton(A, B, Q, R, state, _MAX_NEWTON, from_far=True)
    return _certified_state(A, B, Q, R, state, certified, lambda: True), steps, newton_steps


def _ill_conditioned_input(B, Q, R) -> bool:
    """Whether R is nearly singular at the problem's scale: ``lambda_min(R) <= 1e-8 max(lambda_max(R), ||B||^2 ||Q||)``.

    The doubling works with ``G = B R^{-1} B'``, which is then 1e8 times the cost's scale
    or more along some input, and ``W = I + G H`` loses as many digits; it fails (R + B'PB
    not positive definite, a gain that does not stabilize, a residual that stays large)
    where that ratio nears 1e14, while the QZ pencil keeps R as it is (of
    tests/test_riccati_fuzz.py's 3,000 systems, the 14 failures all had ``lambda_min(R)``
    below 5e-15 of that scale, and scipy solved each to 1e-11 or better; 903 more below
    1e-8 of it the doubling solves, and they never reach this test).
    Norms are Frobenius (a bound on the 2-norms, cheap at any size).
    """
    eigenvalues = np.linalg.eigvalsh(R)
    scale = max(float(eigenvalues[-1]), float(np.linalg.norm(B)) ** 2 * float(np.linalg.norm(Q)))
    return bool(eigenvalues[0] <= _ILL_R_RTOL * scale)


def _from_qz(A, B, Q, R, singular, failure):
    """The stabilizing solution by scipy's QZ solver, refined and certified: ``(state, refinements)``.

    Used only where the doubling path failed and R is ill-conditioned for it
    (:func:`_ill_conditioned_input`): the generalized eigenproblem of the extended
    pencil never inverts R. Its P is accepted only as ours would be: Newton refinement,
    then a residual of at most 1e-8 and a certified stable closed loop
    (:func:`_certified_state`), so a non-stabilizing or inaccurate QZ answer is refused,
    with the reason, after the doubling's own (``failure``).
    """
    import warnings

    import scipy.linalg

    prefix = (f"{failure}; R is nearly singular at the problem's scale, which the doubling cannot resolve, and "
              "scipy's QZ solver (which keeps R in its pencil)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scipy's own ill-conditioning warnings: judged below
            P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise NoStabilizingSolutionError(f"{prefix} fails too: {exc}") from None
    if not np.all(np.isfinite(P)):
        raise NoStabilizingSolutionError(f"{prefix} returns non-finite entries") from None
    try:
        P = _sym(P)
        state = (P,) + _defect(A, B, Q, R, P)
        state, refinements, certified = _newton(A, B, Q, R, state, _MAX_REFINEMENTS, from_far=False)
        state = _certified_state(A, B, Q, R, state, certified, singular)
    except NoStabilizingSolutionError as exc:
        raise NoStabilizingSolutionError(f"{prefix} gives no certified solution either: {exc}") from None
    return state, refinements


def solve_discrete_are(A, B, Q, R, *, check: bool = True, full_output: bool = False,
                       max_steps: int = _SDA_MAX_STEPS):
    """Stabilizing solution of the discrete algebraic Riccati equation.

    Solves ``P = A'PA - A'PB (R + B'PB)^{-1} B'PA + Q`` (the argument order of
    :func:`scipy.linalg.solve_discrete_are`) by the structure-preserving doubling
    algorithm, then Newton-Kleinman corrections ``D = A_cl' D A_cl + F(P)`` (solved
    by Smith's iteration on the stable closed loop) while the relative residual is
    above 1e-14 and falling. Where the doubling fails (it diverges or overflows, does
    not converge, or, with ``check``, its closed loop is not stable or its residual
    stays above 1e-8) and Q is not numerically definite (its smallest eigenvalue is at
    most 1e-8 times its largest; a Cholesky factorization succeeds on numerically
    singular matrices and is no test), a mode that Q does not see may have been left
    uncontrolled: Newton-Kleinman from the stabilizing gain of ``Q + cI`` finds the
    stabilizing solution if there is one. Well-posed problems (the doubling succeeds)
    never pay for the eigenvalues of that rank test. Where both fail and R is nearly
    singular at the problem's scale (``lambda_min(R) <= 1e-8 max(lambda_max(R),
    ||B||^2 ||Q||)``), which the doubling cannot resolve, scipy's QZ solution is refined
    and certified instead (method ``"qz"``), or the refusal says why it was not.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
        Symmetric positive semidefinite.
    R : array_like, shape (m, m)
        Symmetric positive definite.
    check : bool
        Verify the result: relative residual at most 1e-8 and a closed loop
        ``A + BK``, ``K = -(R + B'PB)^{-1} B'PA``, whose repeated squares fall below
        norm 1/2 (a certificate that its spectral radius is below 1). Costs about
        one doubling step; without it only the doubling's convergence is checked
        (where it fails on a singular Q, the fallback's result is certified all the same).
    full_output : bool
        Also return a :class:`SolveInfo`.
    max_steps : int
        Most doubling steps (each squares the closed loop's decay).

    Returns
    -------
    P : ndarray, shape (n, n)
        Symmetric stabilizing solution.
    info : SolveInfo
        Only with ``full_output``.

    Raises
    ------
    ValueError
        Shapes, non-finite entries, Q or R not symmetric, R not positive definite.
    NoStabilizingSolutionError
        No stabilizing solution: (A, B) is not stabilizable, or (Q, A) has an
        unobservable mode on the unit circle. With a numerically definite Q this is
        the doubling's verdict (it diverges or does not converge, or, with ``check``,
        the residual stays large or the closed loop is not stable); with a singular Q
        the fallback's (the gain of ``Q + cI`` does not stabilize; Newton converges
        only linearly, or to a closed loop within about 1e-6 of the unit circle,
        which to working precision is an unobserved mode on the circle). With a nearly
        singular R, the message adds why scipy's QZ solution was not accepted either
        (scipy fails, or its P is not certified: residual or closed loop).
    """
    import scipy.linalg

    A, B, Q, R = _dare_inputs(A, B, Q, R)
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
    try:
        L = scipy.linalg.cholesky(R, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        raise ValueError("R must be positive definite (its Cholesky factorization fails)") from None
    # G_0 = B R^{-1} B' as a Gram matrix, so that it is symmetric semidefinite to rounding.
    BL = scipy.linalg.solve_triangular(L, B.T, lower=True, check_finite=False).T
    G = BL @ BL.T
    max_steps = int(max_steps)
    method = "sda"
    rank_test = []  # Q's rank test, done at most once and only where needed

    def singular() -> bool:
        if not rank_test:
            rank_test.append(not _numerically_definite(Q))
        return rank_test[0]

    try:
        P, steps = _sda(A, G, Q.copy(), max_steps)
        state = (P,) + _defect(A, B, Q, R, P)
        state, refinements, certified = _newton(A, B, Q, R, state, _MAX_REFINEMENTS, from_far=False)
        if check:
            state = _certified_state(A, B, Q, R, state, certified, singular)
    except NoStabilizingSolutionError as failure:
        state = None
        if singular():
            # Q is singular to working precision: the doubling's failure proves nothing.
            try:
                state, steps, refinements = _from_detectable_problem(A, B, Q, R, G, max_steps)
                method = "sda+newton"
            except NoStabilizingSolutionError as again:
                failure = again
        if state is None:
            if not _ill_conditioned_input(B, Q, R):
                # (Q, A) observable and R well scaled: the doubling found the stabilizing solution
                # if any (or, with Q singular, Newton from the gain of Q + cI did).
                raise failure from None
            state, refinements = _from_qz(A, B, Q, R, singular, failure)
            steps, method = 0, "qz"
    P, residual = state[0], state[4]
    info = SolveInfo(residual=residual, method=method, steps=steps, refinements=refinements)
    return (P, info) if full_output else P


# -- the Lyapunov (Stein) equation ----------------------------------------------------------


def _smith(A, Q, *, symmetric: bool):
    """Smith's squared iteration for X = A X A' + Q: (X, doublings), or None if not converged.

    With M = A^(2^k), X <- X + M X M' doubles the number of terms of the series
    summed, and M <- M^2. The remainder after that update starts at A^(2^(k+1)),
    whose norm is at most ||M||^2, so the iteration ends once ||M||_F^2 <= 1e-9
    (remainder below 1e-18 of X) without the last squaring. Raises
    NoStabilizingSolutionError when the powers overflow (A is not stable).
    """
    X = Q.copy()
    M = np.array(A)
    with np.errstate(over="ignore", invalid="ignore"):
        for doubling in range(1, SMITH_MAX_DOUBLINGS + 1):
            X = X + M @ X @ M.T
            if symmetric:
                X = _sym(X)
            size = np.linalg.norm(M)
            if size**2 <= _SMITH_TOL:
                return X, doubling
            M = M @ M
            size = np.linalg.norm(M)
            if not np.isfinite(size):
                raise NoStabilizingSolutionError(
                    "A is not stable (its powers A^(2^k) overflow): the Lyapunov equation has no convergent solution")
            if size > _SMITH_GROWTH:
                return None
    return None


def _split(T: np.ndarray) -> int:
    """A split point near the middle of quasi-triangular T that does not cut a 2 x 2 block."""
    h = T.shape[0] // 2
    if T[h, h - 1] != 0.0:
        h += 1 if h + 1 < T.shape[0] else -1
    return h


def _stein_direct(S, U, C):
    """X = S X U' + C for small S and U, through the Kronecker form (I - U kron S) vec X = vec C."""
    from scipy.linalg import lapack

    p, q = C.shape
    # Row-major vec of X' is the column-major vec of X: vec(S X U') = (U kron S) vec X.
    system = (U[:, None, :, None] * S[None, :, None, :]).reshape(p * q, p * q)
    np.negative(system, out=system)
    system.flat[:: p * q + 1] += 1.0
    _, _, x, info = lapack.dgesv(system, C.T.reshape(-1), overwrite_a=True)
    if info > 0:
        raise NoStabilizingSolutionError("the Stein equation is singular: A has eigenvalues l, m with l m = 1")
    return x.reshape(q, p).T


def _stein(S, U, C):
    """X = S X U' + C for quasi-upper-triangular S (p, p) and U (q, q), by recursive halving."""
    p, q = C.shape
    if p <= _BASE and q <= _BASE:
        return _stein_direct(S, U, C)
    if p >= q:
        h = _split(S)
        X2 = _stein(S[h:, h:], U, C[h:])
        X1 = _stein(S[:h, :h], U, C[:h] + S[:h, h:] @ (X2 @ U.T))
        return np.vstack([X1, X2])
    h = _split(U)
    X2 = _stein(S, U[h:, h:], C[:, h:])
    X1 = _stein(S, U[:h, :h], C[:, :h] + (S @ X2) @ U[:h, h:].T)
    return np.hstack([X1, X2])


def _stein_symmetric(T, C):
    """Y = T Y T' + C for quasi-upper-triangular T and symmetric C; only half the blocks are solved."""
    n = T.shape[0]
    if n <= _BASE:
        return _sym(_stein_direct(T, T, C))
    h = _split(T)
    T11, T12, T22 = T[:h, :h], T[:h, h:], T[h:, h:]
    Y22 = _stein_symmetric(T22, C[h:, h:])
    T12Y22 = T12 @ Y22
    Y12 = _stein(T11, T22, C[:h, h:] + T12Y22 @ T22.T)
    Z = T11 @ Y12 @ T12.T
    Y11 = _stein_symmetric(T11, _sym(C[:h, :h] + Z + Z.T + T12Y22 @ T12.T))
    return np.block([[Y11, Y12], [Y12.T, Y22]])


def _radius_of_quasi_triangular(T: np.ndarray) -> float:
    """Spectral radius from the 1 x 1 and 2 x 2 diagonal blocks of a real Schur form."""
    n = T.shape[0]
    moduli = np.abs(np.diag(T)).copy()
    pairs = np.flatnonzero(np.diag(T, -1) != 0.0)
    for i in pairs:
        # A 2 x 2 block with complex eigenvalues: |lambda|^2 is its determinant.
        block = T[i:i + 2, i:i + 2]
        moduli[i] = moduli[i + 1] = np.sqrt(abs(block[0, 0] * block[1, 1] - block[0, 1] * block[1, 0]))
    return float(moduli.max()) if n else 0.0


class LyapunovSolver:
    """Repeated solves of ``X = A X A' + Q`` (and ``X = A'XA + Q``) for one stable A.

    The real Schur form ``A = U T U'`` is computed once (about 25 n^3 flops, LAPACK's
    ``gees``); each :meth:`solve` then costs a recursive blocked solve of the
    triangular Stein equation (a few n^3 flops in matrix products) and the four
    products of the change of basis. Use it where A is fixed and Q changes; for a
    single right-hand side :func:`solve_discrete_lyapunov` is usually faster.

    Parameters
    ----------
    A : array_like, shape (n, n)
        Stable: spectral radius below 1.

    Attributes
    ----------
    spectral_radius : float
        Spectral radius of A, from its Schur form.

    Raises
    ------
    ValueError
        A not square or with non-finite entries.
    NoStabilizingSolutionError
        A is not stable (spectral radius at least 1): the equation has no
        solution as a convergent series.
    """

    def __init__(self, A):
        import scipy.linalg

        A = _square("A", A)
        self.n = A.shape[0]
        self._A = A
        T, U = scipy.linalg.schur(A, output="real", check_finite=False)
        self.spectral_radius = _radius_of_quasi_triangular(T)
        if not self.spectral_radius < 1.0:
            raise NoStabilizingSolutionError(
                f"A is not stable (spectral radius {self.spectral_radius:.6g} >= 1): "
                "the Lyapunov equation has no convergent solution")
        self._T, self._U = T, U
        # X = A'XA + Q is X = U Y U' with Y = T'YT + U'QU; reversing the order of the
        # indices makes T' upper quasi-triangular again (J T' J), so one solver serves both.
        self._T_reversed = np.ascontiguousarray(T.T[::-1, ::-1])

    def solve(self, Q, *, transpose: bool = False, check: bool = True, full_output: bool = False):
        """Solution X of ``X = A X A' + Q``, or of ``X = A'XA + Q`` with ``transpose``.

        Parameters
        ----------
        Q : array_like, shape (n, n)
            Any real matrix; a symmetric Q gives a symmetric X, solved in half the work.
        transpose : bool
            Solve ``X = A'XA + Q`` (a cost-to-go) instead of ``X = A X A' + Q`` (a covariance).
        check : bool
            Compute the relative residual and raise if it exceeds 1e-8.
        full_output : bool
            Also return a :class:`SolveInfo`.

        Returns
        -------
        X : ndarray, shape (n, n)
        info : SolveInfo
            Only with ``full_output``.

        Raises
        ------
        ValueError
            Q of the wrong shape or with non-finite entries; with ``check``, a residual above 1e-8.
        """
        Q = _square("Q", Q, self.n)
        symmetric = bool(np.array_equal(Q, Q.T))
        U = self._U
        C = U.T @ Q @ U
        if transpose:
            T, C = self._T_reversed, np.ascontiguousarray(C[::-1, ::-1])
        else:
            T = self._T
        Y = _stein_symmetric(T, C) if symmetric else _stein(T, T, C)
        if transpose:
            Y = Y[::-1, ::-1]
        X = U @ Y @ U.T
        if symmetric:
            X = _sym(X)
        residual = _lyapunov_check(self._A, Q, X, transpose) if check else float("nan")
        info = SolveInfo(residual=residual, method="schur", steps=0)
        return (X, info) if full_output else X


def _lyapunov_check(A, Q, X, transpose: bool) -> float:
    AX = A.T @ X @ A if transpose else A @ X @ A.T
    residual = _relative(AX + Q - X, X)
    if not residual <= _CHECK_RTOL:
        raise NoStabilizingSolutionError(
            f"the Lyapunov solution's relative residual is {residual:.3g} (A too close to instability)")
    return residual


def solve_discrete_lyapunov(A, Q, *, transpose: bool = False, method: str = "auto", check: bool = True,
                            full_output: bool = False):
    """Solution of the discrete Lyapunov (Stein) equation ``X = A X A' + Q`` for stable A.

    The argument order of :func:`scipy.linalg.solve_discrete_lyapunov`;
    ``transpose=True`` solves ``X = A'XA + Q`` instead (the cost-to-go
    ``P = A_cl' P A_cl + Q + K'RK``; scipy's call for it is ``(A.T, Q)``).

    Method ``"auto"``: Smith's squared iteration, 6 n^3 flops a doubling, which also
    certifies that A is stable; if it has not converged within
    :data:`SMITH_MAX_DOUBLINGS` doublings (spectral radius above about 0.9997, or a
    strongly non-normal A) or its powers grow past 1e30, the Schur method
    (:class:`LyapunovSolver`) finishes, and its eigenvalues decide stability.

    Parameters
    ----------
    A : array_like, shape (n, n)
        Stable: spectral radius below 1.
    Q : array_like, shape (n, n)
        Any real matrix; symmetric Q gives symmetric X.
    transpose : bool
        Solve ``X = A'XA + Q``.
    method : {"auto", "smith", "schur"}
        ``"smith"`` raises where the iteration does not converge.
    check : bool
        Compute the relative residual ``||A X A' + Q - X||_F / ||X||_F`` and raise if above 1e-8.
    full_output : bool
        Also return a :class:`SolveInfo`.

    Returns
    -------
    X : ndarray, shape (n, n)
    info : SolveInfo
        Only with ``full_output``.

    Raises
    ------
    ValueError
        Shapes, non-finite entries, unknown method.
    NoStabilizingSolutionError
        A is not stable (spectral radius at least 1; or, with ``"smith"``, too close
        to 1 for the iteration).
    """
    if method not in ("auto", "smith", "schur"):
        raise ValueError(f"method must be 'auto', 'smith' or 'schur', got {method!r}")
    A = _square("A", A)
    Q = _square("Q", Q, A.shape[0])
    if method == "schur":
        return LyapunovSolver(A).solve(Q, transpose=transpose, check=check, full_output=full_output)
    symmetric = bool(np.array_equal(Q, Q.T))
    found = _smith(A.T if transpose else A, Q, symmetric=symmetric)
    if found is None:
        if method == "smith":
            raise NoStabilizingSolutionError(
                f"Smith's iteration did not converge in {SMITH_MAX_DOUBLINGS} doublings: A is not stable "
                "or its spectral radius is too close to 1 (use method='schur')")
        return LyapunovSolver(A).solve(Q, transpose=transpose, check=check, full_output=full_output)
    X, doublings = found
    residual = _lyapunov_check(A, Q, X, transpose) if check else float("nan")
    info = SolveInfo(residual=residual, method="smith", steps=doublings)
    return (X, info) if full_output else X
