"""The report's answer, first: three sentences at most between the title and the Findings.

Each sentence has at most :data:`MAX_WORDS` words, states the largest effect first and
where an effect changes sign or size across link budgets says at which; every number in
it is one a table of the page gives. The sentences are chosen by rules, in this order
(docs/reports.md, "The answer"):

(0) **Budget ladder.** Where an experiment's spec asks for one (``[report] ladder``,
    :mod:`compare.report.ladder`): whether some design within its first link budget comes within
    ``near`` % of LQR, system by system, and where not by how much; then a table, one column per
    system, of each method's best cost within every budget (the table is not a sentence).
(0') **Decomposition.** Where the records hold the paper's GRNN-Sparse, the per-node one
    from random weights and the per-node one warm-started from a delayed static design beside
    the delayed static designs (:mod:`compare.report.decomposition`): the excess of the paper's design
    over the best delayed static design at the budget where it is largest, its parts with any
    number of links, and divergence with and without the warm start on the system with the
    largest open-loop spectral radius.
(0'') **Graph against controller.** Where the records hold refits (:mod:`compare.report.graph_gaps`),
    instead of (0'): GRNN-Sparse's graph gap and controller gap within 20 and 60 links, the ℓ1
    paths' (which graphs are the better ones), and whether the trained GRNN on the best static
    graph beats the static gain on it.
(a) **Failures.** A method that diverges or fails (:data:`codesign.status.DIVERGED`,
    :data:`~codesign.status.FAILED`) on at least half of a panel's instances, or whose
    median best cost there is above :data:`FAILURE_COST` × LQR, while another design
    has a usable design on every instance below that: the methods, with counts, and
    the range the others stay in. ``infeasible`` is not a failure (a design problem
    with no solution, such as SLS on a communication graph that is not quadratically
    invariant), nor is the autonomous loop (u = 0), the reference for how hard a panel is.
(b) **Reproduction.** A report with the paper's Table 1 (an experiment asks for its
    section): how many paper values lie inside our 95 % intervals or within 2 standard
    errors, those beyond with their distance in standard errors and what is known of why, and
    the largest gap.
(c) **The result.** Of the findings table's rows (pooled over panels,
    :func:`compare.report.findings.pooled_rows`), the pair that beats at the most budgets
    (then the same information model before crossing models, then the Findings' order):
    where it holds, its largest difference first and its smallest, and the budgets where
    the verdict differs. Then either how it holds panel by panel (where a panel's test can
    pass Holm's correction), or the other pairs against the same design that go the same way.
    Where the panels are different systems (they differ in family, case or damping: a chain beside a
    platoon, :func:`different_systems`), only the pairs compared on panels of one kind are pooled.
(c') **System by system.** Where the panels are different systems, a pair compared on several
    kinds, and every pair where (c) pooled none: never a median over them, but at the budget of
    the pair's largest difference on how many systems the same design costs more, that difference
    with its system as the per-panel table prints it, where it changes across budgets on that
    system and which systems differ ("GRNN-Sparse costs more than Sparse delayed K (l1) within 1
    link per node on all 3 systems compared, most on chain, N = 20: +0.088 × LQR (1 instance);
    there within 3 and 7 links per node and with any number: equal"). One pair is always stated,
    chosen as (c) chooses (none against, the same information model, the delayed comparisons
    first), the next ones by their largest difference among pairs that share no design with one
    stated.
(d) **Difficulty.** Beside the result, where its panels (each one system) differ by a
    factor of :data:`DIFFICULTY_RATIO` or more in what doing nothing (u = 0) costs over LQR:
    that cost on the easiest and hardest of them, and the result's gap on each.

Rules (0), (0') or (0''), and (a) to (c') each add their sentences ((c) and (c') only where none
of (0), (0'), (0'') and (b) did), (d) follows (c) or the pair (c') always states; the first
:data:`MAX_SENTENCES` are kept. The sentences kept of (c) and (c') are then stated largest effect
first (issue 61): each pair's, with the sentences that follow it (its panel by panel or "also"
sentence, its difficulty), in order of the largest difference the pair's sentence states (its
median's size in units of LQR's cost), pairs of equal size in the rules' order. So a preferred
pair (the same information model, the delayed comparisons) is always said, but never ahead of a
larger effect. Failures (a) still come first, and (0), (0'), (0'') and (b) keep their own order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from codesign.status import DIVERGED, FAILED

from ..run.records import Records, as_records, canonical_key
from .system_kinds import different_systems, system_kinds  # noqa: F401  (system_kinds: the Findings' rule too)
from .decomposition import decomposition_sentences
from .findings import BOUND_LABEL, PRACTICAL_MARGIN, Comparison, Pooled, budgets_per_node, pooled_rows
from .ladder import ladder_lines
from .graph_gaps import graph_gap_sentences
from .names import MAX_WORDS, join_words, short_names, words

__all__ = ["answer_lines", "MAX_SENTENCES", "MAX_WORDS", "FAILURE_COST", "DIFFICULTY_RATIO", "words"]

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
#: Spec keys that tell no two systems apart (:mod:`compare.report.ladder`'s rule).
_NOT_SYSTEM = ("seed", "sha256")


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


def _reason(method: str) -> str:
    """What is known of why a paper value lies beyond the noise, in a few words (the full reason is in the
    Table 1 section and docs/reproduction.md)."""
    from .learning_report import GAP_REASONS

    reason = GAP_REASONS.get(method, "")
    return reason.split(" (")[0] if reason else "no known cause"


def reproduction_sentences(records, meta=None, members=None) -> list[str]:
    """Rule (b): the paper's Table 1 values against our intervals, those beyond the noise with their distance and
    what is known of why, and the largest gap."""
    from ..run.meta import StoreMeta
    from .learning_report import paper_values
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
    agree = inside + len(noise)
    head = (f"Paper Table 1 is reproduced within instance-sampling noise for {agree} of its {len(values)} values: "
            f"{inside} lie inside our 95 % intervals")
    if not outside:
        return [head + "."]
    if noise:
        head += (f" and {len(noise)} within 2 standard errors (SE) of the difference between our statistic and the "
                 "paper's")
    sentences = [head + "."]
    if not beyond:
        return sentences
    first = [True]

    def where(v) -> str:
        if not several:
            return ""
        text = f" at ‖A‖₂ = {v.a_norm:g}" if first[0] else f" at {v.a_norm:g}"
        first[0] = False
        return text

    groups: dict[str, list] = {}
    for v in beyond:
        groups.setdefault(_reason(v.method), []).append(v)
    parts = []
    for reason, vs in groups.items():
        items = [f"{v.label}{where(v)} ({abs(v.z):.1f} SE)" for v in vs]
        parts.append(f"{join_words(items)}, {reason}")
    unit = "" if noise else " standard errors (SE) of the difference"
    text = f"Beyond that noise lie {'; '.join(parts)}."
    if unit:
        text = text.replace(" SE)", " SE)", 1)
    sentences.append(text)
    top = beyond[0]
    sentences.append(f"The largest gap, {top.label}{' at ‖A‖₂ = ' + format(top.a_norm, 'g') if several else ''}, "
                     f"is our {top.statistic} {top.ours:.3f} against the paper's {top.paper:.3f} "
                     "(docs/reproduction.md).")
    return sentences


# --------------------------------------------------------------------------- (c) the result


def _group_rank(group: str) -> int:
    if group == "same information model: delayed":
        return 0
    return 1 if "bound" in group else 2


def _level(x) -> str:
    from .findings_text import evidence_level as level

    return level(x)


def _side(x) -> int:
    return -1 if x.paired.median < 0 else 1


def _tiers_phrase(tiers: Sequence, per_node: bool) -> str:
    """"within 20 and 60 links", "within 60 links and with any number", "with any number of links"."""
    finite = [t for t in tiers if t is not None]
    unit = "link" if finite == [1] else "links"
    text = (f"within {join_words([f'{t:g}' for t in finite])} {unit}{' per node' if per_node else ''}"
            if finite else "")
    if None in tiers:
        text += " and with any number" if text else "with any number of links"
    return text


def _tier(t, per_node: bool) -> str:
    from .findings_text import tier_phrase as phrase

    return phrase(t, per_node)


_OTHER_WORDS = {"unclear": "no clear difference", "few": "too few instances", "equal": "equal within 0.1 % of LQR",
                "mixed": "mixed", "direction": "the same way, not significant"}


def _median_text(x) -> str:
    """The median as the tables print it (at the precision its interval supports)."""
    from .findings_text import estimate_text

    return estimate_text(x.paired).split(" [")[0]


def _pair_key(x) -> tuple:
    return (x.group, x.a, x.b)


def _rank(rows: Sequence[Pooled], order: Mapping) -> tuple:
    """Pairs with a claim first, then the same information model before crossing models, then more budgets
    beaten, the delayed comparisons before those against the bound, more budgets with a direction, the Findings'
    order."""
    levels = [_level(r) for r in rows]
    r0 = rows[0]
    return ("beats" not in levels, r0.relation != "same", -levels.count("beats"), _group_rank(r0.group),
            -levels.count("direction"), order[_pair_key(r0)])


def _result(rows: Sequence[Pooled], flagged: set, short: Mapping) -> tuple | None:
    """The pair the answer states: (its rows, the lead level, the lead side), or None where no pair has a tested
    direction."""
    pairs: dict[tuple, list] = {}
    for r in rows:
        pairs.setdefault(_pair_key(r), []).append(r)
    order = {key: i for i, key in enumerate(pairs)}
    candidates = [rs for rs in pairs.values() if any(_level(r) in ("beats", "direction") for r in rs)]
    if not candidates:
        return None
    best = min(candidates, key=lambda rs: _rank(rs, order))
    levels = [_level(r) for r in best]
    lead_level = "beats" if "beats" in levels else "direction"
    votes = [_side(r) for r, lv in zip(best, levels) if lv == lead_level]
    side = -1 if votes.count(-1) > votes.count(1) else 1
    return best, lead_level, side


def _names(a: str, b: str, short: Mapping, side: int) -> tuple[str, str]:
    """(winner, loser) as a sentence names them."""
    winner, loser = (a, b) if side < 0 else (b, a)
    name = lambda x: f"the {x}" if x == BOUND_LABEL else short.get(x, x)  # noqa: E731
    return name(winner), name(loser)


def result_sentence(rows: Sequence[Pooled], level: str, side: int, short: Mapping, per_node: bool,
                    panels: int, _every: bool = False) -> str:
    """"Pooled over its 5 panels, W beats L at every budget: L costs +x [..] × LQR more within 20 links, +y [..]
    with any number of links; within …: no clear difference."."""
    lead = [r for r in rows if _level(r) == level and _side(r) == side]
    rest = [r for r in rows if r not in lead]
    winner, loser = _names(rows[0].a, rows[0].b, short, side)
    pooled = len({c.panel for r in rows for c in r.cells})
    head = "" if pooled < 2 else (f"Pooled over its {panels} panels, " if pooled == panels
                                  else f"Pooled over {pooled} of its {panels} panels, ")
    where = "at every budget" if not rest and len(lead) > 1 else _tiers_phrase([r.tier for r in lead], per_node)
    if _every:  # too long: the budgets are left to the table, the largest and smallest difference say where
        where = "at some budgets"
    big = max(lead, key=lambda r: abs(r.paired.median))
    small = min(lead, key=lambda r: abs(r.paired.median))
    if level == "beats":
        text = f"{head}{winner} beats {loser} {where}: {loser} costs {_signed(big, side)} × LQR more"
    else:
        text = (f"{head}{loser} costs more than {winner} {where} (not significant after Holm's correction): "
                f"{_signed(big, side)} × LQR")
    if len(lead) > 1:
        text += f" {_tier(big.tier, per_node)}"
        smallest = f", {_signed(small, side)} {_tier(small.tier, per_node)}" if small is not big else ""
        # the smallest difference too, where the sentence stays short enough
        text += smallest if words(text + smallest) <= MAX_WORDS - 1 else ""
    others: dict[str, list] = {}
    for r in rest:
        lv = _level(r)
        word = ("the other way" if _side(r) != side else _OTHER_WORDS[lv]) if lv in ("beats", "direction") \
            else _OTHER_WORDS[lv]
        others.setdefault(word, []).append(r.tier)
    clauses = [f"{_tiers_phrase(tiers, per_node)}: {word}" for word, tiers in others.items()]
    full = text + "".join(f"; {c}" for c in clauses) + "."
    text = full if words(full) <= MAX_WORDS else text + "."
    if words(text) > MAX_WORDS and where != "at every budget":  # the budgets listed: the largest says enough
        return result_sentence(rows, level, side, short, per_node, panels, _every=True)
    return text[0].upper() + text[1:]


def _signed(r, side: int) -> str:
    """The difference loser − winner with its interval, as the table prints it (signs turned where a is the winner)."""
    from .findings_text import estimate_text
    from .statistics import Paired

    p = r.paired
    if side > 0:
        return estimate_text(p)
    turned = Paired(p.b, p.a, p.budget, p.instances, p.b_wins, p.a_wins, -p.median, -p.high, -p.low, p.coverage)
    return estimate_text(turned)


def per_panel_sentence(rows: Sequence[Pooled], level: str, side: int, names: Mapping, per_node: bool) -> str | None:
    """Where the result's panels can be tested one by one: in how many (panel, budget) cells it holds, the
    exceptions named."""
    cells = [c for r in rows for c in r.cells]
    if level != "beats" or len({c.panel for c in cells}) < 2 or not any(_level(c) == "beats" for c in cells):
        return None
    holds = [c for c in cells if _level(c) == "beats" and _side(c) == side]
    odd = [c for c in cells if c not in holds]
    text = f"Panel by panel it holds in {len(holds)} of {len(cells)} (panel, budget) cases"
    if not odd:
        return f"Panel by panel it holds in every panel at every budget ({len(cells)} cases)."
    if len(odd) <= 2:
        where = join_words([f"{_tier(c.budget_tier(per_node), per_node)} on {names[c.panel]}" for c in odd])
        return text + f", all but {where}."
    return text + "."


def also_sentence(rows_all: Sequence[Pooled], chosen: Sequence[Pooled], level: str, side: int,
                  short: Mapping, per_node: bool = False) -> str | None:
    """Other pairs against the same second design that go the same way at the same level, never the other way:
    "W also beats X (at every budget) and Y (with any number of links), pooled"."""
    c0 = chosen[0]
    pairs: dict[tuple, list] = {}
    for r in rows_all:
        if r.b == c0.b and r.a != c0.a and r.group == c0.group:
            pairs.setdefault(_pair_key(r), []).append(r)
    same = []
    for rs in pairs.values():
        hits = [r for r in rs if _level(r) == level and _side(r) == side]
        against = [r for r in rs if _level(r) in ("beats", "direction") and _side(r) != side]
        if hits and not against:
            where = "at every budget" if len(hits) == len(rs) > 1 else _tiers_phrase([r.tier for r in hits], per_node)
            same.append(f"{short.get(rs[0].a, rs[0].a)} ({where})")
    second = f"the {c0.b}" if c0.b == BOUND_LABEL else short.get(c0.b, c0.b)
    pooled = ", pooled" if any(len(r.cells) > 1 for r in rows_all) else ""
    for keep in (3, 2, 1):
        names = same[:keep]
        if not names:
            return None
        if side > 0:
            verb = "beats" if level == "beats" else "costs less than"
            text = f"{second[0].upper() + second[1:]} also {verb} {join_words(names)}{pooled}."
        else:
            plural = len(names) > 1
            verb = ("beat" if plural else "beats") if level == "beats" else \
                ("cost less than" if plural else "costs less than")
            text = f"{join_words(names)} also {verb} {second}{pooled}."
        if words(text) <= MAX_WORDS:
            return text
    return None


# --------------------------------------------------------------------------- (c') the result, system by system


def _one_kind(records, panels: Sequence[tuple]) -> bool:
    """Whether ``panels`` are all of one kind of system (:func:`different_systems` says they are not different)."""
    return not different_systems(records, list(dict.fromkeys(panels)))


def _cell_side(c) -> int:
    """+1 / −1 where the first design costs more / less on the cell's system (a tested direction, or the median of
    too few instances to test beyond the 0.1 % margin); 0 where they are equal, mixed or no clear difference."""
    level = _level(c)
    median = c.paired.median
    if level in ("beats", "direction") or (level == "few" and math.isfinite(median)
                                             and abs(median) >= PRACTICAL_MARGIN):
        return _side(c)
    return 0


def _system_candidates(comparisons: Sequence[Comparison], flagged: set, per_node: bool) -> list[tuple]:
    """Per pair: (its cells, the cell of its largest difference with a side, the cells against that one at its
    budget, its order in the Findings); cells where rule (a) names a side as failing are left out."""
    pairs: dict[tuple, list] = {}
    for c in comparisons:
        if (c.panel, c.a) not in flagged and (c.panel, c.b) not in flagged:
            pairs.setdefault(_pair_key(c), []).append(c)
    out = []
    for order, cells in enumerate(pairs.values()):
        sided = [c for c in cells if _cell_side(c)]
        if not sided:
            continue
        lead = max(sided, key=lambda c: abs(c.paired.median))
        tier = lead.budget_tier(per_node)
        against = [c for c in cells if c.budget_tier(per_node) == tier and _cell_side(c) == -_cell_side(lead)]
        out.append((cells, lead, against, order))
    return out


def _system_list(panels: Sequence[tuple], names: Mapping) -> str:
    """"swing_grid, N = 25 and 100" (one family at several sizes), "chain, N = 20 and platoon, N = 20", "3 others"."""
    panels = list(panels)
    if len(panels) > 1 and len({p[0] for p in panels}) == 1 and all(names[p] == f"{p[0]}, N = {p[1]}"
                                                                     for p in panels):
        return f"{panels[0][0]}, N = {join_words([str(p[1]) for p in panels])}"
    return join_words([names[p] for p in panels]) if len(panels) <= 2 else f"{len(panels)} others"


def _instances_note(c) -> str:
    """" (1 instance)", " (3 instances)": how few instances a median untested rests on; "" where it has an interval."""
    n = c.paired.instances
    return f" ({n} instance{'' if n == 1 else 's'})" if c.too_few else ""


def system_sentence(cells: Sequence[Comparison], lead: Comparison, short: Mapping, names: Mapping,
                    per_node: bool) -> str | None:
    """One pair on panels that are different systems, no median pooled over them: at the budget of its largest
    difference, on how many systems the same design costs more, that difference with its system, then where it
    changes on that system across budgets and where the other systems differ; None where even the first clause
    is over :data:`MAX_WORDS` words.

    "GRNN-Sparse costs more than Sparse delayed K (l1) within 1 link per node on all 3 systems compared, most on
    chain, N = 20: +0.088 × LQR (1 instance); there within 3 and 7 links per node and with any number: equal."
    """
    side = _cell_side(lead)
    winner, loser = _names(lead.a, lead.b, short, side)
    tier = lead.budget_tier(per_node)
    at = [c for c in cells if c.budget_tier(per_node) == tier]
    same = [c for c in at if _cell_side(c) == side]
    value = f"{_signed(lead, side)} × LQR{_instances_note(lead)}"
    across = "across information models, " if lead.relation != "same" else ""
    one = len({c.panel for c in cells}) == 1
    there = [c for c in cells if c.panel == lead.panel and c is not lead]
    if one:  # one system: the budgets where it is the same, as the table prints it, named with the largest
        alike = [c for c in there if _cell_side(c) == side and _signed(c, side) == _signed(lead, side)]
        there = [c for c in there if c not in alike]
        tiers = _tiers_phrase(sorted([c.budget_tier(per_node) for c in [lead, *alike]],
                                     key=lambda t: math.inf if t is None else t), per_node)
        text = f"On {names[lead.panel]}, {across}{loser} costs more than {winner} {tiers}: {value}"
    else:
        every = "both" if len(at) == 2 else f"all {len(at)}"
        count = every if len(same) == len(at) else f"{len(same)} of {len(at)}"
        text = (f"{across}{loser} costs more than {winner} {_tier(tier, per_node)} on {count} systems compared, "
                f"most on {names[lead.panel]}: {value}")
    text = text[0].upper() + text[1:]
    if words(text) > MAX_WORDS:
        return None

    def word(c) -> str:
        """"" where the cell goes the lead's way, else what it says instead."""
        s, level = _cell_side(c), _level(c)
        if s:
            return "" if s == side else "the other way"
        return {"equal": "equal", "mixed": "mixed"}.get(level, "no clear difference")

    clauses = []
    # across budgets on the system of the largest difference: where the verdict changes, and the smallest one
    changes: dict[str, list] = {}
    for c in there:
        if word(c):
            changes.setdefault(word(c), []).append(c)
    where = "" if one else "there "
    for w, cs in changes.items():
        tiers = _tiers_phrase([c.budget_tier(per_node) for c in cs], per_node)
        shown = f" ({_signed(cs[0], side)})" if w == "the other way" and len(cs) == 1 else ""
        clauses.append(f"{where}{tiers}: {w}{shown}")
    kept = [c for c in there if _cell_side(c) == side]
    if kept:
        small = min(kept, key=lambda c: abs(c.paired.median))
        if _signed(small, side) != _signed(lead, side):
            clauses.append(f"{where}{_tier(small.budget_tier(per_node), per_node)}: {_signed(small, side)}")
    # the other systems at that budget that do not go the same way
    others: dict[str, list] = {}
    for c in at:
        if c not in same:
            others.setdefault(word(c), []).append(c)
    for w, cs in others.items():
        shown = f" ({_signed(cs[0], side)})" if w == "the other way" and len(cs) == 1 else ""
        clauses.append(f"{w} on {_system_list([c.panel for c in cs], names)}{shown}")
    for clause in clauses:  # in this order, while the sentence stays short enough
        longer = f"{text}; {clause}"
        if words(longer) <= MAX_WORDS:
            text = longer
    return text + "."


def system_sentences(records, comparisons: Sequence[Comparison], flagged: set, short: Mapping, names: Mapping,
                     per_node: bool) -> list[tuple[float, list[str]]]:
    """Rule (c'), where the panels are different systems: the pair of rule (c)'s preference (no system the other
    way, the same information model, the delayed comparisons first), then the largest differences of pairs that
    share no design with a pair stated, each system by system (:func:`system_sentence`), with rule (d) after the
    preferred pair's; as (the size of the pair's largest difference, its sentences) in the order chosen, which
    the answer states largest first (:func:`_largest_first`)."""
    candidates = _system_candidates(comparisons, flagged, per_node)
    if not candidates:
        return []
    size = lambda item: -abs(item[1].paired.median)  # noqa: E731
    first = min(candidates, key=lambda item: (bool(item[2]), item[1].relation != "same",
                                              _group_rank(item[1].group), size(item), item[3]))
    # (rule (d) reads the pooled rows' cells only: what doing nothing costs and the gap, system by system)
    out = [(_size(first[1]), [s for s in (system_sentence(first[0], first[1], short, names, per_node),
                                          difficulty_sentence(records, pooled_rows(first[0]), short, names,
                                                              per_node)) if s])]
    stated = {first[1].a, first[1].b}
    for cells, lead, against, order in sorted(candidates, key=lambda item: (bool(item[2]), size(item), item[3])):
        if sum(len(b) for _, b in out) >= MAX_SENTENCES:
            break
        if lead.a not in stated and lead.b not in stated:
            sentence = system_sentence(cells, lead, short, names, per_node)
            out.append((_size(lead), [sentence] if sentence else []))
            stated |= {lead.a, lead.b}
    return [(s, b) for s, b in out if b]


# --------------------------------------------------------------------------- the largest effect first


def _size(x) -> float:
    """The size of the difference a sentence states of a pooled row or a cell: |median| in units of LQR's cost."""
    median = x.paired.median
    return abs(median) if math.isfinite(median) else 0.0


def _largest_first(blocks: Sequence[tuple[float, list[str]]]) -> list[tuple[float, list[str]]]:
    """Blocks of sentences, each a pair's statement with what follows it (rule (d) after its result), in order of
    the size of the difference the pair's statement leads with, largest first; equal sizes in the rules' order."""
    return sorted(blocks, key=lambda block: -block[0])


# --------------------------------------------------------------------------- (d) difficulty


def _one_system(rs: Records) -> bool:
    """Whether a panel's instances are draws of one system (their specs differ in the seed at most)."""
    return len({canonical_key({k: v for k, v in i.spec.items() if k not in _NOT_SYSTEM})
                for i in rs.instances}) == 1


def _nothing_costs(records: Records) -> dict[tuple, float]:
    """Panel -> median cost of the autonomous loop (u = 0) over its instances, on panels that are one system each
    (a median over two systems, ieee39 at two dampings, describes neither)."""
    out = {}
    for panel, rs in records.by_panel.items():
        costs = [r.cost for r in rs if r.method == _NOTHING and r.ok]
        if costs and _one_system(rs):
            out[panel] = float(np.median(costs))
    return out


def _nothing_text(cost: float) -> str:
    """"+4.7 % above LQR", "68 × LQR"."""
    return _times(cost) if cost >= 10 else f"{_excess(cost)} above LQR"


def difficulty_sentence(records, rows: Sequence[Pooled], short: Mapping, names: Mapping,
                        per_node: bool = False) -> str | None:
    """Rule (d): where the result's panels differ in what doing nothing costs, that cost beside the gaps."""
    nothing = _nothing_costs(as_records(records))
    # One tier: any number of links where the result has it, else its largest.
    tiers = [r.tier for r in rows]
    tier = None if None in tiers else max(tiers)
    (row,) = [r for r in rows if r.tier == tier]
    cells = {c.panel: c for c in row.cells}
    panels = [p for p in cells if p in nothing and nothing[p] > 1]
    by_family: dict = {}
    for p in panels:
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
    c0 = row.cells[0]
    difference = f"{short.get(c0.a, c0.a)} − {short.get(c0.b, c0.b)}"
    bounded = " (a ceiling on every gap there)" if nothing[easy] - 1 < 0.1 else ""
    for extra in (bounded, ""):
        text = (f"Doing nothing (u = 0) costs {_nothing_text(nothing[easy])} on {names[easy]}{extra} but "
                f"{_nothing_text(nothing[hard])} on {names[hard]}, while {difference} is {_median_text(cells[easy])} "
                f"and {_median_text(cells[hard])} there {_tier(tier, per_node)}.")
        if words(text) <= MAX_WORDS:
            return text
    return None


# --------------------------------------------------------------------------- the answer


def answer_lines(records, comparisons: Sequence[Comparison], *, meta=None, members=None) -> list[str]:
    """The report's answer: at most :data:`MAX_SENTENCES` sentences by the rules of this module, one per line,
    then an empty line, then the ladder's table where a spec asks for one; nothing where no rule applies.

    Parameters
    ----------
    records : Records
        As the report shows them (:func:`compare.report.report_records`).
    comparisons : sequence of Comparison
        :func:`compare.report.findings.select_comparisons` of the records.
    meta, members : optional
        The store's metadata and the experiments' members: rules (0) and (b) need them to find
        the experiments that ask for a ladder or for Table 1.
    """
    from .findings_text import comparison_short_names, panel_names

    records = as_records(records)
    all_panels = sorted(records.by_panel, key=_panel_order)
    report_names = panel_names(all_panels) if all_panels else {}
    cell_names = panel_names(list(dict.fromkeys(c.panel for c in comparisons))) if comparisons else {}
    flagged: set = set()
    ladder, ladder_details = ladder_lines(records, meta, members)
    parts = graph_gap_sentences(records) or decomposition_sentences(records)
    sentences = ladder + parts + failure_sentences(records, report_names, flagged)
    reproduction = reproduction_sentences(records, meta, members)
    sentences += reproduction
    if comparisons and not (ladder or parts or reproduction) and len(sentences) < MAX_SENTENCES:
        rows = [r for r in pooled_rows(comparisons)  # a pair rule (a) names as failing on a panel is stated there
                if not any((c.panel, x) in flagged for c in r.cells for x in (c.a, c.b))]
        short = comparison_short_names(comparisons)
        per_node = budgets_per_node(comparisons)
        # no median over systems that differ: a pair compared on panels of several kinds is no pooled result
        different = different_systems(records, list(cell_names))
        if different:
            mixed = {_pair_key(r) for r in rows if not _one_kind(records, [c.panel for c in r.cells])}
            rows = [r for r in rows if _pair_key(r) not in mixed]
        chosen = _result(rows, flagged, short)
        blocks: list[tuple[float, list[str]]] = []  # (the size of a pair's largest difference, its sentences)
        if chosen is not None:
            mine, level, side = chosen
            lead = [r for r in mine if _level(r) == level and _side(r) == side]
            blocks.append((max(_size(r) for r in lead),
                           [s for s in (result_sentence(mine, level, side, short, per_node, len(cell_names)),
                                        per_panel_sentence(mine, level, side, cell_names, per_node)
                                        or also_sentence(rows, mine, level, side, short, per_node),
                                        difficulty_sentence(records, mine, short, cell_names, per_node)) if s]))
        if different:  # the pairs on different systems, one system by one (all of them where nothing pooled)
            pooled_pairs = {_pair_key(r) for r in rows} if chosen is not None else set()
            blocks += system_sentences(records, [c for c in comparisons if _pair_key(c) not in pooled_pairs],
                                       flagged, short, cell_names, per_node)
        # the rules choose what is said (the first sentences in their order); it is said largest effect first
        room, kept = MAX_SENTENCES - len(sentences), []
        for size, block in blocks:
            block = block[:room - sum(len(b) for _, b in kept)]
            if block:
                kept.append((size, block))
        sentences += [s for _, block in _largest_first(kept) for s in block]
    sentences = sentences[:MAX_SENTENCES]
    if ladder_details:  # the ladder's verdict, the other sentences, then its table
        return sentences + [""] + ladder_details + [""]
    return sentences + [""] if sentences else []
