"""One scoring path for every method.

The benchmark cost is

    J = sum_{t=0}^{T-1} [x(t)'Q x(t) + u(t)'R u(t)] + x(T)'P x(T),   x(0) ~ N(0, I),

normalized by trace(P), which is what centralized LQR achieves exactly. Linear
controllers are scored in closed form (no sampling noise); any controller can be
scored by a batched rollout on a fixed, seeded validation set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "static_gain_cost",
    "static_gain_cost_and_grad",
    "response_cost",
    "validation_set",
    "simulate",
    "Rollout",
    "exact_cost",
    "compare_exact_and_simulated",
    "spectral_radius",
]

VALIDATION_SIZE = 1000
# Salt that separates validation draws from the instance generator's stream.
_VALIDATION_SALT = 0x5EED


def spectral_radius(M) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def _cost_to_go(instance, K):
    """Backward recursion P_t = Q + K'RK + Acl' P_{t+1} Acl, P_T = P; returns [P_0..P_T]."""
    Acl = instance.A + instance.B @ K
    stage = instance.Q + K.T @ instance.R @ K
    Ps = [None] * (instance.horizon + 1)
    Ps[-1] = instance.P
    for t in range(instance.horizon - 1, -1, -1):
        Ps[t] = stage + Acl.T @ Ps[t + 1] @ Acl
    return Ps, Acl


def static_gain_cost(instance, K, *, noise_std: float = 0.0) -> float:
    """Exact normalized expected cost of ``u = K x`` over the instance's horizon.

    Parameters
    ----------
    instance : Instance
    K : array_like, shape (n, n)
        Gain with the sign included (``u = K x``).
    noise_std : float
        Standard deviation of i.i.d. process noise ``w(t) ~ N(0, noise_std^2 I)``
        added to ``x(t+1)`` for t = 0..T-1.
    """
    K = np.asarray(K, dtype=float)
    Ps, _ = _cost_to_go(instance, K)
    total = np.trace(Ps[0]) + noise_std**2 * sum(np.trace(Pt) for Pt in Ps[1:])
    return float(total / instance.trace_P)


def static_gain_cost_and_grad(instance, K) -> tuple[float, np.ndarray]:
    """Exact normalized cost of ``u = K x`` and its gradient with respect to K.

    With Sigma_t = E[x(t) x(t)'] = Acl^t Acl^t', the gradient is
    ``sum_t 2 (R K + B' P_{t+1} Acl) Sigma_t`` (divided by trace(P)).
    """
    K = np.asarray(K, dtype=float)
    Ps, Acl = _cost_to_go(instance, K)
    grad = np.zeros_like(K)
    sigma = np.eye(instance.n)
    RK = instance.R @ K
    for t in range(instance.horizon):
        grad += (RK + instance.B.T @ Ps[t + 1] @ Acl) @ sigma
        sigma = Acl @ sigma @ Acl.T
    scale = instance.trace_P
    return float(np.trace(Ps[0]) / scale), 2.0 * grad / scale


def response_cost(instance, phi_x, phi_u, *, noise_std: float = 0.0) -> float:
    """Exact normalized cost from closed-loop response maps.

    Parameters
    ----------
    phi_x : array_like, shape (T + 1, n, n)
        ``x(t) = phi_x[t] x(0)`` for t = 0..T (so ``phi_x[0] = I``).
    phi_u : array_like, shape (T, n, n)
        ``u(t) = phi_u[t] x(0)`` for t = 0..T-1.
    noise_std : float
        Process noise ``w(t) ~ N(0, noise_std^2 I)`` added to ``x(t+1)`` for
        t = 0..T-1, for a time-invariant closed loop: the noise entering at time s
        is answered by the same maps with T - s steps left, so with c(m) the cost
        of the maps over horizon m (terminal P at m),
        ``E[J] = c(T) + noise_std^2 * sum_{m<T} c(m)``.
    """
    phi_x = np.asarray(phi_x, dtype=float)
    phi_u = np.asarray(phi_u, dtype=float)
    T, n = instance.horizon, instance.n
    if phi_x.shape != (T + 1, n, n) or phi_u.shape != (T, n, n):
        raise ValueError(
            f"response maps must have shapes {(T + 1, n, n)} and {(T, n, n)}, "
            f"got {phi_x.shape} and {phi_u.shape}"
        )
    if not (np.isfinite(noise_std) and noise_std >= 0):
        raise ValueError(f"noise_std must be a non-negative number, got {noise_std!r}")
    stage = np.einsum("tij,ik,tkj->t", phi_x[:T], instance.Q, phi_x[:T])
    stage += np.einsum("tij,ik,tkj->t", phi_u, instance.R, phi_u)
    if not noise_std:
        total = stage.sum() + np.einsum("ij,ik,kj->", phi_x[T], instance.P, phi_x[T])
        return float(total / instance.trace_P)
    terminal = np.einsum("tij,ik,tkj->t", phi_x, instance.P, phi_x)
    horizon_cost = np.concatenate([[0.0], np.cumsum(stage)]) + terminal  # c(m), m = 0..T
    total = horizon_cost[T] + noise_std**2 * horizon_cost[:T].sum()
    return float(total / instance.trace_P)


def validation_set(instance, size: int = VALIDATION_SIZE, *, seed: int | None = None) -> np.ndarray:
    """The fixed set of initial conditions x(0) ~ N(0, I) used to score controllers.

    The same instance (and seed) always gives the same set, so every method on
    an instance is scored on the same draws. ``seed`` defaults to the instance's
    generator seed, kept apart from the generator's own stream.
    """
    if size < 2:
        raise ValueError(f"validation size must be at least 2, got {size}")
    seed = instance.seed if seed is None else int(seed)
    rng = np.random.default_rng([seed, _VALIDATION_SALT])
    return rng.standard_normal((size, instance.n))


@dataclass(frozen=True)
class Rollout:
    """Costs of a batched simulation.

    ``cost`` and ``stderr`` are normalized by trace(P); ``costs`` holds each
    trajectory's normalized cost. ``bounded`` is False when a state or input
    became non-finite or exceeded ``bound``; ``max_state`` is the largest
    ``|x_i(t)|`` seen.
    """

    cost: float
    stderr: float
    costs: np.ndarray
    bounded: bool
    max_state: float
    steps: int


def simulate(
    instance,
    controller,
    x0=None,
    *,
    steps: int | None = None,
    noise_std: float = 0.0,
    seed: int = 0,
    bound: float = 1e8,
) -> Rollout:
    """Roll ``controller`` out from each row of ``x0`` and score the trajectories.

    Parameters
    ----------
    instance : Instance
    controller : object
        See :mod:`codesign.controllers` for the interface.
    x0 : array_like, shape (batch, n), optional
        Initial conditions; the instance's validation set by default.
    steps : int, optional
        Number of steps, the instance's horizon by default. The terminal cost
        ``x(steps)' P x(steps)`` is always added.
    noise_std : float
        Process noise ``w(t) ~ N(0, noise_std^2 I)`` added to ``x(t+1)``, drawn
        from ``seed``.
    bound : float
        A state beyond this magnitude marks the rollout as unbounded.
    """
    x = validation_set(instance) if x0 is None else np.array(x0, dtype=float)
    if x.ndim != 2 or x.shape[1] != instance.n:
        raise ValueError(f"x0 must have shape (batch, {instance.n}), got {x.shape}")
    steps = instance.horizon if steps is None else int(steps)
    rng = np.random.default_rng(seed) if noise_std else None
    batch = x.shape[0]
    A_T, B_T = instance.A.T, instance.B.T
    Q, R = instance.Q, instance.R
    costs = np.zeros(batch)
    max_state = float(np.max(np.abs(x)))
    state = controller.reset(batch)
    bounded = True
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(steps):
            u, state = controller.step(state, x)
            costs += np.einsum("bi,ij,bj->b", x, Q, x) + np.einsum("bi,ij,bj->b", u, R, u)
            x = x @ A_T + u @ B_T
            if rng is not None:
                x = x + noise_std * rng.standard_normal(x.shape)
            peak = float(np.max(np.abs(x)))
            max_state = max(max_state, peak) if np.isfinite(peak) else float("inf")
            if not np.isfinite(peak) or peak > bound:
                bounded = False
                break
        costs += np.einsum("bi,ij,bj->b", x, instance.P, x)
    costs = costs / instance.trace_P
    if not bounded or not np.all(np.isfinite(costs)):
        return Rollout(float("inf"), float("inf"), costs, False, max_state, steps)
    return Rollout(
        float(costs.mean()),
        float(costs.std(ddof=1) / np.sqrt(batch)),
        costs,
        True,
        max_state,
        steps,
    )


def exact_cost(instance, controller, *, noise_std: float = 0.0) -> float | None:
    """Closed-form normalized cost of a linear controller, or None if it has none.

    Static gains (``controller.K``) are scored by a Lyapunov recursion; dynamic
    time-invariant linear controllers by their closed-loop responses
    (``controller.closed_loop_responses(instance) -> (phi_x, phi_u)``).
    """
    if hasattr(controller, "closed_loop_responses"):
        phi_x, phi_u = controller.closed_loop_responses(instance)
        return response_cost(instance, phi_x, phi_u, noise_std=noise_std)
    K = getattr(controller, "K", None)
    if K is None:
        return None
    return static_gain_cost(instance, K, noise_std=noise_std)


def compare_exact_and_simulated(instance, controller, x0=None) -> dict:
    """Exact versus simulated cost of a linear controller, with the z-score.

    Returns a dict with ``exact``, ``simulated``, ``stderr`` and ``z``
    (``(simulated - exact) / stderr``); ``|z| <= 3`` is the expected agreement.
    """
    exact = exact_cost(instance, controller)
    if exact is None:
        raise TypeError(f"{type(controller).__name__} has no closed-form cost")
    rollout = simulate(instance, controller, x0)
    z = (rollout.cost - exact) / rollout.stderr if rollout.stderr > 0 else float("inf")
    return {"exact": exact, "simulated": rollout.cost, "stderr": rollout.stderr, "z": float(z)}
