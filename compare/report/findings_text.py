"""The Findings section: one table of the compared pairs, pooled over panels, with the per-panel detail below it.

Rows are the pairs (first − second), columns the link budgets; each cell is the median
difference of best costs with its 95 % interval, k/n (the instances on which the
difference has the median's sign) and a mark for its verdict
(:attr:`compare.report.findings.Comparison.verdict`): ▲ / ▼ one beats the other (the
first costs more / less: the interval excludes 0, the Holm-adjusted sign test gives
p < 0.05, the difference is beyond the practical margin and the budget fronts as drawn
agree), △ / ▽ the same direction without passing Holm's correction, ○ the interval holds
0, = equal within 0.1 % of LQR's cost (never "beats"), ± mixed (the typical instance
favours one design, the median costs the other), ? too few instances for an interval
(counts only). The first table pools the panels where a pair is compared
(:func:`compare.report.findings.pooled_rows`), only panels of one kind of system: a pair compared on different
systems (another family, case or damping) has a row for each; the second gives each panel's cell, the forest plot's rows. Bullets say only what a table
cannot: mixed cells with both numbers, and what a pair's gap means where the pair alone
does not say it. What no single cell can reach is said once, before the table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from .findings import (
    ALPHA,
    BOUND_LABEL,
    PRACTICAL_MARGIN,
    UNCERTAIN_RSE,
    Comparison,
    Pooled,
    budgets_per_node,
    pooled_rows,
)
from .names import join_words, short_names
from .system_kinds import kind_of, system_kinds

__all__ = ["findings_markdown", "complete_plant_panels", "repaired_instances", "EQUAL_WORDS", "number_text",
           "range_text", "side_of", "with_article", "short_label", "panel_names", "scope_text", "models_text",
           "estimate_text", "MARKS", "mark", "pair_name", "tier_header", "fixed_text"]

# A cell's verdict, each marked one way in the table: "beats" (a claim: interval excludes 0, Holm p < ALPHA, beyond
# the margin, the fronts agree), "direction" (interval excludes 0 only), "mixed" (tested, but the fronts as drawn order
# the two the other way), "equal" within the margin, "unclear" (interval contains 0), and "few": too small for an
# interval, counts only.
_BEATS, _DIRECTION, _MIXED, _EQUAL, _UNCLEAR, _FEW = "beats", "direction", "mixed", "equal", "unclear", "few"
#: The mark of each verdict in the tables; (verdict, side) where the side matters (+1: the first costs more).
MARKS = {(_BEATS, 1): "▲", (_BEATS, -1): "▼", (_DIRECTION, 1): "△", (_DIRECTION, -1): "▽", _MIXED: "±",
         _EQUAL: "=", _UNCLEAR: "○", _FEW: "?"}
_NOT_SIGNIFICANT = "not significant after Holm's correction"
#: How an "equal" cell is worded, everywhere.
EQUAL_WORDS = f"equal within {100 * PRACTICAL_MARGIN:g} % of LQR's cost"
_NORM_PREFIX = "‖A‖₂ = "
#: No more decimals than this: 1e-4 of LQR's cost is a tenth of the practical margin, below what the solvers and
#: the simulated costs resolve.
_MAX_DECIMALS = 4
_NBSP = "\u00a0"


# --------------------------------------------------------------------------- numbers


def number_text(x: float) -> str:
    """A number in the text: signed, two significant digits, a true minus."""
    if x == 0:
        return "0"
    # '#' keeps a trailing zero (+0.020, not +0.02), and with it a bare point (+12.) that goes.
    text = f"{x:+,.0f}" if abs(x) >= 100 else f"{x:+#.2g}".rstrip(".")
    return "−" + text[1:] if text.startswith("-") else text


def _decimals(low: float, high: float) -> int:
    """Decimals that give the interval's width two significant digits (at most :data:`_MAX_DECIMALS`)."""
    width = high - low
    if not (math.isfinite(width) and width > 0):
        return _MAX_DECIMALS
    return int(min(max(1 - _exponent(width), 0), _MAX_DECIMALS))


def _exponent(x: float) -> int:
    """The decimal exponent of ``x`` at two significant digits (0.0999999 is 0.10: −1, not −2)."""
    return int(f"{abs(x):.1e}".split("e")[1])


def fixed_text(x: float, decimals: int) -> str:
    """``x`` signed at ``decimals`` decimals, a true minus; "0" where it rounds to zero (never "−0.0000")."""
    text = f"{x:+,.{decimals}f}"
    if float(text.replace(",", "")) == 0:
        return "0"
    return "−" + text[1:] if text.startswith("-") else text


def _alone(x: float) -> str:
    """A median without an interval: two significant digits, at most :data:`_MAX_DECIMALS` decimals ("0" below)."""
    if x == 0:
        return "0"
    return fixed_text(x, int(min(max(1 - _exponent(x), 0), _MAX_DECIMALS)))


def estimate_text(p, *, coverage: bool = False) -> str:
    """"+0.0127 [+0.0102, +0.0147]": a median with its interval, at the precision the interval supports.

    Too few instances for a 95 % interval: the median alone, at two significant digits, unless
    ``coverage``, where the interval follows with its achieved coverage ("(88%)") if that is at
    least 50 %. "—" without instances.
    """
    if not p.instances or not math.isfinite(p.median):
        return "—"
    if p.too_few and not (coverage and p.coverage >= 0.5):
        return _alone(p.median)
    d = _decimals(p.low, p.high)
    # A bound that is not 0 never prints as "0": more decimals, up to the most the costs resolve.
    while d < _MAX_DECIMALS and any(x != 0 and fixed_text(x, d) == "0" for x in (p.low, p.high)):
        d += 1
    # (a narrow page may break the interval after its comma: four budgets of them fit 800 px)
    text = f"{fixed_text(p.median, d)} [{fixed_text(p.low, d)}, {fixed_text(p.high, d)}]"
    return text + (f" ({p.coverage:.0%})" if p.too_few else "")


def range_text(values: Sequence[float]) -> str:
    """"+0.018 to +0.082", or one number where they round alike."""
    low, high = number_text(min(values)), number_text(max(values))
    return low if low == high else f"{low} to {high}"


def _p(p: float) -> str:
    return f"{p:.2g}"


def _plural(k: int, word: str) -> str:
    return f"{k} {word}" + ("" if k == 1 else "s")


def _s(k: int) -> str:
    """The plural ending for a count of ``k``."""
    return "" if k == 1 else "s"


# --------------------------------------------------------------------------- verdicts


def evidence_level(c) -> str:
    """The verdict of a cell or pooled row as the tables mark it (the order of :attr:`Comparison.verdict`)."""
    if c.equal:
        return _EQUAL
    if c.too_few:
        return _FEW
    if c.mixed:
        return _MIXED
    if c.paired.inconclusive:
        return _UNCLEAR
    return _BEATS if c.significant else _DIRECTION


def side_of(c) -> int:
    """−1 where a costs less than b, +1 where it costs more (by the interval, else by the wins), 0: split.

    For a mixed cell, the side the typical instance (the paired median) favours.
    """
    p = c.paired
    if evidence_level(c) in (_BEATS, _DIRECTION, _MIXED):
        return -1 if p.median < 0 else 1
    return int(np.sign(p.b_wins - p.a_wins))


def mark(c) -> str:
    """The mark of a cell or pooled row (:data:`MARKS`)."""
    level = evidence_level(c)
    return MARKS[(level, side_of(c))] if level in (_BEATS, _DIRECTION) else MARKS[level]


def agreeing_count(c) -> int:
    """The instances whose difference has the median's sign (the larger side's wins where the median is 0)."""
    p = c.paired
    if not math.isfinite(p.median) or p.median == 0:
        return max(p.a_wins, p.b_wins)
    return p.a_wins if p.median < 0 else p.b_wins


def _cell(c) -> str:
    """"+0.0127<br>[+0.0102, +0.0147]<br>10/10 ▲": the median, its interval, then k/n and the mark, a line each
    (so that a wide page keeps each interval on one line, and a narrow one breaks it after its comma)."""
    if c is None:
        return ""
    estimate = estimate_text(c.paired).replace(" [", "<br>[", 1)
    return f"{estimate}<br>{agreeing_count(c)}/{c.paired.instances}{_NBSP}{mark(c)}"


# --------------------------------------------------------------------------- names


def with_article(label: str) -> str:
    return f"the {label}" if label == BOUND_LABEL else label


def _strip(label: str) -> str:
    if label == BOUND_LABEL:
        return "SLS bound"
    return label.rsplit(" (", 1)[0] if label.endswith(")") and " (" in label else label


def short_label(label: str, other: str) -> str:
    """The name in a sentence's body, once it has given the full one: without the trailing parenthesis,
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
        # N where it tells panels apart: a family at several sizes ("chain, N = 20"), not a grid of its own ("wecc")
        several = len({p[1] for p in panels if p[0] == family}) > 1
        if (len(sizes) > 1 and (a_norm is not None or several)) or (a_norm is None and len(families) == 1):
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


def tier_header(tier, per_node: bool) -> str:
    """A budget column's header: "≤ 20 links", "≤ 1 link per node", "any"."""
    if tier is None:
        return "any"
    return f"≤ {tier:g} link{'' if tier == 1 else 's'}{' per node' if per_node else ''}"


def tier_phrase(tier, per_node: bool) -> str:
    """"within 20 links", "within 1 link per node", "with any number of links"."""
    if tier is None:
        return "with any number of links"
    return "within " + tier_header(tier, per_node).removeprefix("≤ ")


def _budgets_phrase(budgets: Sequence, per_node: bool = False) -> str:
    """"at ≤ 20 and ≤ 60 links and overall" (overall: any number of links); "links per node" with ``per_node``."""
    finite = [f"≤ {b:g}" for b in budgets if b is not None]
    unit = "link" if [b for b in budgets if b is not None] == [1] else "links"
    text = f"at {join_words(finite)} {unit}{' per node' if per_node else ''}" if finite else ""
    if None in budgets:
        text += (" and " if text else "") + "overall"
    return text


def _where(cells: Sequence[Comparison], names: Mapping, every: bool = True) -> str:
    """Where ``cells`` lie: their budgets, grouped by the panels each holds in, the widest first."""
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
    """Where the headline holds; "in every panel but ‖A‖₂ = 1.2" when the exceptions share one panel of three or
    more (the one named)."""
    mine = {id(c) for c in lead}
    rest = [c for c in cells if id(c) not in mine]
    odd = {c.panel for c in rest}
    per_node = budgets_per_node(cells)
    budgets = list(dict.fromkeys(c.budget_tier(per_node) for c in cells))
    others = {p for p in names if p not in odd}
    complete = all(any(c.panel == p and c.budget_tier(per_node) == b for c in lead) for p in others for b in budgets)
    if len(odd) == 1 and len(names) >= 3 and complete:
        return f"{_budgets_phrase(budgets, per_node)} in every panel but {names[next(iter(odd))]}"
    return _where(lead, names)


_INFO_WORDS = {"delayed": "delayed", "instantaneous": "instantaneous", "none": "none"}


def models_text(c, first: str | None = None) -> str:
    """The information models: "(both delayed)", or "(information: delayed vs instantaneous)" where the designs see
    different information ("none": no communication), in the order in which the sentence names them (``first``
    named first; by default a, then b)."""
    ia, ib = (_INFO_WORDS.get(x, x) for x in (c.info_a, c.info_b))
    if first is not None and first == c.b and first != c.a:
        ia, ib = ib, ia
    return f"(both {ia})" if c.relation == "same" else f"(information: {ia} vs {ib})"


def pair_name(a: str, b: str, short: Mapping[str, str] | None = None) -> str:
    """"GRNN-Sparse − Sparse delayed K (l1)": a pair as its rows name it (labels shortened where ``short`` says)."""
    short = short or {}
    return f"{short.get(a, a)} − {short.get(b, b)}"


def _digits(x: float, y: float) -> tuple[str, str]:
    """Two costs with as many decimals (4 to 7) as it takes to tell them apart."""
    for d in range(4, 8):
        tx, ty = f"{x:.{d}f}", f"{y:.{d}f}"
        if tx != ty:
            break
    return tx, ty


# --------------------------------------------------------------------------- bullets: what a table cannot say


#: A bullet never runs longer than this many words.
BULLET_WORDS = 60


def _drawn_pair(c, typical: str) -> str:
    """"1.0889 against 1.0896": the other side's drawn median cost, then the typical side's."""
    mine, theirs = (c.drawn_a, c.drawn_b) if typical == c.a else (c.drawn_b, c.drawn_a)
    t_text, o_text = _digits(mine, theirs)
    return f"{o_text} against {t_text}"


def _mixed_items(cells: Sequence[Comparison], rows: Sequence[Pooled], names: Mapping, per_node: bool,
                 keep: int) -> list[str]:
    """One clause per mixed pooled row and per mixed cell (at most ``keep`` of each): both numbers, where each holds."""
    items = []
    for r in rows[:keep]:
        typical, other = (r.a, r.b) if r.paired.median < 0 else (r.b, r.a)
        k = r.paired.a_wins if r.paired.median < 0 else r.paired.b_wins
        first, *more = r.against()
        also = f" (and on {_plural(len(more), 'other panel')})" if more else ""
        items.append(f"pooled {tier_phrase(r.tier, per_node)}, {short_label(typical, other)} costs less on {k} of "
                     f"{r.paired.instances} instances, yet on {names[first.panel]}{also} "
                     f"{short_label(other, typical)} costs less (median {number_text(first.paired.median)})")
    for c in cells[:keep]:
        typical, other = (c.a, c.b) if c.paired.median < 0 else (c.b, c.a)
        k = c.paired.a_wins if c.paired.median < 0 else c.paired.b_wins
        where = ", ".join(x for x in (names[c.panel], tier_phrase(c.budget, False)) if x)
        items.append(f"on {where}, {short_label(typical, other)} costs less on {k} of {c.paired.instances} "
                     f"instances (median {number_text(c.paired.median)}), yet {short_label(other, typical)} has the "
                     f"lower median cost ({_drawn_pair(c, typical)})")
    return items


def _mixed_bullet(name: str, cells: Sequence[Comparison], rows: Sequence[Pooled], names: Mapping,
                  per_node: bool) -> str:
    """"**A − B, mixed (±)**: …": the typical instance and the median costs disagree, both numbers given."""
    more = len(cells) + len(rows)
    for keep in (2, 1):
        items = _mixed_items(cells, rows, names, per_node, keep)
        rest = more - len(items)
        text = (f"**{name}, mixed ({MARKS[_MIXED]})**: {'; '.join(items)}"
                + (f"; {rest} more in the detail table" if rest else "") + ".")
        if _words(text) <= BULLET_WORDS:
            return text
    return text


def _words(text: str) -> int:
    """Words as the limits count them: whitespace-separated tokens with a letter or digit."""
    return sum(1 for w in text.split() if any(ch.isalnum() for ch in w))


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


# --------------------------------------------------------------------------- paragraphs


def _power_note(comparisons: Sequence[Comparison], rows: Sequence[Pooled]) -> str:
    """Where no per-panel sign test on these instance counts can pass Holm's correction: said once, before the table,
    with what the pooled rows can reach."""
    k = len(comparisons)
    most = max(c.paired.instances for c in comparisons)
    smallest = 2 * 0.5 ** most  # the smallest p a sign test on `most` instances can give
    if min(1.0, k * smallest) < ALPHA:
        return ""
    pooled = [r for r in rows if len(r.cells) > 1]
    several = len({c.panel for c in comparisons}) > 1
    text = (f"No {'single panel' if several else 'test'} can show significance here: with at most "
            f"{_plural(most, 'instance')} per {'panel and ' if several else ''}budget the smallest sign-test p is "
            f"{_p(smallest)}, and Holm's correction over the K = {_plural(k, 'per-panel test' if several else 'test')} "
            f"asks for p < {_p(ALPHA / k)}.")
    if pooled and any(not r.too_few for r in pooled):
        text += " The pooled rows are where the evidence is."
    elif pooled:
        most = max(r.paired.instances for r in pooled)
        text += f" Pooled over panels, a row still has at most {_plural(most, 'instance')}: too few for an interval."
    return text


def _legend(pooled: bool, split: bool = False, one_panel: bool = False) -> str:
    """What a cell says and what each mark means, once; with ``split``, that no row pools different systems (with
    ``one_panel``, where every row is one panel, that no row pools at all)."""
    text = ("Each cell: the median over instances of the first design's best cost within the budget minus the "
            "second's (× LQR's cost; negative: the first costs less), its 95 % interval, and k/n: the instances, of "
            f"n, on the median's side. {MARKS[(_BEATS, 1)]} / {MARKS[(_BEATS, -1)]}: the first costs more / less, "
            f"passing Holm's correction (one beats the other); {MARKS[(_DIRECTION, 1)]} / "
            f"{MARKS[(_DIRECTION, -1)]}: the interval excludes 0 without passing it; {MARKS[_UNCLEAR]}: the "
            f"interval holds 0; {MARKS[_EQUAL]}: {EQUAL_WORDS}; {MARKS[_MIXED]}: mixed; {MARKS[_FEW]}: too few "
            "instances for an interval.")
    if pooled and split and one_panel:
        text += (" The panels are different systems (another family, case or damping), so no row pools them: a pair "
                 "compared on several has a row for each, as the detail below does.")
    elif pooled and split:
        text += (" A row pools the panels where the pair is compared that are one kind of system (one family, "
                 "case and damping, at any N or ‖A‖₂); a pair compared on different systems has a row for each, and no median "
                 "spans them. The detail below gives each panel.")
    elif pooled:
        text += " A row pools every panel where the pair is compared; the detail below gives each panel."
    return text


#: Words in design names a control researcher may not know: (what to look for in a label, its definition in one
#: sentence). Each is defined once, under the findings table, where the names first appear.
_GLOSSARY = (
    (("β path", "γ path"), "*β path* (*γ path*): the designs a method returns as the weight β (γ) of its penalty on "
                           "links sweeps a grid"),
    (("Per-node",), "*per-node*: one output layer (*readout*) per node, where the paper's GRNN shares one"),
    (("warm start",), "*warm start*: training from a delayed static design on the instance, not random weights"),
    (("diagonal start",), "*diagonal start*: training from the diagonal gain"),
    (("Linear",), "*linear*: the GRNN with its tanh replaced by the identity"),
    (("GraSP",), "*GraSP* (gradient support pursuit): a search for the best gain with at most a given number of "
                 "links"),
    ((BOUND_LABEL,), "*SLS bound*: SLS on the complete graph at one hop per step, the lowest cost any controller "
                     "with the delayed information reaches"),
)


def _glossary(labels: Iterable[str]) -> str:
    """"Names: *β path* …; *per-node* …": the words of :data:`_GLOSSARY` that the compared designs' names use."""
    labels = list(labels)
    used = [text for keys, text in _GLOSSARY if any(k in x for x in labels for k in keys)]
    return ("Names: " + "; ".join(used) + ".") if used else ""


_CAPTION = ("The forest plot draws each panel's cells: the median difference as a marker, its interval as a bar; "
            "filled where one design beats the other, hollow otherwise, grey where too few instances.")


def _unresolved_text(comparisons: Sequence[Comparison], excluded_total: int | None,
                     repaired_instances: int | None = None) -> str:
    """What dropping unresolved costs did, in exact counts: designs dropped, (panel, budget, instance) pairings
    changed, and over how many instances (where the records are known)."""
    changed = sum(c.excluded for c in comparisons)
    rse = f"standard error > {UNCERTAIN_RSE * 100:g} % of the cost"
    pairings = f"{changed} (panel, budget, instance) pairing{_s(changed)}"
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


def _statistics_line(comparisons: Sequence[Comparison], rows: Sequence[Pooled], excluded_total,
                     repaired_instances) -> str:
    """How the cells are tested, the families of Holm's correction, equal and mixed defined once."""
    k = len(comparisons)
    pooled = len(rows) != k or any(len(r.cells) > 1 for r in rows)
    families = (f"over the R = {len(rows)} pooled rows and, separately, the K = {_plural(k, 'per-panel test')}"
                if pooled else f"over the K = {_plural(k, 'comparison')}")
    return (f"Statistics: distribution-free intervals (order statistics, not simultaneous) and exact sign tests on "
            f"the wins{', summed over panels in a pooled row' if pooled else ''}, Holm-corrected {families} "
            f"(family-wise level {ALPHA:g}). **{EQUAL_WORDS[0].upper() + EQUAL_WORDS[1:]}**: the median below that "
            "margin (the paper's third decimal; above the solvers' tolerances and the simulated costs' standard "
            "errors), the interval excluding 0 or inside it. **Mixed**: tested, but the median costs the figures "
            "draw on a panel, or a panel's own interval, order the two the other way. "
            f"{_unresolved_text(comparisons, excluded_total, repaired_instances)}")


# --------------------------------------------------------------------------- tables


def _tiers(comparisons: Sequence[Comparison], per_node: bool) -> list:
    tiers = {c.budget_tier(per_node) for c in comparisons}
    return sorted(tiers, key=lambda t: math.inf if t is None else t)


def _header(first: str, tiers: Sequence, per_node: bool) -> list[str]:
    return [f"| {first} | " + " | ".join(tier_header(t, per_node) for t in tiers) + " |",
            "|---|" + "---|" * len(tiers)]


def _row_label(name: str, cells: Sequence[Comparison], names: Mapping, split: bool = False) -> str:
    """The pair, then what a reader needs beside it: the information models where they differ, the panels where
    the pair is compared on only some (with ``split``, where panels are different systems, the family of several
    panels of one: "on chain, N = 20 and 100", "on chain (3 of 7 panels)")."""
    c0 = cells[0]
    extra = []
    if c0.relation != "same":
        extra.append(models_text(c0).strip("()"))
    panels = list(dict.fromkeys(c.panel for c in cells))
    if len(names) > 1 and len(panels) < len(names):
        family = panels[0][0] if split and len({p[0] for p in panels}) == 1 else None
        if family is not None and len(panels) > 1 and all(names[p] == f"{family}, N = {p[1]}" for p in panels):
            extra.append(f"on {family}, N = {join_words([str(p[1]) for p in panels])}")  # "on chain, N = 20 and 100"
        elif len(panels) <= 2:
            extra.append(f"on {_panel_list(panels, names)}")
        elif family is not None:
            extra.append(f"on {family} ({len(panels)} of {len(names)} panels)")
        else:
            extra.append(f"{len(panels)} of {len(names)} panels")
    return name + "".join(f"<br>{x}" for x in extra)


def _main_table(pairs: Mapping, rows: Sequence[Pooled], tiers: Sequence, per_node: bool, names: Mapping,
                short: Mapping, kinds: Mapping | None = None) -> list[str]:
    """One row per pair; where ``kinds`` (panel -> kind of system) tell the pair's panels apart, one per pair and
    kind of system, as :func:`compare.report.findings.pooled_rows` pools them."""
    split = len({kind_of(kinds, p) for p in names}) > 1
    by_row: dict[tuple, dict] = {}
    for r in rows:
        by_row.setdefault((r.group, r.a, r.b, kind_of(kinds, r.cells[0].panel)), {})[r.tier] = r
    lines = _header("first − second", tiers, per_node)
    for key, cells in pairs.items():
        name = pair_name(key[1], key[2], short)
        for k in dict.fromkeys(kind_of(kinds, c.panel) for c in cells):
            shown = [c for c in cells if kind_of(kinds, c.panel) == k]
            lines.append(f"| {_row_label(name, shown, names, split)} | "
                         + " | ".join(_cell(by_row[(*key, k)].get(t)) for t in tiers) + " |")
    return lines


def _detail_table(pairs: Mapping, tiers: Sequence, per_node: bool, names: Mapping, short: Mapping) -> list[str]:
    lines = _header("first − second, per panel", tiers, per_node)
    for key, cells in pairs.items():
        lines.append(f"| **{pair_name(key[1], key[2], short)}** |" + " |" * len(tiers))
        for panel in dict.fromkeys(c.panel for c in cells):
            mine = {c.budget_tier(per_node): c for c in cells if c.panel == panel}
            lines.append(f"| {names[panel]} | " + " | ".join(_cell(mine.get(t)) for t in tiers) + " |")
    return lines


#: Markers read by :mod:`compare.report.html`: a table shown open however long, and one folded under a summary.
OPEN_TABLE = "<!-- table: open -->"
FOLDED_TABLE = "<!-- table: folded: {summary} -->"


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


def comparison_short_names(comparisons: Sequence[Comparison]) -> dict[str, str]:
    """Arm label -> the name a table row gives it: without trailing training settings where unambiguous."""
    labels = {x for c in comparisons for x in (c.a, c.b)}
    out = short_names(labels - {BOUND_LABEL})
    if BOUND_LABEL in labels:
        out[BOUND_LABEL] = BOUND_LABEL
    return out


def findings_markdown(comparisons: Sequence[Comparison], *, excluded_total: int | None = None,
                      records=None, forest: Sequence[str] = ("forest.png",)) -> list[str]:
    """The "## Findings" section: the findings table (pooled over panels), the per-panel detail, the bullets a
    table cannot replace, the forest plot and how the cells are tested.

    Parameters
    ----------
    comparisons : sequence of Comparison
        As :func:`select_comparisons` gives them (their order is the rows' order).
    excluded_total : int, optional
        Unresolved designs dropped from every comparison (``len(unresolved(records))``);
        when not given, the statistics line says only how many pairings they changed.
    records : Records, optional
        The records compared. With them, the statistics line says over how many
        instances unresolved costs changed pairings, and the note on SLS on the plant
        graph against the bound checks its premise on the instance facts (plant graph
        complete: N(N − 1) links); without them, a plant graph is taken as complete
        where the two cost exactly the same on every instance.
    forest : sequence of str
        The forest plot's image files, in order (the caller saves them).

    Returns
    -------
    list of str
        Markdown lines, ending with an empty line; empty where there is nothing to compare.
    """
    if not comparisons:
        return []
    names = panel_names(list(dict.fromkeys(c.panel for c in comparisons)))
    per_node = budgets_per_node(comparisons)
    tiers = _tiers(comparisons, per_node)
    short = comparison_short_names(comparisons)
    pairs: dict[tuple, list] = {}
    for c in comparisons:
        pairs.setdefault((c.group, c.a, c.b), []).append(c)
    if records is not None:  # panels of one kind of system pool; different systems (family, case or damping) never do
        kinds = system_kinds(records, list(names))
    else:  # without records, a panel's family name (a published system's name) is its kind
        kinds = {p: (p[0],) for p in names}
    rows = pooled_rows(comparisons, kinds)
    several = len(names) > 1
    split = len({kind_of(kinds, p) for p in names}) > 1
    if records is not None:
        complete, repaired = complete_plant_panels(records), repaired_instances(records, comparisons)
    else:
        complete, repaired = _identical_panels(comparisons), None
    power = _power_note(comparisons, rows)
    lines = ["## Findings", ""] + ([power, ""] if power else [])
    lines += [OPEN_TABLE, ""] + _main_table(pairs, rows, tiers, per_node, names, short, kinds) + [""]
    lines += [_legend(several, split, all(len(r.cells) == 1 for r in rows)), ""]
    glossary = _glossary({x for c in comparisons for x in (c.a, c.b)})
    lines += [glossary, ""] if glossary else []
    if several:
        lines += [FOLDED_TABLE.format(summary="the same, panel by panel"), ""]
        lines += _detail_table(pairs, tiers, per_node, names, short) + [""]
    bullets = []
    for key, cells in pairs.items():
        name = pair_name(key[1], key[2], short)
        mixed_cells = [c for c in cells if evidence_level(c) == _MIXED] if several else []
        mixed_rows = [r for r in rows if (r.group, r.a, r.b) == key and evidence_level(r) == _MIXED]
        if several:
            mixed_rows = [r for r in mixed_rows if len(r.cells) > 1]
        else:  # one panel: the rows are the cells
            mixed_cells, mixed_rows = [r.cells[0] for r in mixed_rows], []
        if mixed_cells or mixed_rows:
            bullets.append(_mixed_bullet(name, mixed_cells, mixed_rows, names, per_node))
        note = _note(cells, names, complete)
        if note:
            bullets.append(f"**{name}**: {note}")
    lines += [f"- {b}" for b in bullets] + ([""] if bullets else [])
    lines += [f"![forest plot]({f})" for f in forest] + ["", _CAPTION, ""]
    lines += [_statistics_line(comparisons, rows, excluded_total, repaired), ""]
    return lines
