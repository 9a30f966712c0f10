"""Quadratic invariance of delay constraints (Rotkowitz, Cogill & Lall).

The controller K maps measured states to inputs, ``u_i(t) = sum_{j, m} K[m](i, j) x_j(t - m)``,
and the plant G maps inputs to states with taps ``G[k] = A^(k-1) B`` (k >= 1). The
delay constraints allow tap ``K[m](i, j)`` only from ``m >= D(i, j)``, the same set as
the supports of :mod:`baselines.sls` (the support it gives ``Φu[k]`` and ``Φx[k]`` is
that of K's tap k - 1: ``Φu[1] = K[0]`` acts on the current state):

* transmission delay ``t(i, j) = ceil(d_C(i, j) / speed)``: steps for node j's
  information to reach node i over the communication graph C;
* controller delay ``D(i, i) = 0``, ``D(i, j) = max(0, t(i, j) + act_delay - 1)``: with
  ``act_delay = 1`` node i uses ``x_j(t - t(i, j))``; with ``act_delay = 0`` one step
  earlier (the first ``speed`` hops are instantaneous);
* propagation delay ``p(i, j) = 1 + min {d_A(i, l) : B(l, j) != 0}``: the first k at which
  ``(A^(k-1) B)(i, j)`` is (structurally) nonzero, when node j's input first moves node
  i's state. With a local (diagonal) B it is one step more than the hop distance in
  supp(A); it is the hop distance in supp(A) ∪ supp(B) only when B spreads like A.

The first tap of ``K G K`` that can be nonzero at (k, l) is
``M(k, l) = min_{i, j} D(k, i) + p(i, j) + D(j, l)``, and for generic K in the set it is
nonzero there (its terms are distinct monomials in K's entries, so they cannot
cancel). The set is therefore quadratically invariant (``K G K`` in the set for every
K in it) exactly when ``D(k, l) <= M(k, l)`` for every pair. When D obeys the triangle
inequality (any ``act_delay >= 1``) this reduces to the classical
``D(i, j) <= p(i, j)``: no information travels slower than the plant spreads it. With
``act_delay = 0`` it does not: k may act at once on its neighbour i's state, which
node j's input moves one step later (``B(i, j) != 0``), and j may act at once on its
neighbour l, so l's state reaches k's input after 1 step while K may not use it for 2
(k, l three hops apart at speed 1). With QI, constrained optimal control (and SLS with the
matching supports) is convex. Zeros of A and B are taken as structural: a numerical
cancellation inside ``A^(k-1) B`` can only make the test conservative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from codesign.instances import hop_distances

__all__ = [
    "QIResult",
    "is_quadratically_invariant",
    "transmission_delays",
    "controller_delays",
    "propagation_delays",
    "check_speed",
]


@dataclass(frozen=True)
class QIResult:
    """Outcome of :func:`is_quadratically_invariant`.

    Attributes
    ----------
    qi : bool
        True when the delay constraints are quadratically invariant.
    pair : tuple of int or None
        The first violating ``(k, l)`` in row-major order: node k may use node l's
        state later than that state reaches node k's input through the loop
        ``K G K`` (controller, plant, controller).
    reason : str
        A readable explanation (names the pair, both delays, the act_delay and the
        path through the plant).
    violations : int
        Number of ordered violating pairs.
    transmission : int or None
        Controller delay ``D(k, l)`` of ``pair`` in steps: the first tap at which
        node k may use node l's state (transmission plus the act_delay
        convention; None if QI; ``-1`` if never).
    propagation : int or None
        ``M(k, l)``: the first step at which node l's state can reach node k's
        input through the loop (None if QI). When ``via == pair`` this is the
        plant's propagation delay from node l's input to node k's state.
    via : tuple of int or None
        ``(i, j)`` of a fastest path ``x_l -> u_j -> x_i -> u_k`` (node j's input
        moves node i's state through the plant); ``pair`` itself whenever the plant
        alone (node l's input moving node k's state) is that fast.
    """

    qi: bool
    pair: tuple[int, int] | None
    reason: str
    violations: int = 0
    transmission: int | None = None
    propagation: int | None = None
    via: tuple[int, int] | None = None

    def __bool__(self) -> bool:
        return self.qi


def transmission_delays(comm_adj, speed: float = 1) -> np.ndarray:
    """Steps for node j's information to reach node i: ``ceil(d_C(i, j) / speed)`` (inf if never)."""
    speed = check_speed(speed)
    hops = hop_distances(comm_adj)
    with np.errstate(invalid="ignore"):
        # Round before ceil so that, e.g., 3 hops at speed 1.5 is 2 steps, not 3.
        return np.where(np.isfinite(hops), np.ceil(np.round(hops / speed, 9)), np.inf)


def controller_delays(comm_adj, speed: float = 1, act_delay: int = 1) -> np.ndarray:
    """First tap ``D[i, j]`` of K at which node i may use node j's state (inf if never).

    ``D[i, i] = 0`` and ``D[i, j] = max(0, transmission + act_delay - 1)``: exactly the
    supports of :func:`baselines.sls.sls`, which allow ``floor(speed (k - act_delay))``
    hops in ``Φu[k]``, K's tap k - 1.
    """
    act_delay = _check_act_delay(act_delay)
    delays = transmission_delays(comm_adj, speed)
    delays = np.maximum(0.0, delays + (act_delay - 1))
    np.fill_diagonal(delays, 0.0)
    return delays


def propagation_delays(A, B) -> np.ndarray:
    """First tap ``p[i, j]`` (>= 1) of ``G[k] = A^(k-1) B`` nonzero at (i, j) (inf if never).

    Node j's input moves node i's state after ``1 + min {d_A(i, l) : B(l, j) != 0}``
    steps: first through B (to the nodes l it drives), then along supp(A).
    """
    B_hops = np.where(np.asarray(B) != 0, 0.0, np.inf)
    return 1.0 + _min_plus(hop_distances(np.asarray(A) != 0), B_hops)


def is_quadratically_invariant(instance, comm_adj, *, speed: float = 1, act_delay: int = 1) -> QIResult:
    """Decide whether delayed communication over ``comm_adj`` is QI under the plant.

    Parameters
    ----------
    instance : Instance
        Supplies the plant (the supports of A and B).
    comm_adj : array_like, shape (n, n)
        Communication graph, ``comm_adj[i, j] != 0`` meaning node i receives from j.
    speed : float
        Hops travelled per time step (> 0).
    act_delay : int
        The delay convention of :func:`baselines.sls.sls` (>= 0; 1, its default,
        is one step per hop with the own state used at once; 0 makes the first
        ``speed`` hops instantaneous).

    Returns
    -------
    QIResult
        ``.qi`` and, when it fails, the first violating pair with the reason.
    """
    comm = np.asarray(comm_adj)
    n = instance.nodes
    if comm.shape != (n, n):
        raise ValueError(f"comm_adj must have shape {(n, n)} (one row per node), got {comm.shape}")
    speed = check_speed(speed)
    act_delay = _check_act_delay(act_delay)
    D = controller_delays(comm, speed, act_delay)
    p = _by_node(propagation_delays(instance.A, instance.B), instance.state_nodes, instance.input_nodes, n)
    M = _min_plus(_min_plus(D, p), D)
    bad = D > M
    count = int(bad.sum())
    model = f"speed {speed:g}, act_delay {act_delay}"
    if count == 0:
        return QIResult(True, None, f"every controller delay is within the loop's propagation delay ({model})")
    k, l = (int(v) for v in np.argwhere(bad)[0])
    # The fastest path x_l -> u_j -> x_i -> u_k; the plant alone (i, j) = (k, l) if it is one.
    if D[k, k] + p[k, l] + D[l, l] == M[k, l]:
        i, j = k, l
    else:
        i, j = (int(v) for v in np.argwhere(D[k, :, None] + p + D[None, :, l] == M[k, l])[0])
    hops = hop_distances(comm)[k, l]
    if np.isfinite(D[k, l]):
        told = f"node {k} may use node {l}'s state only after {int(D[k, l])} step(s) ({int(hops)} hop(s) at {model})"
        t_out = int(D[k, l])
    else:
        told = f"node {k} can never use node {l}'s state (no communication path)"
        t_out = -1
    if (i, j) == (k, l):
        path = f"node {l}'s input moves node {k}'s state through the plant after {int(p[k, l])} step(s)"
    else:
        path = (
            f"node {l}'s state reaches node {k}'s input after {int(M[k, l])} step(s) through the loop: "
            f"node {j} may use it after {int(D[j, l])} step(s), node {j}'s input moves node {i}'s state "
            f"after {int(p[i, j])} step(s) through the plant, and node {k} may use that after "
            f"{int(D[k, i])} step(s)"
        )
    reason = (
        f"not QI: {told}, but {path}; {count} ordered pair(s) "
        "violate controller delay <= propagation delay through the loop"
    )
    return QIResult(False, (k, l), reason, count, t_out, int(M[k, l]), (i, j))


def _by_node(delays: np.ndarray, row_nodes, col_nodes, nodes: int) -> np.ndarray:
    """Node-level delays: the first tap at which any state of node i feels any input of node j."""
    out = np.full((nodes, nodes), np.inf)
    np.minimum.at(out, (np.asarray(row_nodes)[:, None], np.asarray(col_nodes)[None, :]), delays)
    return out


def _min_plus(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """``Z[i, j] = min_l X[i, l] + Y[l, j]``, one n x n slice at a time to keep memory O(n²)."""
    out = np.full((X.shape[0], Y.shape[1]), np.inf)
    for l in range(X.shape[1]):
        np.minimum(out, X[:, l, None] + Y[None, l, :], out=out)
    return out


def _check_act_delay(act_delay) -> int:
    if isinstance(act_delay, bool) or not isinstance(act_delay, (int, np.integer)) or act_delay < 0:
        raise ValueError(f"act_delay must be a non-negative integer, got {act_delay!r}")
    return int(act_delay)


def check_speed(speed) -> float:
    """``speed`` (hops per step) as a float; a :class:`ValueError` unless it is a positive finite number."""
    if isinstance(speed, bool) or not isinstance(speed, (int, float, np.integer, np.floating)):
        raise ValueError(f"speed must be a positive number of hops per step, got {speed!r}")
    if not (math.isfinite(speed) and speed > 0):
        raise ValueError(f"speed must be a positive number of hops per step, got {speed!r}")
    return float(speed)
