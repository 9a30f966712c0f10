"""Quadratic invariance of delay constraints (Rotkowitz, Cogill & Lall).

Information travels over a communication graph C at ``speed`` hops per step, so
node i learns node j's measurement ``ceil(d_C(i, j) / speed)`` steps after it was
taken (the transmission delay). Node j's state or input reaches node i through the
plant after ``d_plant(i, j)`` steps (the propagation delay, hop distance in the
support of A or B). Transmission delays on shortest paths satisfy the triangle
inequality, and then the delay constraint set is quadratically invariant under
the plant exactly when no information has to travel slower than the plant
spreads it: ``transmission(i, j) <= propagation(i, j)`` for every pair. With QI,
constrained optimal control (and SLS with the matching supports) is convex.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from codesign.instances import hop_distances

__all__ = ["QIResult", "is_quadratically_invariant", "transmission_delays"]


@dataclass(frozen=True)
class QIResult:
    """Outcome of :func:`is_quadratically_invariant`.

    Attributes
    ----------
    qi : bool
        True when the delay constraints are quadratically invariant.
    pair : tuple of int or None
        The first violating ``(i, j)`` in row-major order: node i receives node
        j's information later than j's influence reaches i through the plant.
    reason : str
        A readable explanation (names the pair and both delays).
    violations : int
        Number of ordered violating pairs.
    transmission : int or None
        Transmission delay of ``pair`` in steps (None if QI; ``-1`` if unreachable).
    propagation : int or None
        Propagation delay of ``pair`` in steps (None if QI).
    """

    qi: bool
    pair: tuple[int, int] | None
    reason: str
    violations: int = 0
    transmission: int | None = None
    propagation: int | None = None

    def __bool__(self) -> bool:
        return self.qi


def transmission_delays(comm_adj, speed: float = 1) -> np.ndarray:
    """Steps for node j's information to reach node i: ``ceil(d_C(i, j) / speed)`` (inf if never)."""
    speed = _check_speed(speed)
    hops = hop_distances(comm_adj)
    with np.errstate(invalid="ignore"):
        # Round before ceil so that, e.g., 3 hops at speed 1.5 is 2 steps, not 3.
        return np.where(np.isfinite(hops), np.ceil(np.round(hops / speed, 9)), np.inf)


def is_quadratically_invariant(instance, comm_adj, *, speed: float = 1) -> QIResult:
    """Decide whether delayed communication over ``comm_adj`` is QI under the plant.

    Parameters
    ----------
    instance : Instance
        Supplies the plant graph (support of A or B).
    comm_adj : array_like, shape (n, n)
        Communication graph, ``comm_adj[i, j] != 0`` meaning node i receives from j.
    speed : float
        Hops travelled per time step (> 0).

    Returns
    -------
    QIResult
        ``.qi`` and, when it fails, the first violating pair with the reason.
    """
    comm = np.asarray(comm_adj)
    n = instance.n
    if comm.shape != (n, n):
        raise ValueError(f"comm_adj must have shape {(n, n)}, got {comm.shape}")
    transmission = transmission_delays(comm, speed)
    propagation = hop_distances(instance.plant_adj)
    bad = transmission > propagation
    np.fill_diagonal(bad, False)
    count = int(bad.sum())
    if count == 0:
        return QIResult(True, None, f"transmission delay <= propagation delay for every pair (speed {speed:g})")
    i, j = (int(v) for v in np.argwhere(bad)[0])
    t, p = transmission[i, j], propagation[i, j]
    hops = hop_distances(comm)[i, j]
    if np.isfinite(t):
        told = f"after {int(t)} step(s) ({int(hops)} hop(s) at speed {speed:g})"
        t_out = int(t)
    else:
        told = "never (no communication path)"
        t_out = -1
    reason = (
        f"not QI: node {i} receives node {j}'s information {told}, but node {j} influences "
        f"node {i} through the plant after {int(p)} step(s); {count} ordered pair(s) violate "
        "transmission delay <= propagation delay"
    )
    return QIResult(False, (i, j), reason, count, t_out, int(p))


def _check_speed(speed) -> float:
    if isinstance(speed, bool) or not isinstance(speed, (int, float, np.integer, np.floating)):
        raise ValueError(f"speed must be a positive number of hops per step, got {speed!r}")
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a positive number of hops per step, got {speed!r}")
    return float(speed)
