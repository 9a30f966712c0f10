"""The result type every method returns, and its status taxonomy."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "Design",
    "STATUSES",
    "INFO_MODELS",
    "count_links",
    "SOLVER_STATUS",
    "solver_status",
    "vet_solver_cost",
    "INACCURATE_RTOL",
]

#: Every status a design can carry. Only ``optimal`` (and, flagged, ``inaccurate``)
#: designs carry a cost; the others carry NaN and a message saying why.
STATUSES = ("optimal", "inaccurate", "infeasible", "diverged", "failed")

#: The one policy from a convex solver's status (cvxpy's names) to a design status;
#: any other status (``user_limit``, ``solver_error``, ``unbounded``, ...) is ``failed``.
SOLVER_STATUS = {
    "optimal": "optimal",
    "optimal_inaccurate": "inaccurate",
    "infeasible": "infeasible",
    "infeasible_inaccurate": "infeasible",
}

#: Relative gap allowed between an ``inaccurate`` solve's objective and the exact cost
#: of its design. Clarabel reports ``optimal_inaccurate`` when it meets its reduced
#: tolerances (5e-5 relative duality gap, 1e-4 feasibility) but not the full ones, so an
#: honest inaccurate solution agrees to about 1e-4; 1e-3 leaves room for that and
#: still rejects the solves that stop far away (objectives off by orders of magnitude,
#: e.g. 1e29 on infeasible supports).
INACCURATE_RTOL = 1e-3


def solver_status(raw) -> str:
    """Design status for a solver's status string (see :data:`SOLVER_STATUS`); unknown -> ``"failed"``."""
    return SOLVER_STATUS.get(str(raw), "failed")


def vet_solver_cost(status: str, objective: float, cost: float, *, rtol: float = INACCURATE_RTOL) -> tuple[str, str]:
    """Keep a solve's status only when the exact cost of its design backs the solver's objective.

    Parameters
    ----------
    status : str
        The design status from :func:`solver_status`; only ``optimal`` and
        ``inaccurate`` are checked, others are returned as they are.
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
    if status not in ("optimal", "inaccurate"):
        return status, ""
    if not np.isfinite(cost):
        return "failed", f"the design's exact cost is {cost}"
    if not np.isfinite(objective):
        return "failed", f"the solver's objective is {objective}"
    gap = abs(cost - objective) / max(1.0, abs(cost))
    if gap > rtol:
        return "failed", (f"the design's exact cost {cost:.6g} disagrees with the solver's objective "
                          f"{objective:.6g} (relative gap {gap:.2e} > {rtol:g})")
    return status, ""


#: How information travels in a design: ``instantaneous`` (links deliver the current
#: state with no delay, possibly over many hops), ``delayed`` (one step per hop, as
#: in the GRNN and SLS), ``none`` (no communication).
INFO_MODELS = ("instantaneous", "delayed", "none")


def count_links(support) -> tuple[int, int]:
    """(directed off-diagonal links, self-loops) of a support matrix (nonzero = link)."""
    support = np.asarray(support) != 0
    self_loops = int(np.trace(support))
    return int(support.sum()) - self_loops, self_loops


@dataclass(frozen=True)
class Design:
    """A controller designed by one method on one instance, and how it scores.

    Attributes
    ----------
    method : str
        Registered method name (``"lqr"``, ``"sparse_admm"``, ``"grnn"``, ...).
    params : dict
        Hyperparameters that produced this design (JSON-serializable).
    controller : object or None
        Implements ``reset(batch)`` and ``step(state, x) -> (u, state)`` (see
        :mod:`codesign.controllers`); None when the design failed.
    cost : float
        Normalized expected cost E[J] / trace(P); NaN unless status is
        ``optimal`` or ``inaccurate``.
    links : int
        Directed off-diagonal communication links the controller needs.
    self_loops : int
        Diagonal entries of its support (local feedback, no link needed).
    info_model : str
        One of :data:`INFO_MODELS`.
    status : str
        One of :data:`STATUSES`.
    message : str
        Why a design is not optimal, or notes from the solver.
    seconds : float
        Wall time of the design (training or solve), evaluation excluded.
    cost_stderr : float
        Standard error of ``cost``; 0 for exact (closed-form) costs.
    cost_kind : str
        ``"exact"`` (closed form) or ``"simulated"`` (validation-set estimate).
    extras : dict
        Method-specific numbers (spectral radius, solver name, training curve, ...).
    """

    method: str
    params: dict
    controller: Any
    cost: float
    links: int
    self_loops: int
    info_model: str
    status: str = "optimal"
    message: str = ""
    seconds: float = 0.0
    cost_stderr: float = 0.0
    cost_kind: str = "exact"
    extras: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")
        if self.info_model not in INFO_MODELS:
            raise ValueError(f"info_model must be one of {INFO_MODELS}, got {self.info_model!r}")
        if self.status in ("infeasible", "diverged", "failed") and np.isfinite(self.cost):
            # A failed design must never look like a number on a plot.
            object.__setattr__(self, "cost", float("nan"))
        if self.status in ("optimal", "inaccurate") and not np.isfinite(self.cost):
            raise ValueError(f"a design with status {self.status!r} needs a finite cost, got {self.cost}")

    @property
    def ok(self) -> bool:
        """True when the design has a trustworthy cost (status ``optimal``)."""
        return self.status == "optimal"

    @classmethod
    def failure(
        cls,
        method: str,
        params: dict,
        status: str,
        message: str,
        *,
        info_model: str = "none",
        seconds: float = 0.0,
        links: int = 0,
        self_loops: int = 0,
        extras: dict | None = None,
    ) -> "Design":
        """A design that produced no usable controller."""
        return cls(
            method=method,
            params=dict(params),
            controller=None,
            cost=float("nan"),
            links=links,
            self_loops=self_loops,
            info_model=info_model,
            status=status,
            message=message,
            seconds=seconds,
            cost_stderr=float("nan"),
            cost_kind="none",
            extras=dict(extras or {}),
        )

    def to_record(self) -> dict:
        """Flat, JSON-friendly dict (no arrays) for storage and DataFrames."""
        return {
            "method": self.method,
            "params": json.dumps(self.params, sort_keys=True, default=_json_default),
            "cost": float(self.cost),
            "cost_stderr": float(self.cost_stderr),
            "cost_kind": self.cost_kind,
            "links": int(self.links),
            "self_loops": int(self.self_loops),
            "info_model": self.info_model,
            "status": self.status,
            "message": self.message,
            "seconds": float(self.seconds),
            "controller": getattr(self.controller, "kind", None),
            "extras": json.dumps(self.extras, sort_keys=True, default=_json_default),
        }

    def __repr__(self) -> str:
        return (
            f"Design(method={self.method!r}, status={self.status!r}, cost={self.cost:.6g}, "
            f"links={self.links}, self_loops={self.self_loops}, info_model={self.info_model!r}, "
            f"seconds={self.seconds:.3g})"
        )


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON-serializable: {type(value).__name__}")
