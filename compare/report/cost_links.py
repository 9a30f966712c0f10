"""Cost against links per method setting (the paper's Fig. 3), drawn only where designs are.

One *setting* is a method label with one set of hyperparameters (one γ of an ℓ1
path, one β of a GRNN-Sparse path) run on every instance of a panel. Its summary
point is the median link count (the lower median, so always a count some design
has) against the median cost. Medians taken separately are not paired and need not
describe the typical instance: a β whose designs have 0 links on 17 of 30 instances,
and more cost where they do, has medians (0 links, cost of the others). So the point
is drawn only where it lies on or above its method's budget front at its link count
(the median over instances of the best cost within that many links, the paired
quantity the findings test): then at least half of the instances the method ran on
reach it, that is some design of the method there has no more links and no more
cost. A marker never stands below its own method's front. Every design is drawn
faintly beside it, and the fronts are drawn through the cloud.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .figures import (COST_PAD, OFF_SCALE, TICK_POINTS, TITLE_POINTS, boundary_handles, cost_range,
                      draw_boundary, draw_front_line, excess, excess_axis, finish_legend, legend_handles, links_axis,
                      mark_above, method_gid, panel_figure, panel_heading, panel_order, per_node_axis, shared_y)
from ..run.records import as_records
from .statistics import best_within, front_quantiles
from .styles import Style

__all__ = ["Point", "aggregate", "pareto_front", "plot_cost_vs_links", "quartiles", "REACH_SHARE", "axis_costs",
           "settings_drawn"]

#: A summary point is drawn only where at least this share of its instances reach it.
REACH_SHARE = 0.5


def quartiles(values) -> tuple[float, float, float]:
    """(25th percentile, median, 75th percentile) of the finite values; NaNs if none."""
    finite = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    if finite.size == 0:
        return (float("nan"),) * 3
    q1, med, q3 = np.percentile(finite, [25, 50, 75])
    return float(q1), float(med), float(q3)


@dataclass(frozen=True)
class Point:
    """One design setting (label + hyperparameters) aggregated over instances.

    ``links`` and ``cost`` are (25 %, median, 75 %) over the usable designs; ``x`` the
    lower median of their link counts (a count some design has); ``reach`` the share of
    the instances the method ran on in the panel where some design of the method has at
    most ``x`` links and at most the median cost; ``reached`` whether the median cost is
    at or above the method's budget front at ``x`` (so that ``reach`` is at least
    :data:`REACH_SHARE`, and the marker never stands below the front it summarizes: the
    point is drawn). ``params_key``, the canonical JSON of ``params``, orders settings.
    """

    panel: tuple
    label: str
    info_model: str
    params: Mapping
    params_key: str
    designs: int
    ok: int
    links: tuple[float, float, float]
    self_loops: float
    cost: tuple[float, float, float]
    cost_mean: float
    statuses: dict
    x: float = float("nan")
    reached: bool = False
    reach: float = 0.0


def aggregate(records) -> list[Point]:
    """Group records by (panel, label, info model, params) into quartile summaries.

    ``records``: :class:`~compare.run.records.Records`, or dicts shaped like the store's rows.
    """
    records = as_records(records)
    groups = records.group(lambda r: (r.instance.panel, r.label, r.info_model, r.params_key))
    methods = records.by_panel_label
    points = []
    for (panel, label, info, params_key), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][3])):
        ok = [r for r in rs if r.ok]
        costs = [r.cost for r in ok]
        x, reach, median, front = float("nan"), 0.0, float("nan"), float("inf")
        if ok:
            x = float(np.percentile([r.links for r in ok], 50, method="lower"))
            median = float(np.median(costs))
            method = methods[(panel, label)]
            hits = {r.instance.key for r in method if r.ok and r.links <= x and r.cost <= median}
            reach = len(hits) / len(method.by_instance)
            front = _front_at(method, x)
        points.append(
            Point(
                panel=panel, label=label, info_model=info, params=rs[0].params, params_key=params_key,
                designs=len(rs), ok=len(ok),
                links=quartiles([r.links for r in ok]),
                self_loops=quartiles([r.self_loops for r in rs])[1],
                cost=quartiles(costs),
                cost_mean=float(np.mean(costs)) if costs else float("nan"),
                statuses=dict(Counter(r.status for r in rs)),
                x=x, reached=median >= front * (1 - 1e-12), reach=reach,
            )
        )
    return points


def _front_at(method, links: float) -> float:
    """The method's budget front at ``links`` (:func:`compare.report.statistics.budget_fronts`' median there)."""
    best = best_within(method, sorted(method.by_instance), [links])
    return float(front_quantiles(best)[0][1, 0])


def axis_costs(points: list[Point], fronts) -> list[float]:
    """The costs a cost-versus-links axis must show: drawn setting medians and front medians, up to OFF_SCALE.

    The static figure and the interactive one take their cost axes from this one list, so
    that both clip alike.
    """
    costs = [p.cost[1] for p in points if p.ok and p.reached]
    costs += [c for f in fronts for c in f.cost[1] if np.isfinite(c)]
    return [c for c in costs if c <= OFF_SCALE]


def settings_drawn(points: list[Point]) -> str:
    """How many of the settings with a usable design have a marker ("55 of 319 settings"): the others lie below
    their method's front (the medians table lists every setting)."""
    usable = [p for p in points if p.ok]
    drawn = sum(p.reached for p in usable)
    return f"all {drawn} settings" if drawn == len(usable) else f"{drawn} of {len(usable)} settings"


def pareto_front(points: list[Point]) -> list[Point]:
    """The reached points no other reached point beats on both links (``x``) and median cost."""
    ok = sorted((p for p in points if p.reached and np.isfinite(p.cost[1])), key=lambda p: (p.x, p.cost[1]))
    front, best = [], float("inf")
    for p in ok:
        if p.cost[1] < best:
            front.append(p)
            best = p.cost[1]
    return front


def _dodge(series_by_label: dict, y_points=None) -> dict:
    """Label -> horizontal offset in points for single-setting methods that share an x position.

    Autonomous and decentralized both sit at 0 links: without an offset one hides the
    other. The offsets are symmetric about the true link count, and a method alone at its
    count is never moved (LQR once stood 6 points left of its 380 links, which on a log
    axis read as about 230, left of the QI boundary). With ``y_points`` (cost -> its height
    in points on the axis) only markers that would touch are moved: LQR on the bottom edge
    stays at its link count below the SLS designs that share it. :func:`_inside` then keeps
    a group within its axes.
    """
    at = defaultdict(list)
    for label, series in series_by_label.items():
        if len(series) == 1:
            at[round(series[0][0], 6)].append(label)
    offsets = {}
    for group in at.values():
        for cluster in _touching(group, series_by_label, y_points):
            if len(cluster) > 1:
                for i, label in enumerate(sorted(cluster)):
                    offsets[label] = _DODGE * (i - (len(cluster) - 1) / 2)
    return offsets


def _touching(labels: list, series_by_label: dict, y_points) -> list[list]:
    """``labels`` (single settings at one link count) in clusters of markers less than a marker apart in height."""
    if y_points is None:
        return [labels]
    ordered = sorted(labels, key=lambda lb: y_points(series_by_label[lb][0][1]))
    clusters: list[list] = []
    for label in ordered:
        y = y_points(series_by_label[label][0][1])
        if clusters and y - y_points(series_by_label[clusters[-1][-1]][0][1]) < _DODGE:
            clusters[-1].append(label)
        else:
            clusters.append([label])
    return clusters


#: Points between the markers of single-setting methods at one link count, and the room a marker needs from
#: an edge of its axes (its radius and its edge line).
_DODGE, _MARKER_ROOM = 7.0, 5.0


def _inside(ax, offsets: dict, series_by_label: dict) -> dict:
    """``offsets`` with each group of dodged markers moved inwards where its outer markers would leave the axes.

    SLS on the plant, plant² and plant³ graphs and on the complete graph all sit at the last link count, where
    symmetric offsets put the hexagons outside the frame on every tradeoff panel.
    """
    groups = defaultdict(list)
    for label, offset in offsets.items():
        groups[round(series_by_label[label][0][0], 6)].append(label)
    width = ax.get_window_extent().width * 72.0 / ax.figure.dpi  # the axes' width in points, as laid out now
    out = dict(offsets)
    for x, labels in groups.items():
        at = (ax.transLimits.transform(ax.transScale.transform((x, 1.0)))[0]) * width  # points from the left edge
        low, high = min(out[lb] for lb in labels), max(out[lb] for lb in labels)
        shift = min(0.0, width - _MARKER_ROOM - (at + high)) + max(0.0, _MARKER_ROOM - (at + low))
        for lb in labels:
            out[lb] += shift
    return out


def _mark_off_scale(ax, marks, top: float) -> int:
    """A triangle on the top edge and the median cost above it for each (x, cost, colour) above the axis.

    The values are written above the axes' frame, under the title, where no line is drawn (inside the axes,
    fronts struck "J = 5.18" through). Labels closer than about 30 points to the previous one in a row go
    one row higher; a label at either edge of the axes extends inwards. Returns the number of label rows.
    """
    labels: dict[tuple, list[str]] = {}  # (x, text) -> colours: methods sharing a value get one label
    for x, cost, colour in sorted(marks):
        mark_above(ax, x, colour)
        labels.setdefault((x, f"{cost:.3g}"), []).append(colour)
    rows: list[float] = []
    left, right = (v * 72.0 / ax.figure.dpi for v in ax.transAxes.transform([(0, 0), (1, 0)])[:, 0])
    for (x, text), colours in labels.items():
        px = ax.transData.transform((x, top))[0] * 72.0 / ax.figure.dpi
        row = next((i for i, last in enumerate(rows) if px - last >= 30.0), len(rows))
        rows[row:row + 1] = [px]
        ha, dx = ("right", 5) if right - px < 20 else ("left", -5) if px - left < 20 else ("center", 0)
        ax.annotate(f"J = {text}" if row == 0 and len(labels) == 1 else text, (x, 1.0),
                    xycoords=ax.get_xaxis_transform(), xytext=(dx, _ABOVE + _ROW * row), textcoords="offset points",
                    ha=ha, va="bottom", fontsize=MIN_TEXT, color=colours[0] if len(set(colours)) == 1 else "0.25",
                    zorder=6, annotation_clip=False)
    return len(rows)


#: Points from the top edge to the first row of off-scale values (above the triangle), and between rows.
_ABOVE, _ROW = 6.0, 10.0
#: The smallest type of this figure (the off-scale values), in points.
MIN_TEXT = 8.0


def plot_cost_vs_links(points: list[Point], *, records=None, axes=None, styles: dict | None = None,
                       boundaries: dict | None = None, instances: dict | None = None, fronts=None):
    """Every design, each method's budget front through them, and its settings' medians, one panel per (family, N, ‖A‖₂).

    Every usable design is a faint dot (when ``records`` are given); each method's
    budget front (:func:`compare.report.statistics.budget_fronts`: per instance the best cost
    within L links, then the median over instances) is a step line in the line style
    of its information model; a setting's summary marker is drawn, unconnected, only
    where :attr:`Point.reached` (on or above its method's front). Costs are
    excess costs over centralized LQR on a log axis
    (:func:`compare.report.figures.excess_axis`); medians above
    :data:`~compare.report.figures.OFF_SCALE` times LQR's are triangles on the top edge with
    their value. With several N the x axis is links per node.

    Parameters
    ----------
    points : list of Point
        From :func:`aggregate`.
    records : Records, optional
        The designs behind ``points``, drawn faintly, and their fronts (unless ``fronts`` is given).
    axes : dict, optional
        Panel -> Axes; a new figure is made if omitted.
    styles : dict, optional
        Label -> :class:`compare.report.styles.Style` (:func:`compare.report.styles.label_styles`).
    boundaries : dict, optional
        Panel -> plant-graph link count, drawn as the QI boundary when a delayed method is present.
    instances : dict, optional
        Panel -> number of instances, for the panel titles.
    fronts : list of :class:`compare.report.statistics.Front`, optional
        The fronts to draw; by default those of ``records`` (none without records).

    Returns
    -------
    fig, axes
    """
    from .statistics import budget_fronts

    panels = panel_order({p.panel for p in points})
    labels = sorted({p.label for p in points})
    styles = styles or {p.label: Style("#333333", "o", p.info_model) for p in points}
    fig, axes, own = panel_figure(panels, axes)
    per_node = per_node_axis(panels)
    designs = as_records(records).by_panel if records is not None else {}
    if fronts is None:
        fronts = budget_fronts(records) if records is not None else []

    limits = cost_range(axis_costs(points, fronts), COST_PAD) if shared_y(panels) else None
    for panel in panels:
        ax = axes[panel]
        usable = [p for p in points if p.panel == panel and p.ok > 0]
        if usable:
            _draw_panel(fig, ax, panel, usable, fronts, designs.get(panel), styles=styles, labels=labels,
                        limits=limits, per_node=per_node, boundaries=boundaries, instances=instances)
    if own:
        finish_legend(fig, legend_handles(styles, labels) + boundary_handles(axes.values()),
                      title="line: median over instances of the best\ncost within L links (budget front)\n"
                            "marker: one setting's medians, where on\nor above its method's front "
                            f"({settings_drawn(points)})\nfaint: every instance's design")
    return fig, axes


def _draw_panel(fig, ax, panel: tuple, usable: list[Point], fronts, designs, *, styles: dict, labels: list[str],
                limits, per_node: bool, boundaries: dict | None, instances: dict | None) -> None:
    """One panel: its designs, each method's front through them, the settings' medians, its axes, the QI boundary.

    ``usable`` are the panel's points with a usable design, ``designs`` its records (None
    without records), ``limits`` the (bottom, top) every panel shares, if they share one.
    """
    mine = {f.label: f for f in fronts if f.panel == panel}
    scale = panel[1] if per_node and panel[1] else 1.0  # links per node; 0: a family without n
    bottom, top = limits or cost_range(axis_costs(usable, mine.values()), COST_PAD)
    right = max(p.links[2] for p in usable) / scale
    _finish_axes(ax, bottom, top, right, per_node)  # first: the markers are kept inside the axes as laid out
    if designs is not None:
        _draw_designs(ax, designs, styles, scale, bottom)
    for label, f in sorted(mine.items()):
        draw_front_line(ax, f, styles[label], bottom, right * scale, scale)
    off_scale = _draw_settings(fig, ax, usable, labels, styles, scale, bottom)
    rows = _mark_off_scale(ax, off_scale, ax.get_ylim()[1]) if off_scale else 0
    # The title clears the off-scale values written above the frame.
    ax.set_title(panel_heading(panel, (instances or {}).get(panel)), fontsize=TITLE_POINTS,
                 pad=6 + (_ABOVE + _ROW * rows if rows else 0))
    if boundaries and panel in boundaries and any(p.info_model == "delayed" for p in usable):
        draw_boundary(ax, boundaries[panel] / scale)
    ax.grid(True, which="major", alpha=0.3)


def _draw_designs(ax, designs, styles: dict, scale: float, bottom: float) -> None:
    """Every usable design of a panel as a faint dot in its method's colour and marker."""
    for label, rs in designs.by_label.items():
        ok = [r for r in rs if r.ok]
        if ok:
            s = styles[label]
            ax.scatter([r.links / scale for r in ok], excess([r.cost for r in ok], bottom), s=7, color=s.colour,
                       marker=s.marker, alpha=0.18, linewidths=0, zorder=1)


def _draw_settings(fig, ax, usable: list[Point], labels: list[str], styles: dict, scale: float,
                   bottom: float) -> list[tuple]:
    """Each method's reached settings' medians as unconnected markers; returns the (x, cost, colour) above the axis.

    Single-setting methods that share a link count are moved apart (:func:`_dodge`).
    """
    from matplotlib.transforms import offset_copy

    series = {label: sorted((p.x / scale, p.cost[1]) for p in usable if p.label == label and p.reached)
              for label in labels}
    drawn = {k: v for k, v in series.items() if v}
    dpi = ax.figure.dpi

    def y_points(cost):  # a cost's height on the axis in points, as drawn (above the axis: on its top edge)
        value = min(excess(min(cost, OFF_SCALE), bottom), ax.get_ylim()[1])
        return ax.transData.transform((1.0, value))[1] * 72.0 / dpi

    offsets = _inside(ax, _dodge(drawn, y_points), drawn)
    off_scale = []
    for label in labels:
        if not series[label]:
            continue
        transform = ax.transData
        if label in offsets:
            transform = offset_copy(ax.transData, fig=fig, x=offsets[label], units="points")
        off_scale += _draw_setting_markers(ax, label, series[label], styles[label], bottom, transform)
    return off_scale


def _draw_setting_markers(ax, label: str, series: list[tuple], s: Style, bottom: float, transform) -> list[tuple]:
    """One method's (x, median cost) markers up to OFF_SCALE; returns the (x, cost, colour) above it."""
    x = np.array([v[0] for v in series])
    y = np.array([v[1] for v in series])
    inside = y <= OFF_SCALE
    off_scale = [(xi, yi, s.colour) for xi, yi in zip(x[~inside], y[~inside])]
    if not inside.any():
        return off_scale  # an empty line drawn unclipped would sit at the figure's origin and spoil the layout
    ax.plot(x[inside], excess(y[inside], bottom), color=s.colour, marker=s.marker, linestyle="none",
            markersize=(6.5 if len(x) == 1 else 5.5) * (1.5 if s.marker == "*" else 1),
            markerfacecolor=s.face, markeredgecolor=s.edge,
            markeredgewidth=s.edge_width, transform=transform,
            # Single-setting methods over the paths whose ends they share (decentralized = γ = ∞).
            zorder=6 if label.startswith("LQR") else 5 if len(x) == 1 else 4, clip_on=False,
            gid=method_gid(label))
    return off_scale


def _finish_axes(ax, bottom: float, top: float, right: float, per_node: bool) -> None:
    """A panel's cost and links axes and their labels.

    What lies above the cost axis is marked on its own top edge afterwards (:func:`_mark_off_scale`, at
    ``ax.get_ylim()[1]``): where every shown cost is within 0.8 % of LQR's, the top lies below
    ``top`` (or at or below 0, far off a log axis, which blew a figure up to 390,000 px).
    """
    excess_axis(ax, bottom, top)
    links_axis(ax, right, per_node=per_node)
    ax.set_xlabel("directed off-diagonal links per node" if per_node else "directed off-diagonal links",
                  fontsize=TICK_POINTS)
    ax.set_ylabel("excess cost over LQR", fontsize=TICK_POINTS)
    ax.tick_params(axis="both", labelsize=TICK_POINTS)
