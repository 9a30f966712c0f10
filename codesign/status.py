"""Design statuses and their groups, defined once.

Every :class:`~codesign.design.Design` carries one of five status words. Code
that branches on them names the constant or, for the question it actually asks,
the group (``status in USABLE``: "does this design's cost count?"), so that the
answer to that question is written in one place and a new status is added in
one place. cvxpy's ``settings.py`` is the model: named status constants and
named groups of them (its ``SOLUTION_PRESENT``, ``INF_OR_UNB``, ...).

A solver's own status words (cvxpy's ``optimal_inaccurate``, ``user_limit``,
...) are not design statuses; :data:`SOLVER_STATUS` is the one policy that turns
them into ours. Code that inspects a raw solver status compares it with cvxpy's
constants (``cvxpy.OPTIMAL``), not with these.

The stability rule is here too, because it decides between ``optimal`` and
``diverged`` for every static design: a closed loop is stable when its spectral radius
is below ``1 - tol``, and ``tol`` is measured in the plant's own time
(:func:`stability_tol`): a tenth of the decay per step of the plant's slowest decaying
mode, capped at :data:`STABILITY_TOL` = 1e-6. A fixed margin per step would make the
verdict depend on the sampling time the model's author chose (a stable plant with a
mode at -5e-6 1/s, held at dt = 0.01, has radius 1 - 5e-8 and was called unstable);
a ratio of two decays does not. Plants whose modes all decay by 1e-5 a step or more
(every shipped instance) keep the fixed margin and every verdict.
"""

from __future__ import annotations

import weakref

import numpy as np

__all__ = [
    "OPTIMAL",
    "INACCURATE",
    "INFEASIBLE",
    "DIVERGED",
    "FAILED",
    "STATUSES",
    "USABLE",
    "NO_DESIGN",
    "SOLVER_STATUS",
    "INACCURATE_RTOL",
    "STABILITY_TOL",
    "STABILITY_FRACTION",
    "STABILITY_RESOLVED",
    "stability_tol",
    "is_stable",
    "solver_status",
    "vet_solver_cost",
]

#: Solved: the design's cost is trustworthy.
OPTIMAL = "optimal"
#: Solved to looser tolerances than asked (a solver's reduced tolerances, a polish that
#: stopped early); the cost counts, and the design's message says what fell short.
INACCURATE = "inaccurate"
#: The problem as posed has no solution (e.g. an SLS support no controller can meet).
INFEASIBLE = "infeasible"
#: Training or a rollout blew up, or the controller does not stabilize the plant.
DIVERGED = "diverged"
#: Anything else that left no usable controller (solver error, iteration limit, an
#: unsupported instance, a method that raised).
FAILED = "failed"

#: Every status a design can carry, in this order.
STATUSES = (OPTIMAL, INACCURATE, INFEASIBLE, DIVERGED, FAILED)

#: The design has a controller and its cost counts (a finite number on plots and in tables).
USABLE = (OPTIMAL, INACCURATE)
#: No usable controller: the cost is NaN and the message says why.
NO_DESIGN = (INFEASIBLE, DIVERGED, FAILED)

#: The one policy from a convex solver's status (cvxpy's names, ``cvxpy.settings``) to a
#: design status; any other status (``user_limit``, ``solver_error``, ``unbounded``, ...)
#: is ``failed``. The keys are cvxpy's words, spelled here so that importing
#: :mod:`codesign` does not import cvxpy (about a second); tests/test_status.py checks
#: them against cvxpy's constants.
SOLVER_STATUS = {
    "optimal": OPTIMAL,
    "optimal_inaccurate": INACCURATE,
    "infeasible": INFEASIBLE,
    "infeasible_inaccurate": INFEASIBLE,
}

#: Relative gap allowed between an ``inaccurate`` solve's objective and the exact cost
#: of its design. Clarabel reports ``optimal_inaccurate`` when it meets its reduced
#: tolerances (5e-5 relative duality gap, 1e-4 feasibility) but not the full ones, so an
#: honest inaccurate solution agrees to about 1e-4; 1e-3 leaves room for that and
#: still rejects the solves that stop far away (objectives off by orders of magnitude,
#: e.g. 1e29 on infeasible supports).
INACCURATE_RTOL = 1e-3

#: The stability rule's margin, at most: a static design (a gain ``u = K x``, or a delayed
#: gain on its augmented loop) is usable only if its closed loop's spectral radius is below
#: ``1 - tol``, where ``tol`` is this, or less on a plant with a slow mode of its own
#: (:func:`stability_tol`); otherwise the design is ``diverged``. The benchmark's cost is a
#: finite-horizon one, finite for unstable gains too, so the cost alone cannot say this.
#: The margin is far above the eigenvalue solver's error on these loops (about 1e-12
#: relative), and on a plant whose own modes decay by 1e-5 a step or faster a loop within
#: it of the unit circle (a time constant of a million steps or more) stabilizes nothing a
#: report should count.
STABILITY_TOL = 1e-6
#: On a plant with a slow stable mode, the margin is this fraction of that mode's decay per
#: step ``1 - |lambda|``: a closed loop counts as stable when it decays at least a tenth as
#: fast as the plant's own slowest decaying mode (:func:`stability_tol`).
STABILITY_FRACTION = 0.1
#: A plant mode gives a time scale only when it decays by at least this much a step
#: (``|lambda| <= 1 - 1e-8``): closer to the circle, the eigenvalue solver cannot tell decay
#: from rounding (a double eigenvalue on the circle comes out within about sqrt(eps) =
#: 1.5e-8 of it), and the plant counts as having no slow decay of its own.
STABILITY_RESOLVED = 1e-8

# stability_tol's answer per instance (the eigenvalues of A, computed at most once).
_TOLERANCES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def stability_tol(instance=None) -> float:
    """The stability rule's margin on this plant: a closed loop is stable when its radius is below ``1 - tol``.

    A margin on the spectral radius is a statement about decay per step, and a step is
    whatever the model's author chose: the same plant sampled ten times finer has every
    ``1 - |lambda|`` ten times smaller. A fixed margin therefore calls a finely sampled
    stable plant unstable (a continuous-time mode at -5e-6 1/s, held at dt = 0.01, has
    radius ``1 - 5e-8``; :data:`STABILITY_TOL` would need it at ``1 - 1e-6``). The rule
    here measures decay in the plant's own time instead: with ``d`` the decay per step
    ``1 - |lambda|`` of the slowest of A's modes that visibly decay (``d >=``
    :data:`STABILITY_RESOLVED`),

        tol = min(STABILITY_TOL, STABILITY_FRACTION * d),

    and ``tol = STABILITY_TOL`` where no mode decays visibly (an unstable plant whose modes
    are all outside, or on, the circle; an undamped chain with every mode on it). So a
    closed loop counts as stable when it decays at least a tenth as fast as the plant's own
    slowest mode, or by 1e-6 a step, whichever asks less; the ratio of two decays does not
    depend on the sampling time (to first order in ``d``), so neither does the verdict on
    a slow plant. It never asks more than the fixed margin did: every plant whose modes
    all decay by 1e-5 a step or more (every shipped instance) keeps the margin 1e-6 and
    every verdict, and a plant with a slow mode keeps a margin at least 1e-9, a thousand
    times the eigenvalue solver's error on these loops.

    Parameters
    ----------
    instance : Instance or array_like, optional
        The plant (anything with an ``A``), or its A itself. None: no plant, the fixed
        margin :data:`STABILITY_TOL`.

    Returns
    -------
    float
        In ``[1e-9, 1e-6]``. Computed from A's eigenvalues once per instance.
    """
    if instance is None:
        return STABILITY_TOL
    A = getattr(instance, "A", None)
    if A is None:
        return _tolerance(np.asarray(instance, dtype=float))
    try:
        return _TOLERANCES[instance]
    except (KeyError, TypeError):
        pass
    tol = _tolerance(np.asarray(A, dtype=float))
    try:
        _TOLERANCES[instance] = tol
    except TypeError:  # not weakly referable: computed again next time
        pass
    return tol


def _tolerance(A: np.ndarray) -> float:
    moduli = np.abs(np.linalg.eigvals(A))
    decaying = moduli[moduli <= 1.0 - STABILITY_RESOLVED]
    if decaying.size == 0:
        return STABILITY_TOL
    return float(min(STABILITY_TOL, STABILITY_FRACTION * (1.0 - decaying.max())))


def is_stable(radius, instance=None) -> bool:
    """Whether a closed loop of this spectral radius counts as stable: ``radius < 1 - stability_tol(instance)``.

    Parameters
    ----------
    radius : float
        The closed loop's spectral radius (NaN and inf are unstable).
    instance : Instance or array_like, optional
        The plant, whose own slowest decay sets the margin (:func:`stability_tol`);
        without it, the fixed margin :data:`STABILITY_TOL`. The plant's eigenvalues are
        computed only where they can change the answer (a radius in ``[1 - 1e-6, 1)``).
    """
    radius = float(radius)
    if not radius < 1.0:
        return False
    if radius < 1.0 - STABILITY_TOL:
        return True
    return instance is not None and radius < 1.0 - stability_tol(instance)


def solver_status(raw) -> str:
    """Design status for a solver's status string (see :data:`SOLVER_STATUS`); unknown -> ``"failed"``."""
    return SOLVER_STATUS.get(str(raw), FAILED)


def vet_solver_cost(status: str, objective: float, cost: float, *, rtol: float = INACCURATE_RTOL) -> tuple[str, str]:
    """Keep a solve's status only when the exact cost of its design backs the solver's objective.

    Parameters
    ----------
    status : str
        The design status from :func:`solver_status`; only :data:`USABLE`
        statuses are checked, others are returned as they are.
    objective : float
        The solver's objective, in the same (normalized) units as ``cost``.
    cost : float
        The design's cost re-evaluated in closed form (from the realized
        controller, not from the solver's variables).
    rtol : float
        Largest relative gap ``|cost - objective| / max(1, |cost|)`` (normalized
        costs are >= 1). The default suits ``inaccurate`` solves; a method passes
        its own, tighter one for ``optimal`` solves.

    Returns
    -------
    (str, str)
        ``(status, "")`` when the cost backs the objective, else ``("failed", why)``.
    """
    if status not in USABLE:
        return status, ""
    if not np.isfinite(cost):
        return FAILED, f"the design's exact cost is {cost}"
    if not np.isfinite(objective):
        return FAILED, f"the solver's objective is {objective}"
    gap = abs(cost - objective) / max(1.0, abs(cost))
    if gap > rtol:
        return FAILED, (f"the design's exact cost {cost:.6g} disagrees with the solver's objective "
                        f"{objective:.6g} (relative gap {gap:.2e} > {rtol:g})")
    return status, ""
