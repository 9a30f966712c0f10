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
  accepts a gain with ρ(A_cl) ≥ 1 (and, after a full step, one interpolated
  shorter step where the full one overshoots);
- G-step: weighted soft-thresholding of K + Λ/ρ (diagonal never penalized);
- dual update Λ += ρ(K − G);
- ρ balanced between the two residuals (Boyd et al. 2011, §3.4.1), never below
  the given ρ, and raised tenfold on a period-2 cycle or a stall, the solve
  stopping at once, saying why, when that does not help (issue 60: at a fixed
  ρ the iterates of a reweighted round can flip between two gains for ever);

then reweighting rounds w_ij = 1/(|G_ij| + ε). Where nodes hold several states or
inputs, the entries are node blocks K_ij (node i's inputs by node j's states): the
penalty is γ Σ_{i≠j} w_ij ‖K_ij‖_F, the G-step the weighted group soft-threshold
K_ij ← K_ij max(0, 1 − t_ij/‖K_ij‖_F), and w_ij = 1/(‖G_ij‖_F + ε). The path is warm-started from LQR;
a γ whose sparse G destabilizes keeps the previous γ's solution. A γ at or above
γ_max, where the diagonal gain meets the ℓ1 optimality conditions
(:func:`admm_gamma_max`), is answered by the diagonal gain without iterating. Each pattern is
polished on the exact finite-horizon benchmark cost, which is also what every
design reports.
"""

from __future__ import annotations

from collections import deque
from typing import Annotated, NamedTuple

import numpy as np

from codesign.evaluation import spectral_radius
from codesign.methods import Above, AtLeast, NotEmpty, method

from ._sparse import DecentralizedCache, GainPoint, check_gammas, infinite_horizon_point, l1_path
from .stabilizing import is_stable, unstable_note

__all__ = ["sparse_admm", "ADMM_GAMMAS", "admm_gamma_max"]

#: Default weights (normalized units): from an (almost) dense LQR gain to a few links
#: on the paper's family; the path is closed by the diagonal gain at γ = inf.
#: np.geomspace(1e-6, 0.1, 10) written out: geomspace's last digit depends on the BLAS
#: build and processor, and these values enter run keys, so two machines would key the
#: same run differently (tests/test_default_grids.py checks the two agree to rounding).
ADMM_GAMMAS = (
    1e-06, 3.5938136638046257e-06, 1.2915496650148827e-05, 4.641588833612782e-05,
    0.0001668100537200059, 0.0005994842503189409, 0.0021544346900318843,
    0.007742636826811277, 0.02782559402207126, 0.1,
)

_ARMIJO = 1e-4        # sufficient-decrease constant of the line search
_BACKTRACK = 0.5
_MAX_BACKTRACKS = 40
#: Anderson–Moore iterations per K-step. Each ends in a stabilizing gain, so a K-step stopped here still
#: gives a usable iterate; how many stopped short of their tolerance is reported (``kstep_unsolved``). With
#: the ρ-scaled tolerance and the interpolated step few do (paper seed 0, N = 20, ‖A‖ = 1.05, default path:
#: 7 of 1,739; issue 60's N = 6 path: 62 of 246), and a cap of 200 that solves them costs 10-25 % more
#: cost evaluations on the default path for the same designs.
_KSTEP_MAXITER = 50
#: Interpolated step lengths tried after an accepted full step. At 0.6 the parabola's minimum lowers the
#: objective 1.8 times as much as the full step did (at 0.5 the full step gained nothing); above it the
#: extra evaluation gains too little, and below 0.1 the backtracking's own halving does as well.
_SHORT_STEP = (0.1, 0.6)
_REL_TOL = 1e-2        # relative part of the ADMM residual test (lqrsp's eps_rel)
#: Residual balancing (Boyd et al. 2011, §3.4.1, eq. 3.13): ρ is multiplied by _RHO_STEP when the primal
#: residual exceeds _RHO_BALANCE times the dual one and divided by it in the opposite case, with each residual
#: taken as a fraction of its own tolerance (Wohlberg 2017, "ADMM penalty parameter selection by residual
#: balancing", arXiv:1704.06209): the two are in different units (K against ρK), and the test to meet is
#: eps_pri against eps_dual. Λ is unscaled here, so a new ρ needs no rescaling of it.
_RHO_BALANCE = 10.0
_RHO_STEP = 2.0
#: ρ never goes below the ``rho`` given (on the paper family a fixed ρ = 100 converges, and lowering it lets
#: the K-step's objective J + (ρ/2)‖K − U‖² lose its convexity, the source of the cycles below) nor above
#: _RHO_RANGE times it.
_RHO_RANGE = 1e6
#: A period-2 cycle: for _CYCLE_COUNT iterations in a row K_t comes back to K_{t−2} within _CYCLE_RTOL of
#: the step ‖K_t − K_{t−1}‖, a step larger than the primal tolerance. For K_t = K* + a(−r)^t the ratio is
#: (1 − r)/r, so this takes in oscillations damped by less than 9 % an iteration, which need 50 or more
#: iterations to shrink a hundredfold. Issue 60's cycle at ρ = 100 (paper seed 1, N = 6, ‖A‖ = 1.05,
#: γ = 3, second reweighting round): steps of 1.1, ‖K_t − K_{t−2}‖ falling from 0.08 to 1e-6 over 80
#: iterations.
_CYCLE_RTOL = 0.1
_CYCLE_COUNT = 5
#: A stall: both residuals unchanged to this relative amount over _STALL_WINDOW iterations. An iteration that
#: still moves does not keep them equal to 12 digits; a K-step that cannot move (no acceptable step) does.
_STALL_RTOL = 1e-12
_STALL_WINDOW = 20
#: A cycle or stall multiplies ρ by _RESCUE_STEP, and balancing may not bring ρ back below twice the value
#: that cycled: a larger ρ makes the K-step's objective convex where J's curvature is negative. The next
#: cycle or stall after _MAX_RESCUES of them stops the weighted solve at once, its message saying why.
_RESCUE_STEP = 10.0
_MAX_RESCUES = 3


def _kstep(instance, point, U, rho, *, tol, maxiter):
    """Minimize trace(P_K) + (rho/2)||K - U||² from a stabilizing point. Returns (point, iterations, solved).

    ``solved`` is False where the gradient norm is still above ``tol``: the iteration cap or a line search
    that found no acceptable step.
    """
    A, B, R = instance.A, instance.B, instance.R
    phi = point.J + 0.5 * rho * np.sum((point.K - U) ** 2)
    for it in range(maxiter):
        K, P, L = point.K, point.P, point.L
        grad = point.grad + rho * (K - U)
        if np.linalg.norm(grad) <= tol:
            return point, it, True
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
            return point, it + 1, False  # no acceptable step along this direction
        if step == 1.0:
            # The Anderson–Moore step overshoots where J bends away from its frozen-P model (near the
            # stability boundary it alternates about the minimum, each full step barely lowering φ):
            # the minimizer of the parabola through φ(0), φ'(0) and φ(1) then lies well short of 1,
            # and one more evaluation there is taken when it is lower.
            curvature = phi_trial - phi - slope
            short = -slope / (2.0 * curvature) if curvature > 0 else 1.0
            if _SHORT_STEP[0] <= short <= _SHORT_STEP[1]:
                better = infinite_horizon_point(instance, K + short * direction)
                if better is not None:
                    phi_better = better.J + 0.5 * rho * np.sum((better.K - U) ** 2)
                    if phi_better < phi_trial:
                        trial, phi_trial = better, phi_better
        point, phi = trial, phi_trial
    return point, maxiter, np.linalg.norm(point.grad + rho * (point.K - U)) <= tol


def _shrink(V, threshold):
    """Weighted soft-thresholding; ``threshold`` is zero on the diagonal."""
    return np.sign(V) * np.maximum(np.abs(V) - threshold, 0.0)


def _group_shrink(instance, V, threshold):
    """Weighted group soft-threshold of the node blocks; ``threshold`` (N, N) is zero on each node's own block."""
    norms = instance.block_norms(V)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(norms > threshold, 1.0 - threshold / norms, 0.0)
    return V * instance.expand_blocks(factor)


class _DiagonalEnd:
    """The decentralized gain as a point of the ADMM objective, and the γ above which it solves the ℓ1 problem.

    The ℓ1 optimality condition at a diagonal K_d (the diagonal is never penalized) is
    |∂J/∂K_ij| <= scale γ w_ij for every off-diagonal (i, j) (node blocks: ‖∂J/∂K_IJ‖_F <= scale γ w_IJ),
    so K_d (with G = K_d, Λ = -∇J) is a fixed point of the ADMM from that γ on:
    γ_max(W) = max_{i≠j} |∂J/∂K_ij| / (scale w_ij). K_d is :func:`baselines.decentralized`'s gain
    (optimal over diagonal gains for the benchmark's finite-horizon cost, a close stand-in for the
    infinite-horizon J the ADMM minimizes), which is also the design the path reports for a diagonal
    pattern. Computed once per path, from the path's own :class:`DecentralizedCache`.
    """

    def __init__(self, instance, decentral: DecentralizedCache):
        self.instance = instance
        self.decentral = decentral
        self._done = False
        self.point = None
        self.off = None  # (N, N) off-diagonal gradient magnitudes (entries or node blocks), zero diagonal

    def get(self):
        """``self`` once the diagonal point is known, or None where the instance has no stabilizing diagonal gain."""
        if not self._done:
            self._done = True
            diagonal = self.decentral.usable()
            point = None if diagonal is None else infinite_horizon_point(self.instance,
                                                                          np.array(diagonal.controller.K))
            if point is not None:
                grad = point.grad
                off = np.abs(grad) if self.instance.scalar_nodes else self.instance.block_norms(grad)
                off = off.copy()
                np.fill_diagonal(off, 0.0)
                self.point, self.off = point, off
        return None if self.point is None else self

    def answers(self, gamma, W, G) -> str:
        """Why the diagonal gain is this weighted solve's answer, or "" where the ADMM has to run.

        It is when K_d meets this round's ℓ1 conditions (γ >= γ_max(W)) and either γ >= γ_max of plain
        ℓ1 (where the ℓ1 solution is the diagonal pattern) or, with reweighting, the warm start G is
        diagonal already. The problem is not convex: from a warm start with links, the ADMM can end at
        a lower local minimum that keeps some of them (paper seed 0, N = 20, ‖A‖ = 1.05, γ = 0.1: one
        link, cost 1.397 against the diagonal's 1.558), so that case is left to the ADMM.
        """
        top, plain_top = self.gamma_max(W), self.gamma_max(np.where(W > 0, 1.0, 0.0))
        if gamma < top:
            return ""
        if gamma >= plain_top:
            return (f"gamma {gamma:.4g} >= gamma_max {plain_top:.4g}: the diagonal gain meets the l1 optimality "
                    "conditions (|dJ/dK_ij| <= gamma w_ij trace(P) off the diagonal), returned without iterating")
        if not np.any(G[~self.instance.block_mask()]):
            return (f"gamma {gamma:.4g} >= {top:.4g}, where the diagonal gain meets this round's reweighted l1 "
                    "optimality conditions, from a diagonal warm start: returned without iterating")
        return ""

    def gamma_max(self, W) -> float:
        """Smallest γ (normalized units) at which the diagonal gain meets the weighted ℓ1 conditions."""
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(self.off > 0, self.off / W, 0.0)
        return float(np.max(ratio)) / self.instance.trace_P


def admm_gamma_max(instance) -> float:
    """Smallest γ (normalized units) at which the best diagonal gain is stationary for plain ℓ1.

    At a diagonal K_d optimal over the diagonal, the subgradient condition of
    J(K)/trace(P) + γ Σ_{i≠j} |K_ij| holds exactly when
    γ ≥ max_{i≠j} |∇J(K_d)_ij| / trace(P). K_d is the decentralized gain of the
    benchmark (finite-horizon) cost, a close stand-in for the infinite-horizon one.
    Reweighting makes paths diagonal well below this value. :func:`sparse_admm`
    answers every γ at or above it with the diagonal gain, without iterating.

    Raises
    ------
    ValueError
        The instance has no stabilizing diagonal gain.
    """
    found = _DiagonalEnd(instance, DecentralizedCache(instance)).get()
    if found is None:
        raise ValueError("no stabilizing diagonal gain on this instance")
    W = np.ones((instance.nodes, instance.nodes))
    np.fill_diagonal(W, 0.0)
    return found.gamma_max(W)


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
        Initial ADMM penalty, in units of trace(P_K) (lqrsp's 100). ρ is then balanced
        (Boyd et al. 2011, §3.4.1: doubled while the primal residual is over 10 times
        the dual one, halved in the opposite case, each relative to its tolerance),
        never below this value, and raised tenfold when the iterates cycle or stall;
        it carries over from γ to γ.
    polish : bool
        Re-optimize the free entries of each pattern on the exact benchmark cost.
    eps_weight : float
        ε of the reweighting.
    tol : float
        Absolute ADMM tolerance per entry: stop when ‖K − G‖_F and ρ‖G − G_prev‖_F
        fall below ``n * tol`` plus 1e-2 times ‖K‖_F (resp. ‖Λ‖_F), lqrsp's test.
    kstep_tol : float
        The K-step stops when the gradient of its objective has norm below this
        times ρ / ``rho`` (the same accuracy in K as ρ grows).
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
        the K-steps that stopped above their tolerance (``kstep_unsolved``: their
        iteration cap or no acceptable step), the ρ changes and the last ρ
        (``rho_changes``, ``rho_final``), ``gamma_max`` (plain ℓ1) and
        ``gamma_max_weighted`` (the last round's weights), reweighting rounds,
        convergence, the polishing, the spectral radius and whether the previous
        γ's gain was kept (``fallback``). A γ answered by the diagonal gain without
        iterating, or a solve that stopped without converging, says so in its
        message.

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

    A weighted solve is answered by the diagonal gain K_d without iterating where K_d
    meets its ℓ1 optimality conditions, |∂J/∂K_ij| <= γ w_ij trace(P) off the diagonal,
    and either γ >= :func:`admm_gamma_max` (plain ℓ1) or the warm start is diagonal
    already; it then costs what :func:`baselines.decentralized` costs, once per path.
    Otherwise the ADMM runs until lqrsp's residual test holds, a cycle or stall
    persists after three tenfold raises of ρ, or ``maxiter``; a solve that stops
    without converging says why in the design's message, and where its G does not
    stabilize the γ is ``failed`` (the path then keeps the previous γ's gain).
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
    decentral = DecentralizedCache(instance)  # shared with the path: the diagonal gain is computed once
    diagonal = _DiagonalEnd(instance, decentral)
    plain = np.ones((instance.nodes, instance.nodes))
    np.fill_diagonal(plain, 0.0)

    def solve(state, gamma, W):
        point, G, Lam, rho_now = state
        found = diagonal.get()
        counts = {}
        if found is not None:
            counts = {"gamma_max": found.gamma_max(plain), "gamma_max_weighted": found.gamma_max(W)}
            note = found.answers(gamma, W, G)
            if note:
                # K = G = K_d, Λ = -∇J is the ADMM's fixed point: there is nothing to iterate.
                start = found.point
                counts.update(admm_iterations=0, kstep_iterations=0, kstep_unsolved=0, rho_changes=0,
                              rho_final=rho_now, message=note)
                return (start, start.K.copy(), -start.grad, rho_now), start.K.copy(), counts, True
        run = _admm(instance, point, G, Lam, scale * gamma * W, rho_now, rho0=float(rho), tol=tol,
                    kstep_tol=kstep_tol, maxiter=maxiter, blocks=blocks)
        counts.update(admm_iterations=run.iterations, kstep_iterations=run.kstep_iterations,
                      kstep_unsolved=run.kstep_unsolved, rho_changes=run.rho_changes, rho_final=run.rho)
        if run.message:
            counts["message"] = run.message
        return (run.point, run.G, run.Lam, run.rho), run.G, counts, run.converged

    return l1_path(instance, "sparse_admm", gammas, solve=solve,
                   start_state=(start_point, K.copy(), np.zeros((m, n)), float(rho)), base=base, reweight=reweight,
                   eps_weight=eps_weight, polish=polish, diagonal_end=diagonal_end, solver="admm",
                   solver_label="ADMM", converged_key="admm_converged", decentral=decentral)


class _Run(NamedTuple):
    """What one weighted ADMM solve ends with."""
    point: GainPoint
    G: np.ndarray
    Lam: np.ndarray
    rho: float
    iterations: int
    kstep_iterations: int
    kstep_unsolved: int   # K-steps that ended above kstep_tol (iteration cap or no acceptable step)
    rho_changes: int
    converged: bool
    message: str          # why it stopped without converging ("" when it converged)


def _admm(instance, point, G, Lam, penalty, rho, *, rho0, tol, kstep_tol, maxiter, blocks=False) -> _Run:
    """ADMM on K = G from a warm start, ρ balanced, cycles and stalls acted on.

    ``penalty`` is the ℓ1 weight in the units of J (scale γ W): the G-step's threshold is penalty / ρ,
    recomputed whenever ρ changes. Λ is the unscaled dual variable, so a new ρ needs no rescaling of it
    (Boyd et al. 2011, §3.4.1, rescale the scaled one, u = Λ/ρ). Stops on lqrsp's primal/dual residual test
    with absolute tolerance ``tol`` (per entry) and relative tolerance :data:`_REL_TOL`.
    """
    size = np.sqrt(G.size)
    floor, ceiling = rho0, rho0 * _RHO_RANGE
    kstep_iters = unsolved = changes = rescues = flips = 0
    previous = []  # K_{t-1}, K_{t-2}
    history = deque(maxlen=_STALL_WINDOW)  # (primal, dual)
    primal = dual = eps_pri = eps_dual = np.nan
    for it in range(1, maxiter + 1):
        # The gradient tolerance grows with ρ: the K-step's objective is ρ-strongly convex where ρ outweighs
        # J's curvature, so ‖gradient‖/ρ bounds its error in K, kept at what it is at the given ρ.
        point, its, solved = _kstep(instance, point, G - Lam / rho, rho, tol=kstep_tol * rho / rho0,
                                    maxiter=_KSTEP_MAXITER)
        kstep_iters += its
        unsolved += not solved
        K = point.K
        V = K + Lam / rho
        G_new = _group_shrink(instance, V, penalty / rho) if blocks else _shrink(V, penalty / rho)
        dual = rho * np.linalg.norm(G_new - G)
        G = G_new
        primal = np.linalg.norm(K - G)
        Lam = Lam + rho * (K - G)
        eps_pri = size * tol + _REL_TOL * max(np.linalg.norm(K), np.linalg.norm(G))
        eps_dual = size * tol + _REL_TOL * np.linalg.norm(Lam)
        if primal < eps_pri and dual < eps_dual:
            return _Run(point, G, Lam, rho, it, kstep_iters, unsolved, changes, True, "")
        trouble = ""
        if len(previous) == 2:
            step = np.linalg.norm(K - previous[0])
            back = np.linalg.norm(K - previous[1])
            flips = flips + 1 if step > eps_pri and back <= _CYCLE_RTOL * step else 0
            if flips >= _CYCLE_COUNT:
                trouble = (f"a period-2 cycle (|K_t - K_t-2| = {back:.2g} while |K_t - K_t-1| = {step:.2g}, "
                           f"primal residual {primal:.3g}, dual {dual:.3g})")
        history.append((primal, dual))
        if not trouble and len(history) == _STALL_WINDOW and all(
                abs(p - primal) <= _STALL_RTOL * primal and abs(d - dual) <= _STALL_RTOL * dual for p, d in history):
            trouble = (f"a stall (primal residual {primal:.3g} and dual {dual:.3g} unchanged to 1e-12 over "
                       f"{_STALL_WINDOW} iterations)")
        if trouble:
            if rescues == _MAX_RESCUES or rho * _RESCUE_STEP > ceiling:
                return _Run(point, G, Lam, rho, it, kstep_iters, unsolved, changes, False,
                            f"ADMM stopped at iteration {it} on {trouble}, after raising rho {rescues} times "
                            f"(now {rho:.3g})")
            rescues += 1
            changes += 1
            floor = rho * _RHO_STEP  # balancing may lower ρ again, but not back to where it cycled
            rho *= _RESCUE_STEP
            flips = 0
            previous.clear()
            history.clear()
            continue
        previous = [K, *previous[:1]]
        # Residual balancing, each residual as a fraction of its tolerance.
        ratio = (primal / eps_pri) / (dual / eps_dual) if dual > 0 else np.inf
        if ratio > _RHO_BALANCE and rho * _RHO_STEP <= ceiling:
            rho *= _RHO_STEP
            changes += 1
        elif ratio < 1.0 / _RHO_BALANCE and rho / _RHO_STEP >= floor:
            rho /= _RHO_STEP
            changes += 1
    return _Run(point, G, Lam, rho, maxiter, kstep_iters, unsolved, changes, False,
                f"ADMM stopped at its iteration limit ({maxiter}) with primal residual {primal:.3g} "
                f"(tolerance {eps_pri:.3g}) and dual {dual:.3g} (tolerance {eps_dual:.3g}), rho {rho:.3g}")
