"""Figure conventions shared by the report's figures, and the budget-front figure.

Every method is drawn in its own colour and marker (:mod:`compare.report.styles`, the same
in every figure of every report) and with its information model's line style.
Costs are shown as *excess cost* J/J_LQR − 1 on a log axis, in percent, so that a
design 0.1 % above centralized LQR and one 30 % above it are both readable (lqrsp
plots its percent performance loss the same way); centralized LQR is the 0 % the
axis is measured from, and designs within :data:`FLOOR` of it sit on the bottom edge.

One axis rule serves the static figures here and the interactive ones
(:mod:`compare.report.interactive`): :func:`cost_range` sets a cost axis from what is
drawn at or below :data:`OFF_SCALE`, :func:`cost_ticks` and :func:`links_ticks` label
it, :func:`grid_cells` lays the panels out (at most :data:`MAX_COLUMNS` side by side),
and :func:`per_node_axis` says whether links are counted per node. What lies above
``OFF_SCALE`` is never drawn on the axis: it is a triangle on the top edge.

Every figure is legible where the page shows it: the report's column is
:data:`PAGE_PX` wide in an 800 px window, where a figure wider than that shrinks; its
smallest type (:data:`MIN_POINTS`) then stays :data:`SCREEN_PX` px tall so long as the
figure is at most :data:`MAX_WIDTH` inches wide (``tests/test_figure_legibility.py``
measures every shipped PNG).
"""

from __future__ import annotations

import math
import textwrap
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter  # noqa: E402

from .statistics import panel_title  # noqa: E402
from .styles import BOUND_COLOUR, INFO_MODELS, INFO_ORDER, Style, label_styles  # noqa: E402

__all__ = ["LINESTYLES", "OFF_SCALE", "FLOOR", "excess", "excess_axis", "panel_grid", "panel_heading",
           "legend_handles", "finish_legend", "draw_boundary", "boundary_handles", "plot_budget_fronts",
           "label_styles", "method_gid", "front_gid", "draw_front_line", "drawn_styles", "axis_floor", "panel_figure",
           "y_limits", "shared_y", "cost_range", "cost_ticks", "links_ticks", "links_axis", "grid_cells",
           "panel_order", "per_node_axis", "bands_drawn", "title_notes", "nowhere_usable", "NOWHERE_SUFFIX",
           "mark_above", "bound_handles",
           "PAGE_PX", "SCREEN_PX", "DPI", "MIN_POINTS", "MAX_WIDTH", "MAX_COLUMNS", "MAX_BANDS", "BUDGET_PAD",
           "COST_PAD", "OFF_SCALE_GID"]

#: Line style and description per information model (from :data:`compare.report.styles.INFO_MODELS`).
LINESTYLES = {info: (style, text) for info, (style, _, text) in INFO_MODELS.items()}
#: Costs above this many times centralized LQR's are off the interesting range:
#: the axis stops there and the figure says which methods lie above.
OFF_SCALE = 2.0
#: Excess costs below this (0.1 %) are drawn on the axis' bottom edge: that close to LQR.
FLOOR = 1e-3
#: A cost axis spans at least this factor (by reaching lower, never higher: the clip stays), so that it has
#: ticks to read; the interactive axis once widened itself to a decade upwards, to 500 % where the static
#: one stopped at 60 %, and drew a front twice (a line at 130 % and a triangle above the axis).
MIN_SPAN = 3.0
#: Head room above the largest cost shown: the budget fronts' axes and the cost-versus-links axes.
BUDGET_PAD, COST_PAD = 1.25, 1.3

#: The report's column in an 800 px window (compare.report.html: 1200 px at most, 1 em padding each side).
PAGE_PX = 768
#: The smallest type on screen there, in px.
SCREEN_PX = 9.0
#: The resolution figures are saved at (compare.report.write).
DPI = 130
#: The smallest type any figure uses, in points.
MIN_POINTS = 8.0
#: The widest a figure may be, in inches, so that MIN_POINTS type stays SCREEN_PX tall in PAGE_PX (9.5 in).
MAX_WIDTH = MIN_POINTS * PAGE_PX / (72.0 * SCREEN_PX)
#: Panels side by side at most: three in a row (plus a legend) made figures of 2,200 px, shown at a third.
MAX_COLUMNS = 2
#: One panel's size in inches; two side by side and their axis labels stay within MAX_WIDTH.
PANEL_WIDTH, PANEL_HEIGHT = 4.1, 3.3
#: A figure draws the 25–75 % bands only where no panel has more fronts than this: eight overlapping bands
#: fused into one block (learned-class).
MAX_BANDS = 4
#: Type sizes: tick labels and axis labels, panel titles, notes and legends (all at least MIN_POINTS).
TICK_POINTS, TITLE_POINTS, NOTE_POINTS = 9.0, 9.5, 8.5
#: The gid of the triangles drawn on a top edge for what lies above the axis.
OFF_SCALE_GID = "off-scale"
#: A links axis' width in characters of its tick labels, for :func:`links_ticks`: a static panel's 3.4 in at 9
#: points, and the narrowest interactive panel's 290 px at 11 px (both about 44).
LINK_AXIS_CHARS = 44.0


def excess(cost, floor: float = FLOOR):
    """J/J_LQR − 1 for display: floored at ``floor`` (LQR itself is 0) and inf kept inf."""
    return np.maximum(np.asarray(cost, dtype=float) - 1.0, floor)


def axis_floor(costs) -> float:
    """The bottom of an excess-cost axis: a little below the lowest excess above :data:`FLOOR`.

    Designs closer to LQR than that (LQR itself) are drawn on the bottom edge, so that an
    axis whose other designs all lie above 5 % does not spend decades on LQR alone.
    """
    above = [float(c) - 1.0 for c in np.ravel(costs) if np.isfinite(c) and float(c) - 1.0 > FLOOR]
    return max(FLOOR, 0.8 * min(above)) if above else FLOOR


def _percent(value, _=None) -> str:
    text = f"{value * 100:.4g}"
    return f"{text} %"


def y_limits(shown) -> tuple[float, float]:
    """(bottom, top) of an excess-cost axis showing the costs ``shown`` (all at most OFF_SCALE), before head room."""
    shown = np.asarray(shown, dtype=float)
    return axis_floor(shown), (float(shown.max()) if shown.size else OFF_SCALE) - 1.0


def cost_range(shown, pad: float) -> tuple[float, float]:
    """(bottom, top) of an excess-cost axis: the one rule of the static and the interactive figures.

    ``shown``: the costs the axis must show, all at most :data:`OFF_SCALE` (what lies above
    is a triangle on the top edge). The top is ``pad`` times the largest excess shown; the
    bottom :func:`axis_floor`, lowered where needed so that the axis spans at least
    :data:`MIN_SPAN` (never raising the top past what is shown).
    """
    bottom, top = y_limits(shown)
    top = max(top * pad, FLOOR * 10)
    return max(FLOOR, min(bottom, top / MIN_SPAN)), top


def cost_ticks(bottom: float, top: float) -> tuple[list[float], list[str]]:
    """Tick positions and texts (percent) of a log excess-cost axis on [bottom, top]: decades, with 2 and 5 between
    where the axis spans at most 3.2 decades (and more where it spans less than one); at least three ticks."""
    decades = math.log10(top / bottom)
    ticks: list[float] = []
    for subs in ((1,), (1, 2, 5), (1, 2, 3, 5, 7), tuple(range(1, 10))):
        if len(subs) == 1 and decades <= 3.2:
            continue
        ticks = [m * 10.0 ** k for k in range(math.floor(math.log10(bottom)) - 1, math.ceil(math.log10(top)) + 1)
                 for m in subs]
        ticks = [t for t in ticks if bottom * (1 - 1e-9) <= t <= top * (1 + 1e-9)]
        if len(ticks) >= 3:
            break
    return ticks, [_percent(t) for t in ticks]


def excess_axis(ax, low: float, high: float) -> None:
    """Log y-axis of excess cost on [low, high] (fractions), labelled in percent at :func:`cost_ticks`."""
    low, high = max(low, FLOOR), max(high, FLOOR * 10)
    ax.set_yscale("log")
    ticks, texts = cost_ticks(low, high)
    ax.yaxis.set_major_locator(FixedLocator(ticks))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: _percent(value)))
    ax.yaxis.set_minor_locator(LogLocator(subs="auto"))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_ylim(low, high)


def links_ticks(right: float, per_node: bool, position, width: float = LINK_AXIS_CHARS) -> list[float]:
    """Link counts (or links per node) to label on a links axis reaching ``right``: 0 and decades, then 5s and 2s.

    ``position(value)`` is where a value sits on the axis, as a share of its width (each
    figure has its own transform: symlog here, log of links + offset in plotly), and
    ``width`` the axis' width in characters of its tick labels. A tick is labelled where its
    label clears those kept before it by a character and a half, in that order, so that
    1, 2 and 5 links are named wherever the axis gives them room (power's claim is about
    one link) and a narrow axis keeps its decades.
    """
    decade = 0.1 if per_node else 1.0
    powers = [decade * 10 ** k for k in range(9)]
    candidates = [0.0] + powers + [5 * p for p in powers] + [2 * p for p in powers]
    kept: list[tuple[float, float, int]] = []  # (value, position, characters)
    for t in candidates:
        if t > right:
            continue
        at, chars = position(t), len(f"{t:g}")
        if all(abs(at - p) * width >= (chars + c) / 2 + 1.5 for _, p, c in kept):
            kept.append((t, at, chars))
    return sorted(t for t, _, _ in kept)


def links_axis(ax, right: float, *, per_node: bool = False) -> None:
    """Symmetric-log x axis of links from 0 to ``right``, labelled at :func:`links_ticks`."""
    ax.set_xscale("symlog", linthresh=1.0 if not per_node else 0.1)
    lo, hi = (-0.04, right * 1.15 + 0.1) if per_node else (-0.4, right * 1.15 + 1)
    ax.set_xlim(lo, hi)
    transform = ax.xaxis.get_transform()
    ends = transform.transform([lo, hi])

    def position(value):
        return (float(transform.transform([value])[0]) - ends[0]) / (ends[1] - ends[0])

    ax.xaxis.set_major_locator(FixedLocator(links_ticks(right * 1.15, per_node, position)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def per_node_axis(panels) -> bool:
    """Whether the links axes count links per node: panels of one family at several N (scale's grid).

    Panels of different systems (power's grids, benchmark-systems' families) keep links:
    each has its own axis, and a claim about one link must be read off it.
    """
    panels = list(panels)
    return len({p[1] for p in panels}) > 1 and len({p[0] for p in panels}) == 1


def method_gid(label: str) -> str:
    """The gid set on every artist drawn for a method, so that tests and tools can find what was drawn."""
    return f"method:{label}"


def front_gid(label: str) -> str:
    """The gid of a method's budget-front line, so that tests read the curves a figure draws."""
    return f"front:{label}"


def draw_front_line(ax, front, style, bottom: float, right: float, scale: float = 1.0, *, linewidth: float = 1.5):
    """A front's median as a step line to the right edge (``right`` links); gaps where it is not defined.

    Its last step holds to ``right * 1.15 + 1`` links, where the links axis ends. A median
    above :data:`OFF_SCALE` is a gap too: what lies above the axis is a triangle on its top
    edge, never also a line (the interactive figure drew both). Returns ``(x, y)`` as drawn
    (y the excess cost, NaN in the gaps).
    """
    x = np.append(front.budgets, max(right, front.budgets[-1]) * 1.15 + 1) / scale
    median = np.append(front.cost[1], front.cost[1][-1])
    y = np.where(np.isfinite(median) & (median <= OFF_SCALE), excess(median, bottom), np.nan)
    ax.step(x, y, where="post", color=style.colour, linestyle=style.linestyle, linewidth=linewidth,
            gid=front_gid(front.label))
    return x, y


def drawn_styles(fig) -> dict[str, set]:
    """Label -> the (colour, marker) pairs of the markers drawn for it in ``fig`` (read back from its artists)."""
    from matplotlib.colors import to_hex

    out: dict[str, set] = {}
    for ax in fig.axes:
        for artist in list(ax.lines) + list(ax.collections):
            gid = artist.get_gid() or ""
            if not gid.startswith("method:"):
                continue
            if isinstance(artist, Line2D):
                if artist.get_marker() in (None, "None", "none", ""):
                    continue
                out.setdefault(gid[7:], set()).add((to_hex(artist.get_color()), artist.get_marker()))
    return out


def panel_heading(panel: tuple, instances: int | None = None) -> str:
    return panel_title(panel) + (f" · {instances} instance{'' if instances == 1 else 's'}" if instances else "")


def panel_order(panels) -> list[tuple]:
    """Panels sorted by (family, n, a_norm); a_norm may be None, which plain tuple sorting refuses."""
    return sorted(set(panels), key=lambda p: (str(p[0]), p[1] or 0, -math.inf if p[2] is None else p[2]))


def shared_y(panels) -> bool:
    """Whether the panels share one cost axis: several N by several ‖A‖₂ (:func:`grid_cells`' rows, columns)."""
    sizes = {p[1] for p in panels}
    norms = {p[2] for p in panels}
    return len(sizes) > 1 and len(norms) > 1 and None not in norms


def grid_cells(panels) -> tuple[int, int, dict]:
    """``(rows, cols, panel -> (row, col))``, 0-based: the one layout of the static and interactive figures.

    Rows = N and columns = ‖A‖₂ when both vary and at most :data:`MAX_COLUMNS` norms; else the
    panels in order, :data:`MAX_COLUMNS` to a row (a row of three or four wraps two by two).
    """
    panels = panel_order(panels)
    norms = sorted({p[2] for p in panels if p[2] is not None})
    if shared_y(panels) and len(norms) <= MAX_COLUMNS:
        sizes = sorted({p[1] for p in panels})
        return len(sizes), len(norms), {p: (sizes.index(p[1]), norms.index(p[2])) for p in panels}
    cols = min(MAX_COLUMNS, max(1, len(panels)))
    rows = -(-max(1, len(panels)) // cols)
    return rows, cols, {p: (i // cols, i % cols) for i, p in enumerate(panels)}


def panel_grid(panels, *, width: float = PANEL_WIDTH, height: float = PANEL_HEIGHT):
    """Axes for the panels in :func:`grid_cells`' layout.

    Returns ``fig, axes`` (panel -> Axes); the legend goes beside or below the panels (:func:`finish_legend`).
    """
    rows, cols, cells = grid_cells(panels)
    fig, grid = plt.subplots(rows, cols, squeeze=False, figsize=(width * cols, height * rows))
    used = set(cells.values())
    for i in range(rows):
        for j in range(cols):
            if (i, j) not in used:
                grid[i, j].set_axis_off()
    return fig, {p: grid[i, j] for p, (i, j) in cells.items()}


def panel_figure(panels, axes=None):
    """``(fig, axes, own)``: a new :func:`panel_grid` (own = True), or the figure of the panel -> Axes given."""
    if axes is None:
        return (*panel_grid(panels), True)
    return next(iter(axes.values())).figure, axes, False


def _panel_type(ax) -> None:
    """A panel's tick labels at :data:`TICK_POINTS` (matplotlib's 10 points were set for figures shown whole)."""
    ax.tick_params(axis="both", labelsize=TICK_POINTS)


def legend_handles(styles: dict, labels) -> list:
    """Legend entries grouped by information model: a heading per model, then its methods in its line style."""
    handles = []
    for info in INFO_ORDER:
        mine = [lb for lb in labels if _style(styles, lb).info_model == info]
        if not mine:
            continue
        handles.append(Line2D([], [], linestyle="none", label=INFO_MODELS[info][2] + ":"))
        for lb in mine:
            s = _style(styles, lb)
            handles.append(Line2D([], [], color=s.colour, marker=s.marker, linestyle=s.linestyle, linewidth=1.4,
                                  markersize=6, markerfacecolor=getattr(s, "face", s.colour),
                                  markeredgecolor=s.colour, label=lb))
    return handles


def _style(styles: dict, label: str) -> Style:
    s = styles[label]
    return s if isinstance(s, Style) else Style(s[0], s[1])


def _heading(handle) -> bool:
    return handle.get_linestyle() in ("None", "none") and handle.get_marker() in ("None", "none", None, "")


def _in_columns(handles: list, ncol: int) -> list:
    """``handles`` laid out in ``ncol`` columns (matplotlib fills a legend column by column), each heading's group
    kept whole in one column, the columns padded with blank entries to one height."""
    groups: list[list] = []
    for h in handles:
        if _heading(h) or not groups:
            groups.append([])
        groups[-1].append(h)
    target = -(-len(handles) // ncol)
    columns: list[list] = [[]]
    for g in groups:
        if columns[-1] and len(columns[-1]) + len(g) > target and len(columns) < ncol:
            columns.append([])
        columns[-1].extend(g)
    height = max(len(c) for c in columns)
    blank = Line2D([], [], linestyle="none", label=" ")
    return [h for c in columns for h in c + [blank] * (height - len(c))], len(columns)


def finish_legend(fig, handles, *, title: str | None = None) -> None:
    """Lay the panels out, then the legend beside them where the figure stays within its width, else below them
    in columns; headings (entries without a line) in bold. The saved figure's tight bounding box takes it in."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Tight layout not applied")
        fig.tight_layout()
    common = dict(frameon=False, fontsize=NOTE_POINTS, title=title, title_fontsize=NOTE_POINTS + 0.5,
                  handlelength=2.6, alignment="left")
    legend = fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 0.98), **common)
    fig.draw_without_rendering()
    width = fig.get_size_inches()[0] + legend.get_window_extent().width / fig.dpi
    if width > MAX_WIDTH - 0.4:
        legend.remove()
        ordered, ncol = _in_columns(handles, 2)
        legend = fig.legend(handles=ordered, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=ncol,
                            columnspacing=1.5, **common)
    for handle, text in zip(legend.legend_handles, legend.get_texts()):
        if _heading(handle):
            text.set_fontweight("bold")


#: How the QI boundary is drawn, on the panels and in the legend.
BOUNDARY_STYLE = {"color": "0.35", "linestyle": (0, (1, 2)), "linewidth": 1.0}
BOUNDARY_LABEL = "QI boundary (plant-graph links)"
BOUNDARY_GID = "qi-boundary"
#: How a lower bound (SLS on the complete graph) is drawn, and its gid.
BOUND_STYLE = {"color": BOUND_COLOUR, "linewidth": 1.0, "linestyle": (0, (4, 2, 1, 2))}
BOUND_GID = "bound"


def draw_boundary(ax, x: float):
    """The plant graph's link count: below it no delayed graph is quadratically invariant.

    A dotted line under the markers (SLS on the plant graph sits on it), named in the
    legend (:func:`boundary_handles`): a name on the panel was covered by the markers
    that crowd that link count. Returns the line.
    """
    return ax.axvline(x, zorder=0, gid=BOUNDARY_GID, **BOUNDARY_STYLE)


def boundary_handles(axes) -> list:
    """The legend entry naming :func:`draw_boundary`'s line, if one of ``axes`` (Axes objects) has it."""
    if any(line.get_gid() == BOUNDARY_GID for ax in axes for line in ax.lines):
        # under a heading of its own, so that it is not read as one of the last model's methods
        return [Line2D([], [], linestyle="none", label="for delayed designs:"),
                Line2D([], [], label=BOUNDARY_LABEL, **BOUNDARY_STYLE)]
    return []


def bound_handles(axes, text: str) -> list:
    """The legend entry naming a bound line (:func:`plot_budget_fronts`' ``bounds``), if one of ``axes`` has it.

    Named in the legend, not on the panel, where fronts crossing it struck the name through.
    """
    if any(line.get_gid() == BOUND_GID for ax in axes for line in ax.lines):
        return [Line2D([], [], linestyle="none", label="lower bound:"),
                Line2D([], [], label=f"{text}, median", **BOUND_STYLE)]
    return []


def mark_above(ax, x: float, colour: str, *, gid: str = OFF_SCALE_GID, size: float = 8.0):
    """A triangle on the top edge at ``x`` in ``colour``: something lies above the axis there."""
    return ax.plot(x, 1.0, marker="^", color=colour, markersize=size, linestyle="none", clip_on=False, zorder=5,
                   transform=ax.get_xaxis_transform(), gid=gid)[0]


def bands_drawn(fronts) -> bool:
    """Whether the budget-front figures draw the 25–75 % bands: where no panel has more than :data:`MAX_BANDS`
    fronts, beyond which overlapping bands read as one block."""
    per_panel: dict = {}
    for f in fronts:
        per_panel[f.panel] = per_panel.get(f.panel, 0) + 1
    return max(per_panel.values(), default=0) <= MAX_BANDS


def plot_budget_fronts(fronts, *, axes=None, styles: dict | None = None, boundaries: dict | None = None,
                       bounds: dict | None = None):
    """Best cost within each link budget: median over instances (step curve) and 25–75 % band.

    A front starts at the budget where more than half of the instances the method ran
    on have a design within it (:attr:`compare.report.statistics.Front.start`), marked by the
    method's marker; the band spans the 25–75 % quantiles over those instances (spread
    across instances, not uncertainty of the median; an instance without a design within
    the budget counts as above every design, so the band runs to the top edge while a
    quarter of them or more have none), drawn where no panel has more than
    :data:`MAX_BANDS` fronts (:func:`bands_drawn`). Costs are excess costs over centralized
    LQR on a log axis (:func:`excess_axis`, :func:`cost_range`); a front wholly above
    :data:`OFF_SCALE` is a triangle on the top edge where it starts, named under the title.

    Parameters
    ----------
    fronts : list of :class:`compare.report.statistics.Front`
    axes : dict, optional
        Panel -> Axes; a new figure is made if omitted.
    styles : dict, optional
        Label -> :class:`compare.report.styles.Style`.
    boundaries : dict, optional
        Panel -> plant-graph link count, drawn when a delayed method is present.
    bounds : dict, optional
        Panel -> (cost, text): a lower bound drawn as a horizontal line, named in the legend.

    Returns
    -------
    fig, axes
    """
    panels = panel_order({f.panel for f in fronts})
    labels = sorted({f.label for f in fronts})
    styles = styles or {f.label: Style("#333333", "o", f.info_model) for f in fronts}
    fig, axes, own = panel_figure(panels, axes)
    per_node = per_node_axis(panels)
    bands = bands_drawn(fronts)

    limits = cost_range(_shown_costs(fronts, bounds), BUDGET_PAD) if shared_y(panels) else None
    nowhere = nowhere_usable(fronts)
    for panel in panels:
        _draw_panel(axes[panel], panel, [f for f in fronts if f.panel == panel], styles, limits=limits,
                    per_node=per_node, boundaries=boundaries, bounds=bounds, bands=bands, nowhere=nowhere)
    if own:
        bound_text = next(iter(bounds.values()))[1] if bounds else ""
        handles = legend_handles(styles, labels)
        for handle in handles:  # said once, in the legend, not under every panel's title
            if handle.get_label() in nowhere:
                handle.set_label(f"{handle.get_label()}{NOWHERE_SUFFIX}")
        finish_legend(fig, handles + bound_handles(axes.values(), bound_text)
                      + boundary_handles(axes.values()),
                      title="median over instances; band 25–75 %" if bands else
                      f"median over instances (no 25–75 % bands:\nmore than {MAX_BANDS} methods on a panel)")
    return fig, axes


def _draw_panel(ax, panel: tuple, fronts, styles: dict, *, limits, per_node: bool, boundaries: dict | None,
                bounds: dict | None, bands: bool = True, nowhere: frozenset = frozenset()) -> None:
    """One panel: each front with its band and start, its axes, a title that names what is not drawn, the bound
    and the QI boundary. A panel none of whose fronts has a finite median stays empty.

    ``limits`` is the (bottom, top) every panel shares, if they share one; ``nowhere`` the labels without a usable
    design on any panel (:func:`nowhere_usable`), which the legend names once instead of every title.
    """
    scale = panel[1] if per_node and panel[1] else 1.0  # links per node; 0: a family without n
    right = max(float(f.budgets[-1]) for f in fronts) / scale
    if not any(np.isfinite(f.cost[1]).any() for f in fronts):
        return
    bottom, top = limits or cost_range(_shown_costs(fronts, bounds), BUDGET_PAD)
    _finish_front_axes(ax, bottom, top, right, per_node)
    above = [_draw_front(ax, f, _style(styles, f.label), bottom, right, scale, bands) for f in fronts]
    notes = title_notes(fronts, [note for note in above if note is not None], nowhere=nowhere)
    ax.set_title("\n".join([panel_heading(panel, max(f.instances for f in fronts))] + notes),
                 fontsize=NOTE_POINTS if notes else TITLE_POINTS, pad=8)
    if bounds and panel in bounds:
        _draw_bound(ax, bounds[panel], bottom)
    if boundaries and panel in boundaries and any(f.info_model == "delayed" for f in fronts):
        draw_boundary(ax, boundaries[panel] / scale)
    ax.grid(True, which="major", alpha=0.3)


def _shown_costs(fronts, bounds: dict | None) -> np.ndarray:
    """The costs a budget-front axis must show: the fronts' finite medians and the panels' bounds, up to OFF_SCALE."""
    finite = np.concatenate([f.cost[1][np.isfinite(f.cost[1])] for f in fronts] + [np.array([])])
    extra = [bounds[p][0] for p in {f.panel for f in fronts} if bounds and p in bounds]
    finite = np.append(finite, extra)
    return finite[finite <= OFF_SCALE]


def _draw_front(ax, front, s: Style, bottom: float, right: float, scale: float, band: bool = True) -> str | None:
    """A front's median step line, its 25–75 % band (where ``band``) and its marker where it starts.

    Returns the note that names the front above the axis where its lowest median is
    above OFF_SCALE (then it is a triangle on the top edge where it starts), else None.
    """
    # Not started (inf) leaves a gap, not a line off the axis.
    x, _ = draw_front_line(ax, front, s, bottom, right * scale, scale)
    if band:
        # A quartile at inf (a quarter of the instances without a design) runs the band to the top edge.
        q1, q3 = (np.append(row, row[-1]) for row in (front.cost[0], front.cost[2]))
        q1 = np.where(np.isfinite(q1), excess(q1, bottom), np.nan)
        q3 = np.where(np.isfinite(q3), excess(q3, bottom), 1e12)
        ax.fill_between(x, q1, q3, where=np.isfinite(q1), step="post", color=s.colour, alpha=0.08, linewidth=0)
    if front.start is None:
        return None
    k = int(np.searchsorted(front.budgets, front.start))
    if np.nanmin(front.cost[1]) > OFF_SCALE:
        mark_above(ax, front.budgets[k] / scale, s.colour, gid=f"{OFF_SCALE_GID}:{front.label}")
        return f"{front.label} ({np.nanmin(front.cost[1]):.3g})"
    if front.cost[1][k] <= OFF_SCALE:  # a start above the axis has no marker: the line begins lower, later
        ax.plot(front.budgets[k] / scale, excess(front.cost[1][k], bottom), marker=s.marker, color=s.colour,
                linestyle="none", markersize=9 if s.marker == "*" else 6, markerfacecolor=s.face,
                markeredgecolor=s.edge, markeredgewidth=s.edge_width,
                zorder=4 if front.label.startswith("LQR") or front.budgets.size == 1 else 3,
                clip_on=False, gid=method_gid(front.label))
    return None


#: What the legend adds to a method without a usable design on any panel of a figure (:func:`nowhere_usable`).
NOWHERE_SUFFIX = " (no usable design)"


def nowhere_usable(fronts) -> frozenset:
    """The labels whose fronts have no usable design on any panel, where a figure has several panels: the legend
    says so once (:data:`NOWHERE_SUFFIX`), not every panel's title (:func:`title_notes`)."""
    if len({f.panel for f in fronts}) < 2:
        return frozenset()
    labels = {f.label for f in fronts}
    return frozenset(x for x in labels if all(f.covered == 0 for f in fronts if f.label == x))


def title_notes(fronts, above: list[str], width: int = 55, nowhere=frozenset()) -> list[str]:
    """The notes under a panel's title: the fronts above the axis (``above``, as "label (cost)"), and
    the methods with designs on some instances only or on none (but those in ``nowhere``, without a usable
    design on any panel, which the legend names once); the interactive panels carry the same."""
    partial = [f"{f.label} ({f.covered} of {f.instances})" for f in fronts if 0 < f.covered < f.instances]
    missing = [f.label for f in fronts if f.covered == 0 and f.label not in nowhere]
    return [textwrap.fill(f"{head}: " + ", ".join(items), width)
            for head, items in (("above the axis", above), ("designs on some instances only", partial),
                                ("no usable design", missing))
            if items]


def _finish_front_axes(ax, bottom: float, top: float, right: float, per_node: bool) -> None:
    """A budget-front panel's cost and links axes and their labels."""
    excess_axis(ax, bottom, top)
    links_axis(ax, right, per_node=per_node)
    ax.set_xlabel("link budget L per node" if per_node else "link budget L (directed off-diagonal links)",
                  fontsize=TICK_POINTS)
    ax.set_ylabel("best excess cost over LQR", fontsize=TICK_POINTS)
    _panel_type(ax)


def _draw_bound(ax, bound: tuple[float, str], bottom: float) -> None:
    """A lower bound (cost, text) as a dash-dotted horizontal line; the legend names it (:func:`bound_handles`)."""
    value, _ = bound
    ax.axhline(excess(value, bottom), zorder=1, gid=BOUND_GID, **BOUND_STYLE)
