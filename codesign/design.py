"""The result type every method returns.

Its status words, their groups and the solver-status policy live in
:mod:`codesign.status`; they are re-exported here, where they were first
defined, so that ``from codesign.design import STATUSES`` keeps working.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .status import (
    INACCURATE_RTOL,
    NO_DESIGN,
    OPTIMAL,
    SOLVER_STATUS,
    STATUSES,
    USABLE,
    solver_status,
    vet_solver_cost,
)

__all__ = [
    "Design",
    "Timer",
    "STATUSES",
    "INFO_MODELS",
    "count_links",
    "SOLVER_STATUS",
    "solver_status",
    "vet_solver_cost",
    "INACCURATE_RTOL",
]

class Timer:
    """Wall-clock seconds inside ``with timer:`` blocks, added up, also when a block raises.

    ``with Timer() as t: ...; t.seconds``: how methods measure the seconds a :class:`Design`
    records, and how the harness measures a run's scoring across its designs.
    """

    def __init__(self):
        self.seconds = 0.0

    def __enter__(self):
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds += time.perf_counter() - self._start
        return False


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
    status: str = OPTIMAL
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
        if self.status in NO_DESIGN and np.isfinite(self.cost):
            # A failed design must never look like a number on a plot.
            object.__setattr__(self, "cost", float("nan"))
        if self.status in USABLE and not np.isfinite(self.cost):
            raise ValueError(f"a design with status {self.status!r} needs a finite cost, got {self.cost}")

    @property
    def ok(self) -> bool:
        """True when the design's cost counts: a :data:`~codesign.status.USABLE` status and a finite cost.

        The same meaning as :attr:`compare.run.records.DesignRecord.ok`.
        """
        return self.status in USABLE and bool(np.isfinite(self.cost))

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
