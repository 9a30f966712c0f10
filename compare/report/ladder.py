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

__all__ = ["Rung", "asked_ladders", "ladder_lines", "ladder_table", "ladder_details", "system_names",
           "verdict_sentence", "verdict_sentences"]

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


def _part(key: str, value) -> str:
    """One key of a system's name: a name bare ("ieee39"), a damping as "d = 2" or "case damping" (the case file's
    own), N as "N = 10", any other key as "key = value"."""
    if key in _NAMES and isinstance(value, str):
        return str(value)
    if key == "damping":
        return f"{value} damping" if isinstance(value, str) else f"d = {_value(value)}"
    return f"{'N' if key == 'n' else key} = {_value(value)}"


def system_names(specs: Mapping[str, Mapping]) -> dict[str, str]:
    """System key -> a short name: what tells it apart from the others ("ieee39 (damping = 2)", "wecc").

    The spec keys whose values differ between systems, in spec order; the first is always
    named, each later one only where systems that agree on the keys named so far still differ
    on it. A family, case or file name is given bare ("ieee39"), a damping as "d = 2" or "case
    damping", other keys as "key = value", the first part before the others' parentheses.
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
                parts.append(_part(k, spec.get(k)))
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
    "best": {key: [(cost, label), ...]}, "rungs": {(key, name): Rung}, "entries": [name]}``: per
    system the best design with no link of any method but u = 0, the best within the first budget
    and within each budget of any method but LQR and u = 0 (cost inf and label None where none; on
    a system with several instances, the label whose median over them is lowest), and per
    (system, method) its :class:`Rung`.
    """
    records = as_records(records)
    budgets = [float(b) for b in ladder["budgets"]]
    by_system, specs = _by_system(records)
    names = system_names(specs)
    entries = _entries(records, ladder["methods"])
    zero, first, best, rungs = {}, {}, {}, {}
    for system, instances in by_system.items():
        zero[system] = _best_without_links(instances)
        best[system] = [_best_within_first(instances, b) for b in budgets]
        first[system] = best[system][0]
        for name, labels in entries:
            rung = _rung(instances, labels, budgets)
            if rung is not None:
                rungs[(system, name)] = rung
    order = sorted(by_system, key=lambda s: _order(specs[s]))
    return {"systems": [(s, names[s]) for s in order], "zero": zero, "first": first, "best": best, "rungs": rungs,
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
    """A cost above LQR's in per cent without the sign of per cent: "+3.6", "+0.41", "+148"; "12 × LQR" from 10 × LQR."""
    if cost >= 10:
        return f"{cost:.2g} × LQR" if cost < 100 else f"{cost:,.0f} × LQR"
    pct = 100 * (cost - 1)
    return f"+{pct:.0f}" if pct >= 10 else f"+{pct:.2g}"


def _pct_unit(cost: float) -> str:
    """"+3.6 %", "12 × LQR"."""
    return _pct(cost) + (" %" if cost < 10 else "")


def _pcts(costs: Sequence[float]) -> str:
    """"+3.6 / +2.7 / +1.9", "none / none / +2.1" (none: no design within that budget); per cent above LQR."""
    return " / ".join("none" if not math.isfinite(c) else _pct(c) for c in costs)


def _plural(k: float, noun: str) -> str:
    return f"{k:g} {noun}{'' if k == 1 else 's'}"


def _rung_text(rung: Rung | None, budgets: Sequence[int]) -> str:
    """One method's cell of the ladder's table."""
    if rung is None:
        return "not run"
    if rung.sparsest is None:
        statuses = ", ".join(f"{s} {k}" for s, k in sorted(rung.statuses.items()))
        return f"no usable design ({statuses})"
    if not any(math.isfinite(c) for c in rung.costs):
        return f"none (sparsest: {_plural(rung.sparsest, 'link')})"
    text = _pcts(rung.costs)
    if not math.isfinite(rung.costs[0]):
        text += f" (sparsest: {_plural(rung.sparsest, 'link')})"
    return text


def _range(values: Sequence[float]) -> str:
    low, high = min(values), max(values)
    return _pct_unit(low) if _pct(low) == _pct(high) else f"{_pct(low)} to {_pct_unit(high)}"


def _systems_phrase(k: int, n: int) -> str:
    if k == n:
        return {1: "its one system", 2: "both systems"}.get(n, f"all {n} systems")
    return "no system" if k == 0 else f"{k} of the {n} systems"


def _closed(zero: float, best: float) -> float | None:
    """The share of the gap between the best design with no link and LQR that ``best`` closes; None where unknown."""
    if not (math.isfinite(zero) and zero > 1 and math.isfinite(best)):
        return None
    return max(0.0, (zero - best) / (zero - 1))


def _share(values: Sequence[float]) -> str:
    low, high = 100 * min(values), 100 * max(values)
    return f"{low:.0f} %" if f"{low:.0f}" == f"{high:.0f}" else f"{low:.0f}–{high:.0f} %"


def verdict_sentences(table: Mapping, ladder: Mapping) -> list[str]:
    """At most three sentences: on how many systems some design within the first budget, of any method, comes
    within ``near`` % of LQR; where it holds, whether it needs any link; where it fails, by how much, and how much
    of the gap to LQR the first budget closes."""
    first, near = ladder["budgets"][0], ladder["near"]
    bound = 1 + near / 100
    systems = table["systems"]
    zero = {s: table["zero"][s][0] for s, _ in systems}
    best = {s: table["first"][s][0] for s, _ in systems}  # of every method: a design with no link included
    held = [(s, n) for s, n in systems if best[s] <= bound]
    missed = [(s, n) for s, n in systems if (s, n) not in held]
    within = f"within {_plural(first, 'link')}"
    out = [_verdict_opening(ladder, within, held, systems)]
    if held:
        out.append(_held_sentence(table, held, systems, zero, best, bound, within))
    closed = [c for c in (_closed(zero[s], best[s]) for s, _ in systems) if c is not None]
    gap = (f"{_plural(first, 'link')} closes {_share(closed)} of the gap between the best design with no link and "
           "LQR") if closed else ""
    if missed:
        text = _missed_sentence(table, missed, within)
        out.append(text + (f"; {gap}." if gap and _words(text + gap) <= 38 else "."))
    elif gap:
        out.append(gap[0].upper() + gap[1:] + ".")
    return out


def _words(text: str) -> int:
    return sum(1 for w in text.split() if any(ch.isalnum() for ch in w))


def verdict_sentence(table: Mapping, ladder: Mapping) -> str:
    """The verdict sentences as one line (kept for callers that want the whole verdict)."""
    return " ".join(verdict_sentences(table, ladder))


def _verdict_opening(ladder: Mapping, within: str, held: list, systems: list) -> str:
    """The spec's claim (or the test itself), and on how many systems it holds."""
    near = ladder["near"]
    claim = ladder.get("claim", "").strip().rstrip(".")
    count = _systems_phrase(len(held), len(systems))
    if claim:
        return (f"{claim[0].upper() + claim[1:]}, read as some design {within} costing at most {near:g} % more "
                f"than LQR, holds on {count}.")
    return f"Some design {within} costs at most {near:g} % more than LQR on {count}."


def _held_sentence(table: Mapping, held: list, systems: list, zero: Mapping, best: Mapping, bound: float,
                   within: str) -> str:
    """Where the claim holds: already without any link (the best design with no link named), or within the budget."""
    trivial = [(s, n) for s, n in held if zero[s] <= bound]
    other = [(s, n) for s, n in held if (s, n) not in trivial]
    one = len(systems) == 1

    def on(group) -> str:
        return "" if one else f" on {join_words([n for _, n in group])}"

    parts = []
    if trivial:
        labels = {table["zero"][s][1] for s, _ in trivial}
        who = labels.pop() if len(labels) == 1 else "the best design with no link"
        parts.append(f"{'it holds without any link: ' if not other else 'without any link, '}{who} is already "
                     f"{_range([zero[s] for s, _ in trivial])} above LQR{on(trivial)}")
    if other:
        parts.append(f"{within} the best design costs {_range([best[s] for s, _ in other])} above LQR{on(other)}")
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."


def _missed_sentence(table: Mapping, missed: list, within: str) -> str:
    """Where the claim fails: the best cost within the first budget and with no link, or that there is none."""
    best = {s: table["first"][s][0] for s, _ in missed}
    zero = {s: table["zero"][s][0] for s, _ in missed}
    costly = [(s, n) for s, n in missed if math.isfinite(best[s])]
    nothing = [n for s, n in missed if not math.isfinite(best[s])]
    parts = []
    if costly:
        names = join_words([n for _, n in costly])
        costs = join_words([f"{_pct_unit(best[s])} above LQR ({table['first'][s][1]})" for s, _ in costly])
        text = f"On {names} it fails: {within} the best design costs {costs}"
        zeros = [zero[s] for s, _ in costly if math.isfinite(zero[s])]
        if zeros:
            text += f", against {_range(zeros)} with no link"
        parts.append(text)
    if nothing:
        parts.append(f"{'on ' if parts else 'On '}{join_words(nothing)} no usable design lies {within}")
    return "; ".join(parts)


def ladder_details(table: Mapping, ladder: Mapping) -> list[str]:
    """The ladder's table: one column per system; the best design with no link, the best of any method within each
    budget, the share of the gap to LQR the first budget closes, then each method's best within each budget."""
    budgets = ladder["budgets"]
    systems = table["systems"]
    zero_labels = {table["zero"][s][1] for s, _ in systems}
    one_label = len(zero_labels) == 1 and None not in zero_labels

    def zero_cell(s) -> str:
        cost, label = table["zero"][s]
        if label is None:
            return "none"
        return _pct(cost) + ("" if one_label else f" ({label})")

    best = table.get("best") or {s: [table["first"][s]] for s, _ in systems}
    head = f"{' / '.join(str(b) for b in budgets)}"
    rows = [(f"with no link{': ' + zero_labels.copy().pop() if one_label else ''}", [zero_cell(s) for s, _ in systems]),
            ("best of any method", [_pcts([c for c, _ in best[s]]) for s, _ in systems])]
    closed = [_closed(table["zero"][s][0], table["first"][s][0]) for s, _ in systems]
    if any(c is not None for c in closed):
        rows.append((f"gap to LQR closed within {_plural(budgets[0], 'link')}",
                     ["—" if c is None else f"{100 * c:.0f} %" for c in closed]))
    rows += [(name, [_rung_text(table["rungs"].get((s, name)), budgets) for s, _ in systems])
             for name in table["entries"]]
    lines = [f"Best cost within {head} links (directed links between nodes), in per cent above LQR: the median over "
             "seeds where a system has several; none: no design within the budget (sparsest: its fewest links).", "",
             "| method | " + " | ".join(n for _, n in systems) + " |", "|---|" + "---|" * len(systems)]
    lines += [f"| {label} | " + " | ".join(cells) + " |" for label, cells in rows]
    return lines


def ladder_lines(records, meta=None, members=None) -> tuple[list[str], list[str]]:
    """The ladder of every experiment that asks for one: (verdict sentences, detail lines).

    The detail lines are the ladder's table (:func:`ladder_details`).
    """
    sentences, details = [], []
    for _, ladder, rs in asked_ladders(records, meta, members):
        table = ladder_table(rs, ladder)
        if not table["systems"] or not table["entries"]:
            continue
        sentences += verdict_sentences(table, ladder)
        details += ([""] if details else []) + ladder_details(table, ladder)
    return sentences, details
