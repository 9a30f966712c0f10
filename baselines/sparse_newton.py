"""Sparse static gains by proximal Newton on the ℓ1-regularized cost (after Wytock & Kolter 2013).

The problem, the γ grid, the reweighting and the polishing are those of
:func:`baselines.sparse_admm` (lqrsp's): for each γ, minimize

    F(K) = J(K) / trace(P) + γ Σ_{i≠j} w_ij |K_ij|,   J(K) = trace(P_K),

over static gains ``u = K x``. Only the weighted solve differs. Where ADMM splits
K = G and needs a hundred or more K-steps per γ, each a dense Lyapunov-type
solve, a proximal Newton step models the smooth part by its gradient and the
curvature

    c · 2 (R + B'PB) ⊗ L / trace(P),   L = A_cl L A_cl' + I,

the exact Hessian of J at the LQR gain (its Gauss–Newton part elsewhere), scaled
by c ≥ 1, which doubles whenever the model promised more than the step delivered
and halves back when it was right. The model plus the ℓ1 term is minimized over
a working set of entries (the gain's nonzeros, the diagonal and the entries whose
gradient comes within half of their threshold) by FISTA with adaptive restart,
each FISTA iteration one product ``(R + B'PB) E L`` restricted to the working set:
O(nnz · n) rather than O(n^3) once the gain is sparse. A backtracking line search
on F accepts only stabilizing gains. A weighted solve ends when no entry violates
the ℓ1 optimality conditions by more than ``tol`` times the smallest weight γ w_ij:
a handful to a few dozen Newton steps per solve, each one evaluation of J and its
gradient by doubling (0.7 s at n = 1000).

The entries come out exactly zero from the soft threshold, so the pattern of γ is
the gain's own. Where nodes hold several states or inputs the penalty is ADMM's group
ℓ1 over node blocks, γ Σ w_IJ ‖K_IJ‖_F, with the group soft-threshold as FISTA's step.

On the paper's family the patterns are ADMM's up to a few entries near their
threshold, because ADMM stops at lqrsp's 1 % relative residual: run to a tight
tolerance, ADMM meets this path. ``benchmarks/bench_sparse_newton.py``
prints the agreement and the times at N = 20, 50 and 100.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from codesign.evaluation import STRUCTURED_ABOVE, spectral_radius
# The static cost's masked-product blocks, reused rather than restated; the evaluation code is
# in every method's fingerprint, so it is extended here, not there.
from codesign.evaluation import MaskedProduct
from codesign.methods import Above, AtLeast, NotEmpty, method

from ._sparse import check_gammas, infinite_horizon_point, l1_path
from .sparse_admm import ADMM_GAMMAS
from .stabilizing import is_stable, unstable_note

__all__ = ["sparse_newton"]

_ARMIJO = 1e-4          # sufficient-decrease constant of the line search
_BACKTRACK = 0.5
_MAX_BACKTRACKS = 40
_WORKING_MARGIN = 0.5   # an entry joins the working set when |gradient| > this x its threshold
_INNER_RTOL = 1e-3      # FISTA stops when its gradient map is this fraction of the first one
_INNER_MAXITER = 2000
_DENSE_WORK = 0.25      # a working set with more than this fraction of the entries takes dense products
_GROW, _SHRINK = 0.25, 0.75  # ratios (achieved / predicted) that double / halve the curvature scale

#: Largest size run through the registry (measured 2026-11-26, one thread: see docs/performance.md).
MAX_STATES = 1000
MAX_STATES_REASON = ("each Newton step evaluates the infinite-horizon cost by dense doubling (0.7 s at 1000 "
                     "states, 8x that at 2000), and the path's few hundred steps were measured up to 1000")


class _WorkingSetProduct(MaskedProduct):
    def entries(self, M: np.ndarray, S: np.ndarray) -> np.ndarray:
        """The entries of ``M @ S`` on the mask (S symmetric), in ``np.nonzero(mask)`` order."""
        if self.full:
            return (M @ S)[self.rows, self.cols]
        out = np.zeros(self.shape)
        for rows, cols, local_rows, local_cols in self.blocks:
            out[rows[local_rows], cols[local_cols]] = (M[rows] @ S[cols].T)[local_rows, local_cols]
        return out[self.rows, self.cols]


class _Curvature:
    """``(R + B'PB) E L`` on a working set of entries, as a vector in the set's order."""

    def __init__(self, Rm, L, rows, cols, shape):
        self.Rm, self.L, self.rows, self.cols, self.shape = Rm, L, rows, cols, shape
        self.dense = shape[1] <= STRUCTURED_ABOVE or len(rows) > _DENSE_WORK * shape[0] * shape[1]
        if not self.dense:
            mask = np.zeros(shape, dtype=bool)
            mask[rows, cols] = True
            self.product = _WorkingSetProduct(mask)

    def apply(self, e: np.ndarray) -> np.ndarray:
        if self.dense:
            E = np.zeros(self.shape)
            E[self.rows, self.cols] = e
            return (self.Rm @ E @ self.L)[self.rows, self.cols]
        import scipy.sparse

        # Rm E = (E' Rm)' with E sparse: scipy multiplies a sparse matrix from the left only.
        Et = scipy.sparse.csr_array((e, (self.cols, self.rows)), shape=self.shape[::-1])
        return self.product.entries(np.asarray(Et @ self.Rm).T, self.L)


def _largest_eigenvalue(S) -> float:
    import scipy.linalg

    n = S.shape[0]
    return float(scipy.linalg.eigh(S, eigvals_only=True, subset_by_index=[n - 1, n - 1])[0])


class _EntryPenalty:
    """``Σ t_ij |K_ij|``: one state and one input per node, a threshold per entry (zero on the diagonal)."""

    def __init__(self, threshold):
        self.threshold = threshold

    def value(self, K) -> float:
        return float(np.sum(self.threshold * np.abs(K)))

    def residual(self, g, K) -> float:
        t = self.threshold
        return float(np.abs(np.where(K != 0, g + t * np.sign(K), np.maximum(np.abs(g) - t, 0.0))).max())

    def working(self, g, K) -> np.ndarray:
        t = self.threshold
        return (K != 0) | (np.abs(g) > _WORKING_MARGIN * t) | (t == 0)

    def smallest(self) -> float:
        positive = self.threshold[self.threshold > 0]
        return positive.min() if positive.size else 1e-12

    def on(self, rows, cols):
        return _EntrySet(self.threshold[rows, cols])


class _EntrySet:
    """The entry penalty on a working set's vector of entries."""

    def __init__(self, tw):
        self.tw = tw

    def prox(self, z, lipschitz):
        return np.sign(z) * np.maximum(np.abs(z) - self.tw / lipschitz, 0.0)

    def change(self, d, k0):
        return self.tw @ (np.abs(d) - np.abs(k0))


class _BlockPenalty:
    """``Σ t_IJ ‖K_IJ‖_F`` over node blocks (inputs of node I by states of node J), t zero on own blocks."""

    def __init__(self, instance, threshold):
        self.instance, self.threshold = instance, threshold
        N = instance.nodes
        self.group = instance.input_nodes[:, None] * N + instance.state_nodes[None, :]

    def value(self, K) -> float:
        return float(np.sum(self.threshold * self.instance.block_norms(K)))

    def residual(self, g, K) -> float:
        inst, t = self.instance, self.threshold
        norms = inst.block_norms(K)
        with np.errstate(divide="ignore", invalid="ignore"):
            toward = np.where(inst.expand_blocks(norms) > 0, K * inst.expand_blocks(t / norms), 0.0)
        on = inst.block_norms(g + toward)
        off = np.maximum(inst.block_norms(g) - t, 0.0)
        return float(np.where(norms > 0, on, off).max())

    def working(self, g, K) -> np.ndarray:
        inst, t = self.instance, self.threshold
        blocks = (inst.block_norms(K) > 0) | (inst.block_norms(g) > _WORKING_MARGIN * t) | (t == 0)
        return inst.expand_blocks(blocks)

    def smallest(self) -> float:
        positive = self.threshold[self.threshold > 0]
        return positive.min() if positive.size else 1e-12

    def on(self, rows, cols):
        groups, index = np.unique(self.group[rows, cols], return_inverse=True)
        return _BlockSet(index, self.threshold.ravel()[groups])


class _BlockSet:
    """The block penalty on a working set's vector of entries (whole blocks): group soft-thresholds."""

    def __init__(self, index, tg):
        self.index, self.tg = index, tg

    def _norms(self, v):
        return np.sqrt(np.bincount(self.index, v * v, minlength=self.tg.size))

    def prox(self, z, lipschitz):
        norms = self._norms(z)
        with np.errstate(divide="ignore", invalid="ignore"):
            factor = np.where(norms > self.tg / lipschitz, 1.0 - self.tg / lipschitz / norms, 0.0)
        return z * factor[self.index]

    def change(self, d, k0):
        return self.tg @ (self._norms(d) - self._norms(k0))


def _model_step(instance, point, penalty, scale, c):
    """Minimize the model ``g·E + (c/scale) tr(E' Rm E L) + penalty(K + E)`` over the working set.

    Returns (new gain, predicted change of F, its linear-plus-ℓ1 part Δ, FISTA iterations).
    """
    K = point.K
    g = point.grad / scale
    Rm = instance.R + instance.B.T @ point.P @ instance.B
    Rm = (Rm + Rm.T) / 2
    L = (point.L + point.L.T) / 2
    rows, cols = np.nonzero(penalty.working(g, K))
    curvature = _Curvature(Rm, L, rows, cols, K.shape)
    k0, gw, on_set = K[rows, cols], g[rows, cols], penalty.on(rows, cols)
    weight = 2.0 * c / scale
    lipschitz = 1.01 * weight * _largest_eigenvalue(Rm) * _largest_eigenvalue(L)

    def changes(d):
        e = d - k0
        delta = float(gw @ e + on_set.change(d, k0))
        return delta, delta + 0.5 * weight * float(e @ curvature.apply(e))

    d = k0.copy()
    y, t, first, d_first = d.copy(), 1.0, None, None
    for it in range(1, _INNER_MAXITER + 1):
        z = y - (gw + weight * curvature.apply(y - k0)) / lipschitz
        d_new = on_set.prox(z, lipschitz)
        gap = np.linalg.norm(d_new - y) * lipschitz
        if first is None:
            first, d_first = gap, d_new
        if np.dot(y - d_new, d_new - d) > 0:  # adaptive restart (O'Donoghue & Candès)
            t = 1.0
        t_new = (1.0 + np.sqrt(1.0 + 4.0 * t * t)) / 2.0
        y = d_new + ((t - 1.0) / t_new) * (d_new - d)
        d, t = d_new, t_new
        if gap <= _INNER_RTOL * first:
            break
    delta, predicted = changes(d)
    if predicted >= 0 and d_first is not None:
        # FISTA is not monotone: where it ends above the model's value at K, the first
        # (proximal gradient) step, which never is, stands in.
        d = d_first
        delta, predicted = changes(d)
    K_new = np.zeros_like(K)
    K_new[rows, cols] = d
    return K_new, predicted, delta, it


def _objective(point, penalty, scale) -> float:
    return point.J / scale + penalty.value(point.K)


def optimality_residual(point, penalty, scale) -> float:
    """Largest violation of the ℓ1 optimality conditions of F at ``point`` (∇ of ``J / scale``).

    Entries: ``∇_ij = -t_ij sign(K_ij)`` where ``K_ij ≠ 0``, ``|∇_ij| <= t_ij`` where
    ``K_ij = 0``; node blocks: ``∇_IJ = -t_IJ K_IJ / ‖K_IJ‖`` and ``‖∇_IJ‖ <= t_IJ``.
    """
    return penalty.residual(point.grad / scale, point.K)


def _prox_newton(instance, point, penalty, *, tol, maxiter):
    """Minimize F from a stabilizing point; returns (point, counts, converged).

    Converged: no entry violates the optimality conditions by more than ``tol`` times the
    smallest positive threshold, the scale at which an entry's pattern is decided.
    """
    scale = instance.trace_P
    target = tol * penalty.smallest()
    F = _objective(point, penalty, scale)
    c = 1.0
    counts = {"newton_iterations": 0, "inner_iterations": 0, "evaluations": 0}
    for _ in range(maxiter):
        if optimality_residual(point, penalty, scale) <= target:
            return point, counts, True
        K_model, predicted, delta, inner = _model_step(instance, point, penalty, scale, c)
        counts["inner_iterations"] += inner
        if not predicted < 0:
            return point, counts, False  # the model sees no decrease left (round-off)
        direction = K_model - point.K
        step = 1.0
        for _ in range(_MAX_BACKTRACKS):
            trial = infinite_horizon_point(instance, point.K + step * direction)
            counts["evaluations"] += 1
            if trial is not None:  # unstable trial gains are never accepted
                F_trial = _objective(trial, penalty, scale)
                if F_trial <= F + _ARMIJO * step * delta:
                    break
            step *= _BACKTRACK
        else:
            return point, counts, False  # no acceptable step along this direction
        counts["newton_iterations"] += 1
        ratio = (F_trial - F) / predicted
        if step < 1.0 or ratio < _GROW:
            c *= 2.0
        elif ratio > _SHRINK:
            c = max(1.0, c / 2.0)
        point, F = trial, F_trial
    return point, counts, optimality_residual(point, penalty, scale) <= target


@method("sparse_newton", label="Sparse K (l1 prox-Newton)", node_blocks=True, max_states=MAX_STATES,
        max_states_reason=MAX_STATES_REASON)
def sparse_newton(
    instance,
    *,
    gammas: Annotated[list[Annotated[float, AtLeast(0)]], NotEmpty()] | None = None,
    reweight: Annotated[int, AtLeast(1)] = 3,
    polish: bool = True,
    eps_weight: Annotated[float, Above(0)] = 1e-3,
    tol: Annotated[float, Above(0)] = 1e-3,
    maxiter: Annotated[int, AtLeast(1)] = 100,
    start: list | None = None,
    diagonal_end: bool = True,
):
    """Sparse static gains along a γ path by proximal Newton on the ℓ1-regularized cost, polished on their patterns.

    The path of :func:`baselines.sparse_admm` (same objective, γ units, reweighting
    and polishing) with a second-order weighted solve; see the module's docstring.

    Parameters
    ----------
    instance : Instance
    gammas : list of float, optional
        Sparsity weights in units of the normalized cost; sorted increasing.
        Default: :data:`baselines.ADMM_GAMMAS` (10 values, 1e-6 to 0.1).
    reweight : int
        Weighted ℓ1 solves per γ; after each, ``w_ij = 1/(|K_ij| + eps_weight)``,
        stopping early once the weights settle. The weights carry over to the next γ.
    polish : bool
        Re-optimize the free entries of each pattern on the exact benchmark cost.
    eps_weight : float
        ε of the reweighting.
    tol : float
        A weighted solve stops when no entry violates the ℓ1 optimality conditions
        (``∇_ij = -γ w_ij sign(K_ij)`` on the pattern, ``|∇_ij| <= γ w_ij`` off it) by
        more than ``tol`` times the smallest weight ``γ w_ij``.
    maxiter : int
        Newton steps per weighted solve.
    start : array_like, shape (n, n), optional
        Stabilizing gain (``u = K x``) to start the path from; LQR by default.
    diagonal_end : bool
        Close the path with the decentralized gain as its γ → ∞ point.

    Returns
    -------
    list of Design
        One per γ (``params = {"gamma": γ, "reweight": ...}``), then the γ = inf end,
        information model ``instantaneous``. Extras record the Newton steps, FISTA
        iterations and cost evaluations of the γ, the reweighting rounds, convergence,
        the polishing, the spectral radius and whether the previous γ's gain was kept
        (``fallback``).

    Raises
    ------
    ValueError
        Negative or non-finite γ, non-positive ε/tol, or a start that is not a
        stabilizing (m, n) gain.
    """
    n, m = instance.n, instance.m
    gammas = check_gammas(ADMM_GAMMAS if gammas is None else gammas)
    for label, value in (("eps_weight", eps_weight), ("tol", tol)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{label} must be a positive number, got {value!r}")
    for label, value in (("reweight", reweight), ("maxiter", maxiter)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{label} must be a positive integer, got {value!r}")
    K = np.array(instance.K_lqr if start is None else start, dtype=float)
    if K.shape != (m, n) or not np.all(np.isfinite(K)):
        raise ValueError(f"start must be a finite ({m}, {n}) gain, got shape {K.shape}")
    evaluated = infinite_horizon_point(instance, K)
    radius = spectral_radius(instance.A + instance.B @ K)
    if evaluated is None or not is_stable(radius, instance):
        raise ValueError(f"start gain does not stabilize the instance ({unstable_note(radius, instance=instance)}); "
                         "the path needs a stabilizing start")

    def solve(point, gamma, W):
        thresholds = gamma * W
        penalty = _EntryPenalty(thresholds) if instance.scalar_nodes else _BlockPenalty(instance, thresholds)
        point, counts, ok = _prox_newton(instance, point, penalty, tol=tol, maxiter=maxiter)
        return point, point.K, counts, ok

    return l1_path(instance, "sparse_newton", gammas, solve=solve, start_state=evaluated,
                   base={"reweight": int(reweight)}, reweight=reweight, eps_weight=eps_weight, polish=polish,
                   diagonal_end=diagonal_end, solver="prox_newton", solver_label="proximal Newton",
                   converged_key="newton_converged")
