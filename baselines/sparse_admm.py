"""Sparse static gains by ℓ1-regularized ADMM (Lin, Fardad & Jovanović 2013, "lqrsp").

For each weight γ on an increasing grid, minimize

    J(K) / trace(P) + γ Σ_{i≠j} w_ij |K_ij|,   J(K) = trace(P_K),   P_K = A_cl' P_K A_cl + Q + K'RK,

over static gains (A_cl = A + BK here: this module uses the evaluator's sign,
``u = K x``, where lqrsp writes ``u = -Kx``; the ℓ1 term does not care and
the gradient below carries the sign). x(0) ~ N(0, I) plays the role of B₁B₁'.
γ is in units of the normalized cost (the lqrsp γ is this γ times trace(P),
the LQR cost): one grid then suits every instance of the family, and a path's
points line up across instances in a report.
ADMM splits K = G:

- K-step: minimize J(K) + (ρ/2)‖K − U‖²_F, U = G − Λ/ρ, by Anderson–Moore
  iterations (freeze P_K and L = A_cl L A_cl' + I, solve the resulting Sylvester
  equation in closed form), each followed by an Armijo line search that never
  accepts a gain with ρ(A_cl) ≥ 1;
- G-step: weighted soft-thresholding of K + Λ/ρ (diagonal never penalized);
- dual update Λ += ρ(K − G);

then reweighting rounds w_ij = 1/(|G_ij| + ε). Where nodes hold several states or
inputs, the entries are node blocks K_ij (node i's inputs by node j's states): the
penalty is γ Σ_{i≠j} w_ij ‖K_ij‖_F, the G-step the weighted group soft-threshold
K_ij ← K_ij max(0, 1 − t_ij/‖K_ij‖_F), and w_ij = 1/(‖G_ij‖_F + ε). The path is warm-started from LQR;
a γ whose sparse G destabilizes keeps the previous γ's solution. Each pattern is
polished on the exact finite-horizon benchmark cost, which is also what every
design reports.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from codesign.evaluation import spectral_radius
from codesign.methods import Above, AtLeast, NotEmpty, method

from ._sparse import DecentralizedCache, check_gammas, infinite_horizon_point, l1_path
from .stabilizing import is_stable, unstable_note

__all__ = ["sparse_admm", "ADMM_GAMMAS", "admm_gamma_max"]

#: Default weights (normalized units): from an (almost) dense LQR gain to a few links
#: on the paper's family; the path is closed by the diagonal gain at γ = inf.
ADMM_GAMMAS = tuple(float(g) for g in np.geomspace(1e-6, 0.1, 10))

_ARMIJO = 1e-4        # sufficient-decrease constant of the line search
_BACKTRACK = 0.5
_MAX_BACKTRACKS = 40
_KSTEP_MAXITER = 50
_REL_TOL = 1e-2        # relative part of the ADMM residual test (lqrsp's eps_rel)


def _kstep(instance, point, U, rho, *, tol, maxiter):
    """Minimize trace(P_K) + (rho/2)||K - U||² from a stabilizing point. Returns (point, iterations)."""
    A, B, R = instance.A, instance.B, instance.R
    phi = point.J + 0.5 * rho * np.sum((point.K - U) ** 2)
    for it in range(maxiter):
        K, P, L = point.K, point.P, point.L
        grad = point.grad + rho * (K - U)
        if np.linalg.norm(grad) <= tol:
            return point, it
        # Anderson–Moore: with P and L frozen the stationarity condition is the
        # Sylvester equation 2 M Kbar L + rho Kbar = -2 B'PA L + rho U, M = R + B'PB,
        # solved exactly in the eigenbases of the two symmetric factors.
        BtP = B.T @ P
        m, V1 = np.linalg.eigh(R + BtP @ B)
        l, V2 = np.linalg.eigh((L + L.T) / 2)
        rhs = V1.T @ (-2.0 * BtP @ A @ L + rho * U) @ V2
        Kbar = V1 @ (rhs / (2.0 * np.outer(m, l) + rho)) @ V2.T
        direction = Kbar - K
        slope = np.sum(grad * direction)
        if not slope < 0:  # not a descent direction: fall back to steepest descent
            direction, slope = -grad, -np.sum(grad * grad)
        step = 1.0
        for _ in range(_MAX_BACKTRACKS):
            trial = infinite_horizon_point(instance, K + step * direction)
            if trial is not None:  # unstable trial gains are never accepted
                phi_trial = trial.J + 0.5 * rho * np.sum((trial.K - U) ** 2)
                if phi_trial <= phi + _ARMIJO * step * slope:
                    break
            step *= _BACKTRACK
        else:
            return point, it + 1  # no acceptable step along this direction
        point, phi = trial, phi_trial
    return point, maxiter


def _shrink(V, threshold):
    """Weighted soft-thresholding; ``threshold`` is zero on the diagonal."""
    return np.sign(V) * np.maximum(np.abs(V) - threshold, 0.0)


def _group_shrink(instance, V, threshold):
    """Weighted group soft-threshold of the node blocks; ``threshold`` (N, N) is zero on each node's own block."""
    norms = instance.block_norms(V)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(norms > threshold, 1.0 - threshold / norms, 0.0)
    return V * instance.expand_blocks(factor)


def admm_gamma_max(instance) -> float:
    """Smallest γ (normalized units) at which the best diagonal gain is stationary for plain ℓ1.

    At a diagonal K_d optimal over the diagonal, the subgradient condition of
    J(K)/trace(P) + γ Σ_{i≠j} |K_ij| holds exactly when
    γ ≥ max_{i≠j} |∇J(K_d)_ij| / trace(P). K_d is the decentralized gain of the
    benchmark (finite-horizon) cost, a close stand-in for the infinite-horizon one.
    Reweighting makes paths diagonal well below this value.
    """
    diagonal = DecentralizedCache(instance).usable()
    point = None if diagonal is None else infinite_horizon_point(instance, np.array(diagonal.controller.K))
    if point is None:
        raise ValueError("no stabilizing diagonal gain on this instance")
    if instance.scalar_nodes:
        grad = point.grad.copy()
        np.fill_diagonal(grad, 0.0)
        return float(np.max(np.abs(grad))) / instance.trace_P
    norms = instance.block_norms(point.grad)
    np.fill_diagonal(norms, 0.0)
    return float(np.max(norms)) / instance.trace_P


#: Past this many states the ADMM path is refused at once through the registry: its iterations
#: solve dense N x N Lyapunov-type equations (a dozen N^3 products each), so one γ takes 14 s at
#: 200 states and 6.5 s per ADMM iteration at 500 (about 170 iterations per γ: 19 minutes, the
#: 10-γ path 3 hours; 2026-11-26, one thread).
MAX_STATES = 300
MAX_STATES_REASON = ("the ADMM path's iterations are dense N^3 solves: one γ takes 14 s at 200 states and about "
                     "19 minutes at 500 (the 10-γ path 3 hours)")


@method("sparse_admm", label="Sparse K (l1 ADMM)", node_blocks=True, max_states=MAX_STATES,
        max_states_reason=MAX_STATES_REASON)
def sparse_admm(
    instance,
    *,
    gammas: Annotated[list[Annotated[float, AtLeast(0)]], NotEmpty()] | None = None,
    reweight: Annotated[int, AtLeast(1)] = 3,
    rho: Annotated[float, Above(0)] = 100.0,
    polish: bool = True,
    eps_weight: Annotated[float, Above(0)] = 1e-3,
    tol: Annotated[float, Above(0)] = 1e-4,
    kstep_tol: Annotated[float, Above(0)] = 1e-2,
    maxiter: Annotated[int, AtLeast(1)] = 1000,
    start: list | None = None,
    diagonal_end: bool = True,
):
    """Sparse static gains along a γ path by ℓ1-regularized ADMM, polished on their patterns.

    Parameters
    ----------
    instance : Instance
    gammas : list of float, optional
        Sparsity weights in units of the normalized cost; sorted increasing.
        Default: :data:`ADMM_GAMMAS` (10 values, 1e-6 to 0.1).
    reweight : int
        Weighted ℓ1 solves per γ (lqrsp's ``reweightedIter``); after each,
        ``w_ij = 1/(|G_ij| + eps_weight)``, stopping early once the weights settle.
        The weights carry over to the next γ, as in lqrsp; the first solve of the
        path is plain ℓ1.
    rho : float
        ADMM penalty.
    polish : bool
        Re-optimize the free entries of each pattern on the exact benchmark cost.
    eps_weight : float
        ε of the reweighting.
    tol : float
        Absolute ADMM tolerance per entry: stop when ‖K − G‖_F and ρ‖G − G_prev‖_F
        fall below ``n * tol`` plus 1e-2 times ‖K‖_F (resp. ‖Λ‖_F), lqrsp's test.
    kstep_tol : float
        The K-step stops when the gradient of its objective has norm below this.
    maxiter : int
        ADMM iterations per weighted solve.
    start : array_like, shape (n, n), optional
        Stabilizing gain (``u = K x``) to start the path from; LQR by default.
    diagonal_end : bool
        Close the path with the decentralized gain as its γ → ∞ point
        (``params["gamma"] = inf``).

    Returns
    -------
    list of Design
        One per γ (``params = {"gamma": γ, "reweight": ..., "rho": ...}``), then
        the γ = inf end, each with its own links and exact finite-horizon cost,
        information model ``instantaneous``. Patterns with no off-diagonal entry
        are the decentralized gain. Extras record the ADMM and K-step iterations,
        reweighting rounds, convergence, the polishing, the spectral radius and
        whether the previous γ's gain was kept (``fallback``).

    Raises
    ------
    ValueError
        Negative or non-finite γ, non-positive ρ/ε/tol, or a start that is not a
        stabilizing (n, n) gain.

    Notes
    -----
    Both ℓ1 variants are heuristics for a combinatorial choice of pattern. On the
    paper's family (seeds 0-29 at ‖A‖ = 0.995 and 1.05, default grid) the front of
    the default ``reweight=3`` matches or beats truncated LQR (:func:`baselines.truncated_lqr`,
    within 1e-4) at every link count on 57 of 60 instances; the three misses are
    single points, by 1.5e-4 to 5.7e-3 in cost. Plain ℓ1 (``reweight=1``) also misses
    on 3 of 60 (other instances), by 1.4e-4 to 3.7e-3.
    """
    n, m = instance.n, instance.m
    blocks = not instance.scalar_nodes
    gammas = check_gammas(ADMM_GAMMAS if gammas is None else gammas)
    for label, value in (("rho", rho), ("eps_weight", eps_weight), ("tol", tol), ("kstep_tol", kstep_tol)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{label} must be a positive number, got {value!r}")
    if isinstance(reweight, bool) or not isinstance(reweight, (int, np.integer)) or reweight < 1:
        raise ValueError(f"reweight must be a positive integer, got {reweight!r}")
    if isinstance(maxiter, bool) or not isinstance(maxiter, (int, np.integer)) or maxiter < 1:
        raise ValueError(f"maxiter must be a positive integer, got {maxiter!r}")
    K = np.array(instance.K_lqr if start is None else start, dtype=float)
    if K.shape != (m, n) or not np.all(np.isfinite(K)):
        raise ValueError(f"start must be a finite ({m}, {n}) gain, got shape {K.shape}")
    start_point = infinite_horizon_point(instance, K)
    radius = spectral_radius(instance.A + instance.B @ K)
    if start_point is None or not is_stable(radius):
        raise ValueError(f"start gain does not stabilize the instance ({unstable_note(radius)}); "
                         "ADMM needs a stabilizing start")

    base = {"reweight": int(reweight), "rho": float(rho)}
    scale = instance.trace_P  # the ADMM itself runs on trace(P_K), as in lqrsp

    def solve(state, gamma, W):
        point, G, Lam, its, kits, ok = _admm(instance, *state, scale * gamma * W / rho, rho, tol=tol,
                                             kstep_tol=kstep_tol, maxiter=maxiter, blocks=blocks)
        return (point, G, Lam), G, {"admm_iterations": its, "kstep_iterations": kits}, ok

    return l1_path(instance, "sparse_admm", gammas, solve=solve, start_state=(start_point, K.copy(), np.zeros((m, n))),
                   base=base, reweight=reweight, eps_weight=eps_weight, polish=polish, diagonal_end=diagonal_end,
                   solver="admm", solver_label="ADMM", converged_key="admm_converged")


def _admm(instance, point, G, Lam, threshold, rho, *, tol, kstep_tol, maxiter, blocks=False):
    """ADMM on K = G from a warm start; returns (point, G, Lam, iterations, K-step iterations, converged).

    Stops on lqrsp's primal/dual residual test with absolute tolerance ``tol``
    (per entry) and relative tolerance 1e-2.
    """
    size = np.sqrt(G.size)
    kstep_iters = 0
    for it in range(1, maxiter + 1):
        point, its = _kstep(instance, point, G - Lam / rho, rho, tol=kstep_tol, maxiter=_KSTEP_MAXITER)
        kstep_iters += its
        K = point.K
        V = K + Lam / rho
        G_new = _group_shrink(instance, V, threshold) if blocks else _shrink(V, threshold)
        dual = rho * np.linalg.norm(G_new - G)
        G = G_new
        primal = np.linalg.norm(K - G)
        Lam = Lam + rho * (K - G)
        eps_pri = size * tol + _REL_TOL * max(np.linalg.norm(K), np.linalg.norm(G))
        eps_dual = size * tol + _REL_TOL * np.linalg.norm(Lam)
        if primal < eps_pri and dual < eps_dual:
            return point, G, Lam, it, kstep_iters, True
    return point, G, Lam, maxiter, kstep_iters, False


