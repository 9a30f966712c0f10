"""The report's answer, first: at most three sentences between the title and the Findings.

The sentences are chosen by rules, in this order (docs/reports.md, "The answer"):

(0) **Budget ladder.** Where an experiment's spec asks for one (``[report] ladder``,
    :mod:`compare.report.ladder`): whether some design within its first link budget comes within
    ``near`` % of LQR on each system, then a list, one item per system, of each method's
    best cost within every budget (the list is not counted among the sentences).
(0') **Decomposition.** Where the records hold the paper's GRNN-Sparse, the per-node one
    from random weights and the per-node one warm-started from the delayed ℓ1 path beside the
    delayed static designs (:mod:`compare.report.decomposition`): the excess of the paper's design
    over the best delayed static design split into model class and training, with intervals;
    divergence with and without the warm start on the system with the largest open-loop
    spectral radius; and whether the nonlinearity adds anything at equal information and links.
(a) **Failures.** A method that diverges or fails (:data:`codesign.status.DIVERGED`,
    :data:`~codesign.status.FAILED`) on at least half of a panel's instances, or whose
    median best cost there is above :data:`FAILURE_COST` × LQR, while another design
    has a usable design on every instance below that: the methods, with counts, and
    the range the others stay in. ``infeasible`` is not a failure (a design problem
    with no solution, such as SLS on a communication graph that is not quadratically
    invariant), nor is the autonomous loop (u = 0), the reference for how hard a panel is.
(b) **Reproduction.** A report with the paper's Table 1 (an experiment asks for its
    section): how many paper values lie inside our 95 % intervals, each one outside
    with its distance in standard errors of the difference, and the known reasons
    (:data:`compare.report.learning_report.GAP_REASONS`, docs/reproduction.md).
(c) **Pooled results.** A pair of designs whose cells, at one link budget, are each too
    small to test (too few instances for an interval, or no sign test on so few can pass
    Holm's correction) but in which every instance of every panel favours the same
    design: the panels are pooled with a stratified sign test (wins counted per panel,
    summed; under no difference each instance is a fair coin, so the total is binomial),
    Holm-adjusted over every pooled test, and the sentence says it is pooled.
(e) **Otherwise the strongest same-information claim**: of the pairs with the same
    information model, the one that "beats" in the most cells (then the earlier group,
    then the one whose weakest interval lies farthest from 0).
(d) **Difficulty.** Beside the gaps the sentence of (c) or (e) states, where the panels
    it spans differ in how hard the problem is, by a factor of :data:`DIFFICULTY_RATIO`
    or more in what doing nothing (u = 0) costs over LQR: u = 0's cost at the easiest and
    hardest of them, and the gap at each.

Rules (0), (0') and (a) to (c) each add their sentences ((c) not beside (0')), (e) only where none of (0),
(0'), (b) and (c) did, and
(d) follows the result of (c) or (e) it qualifies; the first :data:`MAX_SENTENCES` are kept.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from codesign.status import DIVERGED, FAILED

from ..run.records import Records, as_records
from .decomposition import decomposition_sentences
from .findings import ALPHA, BOUND_LABEL, Comparison, budgets_per_node, holm, sign_test
from .ladder import ladder_lines
from .names import join_words, short_names

__all__ = ["answer_lines", "MAX_SENTENCES", "FAILURE_COST", "DIFFICULTY_RATIO", "pooled_tests", "Pooled"]

#: At most this many sentences.
MAX_SENTENCES = 3
#: A method whose median best cost on a panel is above this many times LQR's fails there in effect.
FAILURE_COST = 10.0
#: Panels differ in difficulty when u = 0's excess cost over LQR differs by this factor or more.
DIFFICULTY_RATIO = 2.0
#: Methods trained by gradient descent (the rest are "classical" designs).
_LEARNED = ("grnn", "grnn_sparse", "grnn_dense", "grnn_fixed", "gcnn")
_NOTHING = "autonomous"
_VERBS = {DIVERGED: ("diverges", "diverge"), FAILED: ("fails", "fail")}


# --------------------------------------------------------------------------- wording


def _count_of(k: int, n: int) -> str:
    """"on both instances", "on all 3 instances", "on 1 of 2 instances", "on its one instance"."""
    if k == n:
        return {1: "on its one instance", 2: "on both instances"}.get(n, f"on all {n} instances")
    return f"on {k} of {n} instance{'' if n == 1 else 's'}"



def _times(cost: float) -> str:
    """A cost in units of LQR's: "3,945 × LQR", "2.3 × LQR", "1.9e+07 × LQR"."""
    if cost >= 1e5:
        return f"{cost:.2g} × LQR"
    if cost >= 100:
        return f"{cost:,.0f} × LQR"
    return f"{cost:.2g} × LQR" if cost >= 10 else f"{cost:.1f} × LQR"


def _excess(cost: float) -> str:
    """What a cost is over LQR's: "+4.7 %", "+148 %" (below 10 × LQR), else "70 × LQR"."""
    if cost >= 10:
        return _times(cost)
    pct = 100 * (cost - 1)
    return f"+{pct:.0f} %" if pct >= 10 else f"+{pct:.2g} %"


def _p(p: float) -> str:
    """"8e-6", "0.0002", "0.062": one significant digit below 0.01, two above."""
    return (f"{p:.1g}" if p < 0.01 else f"{p:.2g}").replace("e-0", "e-")


def _approx(p: float) -> str:
    """"≈ 8e-06" for a rounded small p, "= 0.062" otherwise."""
    return f"≈ {_p(p)}" if p < 0.01 else f"= {_p(p)}"


# --------------------------------------------------------------------------- (a) failures


def _best_per_instance(rs: Records) -> tuple[list[float], dict[str, int], int]:
    """A method's best usable cost on each instance it has one, the failures by status (instances with no usable
    design and a diverged or failed one), and the instances it ran on."""
    best, failed = [], {}
    for _, on in rs.by_instance.items():
        costs = [r.cost for r in on if r.ok]
        if costs:
            best.append(min(costs))
            continue
        statuses = {r.status for r in on}
        status = DIVERGED if DIVERGED in statuses else FAILED if FAILED in statuses else None
        if status:
            failed[status] = failed.get(status, 0) + 1
    return best, failed, len(rs.by_instance)


def _radius(rs: Records) -> str:
    """" (open-loop spectral radius 1.87)" for a family without ‖A‖₂ (which the paper family's radius equals)."""
    if rs[0].instance.a_norm is not None:
        return ""
    radii = sorted(i.radius for i in rs.instances if i.radius is not None)
    return f" (open-loop spectral radius {radii[len(radii) // 2]:.3g})" if radii else ""


def failure_sentences(records, names: Mapping[tuple, str], flagged: set | None = None) -> list[str]:
    """Rule (a): per panel, the methods that diverge or fail where others succeed, with counts.

    ``flagged``, where given, receives the (panel, label) of every method stated.
    """
    flagged = set() if flagged is None else flagged
    records = as_records(records)
    short = short_names(records.by_label)
    out = []
    for panel in sorted(records.by_panel, key=_panel_order):
        in_panel = records.by_panel[panel]
        failing, working = [], {}
        for label, rs in in_panel.by_label.items():
            if rs[0].method == _NOTHING:
                continue
            best, failed, ran = _best_per_instance(rs)
            if failed and sum(failed.values()) * 2 >= ran:
                status = max(failed, key=failed.get)
                failing.append((label, status, failed[status], ran))
            elif best and np.median(best) > FAILURE_COST:
                failing.append((label, "cost", float(np.median(best)), ran))
            elif best and len(best) == ran:  # a usable design on every instance (infeasible elsewhere: not here)
                working[label] = float(np.median(best))
        if not failing or not working:
            continue
        parts = []
        groups: dict[tuple, list] = {}
        for label, status, value, ran in failing:
            groups.setdefault((status, value if status != "cost" else None, ran), []).append((label, value))
        for (status, k, ran), members in groups.items():
            members.sort()
            who = join_words([short[x] for x, _ in members])
            if status == "cost":
                parts += [f"{short[x]} costs about {_times(v)}" for x, v in members]
            else:
                parts.append(f"{who} {_VERBS[status][len(members) > 1]} {_count_of(k, ran)}")
        learned = all(records.by_label[x][0].method in _LEARNED for x, *_ in failing)
        classical = not any(records.by_label[x][0].method in _LEARNED for x in working)
        kind = "every classical design" if learned and classical else "every other design"
        low, high = min(working.values()), max(working.values())
        stays = (f"stays within {low:.1f}–{high:.1f} × LQR" if f"{low:.1f}" != f"{high:.1f}"
                 else f"stays at {low:.1f} × LQR")
        out.append(f"On {names[panel]}{_radius(in_panel)}, {join_words(parts)}, while {kind} {stays}.")
        flagged.update((panel, label) for label, *_ in failing)
    return out[:2]


def _panel_order(panel: tuple) -> tuple:
    family, n, a_norm = panel
    return (str(family), n, -math.inf if a_norm is None else a_norm)


# --------------------------------------------------------------------------- (b) reproduction


def reproduction_sentences(records, meta=None, members=None) -> list[str]:
    """Rule (b): the paper's Table 1 values against our intervals, those outside with their distance, and why."""
    from ..run.meta import StoreMeta
    from .learning_report import GAP_REASONS, paper_values
    from .sections import experiments_with

    if meta is None:
        return []
    _, table1 = experiments_with("table1", as_records(records), StoreMeta.of(meta), dict(members or {}))
    values = paper_values(table1) if len(table1) else []
    if not values:
        return []
    outside = [v for v in values if v.outside]
    inside = len(values) - len(outside)
    noise = [v for v in outside if v.within_noise]
    beyond = sorted((v for v in outside if not v.within_noise), key=lambda v: -abs(v.z))
    several = len({v.a_norm for v in values}) > 1
    first = [True]

    def at(vs) -> str:
        """"GRNN-Dense at ‖A‖₂ = 1.05 (1.9 SE) and 0.995 (1.7 SE)": one label's values, farthest first."""
        parts = []
        for v in sorted(vs, key=lambda v: -abs(v.z)):
            where = (f"‖A‖₂ = {v.a_norm:g} " if first[0] else f"{v.a_norm:g} ") if several else ""
            first[0] = False
            parts.append(f"{where}({abs(v.z):.1f} SE)")
        return f"{vs[0].label} at {join_words(parts)}" if several else f"{vs[0].label} {join_words(parts)}"

    def by_label(vs) -> list[str]:
        groups: dict[str, list] = {}
        for v in sorted(vs, key=lambda v: -abs(v.z)):
            groups.setdefault(v.label, []).append(v)
        return [at(g) for g in groups.values()]

    agree = inside + len(noise)
    head = (f"Paper Table 1 is reproduced within instance-sampling noise for {agree} of its {len(values)} values: "
            f"{inside} lie inside our 95 % intervals")
    if not outside:
        return [head + "."]
    if noise:
        head += (f", and of the {len(outside)} outside, {join_words(by_label(noise))} "
                 f"{'is' if len(noise) == 1 else 'are'} under 2 SE off")
    else:
        head += f", and {len(outside)} lie outside"
    sentences = [head + " (SE: standard errors of the difference between our statistic and the paper's, two "
                 "statistics over independent draws of instances)."]
    if not beyond:
        return sentences
    reasons: dict[str, list] = {}
    for v in beyond:
        reasons.setdefault(GAP_REASONS.get(v.method, ""), []).append(v)
    parts = []
    for reason, vs in reasons.items():
        if reason:
            parts.append(f"{join_words(by_label(vs))}, {reason}")
    if "" in reasons:
        parts.append(f"{join_words(by_label(reasons['']))}, with no known cause")
    top = beyond[0]
    sentences.append(f"Beyond that noise: {'; '.join(parts)} (docs/reproduction.md); the largest gap, "
                     f"{top.label} at ‖A‖₂ = {top.a_norm:g}, is our {top.statistic} {top.ours:.3f} against the "
                     f"paper's {top.paper:.3f}.")
    return sentences


def _number(k: int) -> str:
    return ("No", "One", "Two", "Three", "Four", "Five", "Six", "Seven", "Eight", "Nine")[k] if k < 10 else str(k)


# --------------------------------------------------------------------------- (c) pooled


class Pooled(tuple):
    """A pooled test: (cells, a_wins, b_wins, instances, p, p_holm) of one pair at one budget tier."""

    __slots__ = ()

    def __new__(cls, cells, a_wins, b_wins, instances, p, p_holm=1.0):
        return super().__new__(cls, (tuple(cells), a_wins, b_wins, instances, p, p_holm))

    cells = property(lambda self: self[0])
    a_wins = property(lambda self: self[1])
    b_wins = property(lambda self: self[2])
    instances = property(lambda self: self[3])
    p = property(lambda self: self[4])
    p_holm = property(lambda self: self[5])

    @property
    def unanimous(self) -> bool:
        """Every instance of every panel favours the same design (no tie)."""
        return self.instances > 0 and max(self.a_wins, self.b_wins) == self.instances


def _untestable(c: Comparison) -> bool:
    """Too small to test alone: too few instances for an interval, or not tested after Holm, and not equal."""
    return not c.equal and not c.tested and not c.mixed


def pooled_tests(comparisons: Sequence[Comparison]) -> list[Pooled]:
    """Every (pair, budget tier) whose cells span two panels or more and are each too small to test: their wins
    pooled over the panels (stratified sign test), Holm-adjusted over these pooled tests."""
    per_node = budgets_per_node(comparisons)
    groups: dict[tuple, list] = {}
    for c in comparisons:
        groups.setdefault((c.group, c.a, c.b, c.budget_tier(per_node)), []).append(c)
    tests = []
    for cells in groups.values():
        if len({c.panel for c in cells}) < 2 or not all(_untestable(c) for c in cells):
            continue
        a_wins = sum(c.paired.a_wins for c in cells)
        b_wins = sum(c.paired.b_wins for c in cells)
        n = sum(c.paired.instances for c in cells)
        tests.append(Pooled(cells, a_wins, b_wins, n, sign_test(a_wins, b_wins)))
    adjusted = holm([t.p for t in tests])
    return [Pooled(t.cells, t.a_wins, t.b_wins, t.instances, t.p, q) for t, q in zip(tests, adjusted)]


def _tier_phrase(c: Comparison, per_node: bool) -> str:
    tier = c.budget_tier(per_node)
    if tier is None:
        return "with any number of links"
    unit = "link" if tier == 1 else "links"
    return f"within {tier:g} {unit}{' per node' if per_node else ''}"


def _subject(label: str, names: Mapping) -> str:
    return f"the {label}" if label == BOUND_LABEL else names.get(label, label)


def pooled_sentence(comparisons: Sequence[Comparison], order: Mapping,
                    flagged: set = frozenset()) -> tuple[str, list[Comparison]] | None:
    """Rule (c): the strongest unanimous pooled result, and the pairs that share it; with the cells it rests on.

    A pool with a side that rule (a) stated as failing on one of its panels is left out.
    """
    def clean(t: Pooled) -> bool:
        return not any((c.panel, x) in flagged for c in t.cells for x in (c.a, c.b))

    tests_all = pooled_tests(comparisons)
    tests = [t for t in tests_all if t.unanimous and clean(t)]
    if not tests:
        return None
    per_node = budgets_per_node(comparisons)

    def rank(t: Pooled):
        c = t.cells[0]
        tier = c.budget_tier(per_node)
        return (t.p_holm >= ALPHA, order[(c.group, c.a, c.b)], -t.instances, tier is not None,
                math.inf if tier is None else tier)

    best = min(tests, key=rank)
    c0 = best.cells[0]
    short = short_names({c.a for c in comparisons} | {c.b for c in comparisons})
    a_side = best.a_wins == best.instances  # a costs less on every instance
    subject, other, word = c0.a, c0.b, "less" if a_side else "more"
    panels = sorted({c.panel for c in best.cells}, key=_panel_order)
    sizes = sorted({c.paired.instances for c in best.cells})
    each = f"{sizes[0]}" if len(sizes) == 1 else f"{sizes[0]}–{sizes[-1]}"
    tier = _tier_phrase(c0, per_node)
    significant = best.p_holm < ALPHA
    k = len(tests_all)
    why = "too few for an interval" if all(c.too_few for c in best.cells) else "too few for a claim"
    text = (f"Pooled over its {len(panels)} panels ({each} instance{'' if sizes[-1] == 1 else 's'} each, {why} "
            f"one by one), {_subject(subject, short)} costs {word} than {_subject(other, short)} on "
            f"{best.instances} of {best.instances} instances {tier} (stratified sign test p {_approx(best.p)}, "
            f"Holm-adjusted over {k} pooled test{'' if k == 1 else 's'} p {_approx(best.p_holm)}"
            + ("" if significant else ": not significant even pooled") + ")")
    # Other pairs with the same second design, tier and direction, as strong: "so do …".
    also = []
    if significant:
        for t in sorted(tests, key=rank):
            c = t.cells[0]
            if t is best or t.p_holm >= ALPHA or c.b != c0.b or c.budget_tier(per_node) != c0.budget_tier(per_node):
                continue
            if (t.a_wins == t.instances) != a_side or c.a == c0.a:
                continue
            also.append(f"{_subject(c.a, short)} ({t.instances} of {t.instances})")
    if also:
        text += f"; so {'does' if len(also) == 1 else 'do'} {join_words(also[:3])}"
    return text + ".", list(best.cells)


# --------------------------------------------------------------------------- (e) strongest claim


def claim_sentence(comparisons: Sequence[Comparison], order: Mapping, names: Mapping) -> tuple[str, list] | None:
    """Rule (e): the same-information pair that beats in the most cells, said briefly."""
    from .findings_text import (
        models_text,
        range_text,
        scope_text,
        short_label,
        side_of,
        with_article,
    )

    pairs: dict[tuple, list] = {}
    for c in comparisons:
        if c.relation == "same":
            pairs.setdefault((c.group, c.a, c.b), []).append(c)
    best, best_key = None, None
    for key, cells in pairs.items():
        claims = [c for c in cells if c.significant]
        if not claims:
            continue
        votes = [side_of(c) for c in claims]
        side = -1 if votes.count(-1) > votes.count(1) else 1
        lead = [c for c in claims if side_of(c) == side]
        weakest = min(min(abs(c.paired.low), abs(c.paired.high)) for c in lead)
        rank = (-len(lead), _group_rank(key[0]), order[key], -weakest)
        if best_key is None or rank < best_key:
            best, best_key = (cells, lead, side), rank
    if best is None:
        return None
    cells, lead, side = best
    c0 = lead[0]
    winner, loser = (c0.a, c0.b) if side < 0 else (c0.b, c0.a)
    beaten_by_bound = c0.b == BOUND_LABEL and side > 0
    verdict = f"{c0.a} is beaten by the {c0.b}" if beaten_by_bound else f"{with_article(winner)} beats {with_article(loser)}"
    models = models_text(c0, c0.a if beaten_by_bound else winner)
    holm_p = max(c.p_holm for c in lead)
    text = (f"{verdict} {models} {scope_text(lead, cells, names)}: {short_label(loser, winner)} costs "
            f"{range_text([side * c.paired.median for c in lead])} more per instance (median paired difference, "
            f"{'each' if len(lead) > 1 else 'its'} 95 % interval excluding 0; Holm p ≤ {_p(holm_p)}).")
    return text[0].upper() + text[1:], lead


def _group_rank(group: str) -> int:
    if group == "same information model: delayed":
        return 0
    return 1 if "bound" in group else 2


# --------------------------------------------------------------------------- (d) difficulty


def _nothing_costs(records: Records) -> dict[tuple, float]:
    """Panel -> median cost of the autonomous loop (u = 0) over its instances."""
    out = {}
    for panel, rs in records.by_panel.items():
        costs = [r.cost for r in rs if r.method == _NOTHING and r.ok]
        if costs:
            out[panel] = float(np.median(costs))
    return out


def difficulty_sentence(records, cells: Sequence[Comparison], names: Mapping) -> str | None:
    """Rule (d): where the result's panels differ in what doing nothing costs, that cost beside the gaps."""
    nothing = _nothing_costs(as_records(records))
    panels = [c.panel for c in cells if c.panel in nothing and nothing[c.panel] > 1]
    by_family: dict = {}
    for p in dict.fromkeys(panels):
        by_family.setdefault(p[0], []).append(p)
    best = None
    for family_panels in by_family.values():
        if len(family_panels) < 2:
            continue
        easy = min(family_panels, key=lambda p: nothing[p])
        hard = max(family_panels, key=lambda p: nothing[p])
        ratio = (nothing[hard] - 1) / (nothing[easy] - 1)
        if ratio >= DIFFICULTY_RATIO and (best is None or ratio > best[2]):
            best = (easy, hard, ratio)
    if best is None:
        return None
    easy, hard, _ = best
    # One budget tier: any number of links where the result has it, else its largest.
    tiers = {c.budget for c in cells}
    tier = None if None in tiers else max(tiers)
    gap = {c.panel: c.paired.median for c in cells if c.budget == tier}
    if easy not in gap or hard not in gap:
        return None
    c0 = cells[0]
    from .findings_text import number_text

    short = short_names({c0.a, c0.b})
    difference = f"{_subject(c0.a, short)} − {_subject(c0.b, short).removeprefix('the ')}"

    def share(p) -> str:
        """The gap as a share of what u = 0 costs over LQR, where that is a yardstick (under 10 × LQR)."""
        share_ = 100 * abs(gap[p]) / (nothing[p] - 1)
        text = f"{share_:.0f}" if share_ >= 10 else f"{share_:.2g}"
        return f" ({text} % of u = 0's excess)" if nothing[p] < 10 else ""

    bounded = (", which bounds every gap between designs that beat doing nothing there"
               if nothing[easy] - 1 < 0.1 else "")
    return (f"How hard the problem is changes across these panels: doing nothing (u = 0) costs "
            f"{_excess(nothing[easy])} over LQR on {names[easy]} but {_excess(nothing[hard])} on {names[hard]}"
            f"{bounded}; on those two panels {difference} is {number_text(gap[easy])}{share(easy)} and "
            f"{number_text(gap[hard])}{share(hard)} {'with any number of links' if tier is None else f'within {tier:g} links'}"
            ", median paired differences.")


# --------------------------------------------------------------------------- the answer


def answer_lines(records, comparisons: Sequence[Comparison], *, meta=None, members=None) -> list[str]:
    """The report's answer: at most :data:`MAX_SENTENCES` sentences by the rules of this module, one per line,
    then an empty line; nothing where no rule applies.

    Parameters
    ----------
    records : Records
        As the report shows them (:func:`compare.report.report_records`).
    comparisons : sequence of Comparison
        :func:`compare.report.findings.select_comparisons` of the records.
    meta, members : optional
        The store's metadata and the experiments' members: rule (b) needs them to find
        the experiments that ask for Table 1.
    """
    from .findings_text import panel_names

    records = as_records(records)
    all_panels = sorted(records.by_panel, key=_panel_order)
    report_names = panel_names(all_panels) if all_panels else {}
    cell_names = panel_names(list(dict.fromkeys(c.panel for c in comparisons))) if comparisons else {}
    order = {}
    for c in comparisons:
        order.setdefault((c.group, c.a, c.b), len(order))
    flagged: set = set()
    ladder, ladder_details = ladder_lines(records, meta, members)
    parts = decomposition_sentences(records)
    sentences = ladder + parts + failure_sentences(records, report_names, flagged)
    reproduction = reproduction_sentences(records, meta, members)
    sentences += reproduction
    result = pooled_sentence(comparisons, order, flagged) if comparisons and not parts else None
    if result is None and not reproduction and not ladder and not parts and comparisons:
        result = claim_sentence(comparisons, order, cell_names)
    if result is not None:
        text, cells = result
        sentences.append(text)
        context = difficulty_sentence(records, cells, cell_names)
        if context:
            sentences.append(context)
    sentences = sentences[:MAX_SENTENCES]
    if ladder_details:  # the ladder's verdict, its list, then the other sentences
        return sentences[:len(ladder)] + ["", *ladder_details, ""] + sentences[len(ladder):] + (
            [""] if sentences[len(ladder):] else [])
    return sentences + [""] if sentences else []
