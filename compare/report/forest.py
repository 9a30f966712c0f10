"""The forest plot that a report's Findings come from: one row per comparison, one column per panel.

Each row is a :class:`compare.report.findings.Comparison` cell: the median paired difference
of best costs (first − second) and its 95 % interval, a filled marker where one beats
the other (:attr:`Comparison.significant`: interval excludes 0, Holm-adjusted sign test
p < 0.05, beyond the practical margin, and the budget fronts agree), hollow otherwise
(not significant, no clear difference, equal within 0.1 % of LQR's cost, or mixed),
grey where too few instances allow no 95 % interval.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402

from .findings import BOUND_LABEL, PRACTICAL_MARGIN, X_CAP, Comparison, budgets_per_node  # noqa: E402
from .statistics import panel_title  # noqa: E402
from .styles import BOUND_COLOUR  # noqa: E402

__all__ = ["plot_forest"]

_TOO_FEW_COLOUR = "#999999"
_TICK_POINTS = _NAME_POINTS = 8  # font sizes of the tick labels (budgets included) and of the pair names
_OVERHANG = 0.06  # inches a tick label may reach past its panel: under half the gap between panels
_HEADING_INDENT, _PAIR_INDENT = 0.08, 0.18  # inches from the figure's left edge to the group headings, pair names


def _num(x: float) -> str:
    """A forest-plot annotation: three significant digits."""
    return f"{x:+,.0f}" if abs(x) >= 100 else f"{x:+.3g}"

def _rows(comparisons: Sequence[Comparison], by_node: bool = False):
    """Figure layout: [(group, [((a, b), [budgets])])] in the order of ``comparisons``."""
    layout: dict[str, dict[tuple, list]] = {}
    for c in comparisons:
        budgets = layout.setdefault(c.group, {}).setdefault((c.a, c.b), [])
        if c.budget_tier(by_node) not in budgets:
            budgets.append(c.budget_tier(by_node))
    # Budgets in increasing order whichever panel met them first (None, any number of links, last).
    return [(group, [(pair, sorted(budgets, key=_budget_order)) for pair, budgets in pairs.items()])
            for group, pairs in layout.items()]


def _budget_order(budget) -> float:
    return float("inf") if budget is None else float(budget)


def _budget_text(budget, by_node: bool = False) -> str:
    if budget is None:
        return "any"
    return f"≤ {budget:g}/node" if by_node else f"≤ {budget:g}"


def _symlog_axis(ax, values) -> float:
    """Symmetric-log x axis around 0 spanning ``values`` up to ±:data:`X_CAP`, labelled in plain numbers.

    Returns the largest magnitude shown; beyond it rows are drawn at the edge.
    """
    values = np.asarray([v for v in values if np.isfinite(v)] or [0.0])
    nonzero = np.abs(values[values != 0])
    # The linear part around 0 ends a decade below most differences, so that they read on the log part.
    low_decade = int(np.floor(np.log10(np.percentile(nonzero, 5)))) if nonzero.size else -3
    exponent = min(-2, max(-5, low_decade))
    linthresh = 10.0 ** exponent
    ax.set_xscale("symlog", linthresh=linthresh, linscale=0.5)
    lo, hi = max(min(values.min(), 0.0), -X_CAP), min(max(values.max(), 0.0), X_CAP)
    top = int(np.ceil(np.log10(max(abs(lo), abs(hi), linthresh))))
    exponents = range(exponent, top + 1)
    ticks = ([-(10.0 ** e) for e in exponents if -(10.0 ** e) >= lo - linthresh] + [0.0]
             + [10.0 ** e for e in exponents if 10.0 ** e <= hi + linthresh])
    edge = max(abs(lo), abs(hi), linthresh)
    ax.set_xlim(lo * 2.0 - linthresh * 0.5 if lo < 0 else -linthresh, hi * 2.0 + linthresh * 0.5 if hi > 0
                else linthresh)
    labelled = _clear_labels(ax, [t for t in ticks if t == 0 or abs(t) > linthresh])
    ax.xaxis.set_major_locator(FixedLocator(labelled))
    ax.xaxis.set_minor_locator(FixedLocator(sorted(set(ticks) - set(labelled))))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: _tick_text(v)))
    ax.xaxis.set_minor_formatter(NullFormatter())
    return edge


def _inches(text: str, points: float) -> float:
    """Printed width of one line of text in DejaVu Sans (matplotlib's default font) at ``points``."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import text_to_path

    return text_to_path.get_text_width_height_descent(text, FontProperties(size=points), ismath=False)[0] / 72.0


def _tick_text(value: float) -> str:
    return "0" if value == 0 else f"{value:+g}"


def _clear_labels(ax, ticks) -> list[float]:
    """The ticks whose labels fit side by side on their panel as laid out: 0, then ±0.01 and ±1, then the rest.

    ``+t`` and ``-t`` are kept together, each pair only where both labels fit.

    ±linthresh is never offered (it sits next to the 0 label). A decade of a
    symlog axis can be narrower than its label on a small panel (four panels
    side by side), so each label is kept only where it clears those kept before
    it, in that order of importance: most differences lie near ±0.01 and ±1.
    """
    dpi = ax.figure.dpi
    # Each tick's centre and half its label's width (with a gap of 0.06 in), in inches on the figure.
    centre = {t: ax.transData.transform((t, 0.0))[0] / dpi for t in ticks}
    half = {t: (_inches(_tick_text(t), _TICK_POINTS) + 0.06) / 2.0 for t in ticks}
    left, right = (x / dpi for x in ax.transAxes.transform([(0.0, 0.0), (1.0, 0.0)])[:, 0])

    def fits(t, kept):
        inside = left - _OVERHANG <= centre[t] - half[t] and centre[t] + half[t] <= right + _OVERHANG
        return inside and all(abs(centre[t] - centre[k]) >= half[t] + half[k] for k in kept)

    # ±t are labelled together or not at all, so that the axis reads the same both ways.
    pairs = sorted({abs(t) for t in ticks}, key=lambda a: (a != 0, a != 0 and round(np.log10(a)) % 2 != 0, a))
    kept: list[float] = []
    for magnitude in pairs:
        pair = [t for t in ticks if abs(t) == magnitude]
        if all(fits(t, kept + [o for o in pair if o != t]) for t in pair):
            kept += pair
    return sorted(kept)


def plot_forest(comparisons: Sequence[Comparison], styles: Mapping, *, axes=None):
    """Forest plot of the comparisons: one column per panel, one row per (pair, budget).

    Where panels of different sizes have different budgets (1, 3 and 7 links per node
    by default), a row is a budget per node ("≤ 3/node") and holds each panel's own.

    Each row shows the median paired difference a − b (LQR-normalized cost) with its
    distribution-free interval as a bar, in ``a``'s colour and marker; the marker is
    filled where the cell is a claim (:attr:`Comparison.significant`), hollow otherwise
    (equal within the practical margin and mixed cells among them), and grey where too
    few instances allow a 95 % interval. Rows are grouped under headings by relation
    (same information model, crossing models).

    Parameters
    ----------
    comparisons : sequence of Comparison
        As :func:`select_comparisons` gives them.
    styles : mapping
        Label -> :class:`compare.report.styles.Style` (or (colour, marker)); the bound is
        drawn in :data:`compare.report.styles.BOUND_COLOUR`.
    axes : sequence of matplotlib Axes, optional
        One per panel, sharing y; a new figure is made when None.

    Returns
    -------
    (Figure, list of Axes)
    """
    panels = list(dict.fromkeys(c.panel for c in comparisons))
    by_node = budgets_per_node(comparisons)
    layout = _rows(comparisons, by_node)
    # y positions, top to bottom: a heading slot per group, then each pair's budget rows.
    y, row_y, headings, blocks = 0.0, {}, [], []
    for group, pairs in layout:
        y += 0.4
        headings.append((group, y))
        y += 0.9
        for pair, budgets in pairs:
            height = max(len(budgets), 1.7)  # room for the two-line pair name
            start = y
            offset = (height - len(budgets)) / 2
            for i, budget in enumerate(budgets):
                row_y[(group, pair, budget)] = start + offset + i + 0.5
            y += height
            blocks.append((pair, start, y))
    total = max(y, 1.0)
    # The label column holds the two-line pair names, then the budgets (the y tick labels), as printed.
    names = max([_inches(a, _NAME_POINTS) for (a, _), _, _ in blocks]
                + [_inches(f"− {b}", _NAME_POINTS) for (_, b), _, _ in blocks] + [1.2])
    budgets = max([_inches(_budget_text(b, by_node), _TICK_POINTS) for (_, _, b) in row_y] + [0.3])
    label_width = _PAIR_INDENT + names + 0.15 + budgets + 0.1
    created = axes is None
    if created:
        width = label_width + 2.7 * max(1, len(panels))
        height = 0.2 * total + 1.5
        fig, grid = plt.subplots(1, max(1, len(panels)), figsize=(width, height), sharey=True, squeeze=False)
        axes = list(grid[0])
        fig.subplots_adjust(left=label_width / width, right=1 - 0.15 / width, top=1 - 0.45 / height,
                            bottom=1.05 / height, wspace=0.06)
    else:
        axes = list(np.ravel(axes))
        fig = axes[0].figure
    values = [v for c in comparisons for v in (c.paired.low, c.paired.high, c.paired.median)]
    ends = {(c.group, (c.a, c.b), c.budget_tier(by_node), c.panel): c for c in comparisons}
    for ax, panel in zip(axes, panels):
        edge = _symlog_axis(ax, values)
        for i, (_, start, stop) in enumerate(blocks):
            if i % 2 == 0:
                ax.axhspan(start, stop, color="#F2F2F2", zorder=0, linewidth=0)
        for _, hy in headings[1:]:
            ax.axhline(hy, color="0.6", linewidth=0.6, zorder=1)
        ax.axvline(0.0, color="0.25", linewidth=0.8, zorder=1)
        for (group, pair, budget), ry in row_y.items():
            c = ends.get((group, pair, budget, panel))
            if c is not None:
                _draw_row(ax, c, ry, styles, edge)
        n = max((c.panel_instances for c in comparisons if c.panel == panel), default=0)
        ax.set_title(f"{panel_title(panel)}\n{n} instance{'' if n == 1 else 's'}", fontsize=9)
        ax.tick_params(axis="both", labelsize=_TICK_POINTS)
        ax.grid(axis="x", color="0.85", linewidth=0.5, which="both")
        ax.set_axisbelow(True)
        ax.set_xlabel("Δ cost, first − second", fontsize=8)
    first = axes[0]
    first.set_ylim(total + 0.2, 0.0)
    first.set_yticks([ry for ry in row_y.values()], [_budget_text(b, by_node) for (_, _, b) in row_y],
                     fontsize=_TICK_POINTS)
    for ax in axes[1:]:
        ax.tick_params(axis="y", left=False, labelleft=False)
    left = blended_transform_factory(fig.dpi_scale_trans, first.transData)  # x in inches from the figure's edge
    for group, hy in headings:
        first.text(_HEADING_INDENT, hy + 0.45, group, transform=left, fontsize=8.5, fontweight="bold",
                   va="center", ha="left", clip_on=False)
    for (a, b), start, stop in blocks:
        first.text(_PAIR_INDENT, (start + stop) / 2, f"{a}\n− {b}", transform=left, fontsize=_NAME_POINTS,
                   va="center", ha="left", clip_on=False, linespacing=1.05)
    if not comparisons:
        first.text(0.5, 0.5, "no comparisons", transform=first.transAxes, ha="center", va="center")
    if created:
        fig.legend(handles=_legend_handles(), loc="lower center", ncol=2, frameon=False, fontsize=8,
                   bbox_to_anchor=(0.5, 0.0))
    return fig, axes


def _style(c: Comparison, styles: Mapping) -> tuple[str, str]:
    if c.a in styles:
        return styles[c.a][0], styles[c.a][1]
    if c.a == BOUND_LABEL:
        return BOUND_COLOUR, "X"
    return (c.style_a.colour, c.style_a.marker) if c.style_a is not None else ("#555555", "o")


def _draw_row(ax, c: Comparison, y: float, styles: Mapping, edge: float) -> None:
    colour, marker = _style(c, styles)
    if c.too_few:
        colour = _TOO_FEW_COLOUR
    face = colour if c.significant else "white"
    low, high, median = (float(np.clip(v, -edge, edge)) for v in (c.paired.low, c.paired.high, c.paired.median))
    ax.plot([low, high], [y, y], color=colour, linewidth=1.6, solid_capstyle="butt", zorder=2)
    if median != c.paired.median:
        # Off the scale: an arrow at the edge, and the value.
        ax.plot([median], [y], linestyle="none", marker=">" if median > 0 else "<", markersize=6,
                markerfacecolor=face, markeredgecolor=colour, zorder=3, gid="forest-median")
        ax.annotate(_num(c.paired.median), (median, y), xytext=(-4 if median > 0 else 4, 5),
                    textcoords="offset points", ha="right" if median > 0 else "left", va="bottom", fontsize=7,
                    color=colour)
        return
    ax.plot([median], [y], linestyle="none", marker=marker, markersize=6, markerfacecolor=face,
            markeredgecolor=colour, markeredgewidth=1.2, zorder=3, gid="forest-median")


def _legend_handles() -> list:
    common = dict(linestyle="-", marker="o", markersize=6, markeredgewidth=1.2)
    return [Line2D([], [], color="0.2", markerfacecolor="0.2",
                   label="beats: interval excludes 0, Holm-adjusted sign test p < 0.05", **common),
            Line2D([], [], color="0.2", markerfacecolor="white",
                   label=f"hollow: not significant after Holm, no clear difference, equal within "
                         f"{100 * PRACTICAL_MARGIN:g} % of LQR's cost, or mixed", **common),
            Line2D([], [], color=_TOO_FEW_COLOUR, markerfacecolor="white",
                   label="≤ 5 instances: too few for a 95 % interval", **common),
            Line2D([], [], color="none", label="median paired Δ (LQR = 1) and its 95 % interval; Δ < 0: first "
                   "better")]
