"""Figure conventions shared by the report's figures, and the budget-front figure.

Every method is drawn in its own colour and marker (:mod:`compare.report.styles`, the same
in every figure of every report) and with its information model's line style.
Costs are shown as *excess cost* J/J_LQR − 1 on a log axis, in percent, so that a
design 0.1 % above centralized LQR and one 30 % above it are both readable (lqrsp
plots its percent performance loss the same way); centralized LQR is the 0 % the
axis is measured from, and designs within :data:`FLOOR` of it sit on the bottom edge.
"""

from __future__ import annotations

import textwrap
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # noqa: E402

from .statistics import panel_title  # noqa: E402
from .styles import BOUND_COLOUR, INFO_MODELS, INFO_ORDER, Style, label_styles  # noqa: E402

__all__ = ["LINESTYLES", "OFF_SCALE", "FLOOR", "excess", "excess_axis", "panel_grid", "panel_heading",
           "legend_handles", "finish_legend", "draw_boundary", "boundary_handles", "plot_budget_fronts",
           "label_styles", "method_gid", "front_gid", "draw_front_line", "drawn_styles", "axis_floor", "panel_figure",
           "y_limits"]

#: Line style and description per information model (from :data:`compare.report.styles.INFO_MODELS`).
LINESTYLES = {info: (style, text) for info, (style, _, text) in INFO_MODELS.items()}
#: Costs above this many times centralized LQR's are off the interesting range:
#: the axis stops there and the figure says which methods lie above.
OFF_SCALE = 2.0
#: Excess costs below this (0.1 %) are drawn on the axis' bottom edge: that close to LQR.
FLOOR = 1e-3


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


def excess_axis(ax, low: float, high: float) -> None:
    """Log y-axis of excess cost on [low, high] (fractions), labelled in percent."""
    low, high = max(low, FLOOR), max(high, FLOOR * 10)
    ax.set_yscale("log")
    decades = np.log10(high / low)
    ax.yaxis.set_major_locator(LogLocator(subs=(1.0,) if decades > 3.2 else (1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(FuncFormatter(_percent))
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_ylim(low, high)


def method_gid(label: str) -> str:
    """The gid set on every artist drawn for a method, so that tests and tools can find what was drawn."""
    return f"method:{label}"


def front_gid(label: str) -> str:
    """The gid of a method's budget-front line, so that tests read the curves a figure draws."""
    return f"front:{label}"


def draw_front_line(ax, front, style, bottom: float, right: float, scale: float = 1.0, *, linewidth: float = 1.5):
    """A front's median as a step line to the right edge (``right`` links); gaps where it is not defined.

    Its last step holds to ``right * 1.15 + 1`` links, where the links axis ends. Returns
    ``(x, y)`` as drawn (y the excess cost, NaN in the gaps).
    """
    x = np.append(front.budgets, max(right, front.budgets[-1]) * 1.15 + 1) / scale
    median = np.append(front.cost[1], front.cost[1][-1])
    y = np.where(np.isfinite(median), excess(median, bottom), np.nan)
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
    return panel_title(panel) + (f" · {instances} instances" if instances else "")


def shared_y(panels) -> bool:
    """Whether :func:`panel_grid` lays the panels out as rows = N, columns = ‖A‖₂ (one cost axis for all)."""
    sizes = {p[1] for p in panels}
    norms = {p[2] for p in panels}
    return len(sizes) > 1 and len(norms) > 1 and None not in norms


def y_limits(shown) -> tuple[float, float]:
    """(bottom, top) of an excess-cost axis showing the costs ``shown`` (all at most OFF_SCALE)."""
    shown = np.asarray(shown, dtype=float)
    return axis_floor(shown), (float(shown.max()) if shown.size else OFF_SCALE) - 1.0


def panel_grid(panels, *, width: float = 4.6, height: float = 3.9):
    """Axes for the panels: rows = N and columns = ‖A‖₂ when both vary (shared y), else up to 3 columns.

    Returns ``fig, axes`` (panel -> Axes); the legend goes to the right of the panels (:func:`finish_legend`).
    """
    panels = sorted(panels)
    sizes = sorted({p[1] for p in panels})
    norms = sorted({p[2] for p in panels if p[2] is not None})
    if shared_y(panels):
        fig, grid = plt.subplots(len(sizes), len(norms), figsize=(width * len(norms), height * len(sizes)),
                                 squeeze=False)
        axes = {}
        for i, n in enumerate(sizes):
            for j, a in enumerate(norms):
                panel = next((p for p in panels if p[1] == n and p[2] == a), None)
                if panel is None:
                    grid[i, j].set_axis_off()
                else:
                    axes[panel] = grid[i, j]
        return fig, axes
    ncols = min(3, max(1, len(panels)))
    nrows = -(-max(1, len(panels)) // ncols)
    fig, grid = plt.subplots(nrows, ncols, squeeze=False, figsize=(width * ncols, height * nrows))
    flat = [grid[i, j] for i in range(nrows) for j in range(ncols)]
    for extra in flat[len(panels):]:
        extra.set_axis_off()
    return fig, dict(zip(panels, flat))


def panel_figure(panels, axes=None):
    """``(fig, axes, own)``: a new :func:`panel_grid` (own = True), or the figure of the panel -> Axes given."""
    if axes is None:
        return (*panel_grid(panels), True)
    return next(iter(axes.values())).figure, axes, False


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
                                  markersize=6, markerfacecolor=getattr(s, "face", s.colour), label=lb))
    return handles


def _style(styles: dict, label: str) -> Style:
    s = styles[label]
    return s if isinstance(s, Style) else Style(s[0], s[1])


def finish_legend(fig, handles, *, title: str | None = None) -> None:
    """Lay the panels out, then the legend to their right; headings (entries without a line) in bold.

    The saved figure's tight bounding box takes the legend in.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Tight layout not applied")
        fig.tight_layout()
    legend = fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 0.98), frameon=False, fontsize=8.5,
                        title=title, title_fontsize=9, handlelength=2.6, alignment="left")
    for handle, text in zip(legend.legend_handles, legend.get_texts()):
        if handle.get_linestyle() in ("None", "none") and handle.get_marker() in ("None", "none", None, ""):
            text.set_fontweight("bold")


#: How the QI boundary is drawn, on the panels and in the legend.
BOUNDARY_STYLE = {"color": "0.35", "linestyle": (0, (1, 2)), "linewidth": 1.0}
BOUNDARY_LABEL = "QI boundary (plant-graph links)"
BOUNDARY_GID = "qi-boundary"


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


def links_axis(ax, right: float, *, per_node: bool = False) -> None:
    """Symmetric-log x axis of links from 0 to ``right``."""
    ax.set_xscale("symlog", linthresh=1.0 if not per_node else 0.1)
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.set_xlim(-0.04 if per_node else -0.4, right * 1.15 + (0.1 if per_node else 1))


def plot_budget_fronts(fronts, *, axes=None, styles: dict | None = None, boundaries: dict | None = None,
                       bounds: dict | None = None):
    """Best cost within each link budget: median over instances (step curve) and 25–75 % band.

    A front starts at the budget where more than half of the instances the method ran
    on have a design within it (:attr:`compare.report.statistics.Front.start`), marked by the
    method's marker; the band spans the 25–75 % quantiles over those instances (spread
    across instances, not uncertainty of the median; an instance without a design within
    the budget counts as above every design, so the band runs to the top edge while a
    quarter of them or more have none). Costs are excess costs over centralized LQR on a
    log axis (:func:`excess_axis`).

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
        Panel -> (cost, text): a lower bound drawn as a horizontal line.

    Returns
    -------
    fig, axes
    """
    panels = sorted({f.panel for f in fronts})
    labels = sorted({f.label for f in fronts})
    styles = styles or {f.label: Style("#333333", "o", f.info_model) for f in fronts}
    fig, axes, own = panel_figure(panels, axes)
    per_node = len({p[1] for p in panels}) > 1

    limits = y_limits(_shown_costs(fronts, bounds)) if shared_y(panels) else None
    for panel in panels:
        _draw_panel(axes[panel], panel, [f for f in fronts if f.panel == panel], styles, limits=limits,
                    per_node=per_node, boundaries=boundaries, bounds=bounds)
    if own:
        finish_legend(fig, legend_handles(styles, labels) + boundary_handles(axes.values()),
                      title="median over instances; band 25–75 %")
    return fig, axes


def _draw_panel(ax, panel: tuple, fronts, styles: dict, *, limits, per_node: bool, boundaries: dict | None,
                bounds: dict | None) -> None:
    """One panel: each front with its band and start, its axes, a title that names what is not drawn, the bound
    and the QI boundary. A panel none of whose fronts has a finite median stays empty.

    ``limits`` is the (bottom, top) every panel shares, if they share one.
    """
    scale = panel[1] if per_node and panel[1] else 1.0  # links per node; 0: a family without n
    right = max(float(f.budgets[-1]) for f in fronts) / scale
    if not any(np.isfinite(f.cost[1]).any() for f in fronts):
        return
    bottom, top = limits or y_limits(_shown_costs(fronts, bounds))
    above = [_draw_front(ax, f, _style(styles, f.label), bottom, top, right, scale) for f in fronts]
    _finish_front_axes(ax, bottom, top, right, per_node)
    notes = _title_notes(fronts, [note for note in above if note is not None])
    ax.set_title("\n".join([panel_heading(panel, max(f.instances for f in fronts))] + notes),
                 fontsize=9 if notes else 10)
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


def _draw_front(ax, front, s: Style, bottom: float, top: float, right: float, scale: float) -> str | None:
    """A front's median step line, its 25–75 % band and its marker where it starts.

    Returns the note that names the front above the axis where its lowest median is
    above OFF_SCALE (then it has no marker), else None.
    """
    # Not started (inf) leaves a gap, not a line off the axis.
    x, _ = draw_front_line(ax, front, s, bottom, right * scale, scale)
    # A quartile at inf (a quarter of the instances without a design) runs the band to the top edge.
    q1, q3 = (np.append(row, row[-1]) for row in (front.cost[0], front.cost[2]))
    q1 = np.where(np.isfinite(q1), excess(q1, bottom), np.nan)
    q3 = np.where(np.isfinite(q3), excess(q3, bottom), 1e12)
    ax.fill_between(x, q1, q3, where=np.isfinite(q1), step="post", color=s.colour, alpha=0.08, linewidth=0)
    if front.start is None:
        return None
    if np.nanmin(front.cost[1]) > OFF_SCALE:
        return f"{front.label} ({np.nanmin(front.cost[1]):.3g})"
    k = int(np.searchsorted(front.budgets, front.start))
    ax.plot(front.budgets[k] / scale, excess(front.cost[1][k], bottom), marker=s.marker, color=s.colour,
            linestyle="none", markersize=9 if s.marker == "*" else 6, markerfacecolor=s.face,
            markeredgecolor=s.edge, markeredgewidth=s.edge_width,
            zorder=4 if front.label.startswith("LQR") or front.budgets.size == 1 else 3,
            clip_on=bool(front.cost[1][k] - 1.0 > top * 1.25), gid=method_gid(front.label))
    return None


def _title_notes(fronts, above: list[str]) -> list[str]:
    """The notes under a panel's title: the fronts above the axis (``above``, from :func:`_draw_front`), and
    the methods with designs on some instances only or on none."""
    partial = [f"{f.label} ({f.covered} of {f.instances})" for f in fronts if 0 < f.covered < f.instances]
    missing = [f.label for f in fronts if f.covered == 0]
    return [textwrap.fill(f"{head}: " + ", ".join(items), 60)
            for head, items in (("above the axis", above), ("designs on some instances only", partial),
                                ("no usable design", missing))
            if items]


def _finish_front_axes(ax, bottom: float, top: float, right: float, per_node: bool) -> None:
    """A budget-front panel's cost and links axes and their labels."""
    excess_axis(ax, bottom, top * 1.25)
    links_axis(ax, right, per_node=per_node)
    ax.set_xlabel("link budget L per node" if per_node else "link budget L (directed off-diagonal links)")
    ax.set_ylabel("best excess cost over LQR")


def _draw_bound(ax, bound: tuple[float, str], bottom: float) -> None:
    """A lower bound (cost, text) as a dash-dotted horizontal line, named at the axis' left edge."""
    value, text = bound
    ax.axhline(excess(value, bottom), color=BOUND_COLOUR, linewidth=1.0, linestyle=(0, (4, 2, 1, 2)), zorder=1)
    ax.text(0.01, excess(value, bottom), f" {text}", transform=ax.get_yaxis_transform(), ha="left", va="top",
            fontsize=7)
