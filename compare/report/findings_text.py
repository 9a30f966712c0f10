"""The Findings section: one bullet per compared pair, its verdict first, from the forest plot's cells.

Each verdict of :class:`compare.report.findings.Comparison` is worded one way: "beats" (the
interval excludes 0, the Holm-adjusted sign test gives p < 0.05, the difference is
beyond the practical margin and the budget fronts as drawn agree), "costs more/less …
on k of n instances, not significant after Holm's correction" (the interval excludes 0
only), "no clear difference" (the interval contains 0), "equal within 0.1 % of LQR's
cost" (the median difference is inside :data:`compare.report.findings.PRACTICAL_MARGIN`: never
"beats", never a count of wins), "mixed" (the typical instance favours one design, the
median costs the other: both numbers are given); cells with too few instances for a
95 % interval give counts only.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from .findings import (
    ALPHA,
    BOUND_LABEL,
    PRACTICAL_MARGIN,
    UNCERTAIN_RSE,
    Comparison,
    budgets_per_node,
)
from .names import join_words

__all__ = ["findings_markdown", "complete_plant_panels", "repaired_instances", "EQUAL_WORDS", "number_text",
           "range_text", "side_of", "with_article", "short_label", "panel_names", "scope_text", "models_text"]

# A cell's verdict, each worded one way in the text (defined in the Statistics line): "beats" (a claim: interval
# excludes 0, Holm p < ALPHA, beyond the margin, the fronts agree), "costs more/less ..., not significant after Holm's
# correction" (interval excludes 0 only), "mixed" (tested, but the fronts as drawn order the two the other way),
# "equal within the margin", "no clear difference" (interval contains 0); and cells too small for an interval, given
# as counts.
_BEATS, _DIRECTION, _MIXED, _EQUAL, _UNCLEAR, _FEW = "beats", "direction", "mixed", "equal", "unclear", "few"
#: The verdicts in the order a pair's headline is chosen (see :func:`_pair_bullet`).
_HEADLINE_ORDER = (_BEATS, _DIRECTION, _MIXED, _EQUAL, _UNCLEAR, _FEW)
_NOT_SIGNIFICANT = "not significant after Holm's correction"
#: How an "equal" cell is worded, everywhere.
EQUAL_WORDS = f"equal within {100 * PRACTICAL_MARGIN:g} % of LQR's cost"
_NORM_PREFIX = "‖A‖₂ = "


def number_text(x: float) -> str:
    """A number in the text: signed, two significant digits, a true minus."""
    if x == 0:
        return "0"
    # '#' keeps a trailing zero (+0.020, not +0.02), and with it a bare point (+12.) that goes.
    text = f"{x:+,.0f}" if abs(x) >= 100 else f"{x:+#.2g}".rstrip(".")
    return "−" + text[1:] if text.startswith("-") else text


def _p(p: float) -> str:
    return f"{p:.2g}"


def _span(values: Iterable) -> str:
    """"9–10", or "10" when they agree."""
    values = sorted(set(values))
    return str(values[0]) if len(values) == 1 else f"{values[0]}–{values[-1]}"


def range_text(values: Sequence[float]) -> str:
    """"+0.018 to +0.082", or one number where they round alike."""
    low, high = number_text(min(values)), number_text(max(values))
    return low if low == high else f"{low} to {high}"


def _plural(k: int, word: str) -> str:
    return f"{k} {word}" + ("" if k == 1 else "s")


def _s(k: int) -> str:
    """The plural ending for a count of ``k``."""
    return "" if k == 1 else "s"



def _level(c: Comparison) -> str:
    """The cell's verdict as the text words it (the order of :attr:`Comparison.verdict`)."""
    if c.equal:
        return _EQUAL
    if c.too_few:
        return _FEW
    if c.mixed:
        return _MIXED
    if c.paired.inconclusive:
        return _UNCLEAR
    return _BEATS if c.significant else _DIRECTION


def side_of(c: Comparison) -> int:
    """−1 where a costs less than b, +1 where it costs more (by the interval, else by the wins), 0: split.

    For a mixed cell, the side the typical instance (the paired median) favours.
    """
    p = c.paired
    if _level(c) in (_BEATS, _DIRECTION, _MIXED):
        return -1 if p.median < 0 else 1
    return int(np.sign(p.b_wins - p.a_wins))


def with_article(label: str) -> str:
    return f"the {label}" if label == BOUND_LABEL else label


def _strip(label: str) -> str:
    if label == BOUND_LABEL:
        return "SLS bound"
    return label.rsplit(" (", 1)[0] if label.endswith(")") and " (" in label else label


def short_label(label: str, other: str) -> str:
    """The name in a bullet's body, once its headline has given the full one: without the trailing parenthesis,
    unless that leaves it a prefix of the other's (SLS against the SLS bound)."""
    mine, theirs = _strip(label), _strip(other)
    if mine.startswith(theirs) or theirs.startswith(mine):
        mine = label
    return f"the {mine}" if label == BOUND_LABEL else mine


def panel_names(panels: Sequence[tuple]) -> dict[tuple, str]:
    """Short names: what tells the panels apart (‖A‖₂ alone when all share family and N)."""
    families = {p[0] for p in panels}
    sizes = {p[1] for p in panels}
    out = {}
    for family, n, a_norm in panels:
        parts = [] if len(families) == 1 or a_norm is not None else [str(family)]
        if len(sizes) > 1 or (a_norm is None and len(families) == 1):
            parts.append(f"N = {n}")
        if a_norm is not None:
            parts.append(f"{_NORM_PREFIX}{a_norm:g}")
        out[(family, n, a_norm)] = ", ".join(parts)
    return out


def _panel_list(panels: Sequence[tuple], names: Mapping) -> str:
    """"‖A‖₂ = 0.995 and 1.2" rather than repeating "‖A‖₂ =" for each."""
    labels = [names[p] for p in panels]
    if len(labels) > 1 and all(x.startswith(_NORM_PREFIX) and "," not in x for x in labels):
        return _NORM_PREFIX + join_words([x[len(_NORM_PREFIX):] for x in labels])
    return join_words(labels)


def _in_panels(panels: Sequence[tuple], names: Mapping, every: bool = True) -> str:
    """" in all 5 panels" (or "" unless ``every``), " on ‖A‖₂ = 1.2", " in 3 of 5 panels"."""
    total = len(names)
    if len(panels) == total:
        return {1: "", 2: " in both panels"}.get(total, f" in all {total} panels") if every else ""
    if len(panels) <= 2:
        return f" on {_panel_list(panels, names)}"
    return f" in {len(panels)} of {total} panels"


def _budgets_phrase(budgets: Sequence, per_node: bool = False) -> str:
    """"at ≤ 20 and ≤ 60 links and overall" (overall: any number of links); "links per node" with ``per_node``."""
    finite = [f"≤ {b:g}" for b in budgets if b is not None]
    unit = "link" if [b for b in budgets if b is not None] == [1] else "links"
    text = f"at {join_words(finite)} {unit}{' per node' if per_node else ''}" if finite else ""
    if None in budgets:
        text += (" and " if text else "") + "overall"
    return text


def _where(cells: Sequence[Comparison], names: Mapping, every: bool = True) -> str:
    """Where ``cells`` lie: their budgets, grouped by the panels each holds in, the widest first.

    Without ``every``, a budget held in every panel goes unqualified ("at ≤ 20 links"): the
    trailing sentences of a bullet, after its headline has said how many panels there are.
    """
    order = list(names)
    per_node = budgets_per_node(cells)
    held: dict = {}
    for c in cells:
        held.setdefault(c.budget_tier(per_node), set()).add(c.panel)
    groups: dict[tuple, list] = {}
    for budget, panels in held.items():
        groups.setdefault(tuple(p for p in order if p in panels), []).append(budget)
    ranked = sorted(groups.items(), key=lambda item: -len(item[0]))
    return join_words([_budgets_phrase(budgets, per_node) + _in_panels(panels, names, every) for panels, budgets in ranked])



def scope_text(lead: Sequence[Comparison], cells: Sequence[Comparison], names: Mapping) -> str:
    """Where the headline holds; "in every panel but one" when the exceptions share one panel of three or more."""
    mine = {id(c) for c in lead}
    rest = [c for c in cells if id(c) not in mine]
    odd = {c.panel for c in rest}
    per_node = budgets_per_node(cells)
    budgets = list(dict.fromkeys(c.budget_tier(per_node) for c in cells))
    others = {p for p in names if p not in odd}
    complete = all(any(c.panel == p and c.budget_tier(per_node) == b for c in lead) for p in others for b in budgets)
    if len(odd) == 1 and len(names) >= 3 and complete:
        return f"{_budgets_phrase(budgets, per_node)} in every panel but one"
    return _where(lead, names)


def _loc(c: Comparison, names: Mapping) -> str:
    return ", ".join(x for x in (names[c.panel], _budgets_phrase([c.budget]).removeprefix("at ")) if x)


def _n_phrase(cells: Sequence[Comparison]) -> str:
    """"n = 30", "n = 17–30 per cell", and the exact count of pairings unresolved costs changed (the Statistics
    line says why)."""
    many = len(cells) > 1
    text = f"n = {_span(c.paired.instances for c in cells)}" + (" per cell" if many else "")
    changed = [c.excluded for c in cells if c.excluded]
    if changed and many and len(changed) == len(cells) and len(set(changed)) == 1:
        text += f", {changed[0]} re-paired per cell"
    elif changed and many:
        text += f", {_span(changed)} re-paired in {len(changed)} of the {len(cells)} cells"
    elif changed:
        text += f", {changed[0]} re-paired"
    return text


_INFO_WORDS = {"delayed": "delayed", "instantaneous": "instantaneous", "none": "no communication"}


def models_text(c: Comparison, first: str | None = None) -> str:
    """The information models: "(both delayed)", or the marker of a cross-model claim, the models in the order in
    which the sentence names the designs (``first`` named first; by default a, then b)."""
    ia, ib = (_INFO_WORDS.get(x, x) for x in (c.info_a, c.info_b))
    if first is not None and first == c.b and first != c.a:
        ia, ib = ib, ia
    return f"(both {ia})" if c.relation == "same" else f"(crosses models: {ia} vs {ib})"


def _holm(cells: Sequence[Comparison], bound: str) -> str:
    """"Holm p ≤ 0.002" over claims (the largest), "Holm p ≥ 0.094" otherwise (the smallest); "=" for one cell."""
    values = [c.p_holm for c in cells]
    value = max(values) if bound == "≤" else min(values)
    return f"Holm p {bound if len(cells) > 1 else '='} {_p(value)}"


def _wins(cells: Sequence[Comparison], side: int) -> str:
    """"on 10 of 10 instances", "on all 9–10 instances", "on at least 8 of 9–10 instances": a's side of the wins."""
    counts = [(c.paired.a_wins if side < 0 else c.paired.b_wins, c.paired.instances) for c in cells]
    most = max(n for _, n in counts)
    if len(set(counts)) == 1:
        return f"on {counts[0][0]} of {counts[0][1]} instance{_s(counts[0][1])}"
    if all(k == n for k, n in counts):
        return f"on all {_span(n for _, n in counts)} instance{_s(most)}"
    return f"on at least {min(k for k, _ in counts)} of {_span(n for _, n in counts)} instance{_s(most)}"


def _weakest(cells: Sequence[Comparison]) -> Comparison:
    """The cell whose interval comes closest to 0: it bounds every claim of its bullet."""
    return min(cells, key=lambda c: min(abs(c.paired.low), abs(c.paired.high)))


def _beats_sentence(lead, cells, names, side) -> str:
    """"**W beats L** (both delayed) at …: L costs +x to +y more (weakest …; n …; Holm p ≤ …)."."""
    c0 = lead[0]
    a, b = c0.a, c0.b
    winner, loser = (a, b) if side < 0 else (b, a)
    beaten_by_bound = b == BOUND_LABEL and side > 0
    verdict = f"{a} is beaten by the {b}" if beaten_by_bound else f"{with_article(winner)} beats {with_article(loser)}"
    margins = [side * c.paired.median for c in lead]  # loser − winner: positive
    # The information models in the order the verdict names the designs.
    models = models_text(c0, a if beaten_by_bound else winner)
    text = (f"**{verdict}** {models} {scope_text(lead, cells, names)}: {short_label(loser, winner)} costs "
            f"{range_text(margins)} more")
    weak = _weakest(lead)
    low, high = sorted(side * v for v in (weak.paired.low, weak.paired.high))
    interval = f"[{number_text(low)}, {number_text(high)}]"
    where = f"weakest {number_text(side * weak.paired.median)} {interval}, {_loc(weak, names)}" if len(lead) > 1 \
        else f"95 % interval {interval}"
    return text + f" ({where}; {_n_phrase(lead)}; {_holm(lead, '≤')})."


def _direction_sentence(lead, cells, names, side, k) -> str:
    """"**A costs more than B on 10 of 10 instances** (…) at …, +x to +y; not significant after Holm's …"."""
    c0 = lead[0]
    word = "less" if side < 0 else "more"
    verdict = f"{c0.a} costs {word} than {with_article(c0.b)} {_wins(lead, side)}"
    medians = [c.paired.median for c in lead]
    return (f"**{verdict}** {models_text(c0)} {scope_text(lead, cells, names)}, {range_text(medians)}; {_NOT_SIGNIFICANT} "
            f"over K = {_plural(k, 'comparison')} ({_holm(lead, '≥')}).")


def _difference(c0: Comparison) -> str:
    """"GRNN-Sparse − SLS bound": the paired difference's two sides, short."""
    return f"{short_label(c0.a, c0.b)} − {short_label(c0.b, c0.a).removeprefix('the ')}"


def _unclear_sentence(lead, cells, names) -> str:
    c0 = lead[0]
    return (f"**No clear difference between {c0.a} and {with_article(c0.b)}** {models_text(c0)} {scope_text(lead, cells, names)}: "
            f"median {_difference(c0)} {range_text([c.paired.median for c in lead])} ({_n_phrase(lead)}).")


def _equal_sentence(lead, cells, names) -> str:
    """"**A and B are equal within 0.1 % of LQR's cost** (…) at …: median A − B x to y (n …)."

    Never a count of wins: a difference below the margin is no win.
    """
    c0 = lead[0]
    return (f"**{c0.a} and {with_article(c0.b)} are {EQUAL_WORDS}** {models_text(c0)} {scope_text(lead, cells, names)}: "
            f"median {_difference(c0)} {range_text([c.paired.median for c in lead])} ({_n_phrase(lead)}).")


def _digits(x: float, y: float) -> tuple[str, str]:
    """Two costs with as many decimals (4 to 7) as it takes to tell them apart."""
    for d in range(4, 8):
        tx, ty = f"{x:.{d}f}", f"{y:.{d}f}"
        if tx != ty:
            break
    return tx, ty


def _mixed_clause(cells: Sequence[Comparison], names: Mapping, *, where: bool) -> str:
    """What a group of mixed cells (one side for the typical instance) says, both numbers given:
    "A costs less on 27 of 30 instances (median paired difference A − B −0.0014), yet B has the lower median
    cost (1.0889 against A's 1.0896)"."""
    c0 = cells[0]
    side = side_of(c0)
    typical, other = (c0.a, c0.b) if side < 0 else (c0.b, c0.a)
    t_short, o_short = short_label(typical, other), short_label(other, typical)
    drawn = []
    for c in cells:
        mine, theirs = (c.drawn_a, c.drawn_b) if typical == c.a else (c.drawn_b, c.drawn_a)
        t_text, o_text = _digits(mine, theirs)
        drawn.append(f"{o_text} against {t_text}" + (f" on {_loc(c, names)}" if where and len(cells) > 1 else ""))
    return (f"{t_short} costs less {_wins(cells, side)} (median paired difference {_difference(c0)} "
            f"{range_text([c.paired.median for c in cells])}; {_holm(cells, '≤')}), yet {o_short} has the lower median "
            f"cost ({'; '.join(drawn)})")


def _mixed_sentence(lead, cells, names) -> str:
    """"**Mixed between A and B** (…) at …: the typical instance and the median costs disagree: A costs less on
    27 of 30 instances (…), yet B has the lower median cost (…)."."""
    c0 = lead[0]
    return (f"**Mixed between {c0.a} and {with_article(c0.b)}** {models_text(c0)} {scope_text(lead, cells, names)}: the typical "
            f"instance and the median costs disagree: {_mixed_clause(lead, names, where=True)}.")


def _counts(cells: Sequence[Comparison], subject: str, side: int) -> str:
    """"GRNN-Sparse costs more on 3 of 4 and 2 of 2", or for many cells a tally of the cells by direction."""
    word = "less" if side < 0 else "more"
    if len(cells) <= 3:
        shown = [f"{c.paired.a_wins if side < 0 else c.paired.b_wins} of {c.paired.instances}" for c in cells]
        return f"{subject} costs {word} on {join_words(shown)}"
    same = sum(1 for c in cells if (c.paired.a_wins if side < 0 else c.paired.b_wins) == c.paired.instances)
    other = sum(1 for c in cells if (c.paired.b_wins if side < 0 else c.paired.a_wins) == c.paired.instances)
    most = max(c.paired.instances for c in cells)
    text = f"{subject} costs {word} on every instance in {same} of {len(cells)} cells"
    if other:
        text += f", {'more' if side < 0 else 'less'} on every instance in {other}"
    return text + f" ({_span(c.paired.instances for c in cells)} instance{_s(most)} per cell)"


def _few_sentence(lead, names) -> str:
    c0 = lead[0]
    side = 1 if sum(side_of(c) for c in lead) >= 0 else -1
    return (f"**Too few instances to compare {c0.a} and {with_article(c0.b)}** {models_text(c0)} {_where(lead, names)}: "
            f"{_counts(lead, short_label(c0.a, c0.b), side)}, with no 95 % interval.")


def _rest_sentences(rest, names, level: str, side: int) -> list[str]:
    """Short sentences on the cells the headline leaves out, by verdict."""
    if not rest:
        return []
    c0 = rest[0]
    out = []
    beaten = [c for c in rest if _level(c) == _BEATS]
    if beaten:  # the opposite of the headline, significant: a claim of its own
        flip = side_of(beaten[0])
        winner, loser = (c0.a, c0.b) if flip < 0 else (c0.b, c0.a)
        out.append(f"But **{with_article(winner)} beats {with_article(loser)}** {_where(beaten, names, False)} "
                   f"({range_text([flip * c.paired.median for c in beaten])}; {_holm(beaten, '≤')}).")
    for same, what in ((True, "Same direction"), (False, "Opposite direction")):
        cells = [c for c in rest if _level(c) == _DIRECTION and (side_of(c) == side) == same]
        if cells:
            out.append(f"{what}, {_NOT_SIGNIFICANT}, {_where(cells, names, False)} ({_holm(cells, '≥')}).")
    for typical in (-1, 1):  # the typical instance favours a, then b
        mixed = [c for c in rest if _level(c) == _MIXED and side_of(c) == typical]
        if mixed:
            out.append(f"Mixed {_where(mixed, names, False)}: {_mixed_clause(mixed, names, where=True)}.")
    equal = [c for c in rest if _level(c) == _EQUAL]
    if equal:
        out.append(f"{EQUAL_WORDS[0].upper()}{EQUAL_WORDS[1:]} {_where(equal, names, False)}.")
    unclear = [c for c in rest if _level(c) == _UNCLEAR]
    if unclear and level != _UNCLEAR:
        out.append(f"No clear difference {_where(unclear, names, False)}.")
    few = [c for c in rest if _level(c) == _FEW]
    if few:
        # Their counts (on at most 5 instances) cannot move a tested claim: the forest plot has them.
        out.append(f"Too few instances {_where(few, names, False)}.")
    return out


def _pair_bullet(cells: Sequence[Comparison], names: Mapping, k: int, complete_plant=frozenset()) -> str:
    """One bullet on one pair over its panels and budgets: a bold verdict, then the cells it leaves out."""
    by_level = {level: [c for c in cells if _level(c) == level] for level in _HEADLINE_ORDER}
    tested = [x for x in (_BEATS, _DIRECTION, _MIXED) if by_level[x]]
    # A tested verdict leads; otherwise the verdict most cells have (equal, unclear, too few, in that order on ties).
    level = tested[0] if tested else max((_EQUAL, _UNCLEAR, _FEW), key=lambda x: len(by_level[x]))
    pool = by_level[level]
    side = 0
    if level in (_BEATS, _DIRECTION, _MIXED):
        votes = [side_of(c) for c in pool]
        side = -1 if votes.count(-1) > votes.count(1) else 1
        lead = [c for c in pool if side_of(c) == side]
        head = {_BEATS: lambda: _beats_sentence(lead, cells, names, side),
                _DIRECTION: lambda: _direction_sentence(lead, cells, names, side, k),
                _MIXED: lambda: _mixed_sentence(lead, cells, names)}[level]()
    else:
        lead = pool
        head = {_EQUAL: lambda: _equal_sentence(lead, cells, names),
                _UNCLEAR: lambda: _unclear_sentence(lead, cells, names),
                _FEW: lambda: _few_sentence(lead, names)}[level]()
    mine = {id(c) for c in lead}
    parts = [head] + _rest_sentences([c for c in cells if id(c) not in mine], names, level, side)
    note = _note(cells, names, complete_plant)
    return " ".join(parts + ([note] if note else []))


# What a gap means, where the pair alone does not say it.
_NOTES = {
    ("grnn_dense", True): "GRNN-Dense learns on the complete graph: this gap is training error, not topology.",
}
_PLANT_NOTE = "The gap is what restricting communication to the plant graph costs"


def _note(cells: Sequence[Comparison], names: Mapping, complete_plant) -> str:
    """The note on what a pair's gap means, only where its premise holds.

    SLS on the plant graph against the bound: the gap is what restricting communication
    to the plant graph costs, except on panels whose plant graph is the complete graph,
    where the two are one design (``complete_plant``).
    """
    c0 = cells[0]
    if not (c0.method_a in ("sls", "sls_topologies") and c0.b == BOUND_LABEL):
        return _NOTES.get((c0.method_a, c0.b == BOUND_LABEL), "")
    panels = list(dict.fromkeys(c.panel for c in cells))
    complete = [p for p in panels if p in complete_plant]
    if not complete:
        return _PLANT_NOTE + "."
    if len(complete) == len(panels):
        where = "" if len(names) == 1 else f" on {_panel_list(complete, names)}"
        return f"Here the plant graph is the complete graph{where}, so the two are one design."
    return (f"{_PLANT_NOTE}, except on {_panel_list(complete, names)}, where the plant graph is the complete graph "
            "and the two are one design.")


_CAPTION = ("Each row is one cell (pair, panel, link budget): the median over instances of the paired difference of "
            "best costs, first − second (LQR-normalized; negative: the first costs less), and its 95 % interval. "
            "Filled: one beats the other; hollow: " + _NOT_SIGNIFICANT + ", no clear difference, " + EQUAL_WORDS
            + ", or mixed; grey: too few instances for an interval.")


def _power_note(comparisons: Sequence[Comparison]) -> str:
    """Where no sign test on these instance counts can pass Holm's correction: say so before the claims."""
    k = len(comparisons)
    most = max(c.paired.instances for c in comparisons)
    smallest = 2 * 0.5 ** most  # the smallest p a sign test on `most` instances can give
    if min(1.0, k * smallest) < ALPHA:
        return ""
    return (f"With at most {_plural(most, 'instance')} per cell no sign test goes below p = {_p(smallest)}, so none "
            f"can pass Holm's correction over K = {_plural(k, 'comparison')}: these data show directions, not "
            "significance.")


def _unresolved_text(comparisons: Sequence[Comparison], excluded_total: int | None,
                     repaired_instances: int | None = None) -> str:
    """What dropping unresolved costs did, in exact counts: designs dropped, (cell, instance) pairings changed,
    and over how many instances (where the records are known)."""
    changed = sum(c.excluded for c in comparisons)
    rse = f"standard error > {UNCERTAIN_RSE * 100:g} % of the cost"
    pairings = f"{changed} (cell, instance) pairing{_s(changed)}"
    if repaired_instances is not None:
        pairings += f" over {_plural(repaired_instances, 'instance')}"
    if excluded_total:
        verb = "were" if excluded_total != 1 else "was"
        if not changed:
            return (f"{_plural(excluded_total, 'unresolved simulated cost')} ({rse}) {verb} dropped; "
                    "no comparison changed.")
        return (f"{_plural(excluded_total, 'unresolved simulated cost')} ({rse}) {verb} dropped, changing "
                f"{pairings}.")
    if excluded_total is None and changed:
        return f"Unresolved simulated costs ({rse}) were dropped, changing {pairings}."
    if excluded_total is None:
        return f"No unresolved simulated cost ({rse}) entered or changed a comparison."
    return f"No simulated cost was unresolved ({rse})."


def _statistics_line(comparisons: Sequence[Comparison], excluded_total, repaired_instances) -> str:
    """How the claims are tested, each verdict defined once (the margin with its reasons)."""
    k = len(comparisons)
    return (f"Statistics: per cell, a distribution-free 95 % interval for the median difference (not simultaneous) "
            f"and an exact sign test on the wins, Holm-corrected over K = {_plural(k, 'comparison')} (Holm p). "
            f"**Beats**: interval excludes 0, Holm p < {ALPHA:g}; **costs more/less**, {_NOT_SIGNIFICANT}: interval "
            f"excludes 0, Holm p ≥ {ALPHA:g}; **no clear difference**: interval contains 0; **{EQUAL_WORDS}**: "
            "median difference below that margin, interval excluding 0 or inside it (the paper's third decimal; "
            "above the solvers' tolerances and the simulated costs' standard errors); **mixed**: a difference beyond "
            "the margin that the median costs drawn in the budget fronts reverse, so neither is claimed better. "
            f"{_unresolved_text(comparisons, excluded_total, repaired_instances)}")


def complete_plant_panels(records) -> set:
    """The panels whose plant graph is the complete graph: N(N − 1) directed off-diagonal plant links on every
    instance whose facts the records hold (N its node count); panels without such facts are left out."""
    from ..run.records import as_records

    out = set()
    for panel, rs in as_records(records).by_panel.items():
        known = [i for i in rs.instances if i.plant_links is not None and i.nodes]
        if known and all(i.plant_links >= i.nodes * (i.nodes - 1) for i in known):
            out.add(panel)
    return out


def _identical_panels(comparisons: Sequence[Comparison]) -> set:
    """Without records: the panels where SLS on the plant graph costs exactly what the bound costs on every
    instance (the two are one design there, as when the plant graph is complete)."""
    out = set()
    for c in comparisons:
        if c.method_a in ("sls", "sls_topologies") and c.b == BOUND_LABEL:
            p = c.paired
            if p.instances and p.a_wins == p.b_wins == 0 and p.low == p.high == 0:
                out.add(c.panel)
    return out


def repaired_instances(records, comparisons: Sequence[Comparison]) -> int:
    """How many instances hold a (cell, instance) pairing that dropping unresolved costs changed.

    The per-cell counts are :attr:`Comparison.excluded`; the instances behind them are
    found again here as :func:`compare.report.findings.select_comparisons` finds them: in each
    cell, an instance where both sides have a design within the budget and a side's best
    cost differs (or is missing) once unresolved designs are dropped.
    """
    from ..run.records import Records, as_records
    from .findings import arm_labels, is_unresolved
    from .statistics import best_within, instances_by_panel

    records = as_records(records)
    cells = [c for c in comparisons if c.excluded]
    if not cells:
        return 0
    labels = arm_labels(records)
    panels = instances_by_panel(records)
    full: dict[tuple, list] = {}
    kept: dict[tuple, list] = {}
    for r, label in zip(records, labels):
        full.setdefault((r.instance.panel, label), []).append(r)
        if not is_unresolved(r):
            kept.setdefault((r.instance.panel, label), []).append(r)
    changed = set()
    for c in cells:
        grid = [np.inf if c.budget is None else float(c.budget)]
        sides = []
        for arm in (c.a, c.b):
            f = best_within(Records(full.get((c.panel, arm), [])), panels[c.panel], grid)[:, 0]
            k = best_within(Records(kept.get((c.panel, arm), [])), panels[c.panel], grid)[:, 0]
            sides.append((f, k))
        (fa, ka), (fb, kb) = sides
        with np.errstate(invalid="ignore"):
            both = np.isfinite(fa) & np.isfinite(fb)
            same = np.isfinite(ka) & np.isfinite(kb) & (ka == fa) & (kb == fb)
        changed |= {panels[c.panel][i] for i in np.flatnonzero(both & ~same)}
    return len(changed)


def findings_markdown(comparisons: Sequence[Comparison], *, excluded_total: int | None = None,
                      records=None) -> list[str]:
    """The "## Findings" section: one bullet per compared pair, the forest plot, and how the claims are tested.

    Each bullet leads with a bold verdict on the pair: "A beats B" (a claim:
    :attr:`Comparison.significant`), "A costs more/less than B on k of n instances"
    (interval excludes 0, not significant after Holm's correction), "mixed" (the typical
    instance favours one, the median costs the other; both numbers given), "A and B are
    equal within 0.1 % of LQR's cost", "no clear difference" (interval contains 0) or
    counts only, then where it holds, the numbers behind it, and short sentences on the
    cells it leaves out.

    Parameters
    ----------
    comparisons : sequence of Comparison
        As :func:`select_comparisons` gives them (their order is the bullets' order).
    excluded_total : int, optional
        Unresolved designs dropped from every comparison (``len(unresolved(records))``);
        when not given, the statistics line says only how many pairings they changed.
    records : Records, optional
        The records compared. With them, the statistics line says over how many
        instances unresolved costs changed pairings, and the note on SLS on the plant
        graph against the bound checks its premise on the instance facts (plant graph
        complete: N(N − 1) links); without them, a plant graph is taken as complete
        where the two cost exactly the same on every instance.

    Returns
    -------
    list of str
        Markdown lines, ending with an empty line; the figure is referenced as
        ``forest.png`` (the caller saves :func:`plot_forest`'s figure there). Empty
        where there is nothing to compare.
    """
    if not comparisons:
        return []
    names = panel_names(list(dict.fromkeys(c.panel for c in comparisons)))
    k = len(comparisons)
    pairs: dict[tuple, list] = {}
    for c in comparisons:
        pairs.setdefault((c.group, c.a, c.b), []).append(c)
    if records is not None:
        complete, repaired = complete_plant_panels(records), repaired_instances(records, comparisons)
    else:
        complete, repaired = _identical_panels(comparisons), None
    # The claims first (the report's first sentence is its first finding), then the figure they come from.
    # Where no claim can reach significance, the reader learns it before the claims.
    power = _power_note(comparisons)
    lines = ["## Findings", ""] + ([power, ""] if power else [])
    lines += [f"- {_pair_bullet(cells, names, k, complete)}" for cells in pairs.values()]
    lines += ["", "![forest plot](forest.png)", "", _CAPTION]
    lines += ["", _statistics_line(comparisons, excluded_total, repaired), ""]
    return lines
