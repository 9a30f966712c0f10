"""Cost against links per method setting (the paper's Fig. 3), drawn only where designs are.

One *setting* is a method label with one set of hyperparameters (one γ of an ℓ1
path, one β of a GRNN-Sparse path) run on every instance of a panel. Its summary
point is the median link count (the lower median, so always a count some design
has) against the median cost. Medians taken separately need not describe any one
design: a β whose designs have 0 links on 17 of 30 instances, and more cost where
they do, has medians (0 links, cost of the others). So the point is drawn only
where it is *reached*, that is where at least one of the setting's designs has
no more links and no more cost; every design is drawn faintly beside it.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .figures import (OFF_SCALE, _y_limits, boundary_handles, draw_boundary, shared_y, excess, excess_axis,
                      finish_legend, legend_handles, links_axis, method_gid, panel_figure, panel_heading)
from .records import as_records
from .styles import Style

__all__ = ["Point", "aggregate", "pareto_front", "plot_cost_vs_links", "quartiles"]


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
    lower median of their link counts (a count some design has); ``reached`` whether
    some design has at most ``x`` links and at most the median cost (the summary point
    describes a design that exists). ``params_key``, the canonical JSON of ``params``,
    orders settings.
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


def aggregate(records) -> list[Point]:
    """Group records by (panel, label, info model, params) into quartile summaries.

    ``records``: :class:`~compare.records.Records`, or dicts shaped like the store's rows.
    """
    groups = as_records(records).group(lambda r: (r.instance.panel, r.label, r.info_model, r.params_key))
    points = []
    for (panel, label, info, params_key), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][3])):
        ok = [r for r in rs if r.ok]
        costs = [r.cost for r in ok]
        x, reached = float("nan"), False
        if ok:
            x = float(np.percentile([r.links for r in ok], 50, method="lower"))
            median = float(np.median(costs))
            reached = any(r.links <= x and r.cost <= median for r in ok)
        points.append(
            Point(
                panel=panel, label=label, info_model=info, params=rs[0].params, params_key=params_key,
                designs=len(rs), ok=len(ok),
                links=quartiles([r.links for r in ok]),
                self_loops=quartiles([r.self_loops for r in rs])[1],
                cost=quartiles(costs),
                cost_mean=float(np.mean(costs)) if costs else float("nan"),
                statuses=dict(Counter(r.status for r in rs)),
                x=x, reached=reached,
            )
        )
    return points


def pareto_front(points: list[Point]) -> list[Point]:
    """The reached points no other reached point beats on both links (``x``) and median cost."""
    ok = sorted((p for p in points if p.reached and np.isfinite(p.cost[1])), key=lambda p: (p.x, p.cost[1]))
    front, best = [], float("inf")
    for p in ok:
        if p.cost[1] < best:
            front.append(p)
            best = p.cost[1]
    return front


def _dodge(series_by_label: dict, right: float) -> dict:
    """Label -> horizontal offset in points for single-setting methods that share an x position.

    LQR, decentralized and autonomous sit at 0 or N(N-1) links, exactly where path
    methods end: without an offset their markers hide each other.
    """
    at = defaultdict(list)
    for label, series in series_by_label.items():
        if len(series) == 1:
            at[round(series[0][0], 6)].append(label)
    crowded = {x for x in at if len(at[x]) > 1 or any(
        len(s) > 1 and any(round(p[0], 6) == x for p in s) for s in series_by_label.values())}
    offsets = {}
    for x in crowded:
        group = sorted(at[x])
        for i, label in enumerate(group):
            offsets[label] = 7.0 * (i - (len(group) - 1) / 2) + (6.0 if x == 0 else -6.0 if x >= right else 0.0)
    return offsets


def _mark_off_scale(ax, marks, top: float) -> int:
    """A triangle on the top edge and the median cost below it for each (x, cost, colour) above the axis.

    Labels closer than about 30 points to the previous one in a row go one row lower; a
    label at either edge of the axes extends inwards. Returns the number of label rows.
    """
    labels: dict[tuple, list[str]] = {}  # (x, text) -> colours: methods sharing a value get one label
    for x, cost, colour in sorted(marks):
        ax.plot(x, top, marker="^", color=colour, markersize=8, clip_on=False, linestyle="none", zorder=5)
        labels.setdefault((x, f"{cost:.3g}"), []).append(colour)
    rows: list[float] = []
    left, right = (v * 72.0 / ax.figure.dpi for v in ax.transAxes.transform([(0, 0), (1, 0)])[:, 0])
    for (x, text), colours in labels.items():
        px = ax.transData.transform((x, top))[0] * 72.0 / ax.figure.dpi
        row = next((i for i, last in enumerate(rows) if px - last >= 30.0), len(rows))
        rows[row:row + 1] = [px]
        ha, dx = ("right", 5) if right - px < 20 else ("left", -5) if px - left < 20 else ("center", 0)
        ax.annotate(f"J = {text}" if row == 0 and len(labels) == 1 else text, (x, top), xytext=(dx, -4 - 9 * row),
                    textcoords="offset points", ha=ha, va="top", fontsize=7,
                    color=colours[0] if len(set(colours)) == 1 else "0.25", zorder=6,
                    bbox={"boxstyle": "square,pad=0.1", "facecolor": "white", "edgecolor": "none", "alpha": 0.85})
    return len(rows)


def plot_cost_vs_links(points: list[Point], *, records=None, axes=None, styles: dict | None = None,
                       boundaries: dict | None = None, instances: dict | None = None):
    """Median cost against median links per design setting, one panel per (family, N, ‖A‖₂).

    Every usable design is a faint dot (when ``records`` are given); a setting's
    summary marker is drawn only where :attr:`Point.reached`; settings of one
    method are joined in the line style of its information model. Costs are excess
    costs over centralized LQR on a log axis (:func:`compare.figures.excess_axis`);
    medians above :data:`~compare.figures.OFF_SCALE` times LQR's are triangles on
    the top edge with their value. With several N the x axis is links per node.

    Parameters
    ----------
    points : list of Point
        From :func:`aggregate`.
    records : Records, optional
        The designs behind ``points``, drawn faintly.
    axes : dict, optional
        Panel -> Axes; a new figure is made if omitted.
    styles : dict, optional
        Label -> :class:`compare.styles.Style` (:func:`compare.styles.label_styles`).
    boundaries : dict, optional
        Panel -> plant-graph link count, drawn as the QI boundary when a delayed method is present.
    instances : dict, optional
        Panel -> number of instances, for the panel titles.

    Returns
    -------
    fig, axes
    """
    from matplotlib.transforms import offset_copy

    panels = sorted({p.panel for p in points})
    labels = sorted({p.label for p in points})
    styles = styles or {p.label: Style("#333333", "o", p.info_model) for p in points}
    fig, axes, own = panel_figure(panels, axes)
    per_node = len({p[1] for p in panels}) > 1
    designs = as_records(records).by_panel if records is not None else {}

    def shown_costs(group):
        return [p.cost[1] for p in group if p.ok and p.reached and p.cost[1] <= OFF_SCALE]

    limits = _y_limits(shown_costs(points)) if shared_y(panels) else None
    for panel in panels:
        ax = axes[panel]
        usable = [p for p in points if p.panel == panel and p.ok > 0]
        if not usable:
            continue
        scale = panel[1] if per_node and panel[1] else 1.0  # links per node; 0: a family without n
        bottom, top = limits or _y_limits(shown_costs(usable))
        right = max(p.links[2] for p in usable) / scale
        for label, rs in (designs[panel].by_label.items() if panel in designs else ()):
            ok = [r for r in rs if r.ok]
            if ok:
                s = styles[label]
                ax.scatter([r.links / scale for r in ok], excess([r.cost for r in ok], bottom), s=7, color=s.colour,
                           marker=s.marker, alpha=0.18, linewidths=0, zorder=1)
        series = {label: sorted((p.x / scale, p.cost[1]) for p in usable if p.label == label and p.reached)
                  for label in labels}
        offsets = _dodge({k: v for k, v in series.items() if v}, right)
        off_scale = []
        for label in labels:
            if not series[label]:
                continue
            s = styles[label]
            x = np.array([v[0] for v in series[label]])
            y = np.array([v[1] for v in series[label]])
            transform = ax.transData
            if label in offsets:
                transform = offset_copy(ax.transData, fig=fig, x=offsets[label], units="points")
            inside = y <= OFF_SCALE
            off_scale += [(xi, yi, s.colour) for xi, yi in zip(x[~inside], y[~inside])]
            if not inside.any():
                continue  # an empty line drawn unclipped would sit at the figure's origin and spoil the layout
            ax.plot(x[inside], excess(y[inside], bottom), color=s.colour, marker=s.marker,
                    linestyle=s.linestyle if inside.sum() > 1 else "none", markersize=(6.5 if len(x) == 1 else 5.5) * (1.5 if s.marker == "*" else 1),
                    markerfacecolor=s.face, markeredgecolor=s.edge,
                    markeredgewidth=s.edge_width, linewidth=1.3, transform=transform,
                    # Single-setting methods over the paths whose ends they share (decentralized = γ = ∞).
                    zorder=6 if label.startswith("LQR") else 5 if len(x) == 1 else 4, clip_on=False,
                    gid=method_gid(label))
        excess_axis(ax, bottom, top * 1.3)
        links_axis(ax, right, per_node=per_node)
        # On the axis's own top edge: where every shown cost is within 0.8 % of LQR's, top * 1.3 lies
        # below it (or at or below 0, far off a log axis, which blew a figure up to 390,000 px).
        if off_scale:
            _mark_off_scale(ax, off_scale, ax.get_ylim()[1])
        ax.set_xlabel("directed off-diagonal links per node (median)" if per_node
                      else "directed off-diagonal links (median)")
        ax.set_ylabel("excess cost over LQR")
        ax.set_title(panel_heading(panel, (instances or {}).get(panel)), fontsize=10)
        if boundaries and panel in boundaries and any(p.info_model == "delayed" for p in usable):
            draw_boundary(ax, boundaries[panel] / scale)
        ax.grid(True, which="major", alpha=0.3)
    if own:
        finish_legend(fig, legend_handles(styles, labels) + boundary_handles(axes.values()),
                      title="marker: median over instances\nfaint: every instance's design")
    return fig, axes

