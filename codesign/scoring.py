"""Scoring: from a controller to a scored :class:`Design`, and the harness's common evaluation.

Methods design, the evaluation scores (benchopt's split): :func:`score` turns any
controller into a ``Design`` (exact cost where a closed form exists, else the
validation-set estimate), and :func:`evaluate` is what the comparison harness
applies to every design a method returns, so that every simulated cost on an
instance comes from the same validation set of the size the experiment asks for.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .design import INFO_MODELS, Design, count_links
from .evaluation import (MAX_VALIDATION_SIZE, PRECISION_TARGET, VALIDATION_SIZE, exact_cost, simulate,
                         simulate_to_precision, validation_set)
from .status import DIVERGED, FAILED, USABLE

__all__ = ["score", "evaluate"]


def _support(instance, controller):
    """The controller's node-level support (N, N), from its own ``support`` or its gain ``K``."""
    support = getattr(controller, "support", None)
    if support is None:
        support = getattr(controller, "K", None)
    if support is None:
        return None
    support = np.asarray(support)
    if support.shape == (instance.m, instance.n) and support.shape != (instance.nodes, instance.nodes):
        support = instance.node_support(support)  # a gain's entries, input by state
    return support


def _non_finite(controller) -> str | None:
    """The name of a controller array holding NaN or an infinity, or None (also for a controller without arrays).

    Such a controller is a method's arithmetic gone wrong, not a closed loop that blows up: its
    design is ``failed``, not ``diverged`` (a finite unstable gain is the latter).
    """
    arrays = getattr(controller, "arrays", None)
    if arrays is None:
        return None
    try:
        items = dict(arrays()).items()
    except Exception:  # noqa: BLE001 - a controller whose arrays cannot be read is scored as before
        return None
    for name, value in items:
        value = np.asarray(value)
        if value.dtype.kind in "fc" and not np.all(np.isfinite(value)):
            return name
    return None


def score(
    instance,
    controller,
    *,
    info_model: str | None = None,
    links: int | None = None,
    self_loops: int | None = None,
    validation_size: int = VALIDATION_SIZE,
    params: dict | None = None,
    message: str = "",
    seconds: float = 0.0,
    extras: dict | None = None,
) -> Design:
    """A scored :class:`Design` for ``controller`` on ``instance``.

    Parameters
    ----------
    instance : Instance
    controller : object
        A :class:`~codesign.controllers.StaticGain`, a linear dynamic controller
        with ``closed_loop_responses(instance)``, or any object with the
        controller protocol (``reset``/``step``; see :mod:`codesign.controllers`).
    info_model : str, optional
        One of :data:`~codesign.design.INFO_MODELS`; by default the controller's
        ``info_model`` attribute if it has one, else ``"instantaneous"`` when it
        uses links and ``"none"`` when it does not.
    links, self_loops : int, optional
        Directed off-diagonal links and self-loops; by default counted from the
        controller's ``support`` (or its gain ``K``). Required when it has neither.
    validation_size : int
        Draws of the instance's validation set for a controller with no closed-form cost.
    params, message, seconds, extras
        Stored with the design; the harness fills ``params`` with the run's
        hyperparameters when left empty, and stamps the method's name.

    Returns
    -------
    Design
        Exact cost (``cost_kind="exact"``) for linear controllers, else the
        simulated estimate of :func:`evaluate` with its standard error
        (``"simulated"``: the validation-set control-variate estimate, refined
        where a pilot says so); status ``"diverged"`` when a draw of either
        leaves the bound, ``"failed"`` (no controller kept) when the controller's
        arrays hold NaN or infinities. A simulated cost is always computed here,
        whatever ``extras`` hold.
    """
    support = _support(instance, controller)
    if support is not None:
        counted = count_links(support)
        links = counted[0] if links is None else links
        self_loops = counted[1] if self_loops is None else self_loops
    if links is None:
        raise ValueError(f"{type(controller).__name__} has no support or K: pass links= (and self_loops=)")
    self_loops = 0 if self_loops is None else self_loops
    info_model = info_model or getattr(controller, "info_model", None) or ("instantaneous" if links else "none")
    if info_model not in INFO_MODELS:
        raise ValueError(f"info_model must be one of {INFO_MODELS}, got {info_model!r}")
    bad = _non_finite(controller)
    if bad is not None:
        why = f"the controller's {bad} has NaN or infinite entries: no controller to score"
        return Design.failure("", dict(params or {}), FAILED, "; ".join(filter(None, [why, message])),
                              info_model=info_model, seconds=seconds, extras=dict(extras or {}))
    design = Design(method="", params=dict(params or {}), controller=controller, cost=1.0, links=int(links),
                    self_loops=int(self_loops), info_model=info_model, message=message, seconds=seconds,
                    extras=dict(extras or {}))
    exact = exact_cost(instance, controller)
    if exact is not None:
        if not np.isfinite(exact):
            return replace(design, status=DIVERGED, cost=float("nan"), cost_stderr=float("nan"),
                           message=message or "the exact cost is not finite")
        return replace(design, cost=exact, cost_stderr=0.0, cost_kind="exact")
    return _simulated(instance, replace(design, cost_kind="simulated"), validation_size)


def _simulated(instance, design: Design, validation_size: int) -> Design:
    """``design`` with the cost :func:`~codesign.evaluation.simulate_to_precision` gives it, or ``diverged``."""
    rollout = simulate_to_precision(instance, design.controller, validation_size,
                                    max_size=max(validation_size, MAX_VALIDATION_SIZE))
    extras = dict(design.extras, **rollout.summary())
    if not rollout.bounded or not np.isfinite(rollout.cost):
        message = rollout.divergence or f"the controller's {validation_size}-draw validation rollout is unbounded"
        return Design.failure(design.method, design.params, DIVERGED, message, info_model=design.info_model,
                              seconds=design.seconds, links=design.links, self_loops=design.self_loops,
                              extras=extras)
    return replace(design, cost=rollout.cost, cost_stderr=rollout.stderr, extras=extras)


def _scored_to_precision(extras: dict, validation_size: int) -> bool:
    """Whether :func:`~codesign.evaluation.simulate_to_precision` made the design's cost as the harness would.

    Read from the structured record its rollout summary leaves in the extras
    (:class:`~codesign.evaluation.PrecisionRecord`): at least ``validation_size``
    shared validation draws, a precision target no looser than
    :data:`~codesign.evaluation.PRECISION_TARGET` and no fewer draws allowed.
    Such a design is never rolled out again (the GRNN and GCNN score their own
    designs this way, refined ones included).
    """
    target = extras.get("precision_target")
    return (target is not None and target <= PRECISION_TARGET
            and extras.get("shared_validation_draws", 0) >= validation_size
            and extras.get("max_draws", 0) >= max(validation_size, MAX_VALIDATION_SIZE))


def evaluate(instance, design: Design, *, validation_size: int = VALIDATION_SIZE, noise_std: float = 0.0) -> Design:
    """Score a method's design the way the harness does.

    A simulated cost is made by :func:`codesign.evaluation.simulate_to_precision`
    on the instance's first ``validation_size`` validation draws (the same draws
    for every method), refined on importance-sampled draws where a pilot
    projects a relative standard error above 0.1 %; a design whose extras show
    it was already scored that way on at least these draws keeps its cost and
    is not rolled out again. The design becomes ``diverged`` if any draw of that
    estimate (validation, pilot or importance-sampled) leaves the rollout's
    bound, with a message naming the draw; exact costs are kept. The cost is the
    control-variate estimate and the extras keep the plain sample mean
    (``plain_cost``, ``plain_cost_stderr``), the draws, the estimator and the
    precision record. With ``noise_std > 0`` the design also gets a
    process-noise robustness score in its extras (``noise_cost``,
    ``noise_cost_stderr``): exact for linear controllers, simulated otherwise.
    """
    if design.controller is None or design.status not in USABLE:
        return design
    if design.cost_kind == "simulated" and not _scored_to_precision(design.extras, validation_size):
        design = _simulated(instance, design, validation_size)
        if design.status == DIVERGED:
            return design
    if noise_std > 0:
        cost = exact_cost(instance, design.controller, noise_std=noise_std)
        stderr = 0.0
        if cost is None:
            rollout = simulate(instance, design.controller, validation_set(instance, validation_size),
                               noise_std=noise_std, seed=instance.seed, control_variates=True)
            cost, stderr = rollout.cost, rollout.stderr
        design = replace(design, extras=dict(design.extras, noise_std=noise_std, noise_cost=cost,
                                             noise_cost_stderr=stderr))
    return design
