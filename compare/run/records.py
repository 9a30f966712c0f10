"""Typed, read-only records of a result store: what the report and the export read.

:meth:`compare.run.store.Store.records` gives :class:`Records`, one :class:`DesignRecord`
per current design; the designs on one instance share its :class:`InstanceRecord`.
Canonical keys (the sorted JSON of an instance's spec or of a design's
hyperparameters, as the store writes them) are computed once here, so that the
report groups by them without serializing anything again.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from functools import cached_property
from types import MappingProxyType
from typing import Any

from codesign.design import INFO_MODELS
from codesign.status import STATUSES, USABLE

__all__ = ["InstanceRecord", "DesignRecord", "Records", "as_records", "canonical_key", "panel_key", "system_name",
           "OK_STATUSES", "COST_KINDS",
           "row_problem"]

#: Statuses of a design whose cost counts.
OK_STATUSES = USABLE
#: How a design's cost was made (:attr:`codesign.Design.cost_kind`): in closed form, simulated on
#: validation draws, or none (a design without a controller, :meth:`codesign.Design.failure`).
COST_KINDS = ("exact", "simulated", "none")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def row_problem(row: Mapping) -> str | None:
    """What no stored design can hold in ``row`` (the store's columns, decoded), naming the field; None if nothing.

    The values a :class:`codesign.Design` refuses or never writes: an unknown status,
    information model (:data:`codesign.design.INFO_MODELS`) or kind of cost
    (:data:`COST_KINDS`), a usable status (:data:`OK_STATUSES`) without a finite cost > 0,
    a negative count of links or self-loops, a negative standard error or time (None, an
    unknown value, passes; so does an empty information model or kind of cost, as runs.csv
    writes None). The store's rows and a
    report folder's ``runs.csv`` rows are checked alike, so that neither a damaged store
    nor a hand-edited file changes a report's findings unnoticed.
    """
    status = row.get("status")
    if status not in STATUSES:
        return f"status {status!r} is not a design status ({', '.join(STATUSES)})"
    for name, known in (("info_model", INFO_MODELS), ("cost_kind", COST_KINDS)):
        value = row.get(name)
        if value not in (None, "") and value not in known:  # "": runs.csv's None (report.json's null_text)
            return f"{name} {value!r} is not one of {', '.join(known)}"
    cost = row.get("cost")
    if status in USABLE and not (_is_number(cost) and math.isfinite(cost) and cost > 0):
        return f"cost {cost!r}: a design with status {status!r} has a finite cost > 0"
    for name in ("links", "self_loops", "run_designs"):
        value = row.get(name)
        if value is not None and not (_is_number(value) and float(value).is_integer() and value >= 0):
            return f"{name} {value!r} is not a count (a whole number >= 0)"
    for name in ("cost_stderr", "seconds", "run_seconds", "run_peak_mb", "run_scoring_seconds", "run_baseline_mb"):
        value = row.get(name)  # NaN passes: a failed design's standard error is NaN
        if value is not None and not (_is_number(value) and not value < 0):
            return f"{name} {value!r} is not a number >= 0"
    return None


def canonical_key(mapping: Mapping) -> str:
    """The sorted JSON of ``mapping``, as the store writes specs: equal contents give equal keys."""
    return json.dumps(dict(mapping), sort_keys=True)


def panel_key(spec: Mapping) -> tuple:
    """The panel an instance belongs to: (family, n, a_norm), a_norm None for families without one.

    (None, not NaN, for a family without one. A NaN ``a_norm``, which the spec of a run
    that failed may hold, becomes :data:`PANEL_NAN`: a plain NaN never equals itself, so
    a panel keyed by it could not be looked up, matched or sorted.)

    A published system (a spec with a ``case``: ``power_grid``'s grids) is a panel of its
    own, named for the family place by :func:`system_name` ("ieee39 (d = 2)"): two
    dampings of one grid are two systems, and were pooled into one panel of N = 10.
    """
    a_norm = spec.get("a_norm")
    if isinstance(a_norm, float) and math.isnan(a_norm):
        a_norm = PANEL_NAN
    family = system_name(spec) if "case" in spec else spec.get("family", "?")
    return (family, spec.get("n", 0), a_norm)


def system_name(spec: Mapping) -> str:
    """A published system's name: its case and its damping, "ieee39 (d = 2)" or "ieee39 (case damping)"."""
    damping = spec.get("damping")
    if damping is None:
        return str(spec["case"])
    if damping == "case":
        return f"{spec['case']} (case damping)"
    return f"{spec['case']} (d = {float(damping):g})"


class _PanelNaN(float):
    """A NaN that a panel key can hold: equal to itself, one hash, ordered after every number.

    Figures match, sort and format panels' ``a_norm`` like any float (``f"{a:g}"`` is
    ``nan``); Python asks a float subclass's reflected comparison first, so
    ``1.05 < PANEL_NAN`` is True too.
    """

    def __new__(cls):
        return super().__new__(cls, "nan")

    def __eq__(self, other) -> bool:
        return isinstance(other, float) and math.isnan(other)

    def __ne__(self, other) -> bool:
        return not self == other

    def __hash__(self) -> int:
        return hash("a_norm = nan")

    def __lt__(self, other) -> bool:
        return False

    def __le__(self, other) -> bool:
        return self == other

    def __gt__(self, other) -> bool:
        return not self == other

    def __ge__(self, other) -> bool:
        return True

    def __reduce__(self):
        return _panel_nan, ()


def _panel_nan() -> _PanelNaN:
    return PANEL_NAN


#: The ``a_norm`` of a panel whose spec has NaN there (:func:`panel_key`).
PANEL_NAN = _PanelNaN()


def _frozen(mapping: Mapping | None) -> Mapping:
    return MappingProxyType(dict(mapping or {}))


@dataclass(frozen=True)
class InstanceRecord:
    """One problem instance: its spec, canonical key and the facts the runner stored about it.

    Equality and hashing use ``key`` alone, so an InstanceRecord can key a dict.
    Nothing here builds the instance: a report reads what the store holds, and
    says nothing (or falls back to the spec) where it holds nothing. The runner
    stores no facts for an instance it cannot build (a failed run's), and stores
    written before instance facts were recorded have none.

    Parameters
    ----------
    spec : Mapping
        The spec fields (``family``, ``n``, ``a_norm``, ``seed``, ...), read-only.
    key : str
        :func:`canonical_key` of ``spec``.
    n : int or None
        States of the instance (``Instance.n``, which is the node count only when
        each node has one state; the spec's ``n`` is the node count).
    plant_links, comm_links : int or None
        Directed off-diagonal links of the plant and of the communication graph
        (:func:`compare.run.runner.instance_facts`).
    drawing : compare.run.drawing.InstanceDrawing or None
        What the designed-topology figure draws of the instance (its graphs and
        node colours); the runner stores it for instances of at most
        :data:`compare.run.drawing.DRAWN_NODES_AT_MOST` nodes.
    inputs, actuated, node_count : int or None
        Inputs of the instance, the nodes that hold at least one, and the nodes.
    radius : float or None
        Spectral radius of the open-loop A.

    Each fact is None where the store holds none for the instance.
    """

    spec: Mapping[str, Any] = field(compare=False)
    key: str = field(repr=False)
    n: int | None = field(default=None, compare=False)
    plant_links: int | None = field(default=None, compare=False)
    comm_links: int | None = field(default=None, compare=False)
    drawing: Any = field(default=None, compare=False, repr=False)
    inputs: int | None = field(default=None, compare=False)
    actuated: int | None = field(default=None, compare=False)
    radius: float | None = field(default=None, compare=False)
    node_count: int | None = field(default=None, compare=False)

    @classmethod
    def from_spec(cls, spec: Mapping, facts: Mapping | None = None) -> InstanceRecord:
        """The record of ``spec``, with ``facts`` as the runner stores them.

        ``n``, ``plant_links``, ``comm_links``, ``drawing``
        (:meth:`compare.run.drawing.InstanceDrawing.from_facts`; ValueError if malformed),
        ``inputs``, ``actuated``, ``radius`` and ``nodes`` (as ``node_count``).
        """
        facts = facts or {}
        drawing = facts.get("drawing")
        if drawing is not None:
            from .drawing import InstanceDrawing

            drawing = InstanceDrawing.from_facts(drawing)
        return cls(_frozen(spec), canonical_key(spec), facts.get("n"), facts.get("plant_links"),
                   facts.get("comm_links"), drawing, facts.get("inputs"), facts.get("actuated"), facts.get("radius"),
                   facts.get("nodes"))

    @property
    def family(self) -> str:
        return self.spec.get("family", "?")

    @property
    def seed(self) -> int | None:
        return self.spec.get("seed")

    @property
    def a_norm(self) -> float | None:
        return self.spec.get("a_norm")

    @property
    def panel(self) -> tuple:
        """:func:`panel_key` of the spec."""
        return panel_key(self.spec)

    @property
    def nodes(self) -> int | None:
        """The node count as the spec gives it (``n``), else the stored node count, else the stored state count."""
        n = self.spec.get("n", self.node_count if self.node_count is not None else self.n)
        return n if isinstance(n, int) and not isinstance(n, bool) else None

    @property
    def has_facts(self) -> bool:
        """Whether the store holds the counts about this instance (``n``, ``plant_links``, ``comm_links``).

        The ``drawing`` is not among them: it is stored for small instances only.
        """
        return None not in (self.n, self.plant_links, self.comm_links)


@dataclass(frozen=True)
class DesignRecord:
    """One stored design: the columns of the store's design and run rows, decoded and read-only.

    ``params`` and ``extras`` are read-only mappings (values nested in them, such as
    training curves, are not copied); ``params_key`` is the canonical JSON of
    ``params``. ``cost`` and ``cost_stderr`` are NaN where the store has none.
    ``run_seconds``, ``run_designs``, ``run_peak_mb``, ``run_scoring_seconds`` and
    ``run_baseline_mb`` describe the run that made the design: its wall seconds (scoring
    included), its number of designs, its process's peak resident memory in MB, the
    seconds it spent scoring its designs, and the resident memory in MB its process
    started the run from (see :class:`compare.run.execution.RunResult`). None where unknown:
    the last two in stores and report folders written before they were recorded.
    """

    run_key: str
    idx: int
    experiment: str | None
    instance: InstanceRecord
    method: str
    label: str
    params: Mapping[str, Any] = field(hash=False)
    params_key: str = field(repr=False)
    cost: float
    cost_stderr: float
    cost_kind: str | None
    links: int | None
    self_loops: int | None
    info_model: str | None
    status: str | None
    message: str | None
    seconds: float | None
    controller_kind: str | None
    extras: Mapping[str, Any] = field(hash=False, repr=False)
    fingerprint: str | None
    run_seconds: float | None = field(default=None, repr=False)
    run_designs: int | None = field(default=None, repr=False)
    run_peak_mb: float | None = field(default=None, repr=False)
    run_scoring_seconds: float | None = field(default=None, repr=False)
    run_baseline_mb: float | None = field(default=None, repr=False)

    @classmethod
    def from_dict(cls, row: Mapping, instance: InstanceRecord | None = None) -> DesignRecord:
        """A record from a dict of the store's columns (JSON fields decoded); missing columns are None.

        ``instance`` replaces the one built from ``row["instance"]`` (to share it, or to attach facts).
        """
        params = row.get("params") or {}
        values = {f.name: row.get(f.name) for f in fields(cls)}
        values.update(
            instance=instance or InstanceRecord.from_spec(row.get("instance") or {}),
            params=_frozen(params), params_key=canonical_key(params), extras=_frozen(row.get("extras")),
            **{k: math.nan if values[k] is None else values[k] for k in ("cost", "cost_stderr")},
        )
        return cls(**values)

    @property
    def ok(self) -> bool:
        """The design's cost counts: an accepted status and a finite cost."""
        return self.status in OK_STATUSES and math.isfinite(self.cost)

    def params_key_without(self, name: str) -> str:
        """:attr:`params_key` of every hyperparameter but ``name``: one regularization path's key."""
        return canonical_key({k: v for k, v in self.params.items() if k != name})


class Records(Sequence):
    """An immutable sequence of :class:`DesignRecord`, with its groupings computed once.

    Slicing, :meth:`filter` and the groupings give new ``Records``, in the order
    of this one; groupings are dicts in order of first appearance.

    Parameters
    ----------
    designs : iterable of DesignRecord
    """

    def __init__(self, designs: Iterable[DesignRecord] = ()):
        self._designs = tuple(designs)

    @classmethod
    def from_rows(cls, rows: Iterable, facts: Mapping[str, Mapping] | None = None) -> Records:
        """Records from dicts shaped like the store's rows, or DesignRecords (kept as they are).

        Parameters
        ----------
        rows : iterable of dict or DesignRecord
            Dicts with the store's columns, JSON fields decoded; missing columns are None.
        facts : dict, optional
            Instance key -> the facts the runner stored (:meth:`InstanceRecord.from_spec`).

        Returns
        -------
        Records
            The dicts' designs on one instance share one :class:`InstanceRecord`.
        """
        facts = facts or {}
        instances: dict[str, InstanceRecord] = {}

        def design(row) -> DesignRecord:
            if isinstance(row, DesignRecord):
                return row
            spec = row.get("instance") or {}
            key = canonical_key(spec)
            if key not in instances:
                instances[key] = InstanceRecord.from_spec(spec, facts.get(key))
            return DesignRecord.from_dict(row, instances[key])

        return cls(design(row) for row in rows)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return Records(self._designs[index])
        return self._designs[index]

    def __len__(self) -> int:
        return len(self._designs)

    def __iter__(self):
        return iter(self._designs)

    def __repr__(self) -> str:
        return f"Records({len(self)} designs on {len(self.instances)} instances)"

    def filter(self, predicate: Callable[[DesignRecord], bool]) -> Records:
        """The designs for which ``predicate`` is true."""
        return Records(r for r in self if predicate(r))

    def group(self, key: Callable[[DesignRecord], Hashable]) -> dict[Hashable, Records]:
        """``key(design)`` -> the designs with that key."""
        groups: dict[Hashable, list] = {}
        for r in self:
            groups.setdefault(key(r), []).append(r)
        return {k: Records(v) for k, v in groups.items()}

    @cached_property
    def instances(self) -> tuple[InstanceRecord, ...]:
        """Every instance with a design here, once."""
        return tuple(dict.fromkeys(r.instance for r in self))

    @cached_property
    def by_instance(self) -> dict[str, Records]:
        """Instance key -> its designs."""
        return self.group(lambda r: r.instance.key)

    @cached_property
    def by_panel(self) -> dict[tuple, Records]:
        """Panel (:func:`panel_key`) -> its designs."""
        return self.group(lambda r: r.instance.panel)

    @cached_property
    def by_label(self) -> dict[str, Records]:
        """Label -> its designs."""
        return self.group(lambda r: r.label)

    @cached_property
    def by_panel_label(self) -> dict[tuple, Records]:
        """(panel, label) -> the designs of that label on that panel."""
        return self.group(lambda r: (r.instance.panel, r.label))



def as_records(records: Iterable) -> Records:
    """``records`` as :class:`Records`: as they are, or from dicts or DesignRecords (:meth:`Records.from_rows`)."""
    return records if isinstance(records, Records) else Records.from_rows(records)
