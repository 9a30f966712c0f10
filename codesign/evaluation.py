"""One scoring path for every method.

The benchmark cost is

    J = sum_{t=0}^{T-1} [x(t)'Q x(t) + u(t)'R u(t)] + x(T)'P x(T),   x(0) ~ N(0, I),

normalized by trace(P), which is what centralized LQR achieves exactly. Linear
controllers are scored in closed form (no sampling noise); any controller can be
scored by a batched rollout on a fixed, seeded validation set.

A rollout on the validation set reports a control-variate estimate: the
per-draw cost J(x0) is regressed on quadratic monomials x0_i x0_j, whose means
under x0 ~ N(0, I) are known exactly (delta_ij). A learned controller is close
to linear near the origin, so J(x0) is nearly a quadratic form and the residual
variance is a small fraction of the plain one (about 50x smaller in standard
error on paper instances). Coefficients are cross-fitted (each fold's residuals
use coefficients fitted on the other folds), which keeps the estimator exactly
unbiased; the plain sample mean is reported beside it.
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
    "simulate_to_precision",
    "Rollout",
    "exact_cost",
    "compare_exact_and_simulated",
    "spectral_radius",
    "control_variate_estimate",
    "impulse_responses",
]

VALIDATION_SIZE = 2000
#: Relative standard error a simulated cost aims for (:func:`simulate_to_precision`).
PRECISION_TARGET = 1e-3
#: The most validation draws :func:`simulate_to_precision` rolls out (16 x VALIDATION_SIZE).
MAX_VALIDATION_SIZE = 32000
#: Folds of the cross-fitted control-variate regression.
CV_FOLDS = 10
# Regression rows per coefficient at least this many, so that coefficients
# fitted on (CV_FOLDS - 1) folds do not overfit; beyond, fewer features are used.
_ROWS_PER_FEATURE = 4
_MAX_FEATURES = 1500
# Below this many draws the regression has too little to fit: the sample mean is reported.
_MIN_CV_DRAWS = 200
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
    phi_u : array_like, shape (T, m, n)
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
    T, n, m = instance.horizon, instance.n, instance.m
    if phi_x.shape != (T + 1, n, n) or phi_u.shape != (T, m, n):
        raise ValueError(
            f"response maps must have shapes {(T + 1, n, n)} and {(T, m, n)}, "
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

    ``cost`` and ``stderr`` are normalized by trace(P): the control-variate
    estimate when ``estimator`` names one, else the sample mean. ``plain_cost``
    and ``plain_stderr`` are always the sample mean and its standard error;
    ``costs`` holds each trajectory's normalized cost. ``bounded`` is False when
    a state or input became non-finite or exceeded ``bound``; ``max_state`` is
    the largest ``|x_i(t)|`` seen.
    """

    cost: float
    stderr: float
    costs: np.ndarray
    bounded: bool
    max_state: float
    steps: int
    plain_cost: float = float("nan")
    plain_stderr: float = float("nan")
    estimator: str = "sample mean"

    def summary(self) -> dict:
        """What a design stores about this rollout (its extras)."""
        return {"validation_size": int(self.costs.shape[0]), "cost_estimator": self.estimator,
                "plain_cost": self.plain_cost, "plain_cost_stderr": self.plain_stderr}


def _quadratic_features(instance, x0):
    """Quadratic monomials of x0 with their exact means, as many as the draws support.

    All pairs i <= j when there are enough draws; else the squares, the pairs
    coupled in the plant or communication graph, and x0'Px0 (which carries the
    LQR's cost-to-go, the best single quadratic guess).
    """
    m, n = x0.shape
    budget = min(_MAX_FEATURES, (m * (CV_FOLDS - 1)) // (CV_FOLDS * _ROWS_PER_FEATURE))
    rows, cols = np.triu_indices(n)
    name = f"all {rows.size} quadratic monomials"
    extra = None
    if rows.size > budget:
        coupled = (instance.plant_adj != 0) | (instance.comm_adj != 0)
        coupled = coupled | coupled.T | np.eye(coupled.shape[0], dtype=bool)
        nodes = instance.state_nodes  # the graphs are between nodes; the monomials between states
        keep = (rows == cols) | coupled[nodes[rows], nodes[cols]]
        rows, cols = rows[keep], cols[keep]
        name = f"{rows.size} squares and graph-coupled monomials + x0'Px0"
        if rows.size + 1 > budget:
            rows = cols = np.arange(n)
            name = f"{n} squares + x0'Px0"
        extra = np.einsum("bi,bi->b", x0 @ instance.P, x0)[:, None], np.array([instance.trace_P])
    features = x0[:, rows] * x0[:, cols]
    means = (rows == cols).astype(float)
    if extra is not None:
        features = np.hstack([features, extra[0]])
        means = np.concatenate([means, extra[1]])
    return features, means, name


def control_variate_estimate(instance, x0, costs) -> tuple[float, float, str]:
    """Cross-fitted control-variate estimate of the mean of ``costs``.

    Parameters
    ----------
    instance : Instance
    x0 : ndarray, shape (batch, n)
        Initial conditions, drawn i.i.d. N(0, I): the exact means of the
        quadratic features rest on it.
    costs : ndarray, shape (batch,)
        Each trajectory's cost.

    Returns
    -------
    cost, stderr, estimator : float, float, str
        The estimate, its standard error, and a description of the features.
        Unbiased for any controller: draw i's residual uses coefficients fitted
        without the fold that holds it.
    """
    costs = np.asarray(costs, dtype=float)
    m = costs.shape[0]
    features, means, name = _quadratic_features(instance, np.asarray(x0, dtype=float))
    centered = np.hstack([np.ones((m, 1)), features - means])
    fold = np.arange(m) % CV_FOLDS
    gram, moment = centered.T @ centered, centered.T @ costs
    residuals = np.empty(m)
    for k in range(CV_FOLDS):
        inside = fold == k
        Ck = centered[inside]
        coef = np.linalg.lstsq(gram - Ck.T @ Ck, moment - Ck.T @ costs[inside], rcond=None)[0]
        residuals[inside] = costs[inside] - Ck[:, 1:] @ coef[1:]
    estimator = f"control variates: {name}, {CV_FOLDS}-fold cross-fit"
    return float(residuals.mean()), float(residuals.std(ddof=1) / np.sqrt(m)), estimator


def simulate(
    instance,
    controller,
    x0=None,
    *,
    steps: int | None = None,
    noise_std: float = 0.0,
    seed: int = 0,
    bound: float = 1e8,
    control_variates: bool | None = None,
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
    control_variates : bool, optional
        Report the control-variate estimate (:func:`control_variate_estimate`)
        as ``cost``. Only valid when the rows of ``x0`` are i.i.d. N(0, I), so
        the default is True when ``x0`` is the validation set (None) and False
        for a given ``x0``; the sample mean is in ``plain_cost`` either way.
    """
    if control_variates is None:
        control_variates = x0 is None
    x = validation_set(instance) if x0 is None else np.array(x0, dtype=float)
    if x.ndim != 2 or x.shape[1] != instance.n:
        raise ValueError(f"x0 must have shape (batch, {instance.n}), got {x.shape}")
    steps = instance.horizon if steps is None else int(steps)
    rng = np.random.default_rng(seed) if noise_std else None
    batch = x.shape[0]
    A_T, B_T = instance.A.T, instance.B.T
    Q, R = instance.Q, instance.R
    x_start = x
    costs = np.zeros(batch)
    max_state = float(np.max(np.abs(x)))
    state = controller.reset(batch)
    bounded = True
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(steps):
            u, state = controller.step(state, x)
            # Row-wise quadratic forms through a matrix product: a three-operand
            # einsum is several times slower at these sizes.
            costs += np.einsum("bi,bi->b", x @ Q, x) + np.einsum("bi,bi->b", u @ R, u)
            x = x @ A_T + u @ B_T
            if rng is not None:
                x = x + noise_std * rng.standard_normal(x.shape)
            peak = float(np.max(np.abs(x)))
            max_state = max(max_state, peak) if np.isfinite(peak) else float("inf")
            if not np.isfinite(peak) or peak > bound:
                bounded = False
                break
        costs += np.einsum("bi,bi->b", x @ instance.P, x)
    costs = costs / instance.trace_P
    if not bounded or not np.all(np.isfinite(costs)):
        inf = float("inf")
        return Rollout(inf, inf, costs, False, max_state, steps, inf, inf)
    plain, plain_stderr = float(costs.mean()), float(costs.std(ddof=1) / np.sqrt(batch))
    cost, stderr, estimator = plain, plain_stderr, "sample mean"
    if control_variates and batch >= _MIN_CV_DRAWS:
        cost, stderr, estimator = control_variate_estimate(instance, x_start, costs)
    return Rollout(cost, stderr, costs, True, max_state, steps, plain, plain_stderr, estimator)


def simulate_to_precision(instance, controller, size: int = VALIDATION_SIZE, *,
                          target: float = PRECISION_TARGET, max_size: int = MAX_VALIDATION_SIZE) -> Rollout:
    """The control-variate estimate on the first ``size`` validation draws, extended until precise.

    While the relative standard error exceeds ``target``, the rollout continues on
    the next validation draws (doubling the count, up to ``max_size``): validation
    sets are nested, so the first ``size`` draws, which every method shares, stay
    in the estimate, and a well-behaved controller costs no extra rollout. A
    heavy-tailed cost (a closed loop close to unstable) may stop at ``max_size``
    above the target; its standard error says so. ``Rollout.costs`` holds every draw used.
    """
    if max_size < size:
        raise ValueError(f"max_size must be at least size ({size}), got {max_size}")
    x0 = validation_set(instance, size)
    rollout = simulate(instance, controller, x0, control_variates=True)
    while (rollout.bounded and np.isfinite(rollout.cost) and size < max_size
           and rollout.stderr > target * abs(rollout.cost)):
        size = min(2 * size, max_size)
        every = validation_set(instance, size)
        more = simulate(instance, controller, every[x0.shape[0]:], control_variates=False)
        x0 = every
        costs = np.concatenate([rollout.costs, more.costs])
        if not more.bounded:
            inf = float("inf")
            return Rollout(inf, inf, costs, False, more.max_state, rollout.steps, inf, inf)
        cost, stderr, estimator = control_variate_estimate(instance, x0, costs)
        rollout = Rollout(cost, stderr, costs, True, max(rollout.max_state, more.max_state), rollout.steps,
                          float(costs.mean()), float(costs.std(ddof=1) / np.sqrt(costs.size)), estimator)
    return rollout


def impulse_responses(instance, controller, steps: int | None = None):
    """Closed-loop maps ``(phi_x, phi_u)`` of a linear controller, by rollout from ``x(0) = e_j``.

    For a controller that is linear in its state and x (any linear dynamic
    controller with the ``reset``/``step`` protocol), ``x(t) = phi_x[t] x(0)`` and
    ``u(t) = phi_u[t] x(0)``: the actual closed loop, which
    :func:`response_cost` scores exactly. Shapes ``(steps + 1, n, n)`` and
    ``(steps, n, n)``; ``steps`` defaults to the horizon.
    """
    n, m = instance.n, instance.m
    steps = instance.horizon if steps is None else int(steps)
    phi_x = np.empty((steps + 1, n, n))
    phi_u = np.empty((steps, m, n))
    x = np.eye(n)  # row j: the trajectory from x(0) = e_j
    state = controller.reset(n)
    phi_x[0] = x.T
    for t in range(steps):
        u, state = controller.step(state, x)
        x = x @ instance.A.T + u @ instance.B.T
        phi_u[t] = u.T
        phi_x[t + 1] = x.T
    return phi_x, phi_u


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

    Returns a dict with ``exact``, ``simulated`` (the sample mean), ``stderr`` and
    ``z`` (``(simulated - exact) / stderr``; ``|z| <= 3`` is the expected
    agreement), and ``control_variate`` (the control-variate estimate on the
    validation set, which for a linear controller recovers the exact cost up to
    rounding, because its J(x0) is a quadratic form; NaN for a given ``x0``).
    """
    exact = exact_cost(instance, controller)
    if exact is None:
        raise TypeError(f"{type(controller).__name__} has no closed-form cost")
    rollout = simulate(instance, controller, x0)
    cost, stderr = rollout.plain_cost, rollout.plain_stderr
    z = (cost - exact) / stderr if stderr > 0 else float("inf")
    cv = rollout.cost if rollout.estimator != "sample mean" else float("nan")
    return {"exact": exact, "simulated": cost, "stderr": stderr, "z": float(z), "control_variate": cv}
