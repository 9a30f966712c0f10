"""Which panels of a report are one kind of system, and may be pooled, and which are different systems.

Panels that differ in a spec's family, case, name or damping are different systems (a chain
beside a platoon, ieee39 beside wecc, a grid at two dampings); the panels of one random
family at several N or ‖A‖₂ are draws of one kind of system. The opening
(:mod:`compare.report.answer`) and the Findings table (:mod:`compare.report.findings_text`)
take no median over different systems.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..run.records import Records, as_records

#: Spec keys whose text values name a kind of system: panels that differ in them are different systems
#: (a grid at two dampings is two systems, as its panels are).
KIND_KEYS = ("family", "case", "name", "damping")


def _kind(rs: Records) -> tuple:
    """What kind of system a panel's instances are: the text values of their :data:`KIND_KEYS`."""
    return tuple(sorted({(k, str(i.spec[k])) for i in rs.instances for k in KIND_KEYS if k in i.spec}))


def system_kinds(records, panels: Sequence[tuple]) -> dict[tuple, tuple]:
    """Panel -> the kind of system its instances are (:func:`_kind`), for the ``panels`` the records hold:
    panels of one kind may be pooled, panels of different kinds are different systems (:func:`different_systems`)."""
    by_panel = as_records(records).by_panel
    return {p: _kind(by_panel[p]) for p in panels if p in by_panel}


def different_systems(records, panels: Sequence[tuple]) -> bool:
    """Whether ``panels`` are different systems, so that no median may pool them: they differ in family, case or damping
    (a chain beside a platoon, ieee39 beside wecc). The panels of one random family at several sizes or ‖A‖₂
    are draws of one kind of system, which the Findings pool (docs/reports.md, "Pooling")."""
    return len(set(system_kinds(records, panels).values())) > 1


def kind_of(kinds, panel):
    """The kind of system ``kinds`` (panel -> kind) gives ``panel``: a panel it does not name is a kind of its own;
    None for every panel without ``kinds`` (one kind, pooled)."""
    if kinds is None:
        return None
    return kinds.get(panel, ("panel", panel))
