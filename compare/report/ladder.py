"""The budget ladder: how close each method's best design within a few links comes to centralized control.

A spec asks for it with ``[report] ladder`` (:func:`compare.run.spec.parse_ladder`)::

    [report]
    ladder = { budgets = [1, 2, 5], methods = ["sparse_admm", "sparse_delayed", "sls", "grnn_sparse"],
               near = 5.0, claim = "One wide-area link gives almost centralized performance" }

and the report's answer (:func:`compare.report.answer.answer_lines`) then opens with it: one
sentence that checks the claim (some design within the first budget costs at most
``near`` per cent more than LQR), then one line per system with each method's best cost
within every budget, in per cent above LQR. A *system* is an instance spec less its seed:
where a system has several seeds the line gives the median over them of each
instance's best cost (an instance without a design within the budget counting as worse
than any). The read is from the stored spec text, so a report rebuilt from its folder
(whose ``report.json`` keeps the specs) says the same. Links are the report's: directed
off-diagonal links between nodes.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from collections.abc import Mapping, Sequence

import numpy as np

from ..run.records import Records, as_records, canonical_key
from .names import SETTINGS_SUFFIX, join_words, short_names
from .statistics import best_within

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["Rung", "asked_ladders", "ladder_lines", "ladder_table", "system_names", "verdict_sentence"]

#: Methods that are no design choice at any budget: the centralized optimum and doing nothing.
_REFERENCES = ("lqr", "autonomous")
#: Spec keys that tell no two systems apart: the draw, and the data file's digest.
_NOT_SYSTEM = ("seed", "sha256")
#: Spec keys whose text values are names, shown bare ("ieee39", not "case = ieee39").
_NAMES = ("family", "case", "name")


def asked_ladders(records, meta=None, members=None) -> list[tuple[str, dict, Records]]:
    """Every experiment whose stored spec asks for a ladder: (name, ladder, the records of its runs)."""
    from ..run.meta import StoreMeta
    from ..run.spec import SpecError, parse_ladder

    if meta is None:
        return []
    meta, members = StoreMeta.of(meta), dict(members or {})
    records = as_records(records)
    out = []
    for name, text in sorted(meta.specs.items()):
        try:
            ladder = parse_ladder(tomllib.loads(text).get("report", {}).get("ladder"))
        except (tomllib.TOMLDecodeError, SpecError, AttributeError):
            continue
        if ladder is None:
            continue
        keys = frozenset(members.get(name) or ())
        mine = (records.filter(lambda r, keys=keys: r.run_key in keys) if keys
                else records.filter(lambda r, name=name: r.experiment == name))
        if len(mine):
            out.append((name, ladder, mine))
    return out


def _system(spec: Mapping) -> str:
    return canonical_key({k: v for k, v in spec.items() if k not in _NOT_SYSTEM})


def _value(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def system_names(specs: Mapping[str, Mapping]) -> dict[str, str]:
    """System key -> a short name: what tells it apart from the others ("ieee39 (damping = 2)", "wecc").

    The spec keys whose values differ between systems, in spec order; the first is always
    named, each later one only where systems that agree on the keys named so far still differ
    on it. A family, case or file name is given bare ("ieee39"), other keys as "damping = 2", the
    first part before the others' parentheses.
    """
    keys = list(dict.fromkeys(k for spec in specs.values() for k in spec if k not in _NOT_SYSTEM))
    varying = [k for k in keys if len({canonical_key({"v": s.get(k)}) for s in specs.values()}) > 1]
    if not varying:  # one system: its first text value after the family ("ieee39"), else the family
        first = next((k for k in keys if k != "family" and all(isinstance(s.get(k), str) for s in specs.values())),
                     "family" if "family" in keys else None)
        varying = [first] if first else keys[:1]
    out = {}
    for key, spec in specs.items():
        parts, peers = [], list(specs.values())
        for i, k in enumerate(varying):
            values = {canonical_key({"v": s.get(k)}) for s in peers}
            if i == 0 or len(values) > 1:
                v = spec.get(k)
                parts.append(str(v) if k in _NAMES and isinstance(v, str) else
                             f"{'N' if k == 'n' else k} = {_value(v)}")
            peers = [s for s in peers if s.get(k) == spec.get(k)]
        out[key] = parts[0] + (f" ({', '.join(parts[1:])})" if len(parts) > 1 else "")
    return out


class Rung(tuple):
    """One method's ladder on one system: its best cost within each budget (inf: no design), and why not."""

    __slots__ = ()

    def __new__(cls, costs, sparsest, statuses):
        return super().__new__(cls, (tuple(costs), sparsest, dict(statuses)))

    costs = property(lambda self: self[0])
    #: The fewest links of any usable design of the method there (None: it has none).
    sparsest = property(lambda self: self[1])
    #: Status -> designs, where the method has no usable design there.
    statuses = property(lambda self: self[2])


def _median_over(instances: Sequence[Records], budget: float) -> float:
    """Median over a system's instances of the best cost within ``budget`` (an instance without one: inf)."""
    values = [best_within(rs, list(rs.by_instance), [budget])[0, 0] for rs in instances]
    return float(np.median(values)) if values else math.inf


def _entries(records: Records, asked: Sequence[str]) -> list[tuple[str, frozenset]]:
    """The ladder's methods: (shown name, labels). A label names itself; a method name all of its labels."""
    labels = list(records.by_label)
    short = short_names(labels)
    by_method: dict[str, list[str]] = {}
    for r in records:
        if r.label not in by_method.setdefault(r.method, []):
            by_method[r.method].append(r.label)
    if not asked:  # every method with designs at more than one link count
        asked = [m for m, rs in records.group(lambda r: r.method).items()
                 if m not in _REFERENCES and len({r.links for r in rs if r.ok}) > 1]
    out = []
    for x in asked:
        members = [x] if x in records.by_label else by_method.get(x, [])
        if not members:  # asked for, but no design anywhere: named as registered, "not run" on every system
            from .tables import registered_labels

            out.append((SETTINGS_SUFFIX.sub("", registered_labels().get(x, x)), frozenset()))
        elif len(members) == 1:
            name = short[members[0]]
        else:
            heads = {short[m].split(" (")[0] for m in members}
            name = heads.pop() if len(heads) == 1 else x
        out.append((name, frozenset(members)))
    return out


def ladder_table(records, ladder: Mapping) -> dict:
    """The numbers behind the ladder's lines.

    Returns ``{"systems": [(key, name)], "zero": {key: (cost, label)}, "first": {key: (cost, label)},
    "rungs": {(key, name): Rung}, "entries": [name]}``: per system the best design with no link
    of any method but u = 0 and the best within the first budget of any method but LQR and
    u = 0 (cost inf and label None where none; on a system with several instances, the label
    whose median over them is lowest), and per (system, method) its :class:`Rung`.
    """
    records = as_records(records)
    budgets = [float(b) for b in ladder["budgets"]]
    by_system, specs = _by_system(records)
    names = system_names(specs)
    entries = _entries(records, ladder["methods"])
    zero, first, rungs = {}, {}, {}
    for system, instances in by_system.items():
        zero[system] = _best_without_links(instances)
        first[system] = _best_within_first(instances, budgets[0])
        for name, labels in entries:
            rung = _rung(instances, labels, budgets)
            if rung is not None:
                rungs[(system, name)] = rung
    order = sorted(by_system, key=lambda s: _order(specs[s]))
    return {"systems": [(s, names[s]) for s in order], "zero": zero, "first": first, "rungs": rungs,
            "entries": [name for name, _ in entries]}


def _by_system(records: Records) -> tuple[dict[str, dict[str, Records]], dict[str, Mapping]]:
    """System -> instance key -> its records, and system -> the spec of its first instance."""
    by_system: dict[str, dict[str, Records]] = {}
    specs: dict[str, Mapping] = {}
    for key, rs in records.by_instance.items():
        system = _system(rs[0].instance.spec)
        by_system.setdefault(system, {})[key] = rs
        specs.setdefault(system, rs[0].instance.spec)
    return by_system, specs


def _best_without_links(instances: Mapping[str, Records]) -> tuple[float, str | None]:
    """(cost, label) of the best design with no link, of any method but u = 0, on one system."""
    choices = [r for rs in instances.values() for r in rs if r.method != "autonomous" and r.ok and r.links == 0]
    # Named after the diagonal gain where it is as good (every path ends there), else the best.
    low = min((r.cost for r in choices), default=math.inf)
    tied = [r for r in choices if r.cost <= low + 1e-9 * abs(low)]
    named = next((r for r in tied if r.method == "decentralized"), tied[0] if tied else None)
    return low, named.label if named else None


def _best_within_first(instances: Mapping[str, Records], budget: float) -> tuple[float, str | None]:
    """(median cost, label) of the best label within ``budget`` on one system, of any method but LQR and u = 0.

    Of any method: the claim is about the best design, whichever method found it.
    """
    per_label: dict[str, list] = {}
    for rs in instances.values():
        for label, mine in rs.filter(lambda r: r.method not in _REFERENCES).by_label.items():
            per_label.setdefault(label, []).append(mine)
    firsts = sorted((_median_over(v, budget), label) for label, v in per_label.items())
    return firsts[0] if firsts and math.isfinite(firsts[0][0]) else (math.inf, None)


def _rung(instances: Mapping[str, Records], labels: frozenset, budgets: Sequence[float]) -> Rung | None:
    """The :class:`Rung` of the designs labelled ``labels`` on one system; None where it has none."""
    mine = [rs.filter(lambda r: r.label in labels) for rs in instances.values()]
    mine = [rs for rs in mine if len(rs)]
    if not mine:
        return None
    usable = [r.links for rs in mine for r in rs if r.ok and r.links is not None]
    statuses = Counter(r.status for rs in mine for r in rs) if not usable else {}
    return Rung([_median_over(mine, b) for b in budgets], min(usable, default=None), statuses)


def _order(spec: Mapping) -> tuple:
    """Family, then N, then the other keys in spec order, numbers before text."""
    def part(v):
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        return (0, float(v), "") if number else (1, 0.0, canonical_key({"v": v}))

    n = spec.get("n")
    return (str(spec.get("family", "")), part(n), tuple(part(v) for k, v in spec.items() if k not in _NOT_SYSTEM))


# --------------------------------------------------------------------------- wording


def _pct(cost: float) -> str:
    """A cost above LQR's in per cent without the sign of per cent: "+3.6", "+0.41", "+148"; "×12" from 10 × LQR."""
    if cost >= 10:
        return f"{cost:.2g} × LQR" if cost < 100 else f"{cost:,.0f} × LQR"
    pct = 100 * (cost - 1)
    return f"+{pct:.0f}" if pct >= 10 else f"+{pct:.2g}"


def _pcts(costs: Sequence[float]) -> str:
    """"+3.6 / +2.7 / +1.9 %", "none / none / +2.1 %" (none: no design within that budget)."""
    parts = ["none" if not math.isfinite(c) else _pct(c) for c in costs]
    finite = [c for c in costs if math.isfinite(c)]
    return " / ".join(parts) + (" %" if finite and all(c < 10 for c in finite) else "")


def _plural(k: float, noun: str) -> str:
    return f"{k:g} {noun}{'' if k == 1 else 's'}"



def _rung_text(name: str, rung: Rung | None, budgets: Sequence[int]) -> str:
    if rung is None:
        return f"{name} not run"
    if rung.sparsest is None:
        statuses = ", ".join(f"{s} {k}" for s, k in sorted(rung.statuses.items()))
        return f"{name} no usable design ({statuses})"
    if not any(math.isfinite(c) for c in rung.costs):
        return (f"{name} none within {_plural(budgets[-1], 'link')} (its sparsest design has "
                f"{_plural(rung.sparsest, 'link')})")
    text = f"{name} {_pcts(rung.costs)}"
    if not math.isfinite(rung.costs[0]):
        text += f" (its sparsest design has {_plural(rung.sparsest, 'link')})"
    return text


def _range(values: Sequence[float]) -> str:
    low, high = min(values), max(values)
    return f"{_pct(low)} %" if _pct(low) == _pct(high) else f"{_pct(low)} to {_pct(high)} %"


def _systems_phrase(k: int, n: int) -> str:
    if k == n:
        return {1: "its one system", 2: "both systems"}.get(n, f"all {n} systems")
    return "no system" if k == 0 else f"{k} of the {n} systems"


def verdict_sentence(table: Mapping, ladder: Mapping) -> str:
    """Whether some design within the first budget, of any method, comes within ``near`` % of LQR, system by
    system."""
    first, near = ladder["budgets"][0], ladder["near"]
    bound = 1 + near / 100
    systems = table["systems"]
    zero = {s: table["zero"][s][0] for s, _ in systems}
    best = {s: table["first"][s][0] for s, _ in systems}  # of every method: a design with no link included
    held = [(s, n) for s, n in systems if best[s] <= bound]
    within = f"within {_plural(first, 'link')}"
    text = _verdict_opening(ladder, within, held, systems)
    trivial = [(s, n) for s, n in held if zero[s] <= bound]
    if trivial:
        text += _trivial_clause(table, trivial, held, systems, near)
    text += _missed_clauses(table, [(s, n) for s, n in systems if (s, n) not in held], within)
    text += _gap_clause(systems, zero, best, first)
    return text + "."


def _verdict_opening(ladder: Mapping, within: str, held: list, systems: list) -> str:
    """The spec's claim (or the test itself), and on how many systems it holds: which, where not on all."""
    near = ladder["near"]
    test = (f"some design {within} (links counted between nodes) costing at most {near:g} % more than LQR")
    claim = ladder.get("claim", "").strip().rstrip(".")
    count = _systems_phrase(len(held), len(systems))
    text = (f"{claim[0].upper() + claim[1:]}, taken here as {test}, holds on {count}" if claim
            else f"Some design {within} (links counted between nodes) costs at most {near:g} % more than LQR on "
                 f"{count}")
    if held and len(held) < len(systems):
        text += f" ({join_words([n for _, n in held])})"
    return text


def _trivial_clause(table: Mapping, trivial: list, held: list, systems: list, near: float) -> str:
    """Where the claim holds without any link: the best design with no link is already within ``near`` %."""
    label = {table["zero"][s][1] for s, _ in trivial}
    who = label.pop() if len(label) == 1 else "the best design with no link"
    where = ("" if len(systems) == 1 else f" on each{'' if len(held) == len(systems) else ' of them'}"
             if len(trivial) == len(held) else f" on {join_words([n for _, n in trivial])}")
    return (f"{', trivially' if len(trivial) == len(held) else ''}: with no link at all {who} is already within "
            f"{near:g} % of LQR{where} ({_range([table['zero'][s][0] for s, _ in trivial])})")


def _missed_clauses(table: Mapping, missed: list, within: str) -> str:
    """Where the claim fails: the best cost within the first budget, or that there is no usable design."""
    best = {s: table["first"][s][0] for s, _ in missed}
    text = ""
    costs = [f"{n} {_pct(best[s])}{' %' if best[s] < 10 else ''} ({table['first'][s][1]})" for s, n in missed
             if math.isfinite(best[s])]
    if costs:
        text += f"; the best design {within} costs, above LQR: {join_words(costs)}"
    nothing = [n for s, n in missed if not math.isfinite(best[s])]
    if nothing:
        text += f"; {join_words(nothing)} {'has' if len(nothing) == 1 else 'have'} no usable design {within}"
    return text


def _gap_clause(systems: list, zero: Mapping, best: Mapping, first) -> str:
    """How much of the gap between no link and LQR the first budget closes, over the systems: "" where unknown."""
    closed = [(zero[s] - best[s]) / (zero[s] - 1) for s, _ in systems
              if math.isfinite(zero[s]) and zero[s] > 1 and math.isfinite(best[s])]
    if not closed:
        return ""
    low, high = 100 * max(0.0, min(closed)), 100 * max(closed)
    share = f"{low:.0f} %" if f"{low:.0f}" == f"{high:.0f}" else f"{low:.0f}–{high:.0f} %"
    return f"; {_plural(first, 'link')} closes {share} of the gap between the best design with no link and LQR"


def ladder_lines(records, meta=None, members=None) -> tuple[list[str], list[str]]:
    """The ladder of every experiment that asks for one: (verdict sentences, detail lines).

    The detail lines are a Markdown list, one item per system: the best design with no
    link, then each method's best cost within every budget in per cent above LQR.
    """
    sentences, details = [], []
    for _, ladder, rs in asked_ladders(records, meta, members):
        table = ladder_table(rs, ladder)
        if not table["systems"] or not table["entries"]:
            continue
        sentences.append(verdict_sentence(table, ladder))
        budgets = ladder["budgets"]
        head = f"within {' / '.join(str(b) for b in budgets)} links, above LQR"
        for system, name in table["systems"]:
            cost, label = table["zero"][system]
            zero = (f"with no link, {label} {_pct(cost)}{' %' if cost < 10 else ''}" if label
                    else "no design with no link")
            rungs = [_rung_text(e, table["rungs"].get((system, e)), budgets) for e in table["entries"]]
            details.append(f"- {name}: {zero}; {head}: {'; '.join(rungs)}.")
    return sentences, details
