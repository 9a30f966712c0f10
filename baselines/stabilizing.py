"""One stabilizing search for every static gain: several starts, the best stabilizing minimum.

The benchmark cost is a finite-horizon cost, finite for unstable gains too, and it is
not convex in the gain: L-BFGS from one start can stop at a local minimum whose closed
loop is unstable (the diagonal gain of ``paper_instance(1, n=4, degree=2, a_norm=1.2)``
from the LQR diagonal: cost 58.5 at spectral radius 1.02, where a stabilizing diagonal
gain costs 13.99 at 0.84). So every static design is usable only if its closed loop is
stable (:func:`is_stable`, the margin :data:`codesign.status.STABILITY_TOL`), and every
method that polishes a gain on a pattern asks this module for it: :func:`search` polishes
from several starts and keeps the lowest-cost stabilizing minimum, so that "no
stabilizing gain on this pattern" is said only after all of them failed.

Starts, in order: the caller's own (a method's sparse gain, the user's ``start``), then
the local gains of :func:`local_starts` — the LQR gain's own blocks, zero, the local
deadbeat gain ``K_ii = -B_ii⁺ A_ii`` (each node cancels its own dynamics), and seeded
random perturbations of the LQR gain's own blocks, of the LQR gain's size; the last two
scaled down where their closed loop starts far outside the unit circle. The seed is
fixed and salted with the instance's seed and size, so a design is reproducible.

How far the search goes. An exhaustive search polishes every start and keeps the
lowest-cost stabilizing minimum; a first-stabilizing search stops at the first start
whose minimum stabilizes. The diagonal gain searches exhaustively up to
:data:`EXHAUSTIVE_STATES` states (a polish there takes well under a second) and stops
at the first stabilizing minimum above; pattern searches (truncation, the ℓ1 paths'
patterns, the budget searches) stop at the first, so their first start — the method's
own gain — decides wherever it stabilizes, as before. Either way a later start replaces
the kept minimum only when it is lower by more than :data:`SAME_MINIMUM_RTOL`, so where
the first start already finds the best minimum the design is the first start's, to the
last digit.
"""

from __future__ import annotations

from typing import Callable, Iterable, Iterator, NamedTuple

import numpy as np

from codesign.evaluation import spectral_radius
from codesign.status import STABILITY_TOL

from .polish import polish_gain

__all__ = ["STABILITY_TOL", "EXHAUSTIVE_STATES", "RANDOM_STARTS", "SAME_MINIMUM_RTOL", "is_stable",
           "unstable_note", "deadbeat_gain", "local_starts", "Minimum", "search", "stabilizing_gain"]

#: Up to this many states the diagonal gain's search polishes every start (9 polishes:
#: 0.12-0.21 s of CPU at 20 states on the paper family instead of 0.01-0.02 s for one,
#: under a second at 50 on the swing grid); above it, it stops at the first stabilizing minimum,
#: so that at N = 100-1000 the LQR-diagonal start alone decides where it stabilizes (a
#: polish at 1000 states takes minutes).
EXHAUSTIVE_STATES = 50
#: Seeded random starts per search, up to :data:`EXHAUSTIVE_STATES` states and above.
RANDOM_STARTS = (6, 2)
#: A later start's minimum replaces the kept one only when lower by more than this
#: (relative): the same minimum reached from two starts differs in the last digits.
SAME_MINIMUM_RTOL = 1e-6
# Salt of the random starts' generator (with the instance's seed and size).
_SALT = 0x57AB
# A random start's closed-loop radius may exceed max(1, open-loop radius) by this much.
_START_SLACK = 0.1
# At most this many halvings of a random start's perturbation (then it is taken as it is).
_HALVINGS = 10


def is_stable(radius) -> bool:
    """Whether a closed loop of this spectral radius counts as stable: ``radius < 1 - STABILITY_TOL``."""
    return bool(radius < 1.0 - STABILITY_TOL)


def unstable_note(radius, loop: str = "the closed loop") -> str:
    """Why a gain is not usable: the radius against the rule."""
    return f"spectral radius of {loop} {radius:.6g} (not below 1 - {STABILITY_TOL:g})"


def _node_blocks(instance):
    """(inputs, states) index arrays of each node that has an input."""
    for node in np.unique(instance.input_nodes):
        yield np.flatnonzero(instance.input_nodes == node), np.flatnonzero(instance.state_nodes == node)


def deadbeat_gain(instance) -> np.ndarray:
    """The local deadbeat gain ``K_ii = -B_ii⁺ A_ii``: each node cancels its own block of A (least squares).

    The coupling between nodes is ignored: this is a start, not a design.
    """
    K = np.zeros((instance.m, instance.n))
    for inputs, states in _node_blocks(instance):
        B_ii, A_ii = instance.B[np.ix_(states, inputs)], instance.A[np.ix_(states, states)]
        K[np.ix_(inputs, states)] = -np.linalg.pinv(B_ii) @ A_ii
    return K


def local_starts(instance) -> Iterator[tuple[str, np.ndarray]]:
    """The search's own starts, as ``(name, gain)`` pairs on the own blocks, built as they are used.

    ``lqr_diagonal`` (the LQR gain's own blocks), ``zero``, ``deadbeat`` (the local deadbeat
    gain ``K_ii = -B_ii⁺ A_ii``, scaled down by :func:`_within` where it is far off), then
    ``random 1``, ``random 2``, ...: :data:`RANDOM_STARTS` random own-block perturbations
    of the first, of the LQR gain's size (its largest row norm), scaled down the same way.

    Random starts matter even where the deterministic ones stabilize: those share the
    instance's symmetries (the gradient keeps a symmetric gain symmetric), while the best
    diagonal gain of a symmetric instance can break them (``paper_instance(1, n=4,
    degree=2, a_norm=1.2)``: 13.99 from a random start, 58.5 unstable from the LQR
    diagonal).
    """
    mask = instance.block_mask()
    own = np.where(mask, instance.K_lqr, 0.0)
    yield "lqr_diagonal", own
    yield "zero", np.zeros(mask.shape)
    yield "deadbeat", _within(instance, np.zeros(mask.shape), deadbeat_gain(instance))
    rng = np.random.default_rng([_SALT, instance.seed, instance.n])
    size = float(np.max(np.linalg.norm(instance.K_lqr, axis=1), initial=0.0)) or 1.0
    count = RANDOM_STARTS[0] if instance.n <= EXHAUSTIVE_STATES else RANDOM_STARTS[1]
    for k in range(1, count + 1):
        yield f"random {k}", _within(instance, own, size * np.where(mask, rng.standard_normal(mask.shape), 0.0))


def _within(instance, base, step) -> np.ndarray:
    """``base + step``, the step halved (at most :data:`_HALVINGS` times) until the closed loop is near stable.

    Near: a spectral radius at most :data:`_START_SLACK` above ``max(1, open-loop radius)``.
    A start far outside it begins at costs of 1e30 and more, where L-BFGS spends hundreds
    of iterations to find the same minima (without this, the random starts took 4x the
    search's time on the swing grid at 50 states, the deadbeat start 10x the first
    start's on the paper family at N = 20).
    """
    limit = max(1.0, instance.open_loop_radius) + _START_SLACK
    for _ in range(_HALVINGS):
        if spectral_radius(instance.A + instance.B @ (base + step)) <= limit:
            break
        step = step / 2.0
    return base + step


class Minimum(NamedTuple):
    """What :func:`search` keeps: the polished gain, its cost and spectral radius, and how it was found.

    ``result`` is what the polish returned for it (a :class:`~baselines.PolishResult`, say),
    ``start`` the name of the start it came from, ``tried`` the starts polished.
    """
    gain: object
    cost: float
    radius: float
    result: object
    start: str
    tried: int

    @property
    def stable(self) -> bool:
        return is_stable(self.radius)


#: A polish for :func:`search`: from a start, ``(gain, cost, spectral radius, result)``.
Polish = Callable[[object], tuple[object, float, float, object]]


def _same(a, b) -> bool:
    if isinstance(a, tuple):
        return all(np.array_equal(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b)


def _radius(found: Minimum) -> float:
    return found.radius if np.isfinite(found.radius) else np.inf


def search(polish: Polish, starts: Iterable[tuple[str, object]], *, exhaustive: bool) -> Minimum | None:
    """Polish from each start; the lowest-cost stabilizing minimum, else the least unstable one.

    Parameters
    ----------
    polish : callable
        ``polish(start) -> (gain, cost, radius, result)``.
    starts : iterable of (str, gain)
        Named starts, tried in order (a generator is consumed only as far as needed);
        a start equal to one already tried is skipped.
    exhaustive : bool
        Polish every start; otherwise stop at the first stabilizing minimum.

    Returns
    -------
    Minimum or None
        The stabilizing minimum of lowest cost (a later one only when lower by more than
        :data:`SAME_MINIMUM_RTOL`); where none stabilizes, the one of smallest spectral
        radius (``stable`` False); None when there was no start.
    """
    best, closest, seen = None, None, []
    for name, start in starts:
        if any(_same(start, other) for other in seen):
            continue
        seen.append(start)
        gain, cost, radius, result = polish(start)
        found = Minimum(gain, float(cost), float(radius), result, name, len(seen))
        if found.stable and np.isfinite(found.cost):
            if best is None or found.cost < best.cost * (1.0 - SAME_MINIMUM_RTOL):
                best = found
            if not exhaustive:
                break
        elif closest is None or _radius(found) < _radius(closest):
            closest = found
    kept = best if best is not None else closest
    return None if kept is None else kept._replace(tried=len(seen))


def stabilizing_gain(instance, mask, starts: Iterable[tuple[str, np.ndarray]], *, exhaustive: bool = False,
                     local: bool = True) -> Minimum:
    """The stabilizing gain ``u = K x`` on ``mask`` found from ``starts``, then from :func:`local_starts`.

    Parameters
    ----------
    instance : Instance
    mask : ndarray of bool, shape (m, n)
        Free entries; each node's own block should be among them (the local starts
        live there).
    starts : iterable of (str, ndarray)
        The caller's starts, tried first (entries outside ``mask`` are dropped).
    exhaustive : bool
        See :func:`search`.
    local : bool
        Go on with :func:`local_starts` after the caller's starts.

    Returns
    -------
    Minimum
        ``gain`` the polished K, ``result`` its :class:`~baselines.PolishResult`.
    """
    mask = np.asarray(mask, dtype=bool)

    def polish(K):
        result = polish_gain(instance, np.where(mask, K, 0.0), mask)
        radius = spectral_radius(instance.A + instance.B @ result.K) if np.all(np.isfinite(result.K)) else np.inf
        return result.K, result.cost, radius, result

    def every_start():
        for name, K in starts:
            yield name, np.where(mask, K, 0.0)
        if local:
            yield from local_starts(instance)

    found = search(polish, every_start(), exhaustive=exhaustive)
    if found is None:
        raise ValueError("stabilizing_gain needs at least one start")
    return found
