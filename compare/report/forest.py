"""The forest plot that a report's Findings come from: one row per comparison, one column per panel.

Each row is a :class:`compare.report.findings.Comparison` cell: the median paired difference
of best costs (first − second) and its 95 % interval, a filled marker where one beats
the other (:attr:`Comparison.significant`: interval excludes 0, Holm-adjusted sign test
p < 0.05, beyond the practical margin, and the budget fronts agree), hollow otherwise
(not significant, no clear difference, equal within 0.1 % of LQR's cost, or mixed),
grey where too few instances allow no 95 % interval.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402

from .figures import MAX_WIDTH  # noqa: E402
from .findings import BOUND_LABEL, PRACTICAL_MARGIN, X_CAP, Comparison, budgets_per_node  # noqa: E402
from .statistics import panel_title  # noqa: E402
from .styles import BOUND_COLOUR  # noqa: E402

__all__ = ["plot_forest", "forest_figures", "forest_parts", "forest_stem", "forest_markdown", "splice_forest",
           "FOREST_ROWS", "FOREST_COLUMNS"]

#: Rows of one forest figure at most (:func:`forest_parts`), and panels side by side at most.
FOREST_ROWS, FOREST_COLUMNS = 20, 3

_TOO_FEW_COLOUR = "#999999"
_TICK_POINTS = _NAME_POINTS = 8  # font sizes of the tick labels (budgets included) and of the pair names
_TITLE_POINTS, _HEADING_POINTS = 9, 8.5
_OVERHANG = 0.06  # inches a tick label may reach past its panel: under half the gap between panels
_HEADING_INDENT, _PAIR_INDENT = 0.08, 0.18  # inches from the figure's left edge to the group headings, pair names
#: A pair name's line at most, in characters; a line of it in rows (of 0.2 in: 8-point type at 1.05 spacing).
_NAME_CHARS, _LINE_ROWS = 36, 0.62
#: A panel's width in inches at least; what the page keeps free of the figure's width; a row of panels' title and
#: axis below it, in inches; the legend's height below the panels.
_PANEL_WIDTH, _WIDTH_MARGIN, _BLOCK_EXTRA, _LEGEND_HEIGHT = 1.9, 0.4, 1.15, 0.75


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


def _inches(text: str, points: float, weight: str = "normal") -> float:
    """Printed width of one line of text in DejaVu Sans (matplotlib's default font) at ``points``."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import text_to_path

    font = FontProperties(size=points, weight=weight)
    return text_to_path.get_text_width_height_descent(text, font, ismath=False)[0] / 72.0


def _heading_lines(group: str, width: float | None) -> list[str]:
    """A group's heading in lines no wider than ``width`` inches (None: one line), so that it ends before the
    panels: a heading that ran on over the first panel was struck through by its lines."""
    if width is None:
        return [group]
    lines: list[str] = []
    for word in group.split(" "):
        if lines and _inches(f"{lines[-1]} {word}", _HEADING_POINTS, "bold") <= width:
            lines[-1] += f" {word}"
        else:
            lines.append(word)
    return lines


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


def _pair_text(a: str, b: str) -> tuple[str, int]:
    """A pair's name as printed left of its rows, wrapped at :data:`_NAME_CHARS`: ``a``, then "− b"; and its lines."""
    first = textwrap.wrap(a, _NAME_CHARS) or [a]
    second = textwrap.wrap(f"− {b}", _NAME_CHARS, subsequent_indent="  ") or [f"− {b}"]
    return "\n".join(first + second), len(first) + len(second)


def _layout(comparisons: Sequence[Comparison], by_node: bool, heading_width: float | None = None):
    """(total height in rows, row_y, headings, blocks) of the comparisons' rows, top to bottom.

    A heading slot per group (its text wrapped to ``heading_width`` inches), then each pair's
    budget rows, a pair at least as tall as its wrapped name.
    """
    y, row_y, headings, blocks = 0.0, {}, [], []
    for group, pairs in _rows(comparisons, by_node):
        lines = _heading_lines(group, heading_width)
        y += 0.4
        headings.append(("\n".join(lines), y))
        y += 0.9 + _LINE_ROWS * (len(lines) - 1)
        for pair, budgets in pairs:
            text, lines = _pair_text(*pair)
            height = max(len(budgets), _LINE_ROWS * lines + 0.35)  # room for the wrapped pair name
            start = y
            offset = (height - len(budgets)) / 2
            for i, budget in enumerate(budgets):
                row_y[(group, pair, budget)] = start + offset + i + 0.5
            y += height
            blocks.append((pair, text, start, y))
    return max(y, 1.0), row_y, headings, blocks


def plot_forest(comparisons: Sequence[Comparison], styles: Mapping, *, axes=None, columns: int | None = None):
    """Forest plot of the comparisons: a small multiple per panel, one row per (pair, budget).

    The panels stand :data:`FOREST_COLUMNS` to a row (fewer where the pair names take the
    width), each row of panels with its pair names and budgets at its left and only the rows
    its panels have, so that the figure stays within :data:`compare.report.figures.MAX_WIDTH`
    and its type legible on the page; :func:`forest_figures` splits a long forest into such
    figures of at most :data:`FOREST_ROWS` rows. Where panels of different sizes have
    different budgets (1, 3 and 7 links per node by default), a row is a budget per node
    ("≤ 3/node") and holds each panel's own.

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
        One per panel, sharing y (every row in each); a new figure is made when None.
    columns : int, optional
        Panels side by side at most (default: as many of :data:`FOREST_COLUMNS` as fit).

    Returns
    -------
    (Figure, list of Axes)
        The axes one per panel, in the order the comparisons meet the panels.
    """
    panels = list(dict.fromkeys(c.panel for c in comparisons))
    by_node = budgets_per_node(comparisons)
    values = [v for c in comparisons for v in (c.paired.low, c.paired.high, c.paired.median)]
    if axes is not None:  # one row of panels given: every row in each
        axes = list(np.ravel(axes))
        fig = axes[0].figure
        _draw_panels(fig, axes, panels, comparisons, styles, by_node, values, _layout(comparisons, by_node))
        return fig, axes
    label_width = _label_width(comparisons, by_node)
    cols = _columns(len(panels), label_width, columns)
    rows = [panels[i:i + cols] for i in range(0, len(panels), cols)] or [[]]
    heading_width = label_width - _HEADING_INDENT - 0.1
    layouts = [_layout([c for c in comparisons if c.panel in row], by_node, heading_width) for row in rows]
    fig, grid = _forest_grid(label_width, cols, [layout[0] for layout in layouts])
    axes = []
    for r, (row, layout) in enumerate(zip(rows, layouts)):
        mine = [fig.add_subplot(grid[r, c]) for c in range(max(1, len(row)))]
        for ax in mine[1:]:
            ax.sharey(mine[0])
        _draw_panels(fig, mine, row, [c for c in comparisons if c.panel in row], styles, by_node, values, layout)
        axes += mine[:len(row)] if row else mine
    if not comparisons:
        axes[0].text(0.5, 0.5, "no comparisons", transform=axes[0].transAxes, ha="center", va="center")
    fig.legend(handles=_legend_handles(), loc="lower left", ncol=1, frameon=False, fontsize=_NAME_POINTS,
               bbox_to_anchor=(_HEADING_INDENT / fig.get_figwidth(), 0.0))
    return fig, axes


def _label_width(comparisons: Sequence[Comparison], by_node: bool) -> float:
    """The label column's width in inches: the wrapped pair names, then the budgets (the y tick labels), as printed."""
    texts = [_pair_text(c.a, c.b)[0] for c in comparisons]
    names = max([_inches(line, _NAME_POINTS) for text in texts for line in text.split("\n")] + [1.2])
    budgets = max([_inches(_budget_text(c.budget_tier(by_node), by_node), _TICK_POINTS) for c in comparisons]
                  + [0.3])
    return _PAIR_INDENT + names + 0.15 + budgets + 0.1


def _columns(panels: int, label_width: float, columns: int | None) -> int:
    """Panels side by side: :data:`FOREST_COLUMNS` (or ``columns``), fewer where MAX_WIDTH leaves less room."""
    fit = max(1, int((MAX_WIDTH - _WIDTH_MARGIN - label_width) // _PANEL_WIDTH))
    return max(1, min(panels or 1, columns or FOREST_COLUMNS, fit))


def _forest_grid(label_width: float, cols: int, totals: list[float]):
    """A new figure for the forest, rows of panels each as tall as its rows (``totals``, in rows of 0.2 in), a
    title above and an axis below each; returns (fig, gridspec)."""
    space = MAX_WIDTH - _WIDTH_MARGIN - label_width
    panel_width = min(_PANEL_WIDTH * 1.4, max(_PANEL_WIDTH, space / cols))
    width = label_width + panel_width * cols + 0.15
    blocks = [0.2 * (t + 0.2) for t in totals]
    height = sum(blocks) + _BLOCK_EXTRA * len(blocks) + _LEGEND_HEIGHT
    fig = plt.figure(figsize=(width, height))
    grid = fig.add_gridspec(len(blocks), cols, left=label_width / width, right=1 - 0.15 / width,
                            top=1 - 0.45 / height, bottom=(_LEGEND_HEIGHT + 0.6) / height, height_ratios=blocks,
                            wspace=0.06, hspace=_BLOCK_EXTRA / (sum(blocks) / len(blocks)))
    return fig, grid


def _draw_panels(fig, axes: list, panels: list, comparisons: Sequence[Comparison], styles: Mapping, by_node: bool,
                 values: list, layout) -> None:
    """One row of panels: each panel's rows on its axes, and the row labels left of the first."""
    total, row_y, headings, blocks = layout
    ends = {(c.group, (c.a, c.b), c.budget_tier(by_node), c.panel): c for c in comparisons}
    for ax, panel in zip(axes, panels):
        edge = _symlog_axis(ax, values)
        for i, (_, _, start, stop) in enumerate(blocks):
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
        ax.set_title(f"{panel_title(panel)}\n{n} instance{'' if n == 1 else 's'}", fontsize=_TITLE_POINTS)
        ax.tick_params(axis="both", labelsize=_TICK_POINTS)
        ax.grid(axis="x", color="0.85", linewidth=0.5, which="both")
        ax.set_axisbelow(True)
        ax.set_xlabel("Δ cost, first − second", fontsize=_TICK_POINTS)
    first = axes[0]
    first.set_ylim(total + 0.2, 0.0)
    first.set_yticks([ry for ry in row_y.values()], [_budget_text(b, by_node) for (_, _, b) in row_y],
                     fontsize=_TICK_POINTS)
    for ax in axes[1:]:
        ax.tick_params(axis="y", left=False, labelleft=False)
    left = blended_transform_factory(fig.dpi_scale_trans, first.transData)  # x in inches from the figure's edge
    for group, hy in headings:
        lines = group.count("\n") + 1
        first.text(_HEADING_INDENT, hy + 0.45 + _LINE_ROWS * (lines - 1) / 2, group, transform=left,
                   fontsize=_HEADING_POINTS, fontweight="bold", va="center", ha="left", clip_on=False,
                   linespacing=1.05)
    for _, text, start, stop in blocks:
        first.text(_PAIR_INDENT, (start + stop) / 2, text, transform=left, fontsize=_NAME_POINTS,
                   va="center", ha="left", clip_on=False, linespacing=1.05)


def forest_parts(comparisons: Sequence[Comparison], max_rows: int | None = None) -> list[list[Comparison]]:
    """The comparisons in parts of at most ``max_rows`` (:data:`FOREST_ROWS`) rows, whole pairs each, in order.

    The parts are about equally long (a forest of 26 rows is two of 13, not 20 and 6); a
    pair with more budgets than ``max_rows`` is a part of its own.
    """
    max_rows = max_rows or FOREST_ROWS
    by_node = budgets_per_node(comparisons)
    pairs: dict[tuple, list] = {}
    for c in comparisons:
        pairs.setdefault((c.group, c.a, c.b), []).append(c)
    sizes = {key: len({c.budget_tier(by_node) for c in cells}) for key, cells in pairs.items()}
    total = sum(sizes.values())
    if total <= max_rows:
        return [list(comparisons)] if comparisons else []
    target = total / -(-total // max_rows)
    parts: list[list] = [[]]
    rows = 0
    for key, cells in pairs.items():
        if parts[-1] and (rows + sizes[key] > max_rows or rows + sizes[key] / 2 > target):
            parts.append([])
            rows = 0
        parts[-1].extend(cells)
        rows += sizes[key]
    return parts


def forest_stem(k: int) -> str:
    """The file stem of the forest's ``k``-th part (0-based): forest, forest-2, forest-3, ..."""
    return "forest" if k == 0 else f"forest-{k + 1}"


def forest_figures(comparisons: Sequence[Comparison], styles: Mapping, *, max_rows: int | None = None):
    """The forest as figures of at most ``max_rows`` rows each (:func:`forest_parts`): ``[(stem, fig), ...]``.

    learned-class's forest was one 2,878 × 2,347 px figure of 71 rows by 7 panels, shown at a
    quarter of its size; each part is a :func:`plot_forest` of its own.
    """
    parts = forest_parts(comparisons, max_rows)
    return [(forest_stem(k), plot_forest(part, styles)[0]) for k, part in enumerate(parts)]


def forest_markdown(stems: Sequence[str], comparisons: Sequence[Comparison], *,
                    max_rows: int | None = None) -> list[str]:
    """The Markdown that shows the forest's parts: one image each, under a line naming its groups."""
    parts = forest_parts(comparisons, max_rows)
    if len(stems) <= 1:
        return [f"![forest plot]({stems[0] if stems else 'forest'}.png)"]
    lines = []
    for k, (stem, part) in enumerate(zip(stems, parts)):
        groups = "; ".join(dict.fromkeys(c.group for c in part))
        lines += [f"Forest plot, part {k + 1} of {len(parts)} ({groups}):", "", f"![forest plot, part {k + 1}]"
                  f"({stem}.png)", ""]
    return lines[:-1]


def splice_forest(lines: list[str], stems: Sequence[str], comparisons: Sequence[Comparison]) -> list[str]:
    """``lines`` with the forest's one image line (``![...](forest.png)``) replaced by all its parts'."""
    if len(stems) <= 1:
        return list(lines)
    out = []
    for line in lines:
        if line.startswith("![") and line.rstrip().endswith("(forest.png)"):
            out += forest_markdown(stems, comparisons)
        else:
            out.append(line)
    return out


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
                    textcoords="offset points", ha="right" if median > 0 else "left", va="bottom",
                    fontsize=_TICK_POINTS, color=colour)
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
