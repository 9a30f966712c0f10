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
"""

from __future__ import annotations

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

#: A static design (a gain ``u = K x``, or a delayed gain on its augmented loop) is usable
#: only if its closed loop's spectral radius is below ``1 - STABILITY_TOL``; otherwise it
#: is ``diverged``. The benchmark's cost is a finite-horizon one, finite for unstable gains
#: too, so the cost alone cannot say this. The margin is far above the eigenvalue solver's
#: error on these loops (about 1e-12 relative), and a loop within it of the unit circle
#: (a time constant of a million steps or more) stabilizes nothing a report should count.
STABILITY_TOL = 1e-6


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
