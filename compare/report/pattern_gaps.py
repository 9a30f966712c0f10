"""The report's gap to the best pattern: how far each method's budget front is from the exhaustive search's.

Appears when the store holds ``best_pattern`` designs (small systems). For each
panel and information model, the best pattern found at budget L (its design with
at most L links) is the yardstick; a method's best cost within L links on an
instance is divided by it, and the table gives the median of ``cost / best − 1``
over the instances where the method has a design within L. A static-gain heuristic
of the same information model cannot go below 0 unless the exhaustive search
missed a pattern's optimum (the polish is non-convex); a dynamic or nonlinear
controller (SLS, the GRNN, the GCNN) can, and a negative gap is what its extra
freedom buys at that budget.
"""

from __future__ import annotations

import numpy as np

from ..run.records import as_records
from .statistics import best_within, instances_by_panel, panel_title

__all__ = ["pattern_gap_section", "pattern_gaps", "YARDSTICK"]

#: The method whose designs are the yardstick.
YARDSTICK = "best_pattern"
#: At most this many budgets in one table (wider ones are split, so that each fits 800 px).
COLUMNS = 5


def pattern_gaps(records) -> dict:
    """(panel, info model) -> (budgets, {label: median relative gaps per budget, NaN where no instance has one},
    {label: instances compared}, starts_to_best values, {label: instances behind each budget's median})."""
    records = as_records(records)
    panels = instances_by_panel(records)
    out = {}
    for (panel, _), floor in records.filter(lambda r: r.method == YARDSTICK).by_panel_label.items():
        info = floor[0].info_model
        budgets = np.unique([float(r.params.get("budget", r.links)) for r in floor if r.ok])
        if not budgets.size:
            continue
        reference = best_within(floor, panels[panel], budgets)
        medians, counts, per_budget = {}, {}, {}
        for (pnl, label), rs in sorted(records.by_panel_label.items()):
            if pnl != panel or rs[0].method == YARDSTICK or rs[0].info_model != info:
                continue
            with np.errstate(invalid="ignore", divide="ignore"):  # inf / inf where neither has a design
                gap = best_within(rs, panels[panel], budgets) / reference - 1.0
            finite = np.isfinite(gap)
            medians[label] = np.array([np.median(gap[finite[:, k], k]) if finite[:, k].any() else np.nan
                                       for k in range(budgets.size)])
            counts[label] = int(finite.any(axis=1).sum())
            per_budget[label] = finite.sum(axis=0).astype(int)
        starts = ([int(r.extras.get("starts_to_best", 0)) for r in floor if r.ok],
                  max(int(r.params.get("starts", 0)) for r in floor))
        out[(panel, info)] = (budgets, medians, counts, starts, per_budget)
    return out


def _pct(value: float) -> str:
    if not np.isfinite(value):
        return "—"
    if abs(value) < 5e-7:
        return "0"
    return f"{100 * value:+.2g} %".replace("-", "−")


def _cell(value: float, instances: int, row: int) -> str:
    """A gap, with the number of instances behind it where that is fewer than its row's ("+2.1 % (6)")."""
    text = _pct(value)
    return f"{text} ({instances})" if np.isfinite(value) and instances < row else text


def pattern_gap_section(records) -> list[str]:
    """Markdown: per panel and information model, each method's median gap to the best pattern at each budget.

    A cell whose median rests on fewer instances than its row's count (the method has no
    design within the budget on the others) gives its own count in parentheses.
    """
    gaps = pattern_gaps(records)
    if not gaps:
        return []
    lines = ["## Gap to the best pattern found", "",
             "The exhaustive search (`best_pattern`) polishes every pattern of L node links from several starts "
             "and keeps the best: the best static gain *found* with at most L links (the polish is non-convex, so "
             "it is not a certificate). Each cell is a method's median, over the instances, of its best cost "
             "within L links divided by that, minus 1. Static-gain heuristics of the same information model sit "
             "at or above 0; a dynamic or nonlinear controller may go below, by what its extra freedom buys.", ""]
    for (panel, info), (budgets, medians, counts, starts, per_budget) in sorted(gaps.items()):
        if not medians:
            continue
        heads = [f"≤ {int(b)} link{'' if b == 1 else 's'}" for b in budgets]
        lines += [f"### {panel_title(panel)}, {info} information", ""]
        fewer = False
        rows = []
        for label, values in medians.items():
            if not counts[label]:
                continue  # no usable design on any instance (SLS on an infeasible graph)
            row = counts[label]
            cells = [_cell(v, k, row) for v, k in zip(values, per_budget[label])]
            fewer |= any(c.endswith(")") for c in cells)
            rows.append((label, row, cells))
        # At most COLUMNS budgets a table, so that it fits 800 px: 13 budgets are three tables of 5, 4 and 4.
        parts = -(-len(budgets) // COLUMNS)
        size = -(-len(budgets) // parts)
        for start in range(0, len(budgets), size):
            part = slice(start, start + size)
            first = start == 0
            lines += ["| method | " + ("instances | " if first else "") + " | ".join(heads[part]) + " |",
                      "|---|" + ("---:|" if first else "") + "---:|" * len(heads[part])]
            lines += [f"| {label} | " + (f"{row} | " if first else "") + " | ".join(cells[part]) + " |"
                      for label, row, cells in rows]
            lines.append("")
        lines.pop()
        reached, tried = starts
        note = (f"Starts per pattern: {tried}; the best value of every budget was reached by start "
                f"{max(reached)} (median {int(np.median(reached))})" if reached else f"Starts per pattern: {tried}")
        if reached and max(reached) == tried:
            note += ": where that is the last start, more starts may still lower it"
        counted = (" A count in parentheses: the median rests on that many instances, those where both the method "
                   "and the best pattern have a design within the budget, fewer than the row's." if fewer else "")
        lines += ["", note + ". — : no design within the budget." + counted, ""]
    return lines
