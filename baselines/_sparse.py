"""What the sparse static-gain methods share: from a raw gain to a scored design.

Every sparse method (ADMM, SDP, truncation) ends the same way: fix the pattern
of the gain it found (diagonal always free, since local feedback needs no link),
polish the free entries on the exact finite-horizon benchmark cost, check that
the result stabilizes, and score it exactly. Where the polish from the method's
gain does not stabilize, the shared stabilizing search (:mod:`baselines.stabilizing`)
goes on from the decentralized gain and its own starts; a pattern is ``diverged``
only when none of them stabilizes. The diagonal pattern is the decentralized design,
so it is taken from :func:`baselines.decentralized`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, NamedTuple

import numpy as np

from codesign.controllers import StaticGain
from codesign.design import Design, Timer, count_links
from codesign.evaluation import spectral_radius, static_gain_cost, static_gain_cost_and_grad
from codesign.status import DIVERGED, FAILED, INACCURATE, OPTIMAL, USABLE

from .lqr import decentralized
from .polish import GRAD_RTOL
from .stabilizing import is_stable, stabilizing_gain, unstable_note

__all__ = ["GRAD_RTOL", "check_gammas", "pattern_of", "polished_gain", "gain_design",
           "as_path_point", "design_on_pattern", "with_diagonal_end", "DecentralizedCache",
           "GainPoint", "infinite_horizon_point", "l1_path", "pattern_starts"]

_DOUBLINGS = 60        # A_cl^(2^60): only a gain at the stability boundary needs more
_POWER_TOL = 1e-12     # max |A_cl^(2^k)| below which the remaining terms are negligible
_WEIGHTS_SETTLED = 1e-2  # reweighting stops when the weights move less than this (relative)


class GainPoint(NamedTuple):
    """A stabilizing gain with its infinite-horizon cost J = trace(P Σ₀), P, L and ∇J."""
    K: np.ndarray
    J: float
    P: np.ndarray
    L: np.ndarray
    grad: np.ndarray


def infinite_horizon_point(instance, K) -> GainPoint | None:
    """J(K) = trace(P_K Σ₀) and its gradient, or None when u = Kx does not stabilize.

    P = A_cl' P A_cl + Q + K'RK and L = A_cl L A_cl' + Σ₀ are summed by doubling
    (Smith's squared iteration): both series share the powers A_cl^(2^k), and the
    powers' decay doubles as the stability test, so a trial gain costs a few
    dozen products instead of two Schur-based Lyapunov solves and an eigenvalue
    problem (0.7 s at n = 1000, where scipy's Lyapunov solver takes 16 s).
    ∇J = 2[(R + B'PB)K + B'PA] L. This is the objective of both ℓ1 paths
    (lqrsp's, with the initial-state covariance Σ₀, the identity unless the instance
    sets ``x0_cov``, in the role of B₁B₁').
    """
    A, B, R = instance.A, instance.B, instance.R
    M = A + B @ K
    P = instance.Q + K.T @ R @ K
    L = np.array(instance.x0_covariance)
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(_DOUBLINGS):
            P = P + M.T @ P @ M
            L = L + M @ L @ M.T
            M = M @ M
            size = np.abs(M).max()
            if not np.isfinite(size):
                return None
            if size < _POWER_TOL:
                break
        else:
            return None  # too close to (or past) the stability boundary to sum
    BtP = B.T @ P
    grad = 2.0 * ((R + BtP @ B) @ K + BtP @ A) @ L
    return GainPoint(K, instance.x0_mean(P), P, L, grad)


def check_gammas(gammas) -> np.ndarray:
    """Validate a user's weight grid: finite, non-negative, sorted increasing."""
    try:
        values = np.array(gammas, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"gammas must be a list of numbers: {exc}") from None
    if values.size == 0:
        raise ValueError("gammas must hold at least one value")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"gammas must be finite, got {values.tolist()}")
    if np.any(values < 0):
        raise ValueError(f"gammas must be non-negative, got {values.tolist()}")
    # Warm starts only make sense along an increasing grid.
    return np.sort(values)


def pattern_of(K, instance=None) -> np.ndarray:
    """Free entries for polishing: the nonzeros of K plus the diagonal (each node's own block)."""
    mask = np.asarray(K) != 0
    if instance is None or instance.scalar_nodes:
        np.fill_diagonal(mask, True)
        return mask
    return mask | instance.block_mask()


def masked_grad_norm(instance, K, mask) -> tuple[float, float]:
    """(normalized cost, norm of its gradient restricted to ``mask``, the only entries computed)."""
    cost, grad = static_gain_cost_and_grad(instance, K, mask=mask)
    return cost, float(np.linalg.norm(grad[mask]))


def pattern_starts(decentral: "DecentralizedCache | None") -> list:
    """The stabilizing search's first fallback on a pattern: the decentralized gain, where it stabilizes.

    Every pattern frees each node's own block, so that gain is a point of it, and a
    stabilizing one: polishing from it gives a stabilizing gain wherever the descent
    stays stable, at a cost no higher than the diagonal gain's.
    """
    diagonal = None if decentral is None else decentral.usable()
    return [] if diagonal is None else [("decentralized", np.array(diagonal.controller.K))]


def polished_gain(instance, K, mask, *, polish: bool = True,
                  decentral: "DecentralizedCache | None" = None) -> tuple[np.ndarray, dict]:
    """Polish ``K`` on ``mask`` (or not) and report what happened.

    The polish is the stabilizing search (:func:`baselines.stabilizing.stabilizing_gain`)
    from ``K``, then, where that minimum does not stabilize, from the decentralized gain
    (``decentral``) and the search's own starts. Returns the gain and extras with
    ``grad_norm`` (masked, of the normalized cost), ``polish_iterations`` and
    ``polish_message``, and, where a later start gave the gain, ``polish_start`` (its
    name) and ``polish_starts`` (the starts polished).
    """
    K = np.where(mask, K, 0.0)
    if not polish:
        _, grad_norm = masked_grad_norm(instance, K, mask)
        return K, {"grad_norm": grad_norm, "polish_iterations": 0, "polish_message": "not polished"}
    found = stabilizing_gain(instance, mask, [("given", K)] + pattern_starts(decentral))
    result = found.result
    extras = {"grad_norm": result.grad_norm, "polish_iterations": result.iterations,
              "polish_message": result.message}
    if found.tried > 1:
        extras.update(polish_start=found.start, polish_starts=found.tried)
    return result.K, extras


def gain_design(instance, method: str, params: dict, K, *, seconds: float, extras: dict,
                polished: bool, status: str = OPTIMAL, message: str = "") -> Design:
    """A :class:`Design` for the static gain ``u = K x``, scored exactly.

    A polished gain whose masked gradient is not below :data:`GRAD_RTOL` times its
    cost is flagged ``inaccurate``; a gain that does not stabilize
    (:func:`baselines.stabilizing.is_stable`) is recorded as ``diverged`` (no cost),
    never returned as a number.
    """
    K = np.asarray(K, dtype=float)
    radius = spectral_radius(instance.A + instance.B @ K)
    links, self_loops = count_links(instance.node_support(K))
    extras = {**extras, "spectral_radius": radius}
    if not is_stable(radius, instance):
        return Design.failure(method, params, DIVERGED,
                              f"gain does not stabilize ({unstable_note(radius, instance=instance)}); "
                              f"{message}".rstrip("; "),
                              info_model="instantaneous", seconds=seconds, links=links,
                              self_loops=self_loops, extras=extras)
    cost = static_gain_cost(instance, K)
    if polished and status == OPTIMAL and not extras.get("grad_norm", 0.0) < GRAD_RTOL * cost:
        status = INACCURATE
        message = (f"{message}; " if message else "") + (
            f"polishing stopped at masked gradient norm {extras['grad_norm']:.3g} "
            f"(> {GRAD_RTOL:g} x cost): {extras.get('polish_message', '')}")
    return Design(
        method=method,
        params=dict(params),
        controller=StaticGain(K),
        cost=cost,
        links=links,
        self_loops=self_loops,
        # Kept for the zero-link end too, so that a path is one series on the plot.
        info_model="instantaneous",
        status=status,
        message=message,
        seconds=seconds,
        extras=extras,
    )


def as_path_point(design, method: str, params: dict, extras: dict, message: str = "") -> Design:
    """An existing design (the decentralized gain, a previous γ's gain) as a point of a path."""
    return replace(design, method=method, params=dict(params), info_model="instantaneous",
                   extras={**design.extras, **extras}, message=message or design.message)


def design_on_pattern(instance, method: str, params: dict, K, *, extras: dict, polish: bool,
                      decentral: "DecentralizedCache") -> Design:
    """Polish ``K`` on its own pattern (diagonal always free) and score it.

    A diagonal pattern is the decentralized design, taken from
    :func:`baselines.decentralized` (its failure, where that found no stabilizing gain).
    """
    mask = pattern_of(K, instance)
    if not (mask & ~instance.block_mask()).any():
        diagonal = decentral.usable()
        if diagonal is not None:
            return as_path_point(diagonal, method, params, {**extras, "decentralized": True})
        if polish:  # the decentralized search already tried every start this one would
            found = decentral.get()
            return Design.failure(method, params, found.status, found.message, info_model="instantaneous",
                                  extras={**found.extras, **extras, "decentralized": True})
    gain, polish_extras = polished_gain(instance, K, mask, polish=polish, decentral=decentral)
    return gain_design(instance, method, params, gain, seconds=0.0, extras={**extras, **polish_extras},
                       polished=polish)


def with_diagonal_end(designs: list, method: str, base: dict, decentral: "DecentralizedCache") -> list:
    """Close a path at γ → ∞ with the decentralized gain (``params["gamma"] = inf``).

    Every path gets this point, even one already diagonal at its largest γ, so that
    reports aggregating a γ over instances see the same points for every instance.
    A path with no usable design (an infeasible SDP, say) is left as it is: its
    γ → ∞ limit is just as infeasible.
    """
    # The end point's seconds are what finding the diagonal gain costs here: nothing where an
    # earlier γ's timer already paid for it (the decentralized design's own seconds would count
    # it twice, and the path's seconds then exceeded its run's wall time).
    with Timer() as timer:
        diagonal = decentral.usable()
    if diagonal is None or not any(d.status in USABLE for d in designs):
        return designs
    params = {**base, "gamma": float("inf")}
    point = as_path_point(diagonal, method, params, {"solver": "decentralized", "decentralized": True})
    return designs + [replace(point, seconds=float(timer.seconds))]


class DecentralizedCache:
    """The best diagonal gain of an instance, computed once per path."""

    def __init__(self, instance):
        self.instance = instance
        self._design = None

    def get(self) -> Design:
        if self._design is None:
            self._design = decentralized(self.instance)
        return self._design

    def usable(self) -> Design | None:
        """The decentralized design if it has a stabilizing gain, else None."""
        design = self.get()
        if design.status not in USABLE or not is_stable(design.extras.get("spectral_radius", np.inf)):
            return None
        return design


#: What a weighted ℓ1 solver of :func:`l1_path` returns: its new state, the sparse gain whose
#: pattern the γ stands for, extras (iteration counts, added over reweighting rounds; other values,
#: the last round's; an optional ``"message"`` for the design) and whether it converged.
WeightedSolve = Callable[[object, float, np.ndarray], tuple[object, np.ndarray, dict, bool]]


def l1_path(instance, method: str, gammas, *, solve: WeightedSolve, start_state, base: dict, reweight: int,
            eps_weight: float, polish: bool, diagonal_end: bool, solver: str, solver_label: str,
            converged_key: str, decentral: "DecentralizedCache | None" = None) -> list:
    """The reweighted ℓ1 path shared by the static-gain solvers (ADMM, proximal Newton).

    For each γ (increasing), up to ``reweight`` weighted solves ``solve(state, γ, W)``, after
    each ``w_ij = 1/(|G_ij| + eps_weight)`` (block norms with node blocks), stopping early once
    the weights settle; the weights carry over to the next γ, as in lqrsp, and the first solve
    of the path is plain ℓ1. Each γ's gain is polished on its pattern and scored; a γ whose gain
    does not give a usable design keeps the previous γ's (``fallback``), and the solver state
    restarts from ``start_state`` when there is none.

    The solver's extras are added over the rounds where they are counts (ints) and are the last
    round's otherwise; a ``"message"`` among them (why the solve stopped, or how it was answered) goes
    into the design's message, and where the solver stopped for a stated reason and its gain does not
    stabilize the γ is ``failed`` with that reason, not ``diverged``. ``decentral`` lets a solver share
    the path's diagonal gain (computed once).
    """
    N = instance.nodes
    blocks = not instance.scalar_nodes
    decentral = DecentralizedCache(instance) if decentral is None else decentral
    state = start_state
    W = np.ones((N, N))
    np.fill_diagonal(W, 0.0)
    previous = None  # (design, state, W) of the last γ with a usable design
    designs = []
    for gamma in gammas:
        params = {**base, "gamma": float(gamma)}
        with Timer() as timer:
            counts: dict = {}
            converged = True
            rounds = 0
            note = ""
            for rounds in range(1, reweight + 1):
                state, G, its, ok = solve(state, gamma, W)
                its = dict(its)
                note = str(its.pop("message", ""))  # the last round's, as its G is the one used
                for key, value in its.items():
                    counted = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
                    counts[key] = counts.get(key, 0) + value if counted else value
                converged &= ok
                W_new = 1.0 / ((instance.block_norms(G) if blocks else np.abs(G)) + eps_weight)
                np.fill_diagonal(W_new, 0.0)
                settled = np.linalg.norm(W_new - W) < _WEIGHTS_SETTLED * np.linalg.norm(W)
                W = W_new
                if settled:
                    break
            extras = {"solver": solver, **counts, "reweight_rounds": rounds, converged_key: bool(converged),
                      "fallback": False}
            design = None
            failure = DIVERGED
            if is_stable(spectral_radius(instance.A + instance.B @ G), instance):
                design = design_on_pattern(instance, method, params, G, extras=extras, polish=polish,
                                           decentral=decentral)
                if note:
                    design = replace(design, message="; ".join(m for m in (note, design.message) if m))
                why = design.message
            else:
                why = f"the sparse gain G found by {solver_label} does not stabilize"
                if note:  # the solver stopped for a reason it names: that, not the gain, is the failure
                    failure, why = FAILED, f"{note}; its sparse gain G does not stabilize"
            if design is not None and design.status in USABLE:
                previous = (design, state, W.copy())
            elif previous is not None:
                # Keep the previous γ's solution and continue the path from it.
                prev_design, state, W = previous
                design = as_path_point(prev_design, method, params, {**extras, "fallback": True},
                                       f"kept the previous gamma's gain: {why}")
            else:
                state = start_state
                design = Design.failure(method, params, failure, why, info_model="instantaneous", extras=extras)
        designs.append(replace(design, seconds=float(timer.seconds)))
    return with_diagonal_end(designs, method, base, decentral) if diagonal_end else designs
