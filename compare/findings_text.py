"""The Findings section: one bullet per compared pair, its verdict first, from the forest plot's cells.

Three verdicts, each worded one way: "beats" (the interval excludes 0 and the
Holm-adjusted sign test gives p < 0.05), "costs more/less … on k of n instances,
not significant after Holm's correction" (the interval excludes 0 only), "no clear
difference" (the interval contains 0); cells with too few instances for a 95 %
interval give counts only.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from .findings import ALPHA, BOUND_LABEL, UNCERTAIN_RSE, Comparison, budgets_per_node

__all__ = ["findings_markdown"]

# A tested cell's verdict, each worded one way in the text (defined in the Statistics line): "beats" (interval
# excludes 0 and Holm p < ALPHA), "costs more/less ..., not significant after Holm's correction" (interval excludes
# 0 only), "no clear difference" (interval contains 0); and cells too small for an interval, given as counts.
_BEATS, _DIRECTION, _UNCLEAR, _FEW = "beats", "direction", "unclear", "few"
_NOT_SIGNIFICANT = "not significant after Holm's correction"
_NORM_PREFIX = "‖A‖₂ = "


def _fmt(x: float) -> str:
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


def _range(values: Sequence[float]) -> str:
    """"+0.018 to +0.082", or one number where they round alike."""
    low, high = _fmt(min(values)), _fmt(max(values))
    return low if low == high else f"{low} to {high}"


def _plural(k: int, word: str) -> str:
    return f"{k} {word}" + ("" if k == 1 else "s")


def _join(parts: Sequence[str]) -> str:
    parts = list(parts)
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def _level(c: Comparison) -> str:
    if c.too_few:
        return _FEW
    if c.paired.inconclusive:
        return _UNCLEAR
    return _BEATS if c.significant else _DIRECTION


def _side(c: Comparison) -> int:
    """−1 where a costs less than b, +1 where it costs more (by the interval, else by the wins), 0: split."""
    p = c.paired
    if _level(c) in (_BEATS, _DIRECTION):
        return -1 if p.high < 0 else 1
    return int(np.sign(p.b_wins - p.a_wins))


def _the(label: str) -> str:
    return f"the {label}" if label == BOUND_LABEL else label


def _strip(label: str) -> str:
    if label == BOUND_LABEL:
        return "SLS bound"
    return label.rsplit(" (", 1)[0] if label.endswith(")") and " (" in label else label


def _short(label: str, other: str) -> str:
    """The name in a bullet's body, once its headline has given the full one: without the trailing parenthesis,
    unless that leaves it a prefix of the other's (SLS against the SLS bound)."""
    mine, theirs = _strip(label), _strip(other)
    if mine.startswith(theirs) or theirs.startswith(mine):
        mine = label
    return f"the {mine}" if label == BOUND_LABEL else mine


def _panel_names(panels: Sequence[tuple]) -> dict[tuple, str]:
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
        return _NORM_PREFIX + _join([x[len(_NORM_PREFIX):] for x in labels])
    return _join(labels)


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
    text = f"at {_join(finite)} {unit}{' per node' if per_node else ''}" if finite else ""
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
    return _join([_budgets_phrase(budgets, per_node) + _in_panels(panels, names, every) for panels, budgets in ranked])



def _scope(lead: Sequence[Comparison], cells: Sequence[Comparison], names: Mapping) -> str:
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
    many = len(cells) > 1
    text = f"n = {_span(c.paired.instances for c in cells)}" + (" per cell" if many else "")
    dropped = max(c.excluded for c in cells)
    if dropped:
        text += f", {'≤ ' if many else ''}{dropped} re-paired"  # the Statistics line says why
    return text


_INFO_WORDS = {"delayed": "delayed", "instantaneous": "instantaneous", "none": "no communication"}


def _models(c: Comparison) -> str:
    """The information models: "(both delayed)", or the marker of a cross-model claim."""
    ia, ib = (_INFO_WORDS.get(x, x) for x in (c.info_a, c.info_b))
    return f"(both {ia})" if c.relation == "same" else f"(crosses models: {ia} vs {ib})"


def _holm(cells: Sequence[Comparison], bound: str) -> str:
    """"Holm p ≤ 0.002" over claims (the largest), "Holm p ≥ 0.094" otherwise (the smallest); "=" for one cell."""
    values = [c.p_holm for c in cells]
    value = max(values) if bound == "≤" else min(values)
    return f"Holm p {bound if len(cells) > 1 else '='} {_p(value)}"


def _wins(cells: Sequence[Comparison], side: int) -> str:
    """"on 10 of 10 instances", "on all 9–10 instances", "on at least 8 of 9–10 instances": a's side of the wins."""
    counts = [(c.paired.a_wins if side < 0 else c.paired.b_wins, c.paired.instances) for c in cells]
    if len(set(counts)) == 1:
        return f"on {counts[0][0]} of {counts[0][1]} instances"
    if all(k == n for k, n in counts):
        return f"on all {_span(n for _, n in counts)} instances"
    return f"on at least {min(k for k, _ in counts)} of {_span(n for _, n in counts)} instances"


def _weakest(cells: Sequence[Comparison]) -> Comparison:
    """The cell whose interval comes closest to 0: it bounds every claim of its bullet."""
    return min(cells, key=lambda c: min(abs(c.paired.low), abs(c.paired.high)))


def _beats_sentence(lead, cells, names, side) -> str:
    """"**W beats L** (both delayed) at …: L costs +x to +y more (weakest …; n …; Holm p ≤ …)."."""
    c0 = lead[0]
    a, b = c0.a, c0.b
    winner, loser = (a, b) if side < 0 else (b, a)
    verdict = (f"{a} is beaten by the {b}" if b == BOUND_LABEL and side > 0
               else f"{_the(winner)} beats {_the(loser)}")
    margins = [side * c.paired.median for c in lead]  # loser − winner: positive
    text = (f"**{verdict}** {_models(c0)} {_scope(lead, cells, names)}: {_short(loser, winner)} costs "
            f"{_range(margins)} more")
    weak = _weakest(lead)
    low, high = sorted(side * v for v in (weak.paired.low, weak.paired.high))
    interval = f"[{_fmt(low)}, {_fmt(high)}]"
    where = f"weakest {_fmt(side * weak.paired.median)} {interval}, {_loc(weak, names)}" if len(lead) > 1 \
        else f"95 % interval {interval}"
    return text + f" ({where}; {_n_phrase(lead)}; {_holm(lead, '≤')})."


def _direction_sentence(lead, cells, names, side, k) -> str:
    """"**A costs more than B on 10 of 10 instances** (…) at …, +x to +y; not significant after Holm's …"."""
    c0 = lead[0]
    word = "less" if side < 0 else "more"
    verdict = f"{c0.a} costs {word} than {_the(c0.b)} {_wins(lead, side)}"
    medians = [c.paired.median for c in lead]
    return (f"**{verdict}** {_models(c0)} {_scope(lead, cells, names)}, {_range(medians)}; {_NOT_SIGNIFICANT} "
            f"over K = {k} comparisons ({_holm(lead, '≥')}).")


def _unclear_sentence(lead, cells, names) -> str:
    c0 = lead[0]
    a, b = _short(c0.a, c0.b), _short(c0.b, c0.a).removeprefix("the ")
    return (f"**No clear difference between {c0.a} and {_the(c0.b)}** {_models(c0)} {_scope(lead, cells, names)}: "
            f"median {a} − {b} {_range([c.paired.median for c in lead])} ({_n_phrase(lead)}).")


def _counts(cells: Sequence[Comparison], subject: str, side: int) -> str:
    """"GRNN-Sparse costs more on 3 of 4 and 2 of 2", or for many cells a tally of the cells by direction."""
    word = "less" if side < 0 else "more"
    if len(cells) <= 3:
        shown = [f"{c.paired.a_wins if side < 0 else c.paired.b_wins} of {c.paired.instances}" for c in cells]
        return f"{subject} costs {word} on {_join(shown)}"
    same = sum(1 for c in cells if (c.paired.a_wins if side < 0 else c.paired.b_wins) == c.paired.instances)
    other = sum(1 for c in cells if (c.paired.b_wins if side < 0 else c.paired.a_wins) == c.paired.instances)
    most = max(c.paired.instances for c in cells)
    text = f"{subject} costs {word} on every instance in {same} of {len(cells)} cells"
    if other:
        text += f", {'more' if side < 0 else 'less'} on every instance in {other}"
    return text + f" (at most {most} instances per cell)"


def _few_sentence(lead, names) -> str:
    c0 = lead[0]
    side = 1 if sum(_side(c) for c in lead) >= 0 else -1
    return (f"**Too few instances to compare {c0.a} and {_the(c0.b)}** {_models(c0)} {_where(lead, names)}: "
            f"{_counts(lead, _short(c0.a, c0.b), side)}, with no 95 % interval.")


def _rest_sentences(rest, names, level: str, side: int) -> list[str]:
    """Short sentences on the cells the headline leaves out, by verdict."""
    if not rest:
        return []
    c0 = rest[0]
    out = []
    beaten = [c for c in rest if _level(c) == _BEATS]
    if beaten:  # the opposite of the headline, significant: a claim of its own
        flip = _side(beaten[0])
        winner, loser = (c0.a, c0.b) if flip < 0 else (c0.b, c0.a)
        out.append(f"But **{_the(winner)} beats {_the(loser)}** {_where(beaten, names, False)} "
                   f"({_range([flip * c.paired.median for c in beaten])}; {_holm(beaten, '≤')}).")
    for same, what in ((True, "Same direction"), (False, "Opposite direction")):
        cells = [c for c in rest if _level(c) == _DIRECTION and (_side(c) == side) == same]
        if cells:
            out.append(f"{what}, {_NOT_SIGNIFICANT}, {_where(cells, names, False)} ({_holm(cells, '≥')}).")
    unclear = [c for c in rest if _level(c) == _UNCLEAR]
    if unclear and level != _UNCLEAR:
        out.append(f"No clear difference {_where(unclear, names, False)}.")
    few = [c for c in rest if _level(c) == _FEW]
    if few:
        # Their counts (on at most 5 instances) cannot move a tested claim: the forest plot has them.
        out.append(f"Too few instances {_where(few, names, False)}.")
    return out


def _pair_bullet(cells: Sequence[Comparison], names: Mapping, k: int) -> str:
    """One bullet on one pair over its panels and budgets: a bold verdict, then the cells it leaves out."""
    by_level = {level: [c for c in cells if _level(c) == level] for level in (_BEATS, _DIRECTION, _UNCLEAR, _FEW)}
    level = next(x for x in (_BEATS, _DIRECTION, _UNCLEAR, _FEW) if by_level[x])
    pool = by_level[level]
    side = 0
    if level in (_BEATS, _DIRECTION):
        votes = [_side(c) for c in pool]
        side = -1 if votes.count(-1) > votes.count(1) else 1
        lead = [c for c in pool if _side(c) == side]
        head = (_beats_sentence(lead, cells, names, side) if level == _BEATS
                else _direction_sentence(lead, cells, names, side, k))
    elif level == _UNCLEAR:
        lead = pool
        head = _unclear_sentence(lead, cells, names)
    else:
        lead = pool
        head = _few_sentence(lead, names)
    mine = {id(c) for c in lead}
    parts = [head] + _rest_sentences([c for c in cells if id(c) not in mine], names, level, side)
    note = _NOTES.get((cells[0].method_a, cells[0].b == BOUND_LABEL))
    return " ".join(parts + ([note] if note else []))


# What a gap means, where the pair alone does not say it.
_NOTES = {
    ("grnn_dense", True): "GRNN-Dense learns on the complete graph: this gap is training error, not topology.",
    ("sls", True): "The gap is what restricting communication to the plant graph costs.",
    ("sls_topologies", True): "The gap is what restricting communication to the plant graph costs.",
}

_CAPTION = ("Each row is one cell (pair, panel, link budget): the median over instances of the paired difference of "
            "best costs, first − second (LQR-normalized; negative: the first costs less), and its 95 % interval. "
            "Filled: one beats the other; hollow: " + _NOT_SIGNIFICANT + ", or no clear difference; grey: too few "
            "instances for an interval.")


def _power_note(comparisons: Sequence[Comparison]) -> str:
    """Where no sign test on these instance counts can pass Holm's correction: say so before the claims."""
    k = len(comparisons)
    most = max(c.paired.instances for c in comparisons)
    smallest = 2 * 0.5 ** most  # the smallest p a sign test on `most` instances can give
    if min(1.0, k * smallest) < ALPHA:
        return ""
    return (f"With at most {most} instances per cell no sign test goes below p = {_p(smallest)}, so none can pass "
            f"Holm's correction over K = {_plural(k, 'comparison')}: these data show directions, not significance.")


def _unresolved_text(comparisons: Sequence[Comparison], excluded_total: int | None) -> str:
    changed = sum(c.excluded for c in comparisons)
    rse = f"standard error > {UNCERTAIN_RSE * 100:g} % of the cost"
    if excluded_total:
        return (f"{_plural(excluded_total, 'unresolved simulated cost')} ({rse}) "
                f"{'were' if excluded_total != 1 else 'was'} dropped, re-pairing {_plural(changed, 'instance')}.")
    if excluded_total is None and changed:
        return f"Unresolved simulated costs ({rse}) were dropped, re-pairing {_plural(changed, 'instance')}."
    if excluded_total is None:
        return f"No unresolved simulated cost ({rse}) entered or changed a comparison."
    return f"No simulated cost was unresolved ({rse})."


def findings_markdown(comparisons: Sequence[Comparison], *, excluded_total: int | None = None) -> list[str]:
    """The "## Findings" section: one bullet per compared pair, the forest plot, and how the claims are tested.

    Each bullet leads with a bold verdict on the pair: "A beats B" (interval excludes 0
    and Holm-adjusted p < :data:`ALPHA`), "A costs more/less than B on k of n
    instances" (interval excludes 0, not significant after Holm's correction) or "no
    clear difference" (interval contains 0), then where it holds, the numbers behind
    it, and short sentences on the cells it leaves out.

    Parameters
    ----------
    comparisons : sequence of Comparison
        As :func:`select_comparisons` gives them (their order is the bullets' order).
    excluded_total : int, optional
        Unresolved designs dropped from every comparison (``len(unresolved(records))``);
        when not given, the statistics line says only how many pairings they changed.

    Returns
    -------
    list of str
        Markdown lines, ending with an empty line; the figure is referenced as
        ``forest.png`` (the caller saves :func:`plot_forest`'s figure there). Empty
        where there is nothing to compare.
    """
    if not comparisons:
        return []
    names = _panel_names(list(dict.fromkeys(c.panel for c in comparisons)))
    k = len(comparisons)
    pairs: dict[tuple, list] = {}
    for c in comparisons:
        pairs.setdefault((c.group, c.a, c.b), []).append(c)
    # The claims first (the report's first sentence is its first finding), then the figure they come from.
    # Where no claim can reach significance, the reader learns it before the claims.
    power = _power_note(comparisons)
    lines = ["## Findings", ""] + ([power, ""] if power else [])
    lines += [f"- {_pair_bullet(cells, names, k)}" for cells in pairs.values()]
    lines += ["", "![forest plot](forest.png)", "", _CAPTION]
    lines += ["", f"Statistics: per cell, a distribution-free 95 % interval for the median difference (not "
                  f"simultaneous) and an exact sign test on the wins, Holm-corrected over K = {k} comparisons "
                  f"(Holm p). **Beats**: interval excludes 0, Holm p < {ALPHA:g}; **costs more/less**, "
                  f"{_NOT_SIGNIFICANT}: interval excludes 0, Holm p ≥ {ALPHA:g}; **no clear difference**: interval "
                  f"contains 0. {_unresolved_text(comparisons, excluded_total)}", ""]
    return lines
