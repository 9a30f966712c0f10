"""What the sparse static-gain methods share: from a raw gain to a scored design.

Every sparse method (ADMM, SDP, truncation) ends the same way: fix the pattern
of the gain it found (diagonal always free, since local feedback needs no link),
polish the free entries on the exact finite-horizon benchmark cost, check that
the result stabilizes, and score it exactly. The diagonal pattern is the
decentralized design, so it is taken from :func:`baselines.decentralized`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from codesign.controllers import StaticGain
from codesign.design import Design, count_links
from codesign.evaluation import spectral_radius, static_gain_cost, static_gain_cost_and_grad
from codesign.status import DIVERGED, INACCURATE, OPTIMAL, USABLE

from .lqr import decentralized
from .polish import GRAD_RTOL, polish_gain

__all__ = ["GRAD_RTOL", "check_gammas", "pattern_of", "polished_gain", "gain_design",
           "as_path_point", "design_on_pattern", "with_diagonal_end", "DecentralizedCache"]


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


def polished_gain(instance, K, mask, *, polish: bool = True) -> tuple[np.ndarray, dict]:
    """Polish ``K`` on ``mask`` (or not) and report what happened.

    Returns the gain and extras with ``grad_norm`` (masked, of the normalized
    cost), ``polish_iterations`` and ``polish_message``.
    """
    K = np.where(mask, K, 0.0)
    if not polish:
        _, grad_norm = masked_grad_norm(instance, K, mask)
        return K, {"grad_norm": grad_norm, "polish_iterations": 0, "polish_message": "not polished"}
    result = polish_gain(instance, K, mask)
    return result.K, {
        "grad_norm": result.grad_norm,
        "polish_iterations": result.iterations,
        "polish_message": result.message,
    }


def gain_design(instance, method: str, params: dict, K, *, seconds: float, extras: dict,
                polished: bool, status: str = OPTIMAL, message: str = "") -> Design:
    """A :class:`Design` for the static gain ``u = K x``, scored exactly.

    A polished gain whose masked gradient is not below :data:`GRAD_RTOL` times its
    cost is flagged ``inaccurate``; a gain that does not stabilize is recorded as
    ``diverged`` (no cost), never returned as a number.
    """
    K = np.asarray(K, dtype=float)
    radius = spectral_radius(instance.A + instance.B @ K)
    links, self_loops = count_links(instance.node_support(K))
    extras = {**extras, "spectral_radius": radius}
    if not radius < 1.0:
        return Design.failure(method, params, DIVERGED,
                              f"gain does not stabilize (spectral radius {radius:.6g}); {message}".rstrip("; "),
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
    :func:`baselines.decentralized` when that one stabilizes.
    """
    mask = pattern_of(K, instance)
    if not (mask & ~instance.block_mask()).any():
        diagonal = decentral.usable()
        if diagonal is not None:
            return as_path_point(diagonal, method, params, {**extras, "decentralized": True})
    gain, polish_extras = polished_gain(instance, K, mask, polish=polish)
    return gain_design(instance, method, params, gain, seconds=0.0, extras={**extras, **polish_extras},
                       polished=polish)


def with_diagonal_end(designs: list, method: str, base: dict, decentral: "DecentralizedCache") -> list:
    """Close a path at γ → ∞ with the decentralized gain (``params["gamma"] = inf``).

    Every path gets this point, even one already diagonal at its largest γ, so that
    reports aggregating a γ over instances see the same points for every instance.
    A path with no usable design (an infeasible SDP, say) is left as it is: its
    γ → ∞ limit is just as infeasible.
    """
    diagonal = decentral.usable()
    if diagonal is None or not any(d.status in USABLE for d in designs):
        return designs
    params = {**base, "gamma": float("inf")}
    return designs + [as_path_point(diagonal, method, params, {"solver": "decentralized", "decentralized": True})]


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
        if design.controller is None or not design.extras.get("spectral_radius", np.inf) < 1.0:
            return None
        return design
