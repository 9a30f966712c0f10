"""One stabilizing search for every static gain: several starts, the best stabilizing minimum.

The benchmark cost is a finite-horizon cost, finite for unstable gains too, and it is
not convex in the gain: L-BFGS from one start can stop at a local minimum whose closed
loop is unstable (the diagonal gain of ``paper_instance(1, n=4, degree=2, a_norm=1.2)``
from the LQR diagonal: cost 58.5 at spectral radius 1.02, where a stabilizing diagonal
gain costs 13.99 at 0.84). So every static design is usable only if its closed loop is
stable (:func:`is_stable`: a margin in the plant's own time,
:func:`codesign.status.stability_tol`, at most :data:`codesign.status.STABILITY_TOL`), and
every method that polishes a gain on a pattern asks this module for it: :func:`search`
polishes from several starts and keeps the lowest-cost stabilizing minimum, so that "no
stabilizing gain on this pattern" is said only after all of them failed.

Starts, in order: the caller's own (a method's sparse gain, the user's ``start``), then
the local gains of :func:`local_starts` — the LQR gain's own blocks, zero, the local
deadbeat gain ``K_ii = -B_ii⁺ A_ii`` (each node cancels its own dynamics), and seeded
random perturbations of the LQR gain's own blocks, of the LQR gain's size; the last two
scaled down where their closed loop starts far outside the unit circle (relative to the
plant, or, where the LQR diagonal is itself far outside, to it: :func:`_within`). The seed
is fixed and salted with the instance's seed and size, so a design is reproducible.

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

Past the horizon. The polish minimizes the finite-horizon cost, which cannot see an
instability that grows less than e-fold over the horizon (a plant with a slow stable
mode: every start's minimum may let it drift just outside the circle). Where no start's
minimum stabilizes and the least unstable one is such an instability
(:data:`BLIND_GROWTH`), :func:`stabilizing_gain` goes on with a cost that does not depend
on the horizon: :func:`horizon_free_gain` minimizes the infinite-horizon cost on the
pattern, reached from the least unstable minimum through discounted costs. Its minimum is
the design (start ``"horizon-free"``), with its finite-horizon cost and a message saying
it is not that cost's minimum. Where the horizon sees the instability, nothing changes.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Iterable, Iterator, NamedTuple

import numpy as np

from codesign.evaluation import spectral_radius, static_gain_cost_and_grad
from codesign.status import STABILITY_TOL, is_stable, stability_tol

from .polish import PolishResult, polish_gain

__all__ = ["STABILITY_TOL", "EXHAUSTIVE_STATES", "RANDOM_STARTS", "SAME_MINIMUM_RTOL", "BLIND_GROWTH",
           "HORIZON_FREE_STATES", "is_stable",
           "stability_tol", "unstable_note", "deadbeat_gain", "local_starts", "Minimum", "search",
           "stabilizing_gain", "lyapunov_cost_and_grad", "horizon_free_gain"]

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
#: Where no start's minimum stabilizes and the least unstable one grows by at most e^1 over
#: the horizon (``horizon * ln(radius) <= 1``: a time constant longer than the horizon), the
#: finite-horizon cost cannot tell that instability from a slow stable mode, and the search
#: goes on with the horizon-free cost (:func:`horizon_free_gain`).
BLIND_GROWTH = 1.0
#: Up to this many states (a Lyapunov solve pair: 0.01 s at 75 states, 0.1 s at 200, 1.2 s at
#: 500, one core), so that the continuation takes seconds to a minute, not the hour it
#: would at 1000 states; above, the search's verdict stands as it was.
HORIZON_FREE_STATES = 300
# horizon_free_gain: each discounted round starts with its scaled loop at radius at most this,
_DISCOUNT_RADIUS = 0.99
# then lowers the discount as far as its minimum's discounted cost at most doubles (found by
# this many bisections of log(alpha)), a stall being a fall of less than 1 % of alpha - 1;
_DISCOUNT_GROWTH = 2.0
_DISCOUNT_BISECTIONS = 30
_DISCOUNT_STEP = 0.01
# at most this many rounds, each at most this many L-BFGS iterations.
_DISCOUNT_ROUNDS = 40
_LYAPUNOV_MAXITER = 500


def unstable_note(radius, loop: str = "the closed loop", instance=None) -> str:
    """Why a gain is not usable: the radius against the rule (the plant's own margin when ``instance`` is given)."""
    return f"spectral radius of {loop} {radius:.6g} (not below 1 - {stability_tol(instance):g})"


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

    Where the base itself is that far out, no halving gets there: the step only shrinks
    toward the base, and every start would be the base's copy (on ``paper_instance(25,
    n=4, degree=2, a_norm=1.2)`` the LQR diagonal has radius 1.846 against the limit 1.3,
    and all six random starts ended within 0.005 of its minimum, 7.29, where 37 of 40
    plain random starts reach 4.41). Then the step is halved against the base's own
    radius instead (at most :data:`_START_SLACK` above it): the start is a genuine
    neighbour of the base, no farther out than it. Starts that met the first limit are
    unchanged, to the last digit.
    """
    limit = max(1.0, instance.open_loop_radius) + _START_SLACK
    scaled = _halved(instance, base, step, limit)
    if scaled is None:
        own = spectral_radius(instance.A + instance.B @ base)
        if np.isfinite(own) and own + _START_SLACK > limit:
            scaled = _halved(instance, base, step, own + _START_SLACK)
    return scaled if scaled is not None else base + step / 2.0**_HALVINGS


def _halved(instance, base, step, limit):
    """``base + step / 2^k``, k < :data:`_HALVINGS` least with the closed loop's radius at most ``limit``; else None."""
    for _ in range(_HALVINGS):
        if spectral_radius(instance.A + instance.B @ (base + step)) <= limit:
            return base + step
        step = step / 2.0
    return None


class Minimum(NamedTuple):
    """What :func:`search` keeps: the polished gain, its cost and spectral radius, and how it was found.

    ``result`` is what the polish returned for it (a :class:`~baselines.PolishResult`, say),
    ``start`` the name of the start it came from, ``tried`` the starts polished, ``plant``
    the instance whose own time scale the stability rule uses (:func:`is_stable`; None:
    the fixed margin).
    """
    gain: object
    cost: float
    radius: float
    result: object
    start: str
    tried: int
    plant: object = None

    @property
    def stable(self) -> bool:
        return is_stable(self.radius, self.plant)


#: A polish for :func:`search`: from a start, ``(gain, cost, spectral radius, result)``.
Polish = Callable[[object], tuple[object, float, float, object]]


def _same(a, b) -> bool:
    if isinstance(a, tuple):
        return all(np.array_equal(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b)


def _radius(found: Minimum) -> float:
    return found.radius if np.isfinite(found.radius) else np.inf


def search(polish: Polish, starts: Iterable[tuple[str, object]], *, exhaustive: bool,
           instance=None) -> Minimum | None:
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
    instance : Instance, optional
        The plant, whose own slowest decay sets the stability margin
        (:func:`codesign.status.stability_tol`); None: the fixed margin.

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
        found = Minimum(gain, float(cost), float(radius), result, name, len(seen), instance)
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
                     local: bool = True, horizon_free: bool = True) -> Minimum:
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
    horizon_free : bool
        Where no start's minimum stabilizes and the least unstable one is one the horizon
        cannot see (it grows by at most e^:data:`BLIND_GROWTH` over the horizon), go on
        with :func:`horizon_free_gain` from it (up to :data:`HORIZON_FREE_STATES` states).

    Returns
    -------
    Minimum
        ``gain`` the polished K, ``result`` its :class:`~baselines.PolishResult`. A gain
        from :func:`horizon_free_gain` has ``start == "horizon-free"``, its
        finite-horizon cost, and a result whose message says why it is not a minimum
        of that cost.
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

    found = search(polish, every_start(), exhaustive=exhaustive, instance=instance)
    if found is None:
        raise ValueError("stabilizing_gain needs at least one start")
    if (horizon_free and instance.n <= HORIZON_FREE_STATES and not found.stable
            and _horizon_blind(instance, found.radius)):
        rescued = _horizon_free_minimum(instance, mask, found)
        if rescued is not None:
            return rescued
    return found


def _horizon_blind(instance, radius) -> bool:
    """Whether the finite-horizon cost may not see this closed loop's instability.

    Either the horizon is too short (``T ln(radius) <= BLIND_GROWTH``), or the instance
    sets an initial-state covariance Σ₀: the cost then weighs a mode only by what Σ₀
    puts into it, which for a low-rank Σ₀ (disturbances through a few channels B1) can be
    too little for an unstable mode to show within the horizon. The infinite-horizon
    cost sees every mode that Σ₀ reaches at all.
    """
    if not np.isfinite(radius):
        return False
    return bool(instance.x0_cov is not None or instance.horizon * np.log(max(radius, 1e-300)) <= BLIND_GROWTH)


def _horizon_free_minimum(instance, mask, found: Minimum) -> Minimum | None:
    """:func:`horizon_free_gain` from the least unstable minimum, as the search's :class:`Minimum`; None if it fails."""
    start = found.gain if np.all(np.isfinite(found.gain)) else np.zeros(mask.shape)
    free = horizon_free_gain(instance, mask, start)
    via = ""
    if free is None and instance.x0_cov is not None:
        # Which gains stabilize does not depend on Σ₀: the search for Σ₀ = I, whose cost weighs every
        # mode, gives a stabilizing start, and the infinite-horizon cost is finite only where K stabilizes.
        plain = stabilizing_gain(replace(instance, x0_cov=None), mask, [(found.start, start)])
        if plain.stable:
            free = horizon_free_gain(instance, mask, plain.gain)
            via = "from the stabilizing minimum for x(0) ~ N(0, I), "
    if free is None:
        return None
    K, radius, rounds, iterations = free
    cost, grad = static_gain_cost_and_grad(instance, K, mask=mask)
    if instance.x0_cov is None:
        blind = (f"grows at most e-fold over the {instance.horizon}-step horizon, which cannot tell it from a "
                 "slow stable mode")
    else:
        blind = "and the cost weighs a mode only by what the initial-state covariance x0_cov puts into it"
    message = (f"the finite-horizon cost's minima on this pattern do not stabilize (the least unstable, from "
               f"{found.start}, at spectral radius {found.radius:.6g}, {blind}); this gain minimizes "
               f"the infinite-horizon cost on the pattern instead ({via}{rounds} discounted rounds, spectral radius "
               f"{radius:.6g})")
    result = PolishResult(K, float(cost), float(np.linalg.norm(grad[mask])), False, message, iterations)
    return Minimum(K, float(cost), float(radius), result, "horizon-free", found.tried + 1, instance)


def lyapunov_cost_and_grad(instance, K, mask=None, *, discount: float = 1.0) -> tuple[float, np.ndarray]:
    """The infinite-horizon cost of ``u = K x`` (normalized), discounted by ``discount``, and its gradient.

    With the scaled closed loop ``F = (A + BK) / discount``, ``P = F' P F + Q + K'RK`` and
    ``S = F S F' + Σ₀`` (Lyapunov equations), the cost is ``trace(P Σ₀) / trace(P_lqr Σ₀)`` (the
    finite-horizon cost's limit as the horizon grows, for ``discount = 1``: 1 for the
    LQR gain) and its gradient ``2 (R K + B' P F / discount) S / trace(P_lqr)``. The
    discount ``alpha`` weighs step t by ``alpha^(-2t)``: finite wherever the closed
    loop's spectral radius is below ``alpha``, so an unstable gain can start a search
    that lowers ``alpha`` to 1 (:func:`horizon_free_gain`).

    Parameters
    ----------
    instance : Instance
    K : array_like, shape (m, n)
    mask : array_like of bool, shape (m, n), optional
        Entries of the gradient wanted; the others are 0.
    discount : float
        ``alpha >= 1``.

    Returns
    -------
    cost : float
        ``inf`` (and a zero gradient) where ``rho(A + BK) >= discount``.
    grad : ndarray, shape (m, n)
    """
    import scipy.linalg

    K = np.asarray(K, dtype=float)
    F = (instance.A + instance.B @ K) / discount
    if not np.all(np.isfinite(F)) or not spectral_radius(F) < 1.0:
        return np.inf, np.zeros_like(K)
    # scipy's Schur-based solver (bilinear map to the continuous equation): 10 ms at 75 states,
    # 0.1 s at 200, where codesign.riccati's recursive Stein solve spends 0.3-0.6 s in Python.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        try:
            P = scipy.linalg.solve_discrete_lyapunov(F.T, instance.Q + K.T @ instance.R @ K)
            S = scipy.linalg.solve_discrete_lyapunov(F, np.array(instance.x0_covariance))
        except (np.linalg.LinAlgError, ValueError):
            return np.inf, np.zeros_like(K)
    scale = instance.trace_P
    cost = instance.x0_mean(P) / scale
    grad = 2.0 * (instance.R @ K + instance.B.T @ P @ F / discount) @ S / scale
    if not (np.isfinite(cost) and np.all(np.isfinite(grad))):
        return np.inf, np.zeros_like(K)
    if mask is not None:
        grad = np.where(np.asarray(mask, dtype=bool), grad, 0.0)
    return cost, grad


def _lyapunov_polish(instance, K0, mask, discount: float) -> tuple[np.ndarray, int]:
    """L-BFGS on the discounted infinite-horizon cost over ``mask`` from ``K0``: (gain, iterations)."""
    import scipy.optimize

    index = np.nonzero(mask)

    def unpack(theta):
        K = np.zeros(mask.shape)
        K[index] = theta
        return K

    def fun(theta):
        cost, grad = lyapunov_cost_and_grad(instance, unpack(theta), mask, discount=discount)
        return cost, grad[index]

    res = scipy.optimize.minimize(fun, K0[index], jac=True, method="L-BFGS-B",
                                  options={"maxiter": _LYAPUNOV_MAXITER, "gtol": 1e-9, "ftol": 1e-13, "maxcor": 30})
    K = unpack(res.x)
    if not np.isfinite(fun(res.x)[0]):  # L-BFGS returns its best point, which is finite; be sure
        return np.where(mask, K0, 0.0), int(res.nit)
    return K, int(res.nit)


def horizon_free_gain(instance, mask, start) -> tuple[np.ndarray, float, int, int] | None:
    """A stabilizing gain on ``mask`` that does not depend on the cost's horizon, or None.

    The finite-horizon cost cannot see a mode whose growth over the horizon is small (a
    plant with a slow stable mode, whose best finite-horizon gain lets that mode drift
    just outside the circle); the infinite-horizon cost sees every mode, but is finite
    only where the gain stabilizes. Discounting bridges the two (the discount method of
    Perdomo et al., 2021, "Stabilizing dynamical systems via policy gradient methods"):
    the cost discounted by ``alpha`` (:func:`lyapunov_cost_and_grad`) is finite for every
    gain whose radius is below ``alpha``. From ``start``, at an ``alpha`` that puts its
    scaled loop at radius 0.99, each round minimizes the discounted cost, then lowers
    ``alpha`` as far as the minimum's discounted cost at most doubles (bisection), until
    a round at ``alpha = 1``: a minimum of the undiscounted infinite-horizon cost on the
    pattern. The doubling rule, not a fixed schedule, is what reaches 1: a discount of 1%
    a step weighs a mode over about 50 steps, as blind to a slow one as a 50-step horizon.
    A stall (``alpha`` no longer falls) means no stabilizing gain was found.

    Parameters
    ----------
    instance : Instance
    mask : ndarray of bool, shape (m, n)
    start : ndarray, shape (m, n)
        Any gain (entries outside ``mask`` are dropped); stabilizing or not.

    Returns
    -------
    (K, radius, rounds, iterations) or None
        The gain, its closed loop's spectral radius (stable by :func:`is_stable` on this
        instance), the discounted rounds and their L-BFGS iterations; None where no
        stabilizing gain was found.
    """
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return None
    K = np.where(mask, np.asarray(start, dtype=float), 0.0)
    radius = spectral_radius(instance.A + instance.B @ K)
    if not np.isfinite(radius):
        return None
    alpha = max(1.0, radius / _DISCOUNT_RADIUS)
    iterations = 0
    for rounds in range(1, _DISCOUNT_ROUNDS + 1):
        K, nit = _lyapunov_polish(instance, K, mask, alpha)
        iterations += nit
        radius = spectral_radius(instance.A + instance.B @ K)
        if alpha == 1.0:
            break
        lower = _lower_discount(instance, K, alpha)
        if lower is None:
            if not radius < 1.0:
                return None  # stalled outside: the discounted minima do not come inside
            lower = 1.0  # stalled inside: K stabilizes, so the undiscounted cost is finite from it
        alpha = lower
    else:
        return None
    if not is_stable(radius, instance):
        return None
    return K, float(radius), rounds, iterations


def _lower_discount(instance, K, alpha: float) -> float | None:
    """The least discount in ``[1, alpha)`` at which K's discounted cost is at most twice its cost at ``alpha``.

    Bisection on ``log(alpha)`` (the cost falls as the discount grows); 1 where K's
    undiscounted cost is within the factor already. None where it cannot be lowered by
    at least :data:`_DISCOUNT_STEP` of ``alpha - 1`` (a stall).
    """
    cost = lyapunov_cost_and_grad(instance, K, discount=alpha)[0]
    if not np.isfinite(cost):
        return None
    allowed = _DISCOUNT_GROWTH * cost
    if lyapunov_cost_and_grad(instance, K)[0] <= allowed:
        return 1.0
    low, high = 0.0, np.log(alpha)  # log(1), log(alpha): too low, acceptable
    for _ in range(_DISCOUNT_BISECTIONS):
        middle = 0.5 * (low + high)
        if lyapunov_cost_and_grad(instance, K, discount=float(np.exp(middle)))[0] <= allowed:
            high = middle
        else:
            low = middle
    lower = float(np.exp(high))
    if lower - 1.0 > (1.0 - _DISCOUNT_STEP) * (alpha - 1.0):
        return None
    return lower
