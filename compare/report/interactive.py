"""Interactive (plotly) versions of the report's two panel figures, for the HTML page.

The static PNG/SVG figures (:func:`compare.report.cost_links.plot_cost_vs_links`,
:func:`compare.report.figures.plot_budget_fronts`) stay the reference, and these draw what
they draw: every design faintly, each method's budget front as a step line in its
information model's dash, the settings' medians where they lie on or above
their method's front, so that at least half of the instances reach them (unconnected), the QI
boundary, excess costs on a log axis clipped as the static axis is clipped (one rule:
:func:`compare.report.figures.cost_range`). A page adds what paper cannot: hovering a
point names the design (instance, hyperparameters, cost ± standard error), clicking
a method in the legend hides it in every panel, and two buttons switch the cost
axes between log and linear (both keep the clip).

The figure, as data
-------------------
:func:`cost_links_figure` and :func:`budget_fronts_figure` return one
:class:`plotly.graph_objects.Figure` with a subplot per panel; a test can recover
every link count and cost from its plotly JSON alone:

- ``layout.meta`` holds ``{"x_offset": o, "x_per_node": p, ...}``: a trace's ``x``
  is ``links / N + o`` where ``p`` is true (N the panel's ``n``, 1 if it has none;
  the figures switch to links per node when the panels are one family at several N,
  :func:`compare.report.figures.per_node_axis`, as the static ones do), else ``links + o``.
  ``o`` is :data:`X_OFFSET` (1.0) for links and
  :data:`X_OFFSET_PER_NODE` (0.1) for links per node: the x axes are log axes of
  that sum (plotly has no symlog axis), labelled with the link counts themselves.
  ``layout.meta["panels"]`` lists, per panel, ``panel``, ``title``, its grid ``row``
  and ``col``, its axes (``xaxis``, ``yaxis``: layout keys such as ``"xaxis2"``), and
  ``floor`` and ``top``: the ends of its cost axis (excess costs; the axis' range is
  ``[log10(floor), log10(top)]``, widened by 1e-6 at either end so that a marker on
  an edge is not lost to rounding; :func:`compare.report.figures.cost_range` sets both,
  for the static axis too), ``notes`` and ``margin_top`` (the room above the plot for the
  off-scale values). ``layout.meta["grid"]`` is ``{"rows", "cols"}``
  (:func:`compare.report.figures.grid_cells`, the static layout: rows = N and columns =
  ‖A‖₂ when both vary, else two columns);
  ``layout.meta["legend"]`` the legend's entries, and ``layout.meta["key"]`` what
  the marks mean.
- Every trace's ``meta`` is ``{"kind": K, "label": LABEL, "panel": [family, n,
  a_norm]}``, with K one of

  ``"designs"``
      every usable design of the label on the panel (one point each);
  ``"front"``
      the label's budget front (:func:`compare.report.statistics.budget_fronts`): the
      median step line (``line.shape == "hv"``), one point per budget, ``None``
      where the median is infinite (half of the instances or more have no design
      within the budget) or above ``OFF_SCALE`` (drawn above the axis as a triangle,
      never also as a line); the last point repeats the last step at the axis' right
      edge; in the budget-front figure a marker (the only point with a size) marks
      where it starts;
  ``"band"``
      the budget-front figure's 25 % (first) and 75 % (second) quantile traces,
      filled between; a 75 % quantile at infinity is drawn at the axis' ``top``;
      only where the static figure draws bands (no panel with more than
      :data:`~compare.report.figures.MAX_BANDS` fronts);
  ``"setting"``
      the median (links, cost) of each setting of the label (one γ, one β)
      where :attr:`compare.report.cost_links.Point.reached` and the median cost is at
      most :data:`~compare.report.figures.OFF_SCALE` times LQR's, markers only (x the
      setting's :attr:`~compare.report.cost_links.Point.x`);
  ``"off-scale"``
      what lies above the cost axis, as triangles on its top edge: the designs
      above it (faint), the reached settings' medians above ``OFF_SCALE`` (with
      their ``J = …`` written above the plot, where no line runs), and, in the
      budget-front figure, a front wholly above ``OFF_SCALE`` (at the budget where
      it starts; the panel's notes name it, as the static title does); ``y`` is the
      axis' ``top``, ``customdata`` the true excess costs, and hovering one gives
      the value;
  ``"boundary"``
      the QI boundary (:func:`compare.report.plant_links`), a dotted vertical line
      ``x = [b, b]``, ``y = [floor, top]``, on panels with a delayed method; its
      label is :data:`compare.report.figures.BOUNDARY_LABEL`, named in the legend once.

- ``y`` is the excess cost J − 1 over centralized LQR, floored at the panel's
  ``floor`` as the static figures floor it (:func:`compare.report.figures.excess`: LQR and
  designs closer to it than the axis reaches sit on its bottom edge). Designs and
  fronts above ``top`` keep their values (plotly clips them; the designs are drawn
  again as ``"off-scale"``); the exceptions are said above (a band's infinite
  quantile, the boundary, the off-scale triangles).

The page
--------
:func:`figure_div` writes the figure's traces and layout (less plotly's template and
the subplot titles) as the arguments of a ``Plotly.newPlot("<div id>", data, layout,
config)`` call, where plotly's own HTML has them, so that a reader of the page finds
the JSON above; the page's script (:data:`FIGURE_JS`, ``comparePanels.newPlot``)
then draws each panel as its own plotly plot in a CSS grid (the figure's columns,
one column below 900 px wide), under an HTML legend, so that no legend, axis title
or tick label of one panel can cover another's. Each panel plot's ``layout.meta``
holds ``x_offset``, ``x_per_node``, ``panel``, ``floor`` and ``top``. The script
and the style (:data:`FIGURE_CSS`) go once into the page's head
(:func:`compare.report.html.render_html`). The JSON is written by Python's own
:mod:`json` (never plotly's engine, which is orjson where that is installed and
writes other bytes), so that a report folder rebuilds to the same bytes everywhere.

Colours, markers and dashes come from :mod:`compare.report.styles`, so a method looks the
same here as in the static figures.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Iterable, Mapping

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from .cost_links import aggregate, axis_costs, settings_drawn
from .figures import (BOUNDARY_LABEL, BUDGET_PAD, COST_PAD, FLOOR, MAX_BANDS, OFF_SCALE, bands_drawn, cost_range,
                      cost_ticks, excess, grid_cells, links_ticks, panel_heading, panel_order, per_node_axis, shared_y,
                      title_notes)
from ..run.records import as_records
from .statistics import budget_fronts
from .styles import INFO_MODELS, INFO_ORDER

__all__ = ["cost_links_figure", "budget_fronts_figure", "figure_div", "FIGURE_CSS", "FIGURE_JS", "X_OFFSET",
           "X_OFFSET_PER_NODE", "KINDS"]

#: What x adds to the link count on the log links axis (0 links stays visible).
X_OFFSET = 1.0
#: What x adds to the links per node when the panels have several N.
X_OFFSET_PER_NODE = 0.1
#: The kinds of trace (``trace.meta["kind"]``).
KINDS = ("designs", "front", "band", "setting", "off-scale", "boundary")

_BOUNDARY_GROUP = "qi-boundary"
_BOUNDARY_COLOUR = "#595959"  # matplotlib's "0.35", the static figures' boundary grey
_TOP_TRIANGLE = "triangle-up"
_RANGE_PAD = 1e-6  # in decades


# --- layout ---------------------------------------------------------------------------------------------------


def _panel_order(panels: Iterable[tuple]) -> list[tuple]:
    """Panels sorted by (family, n, a_norm), as the static figures order them."""
    return panel_order(panels)


def _label_order(labels: Iterable[str], styles: Mapping) -> list[str]:
    """Labels grouped by information model (in :data:`INFO_ORDER`), alphabetical within a group."""
    def rank(label):
        info = styles[label].info_model
        return (INFO_ORDER.index(info) if info in INFO_ORDER else len(INFO_ORDER), info, label)

    return sorted(set(labels), key=rank)


def _cells(panels: list[tuple]) -> tuple[int, int, dict]:
    """(rows, cols, panel -> (row, col)), 1-based: :func:`compare.report.figures.grid_cells`, the static layout."""
    rows, cols, cells = grid_cells(panels)
    return rows, cols, {p: (r + 1, c + 1) for p, (r, c) in cells.items()}


class _Axes:
    """One panel's coordinates: x = links / scale + offset on a log axis, y the excess cost on [floor, top]."""

    def __init__(self, panel: tuple, per_node: bool, floor: float, top: float, right_links: float):
        self.panel = panel
        self.scale = float(panel[1]) if per_node and panel[1] else 1.0
        self.offset = X_OFFSET_PER_NODE if per_node else X_OFFSET
        self.per_node = per_node
        # cost_range's ends, as the static axis has them (a decade forced here once took the axis to 500 %)
        self.floor = max(float(floor), FLOOR)
        self.top = max(float(top), self.floor * 1.0001)
        # The links axis ends 15 % right of the largest count, as the static one; the fronts' last step runs there.
        self.right = max(float(right_links), 1.0) / self.scale * 1.15 + self.offset
        self.label_rows = 0  # rows of off-scale values written above the plot (_stacked_labels)

    def x(self, links) -> list[float]:
        return [float(v) / self.scale + self.offset for v in np.atleast_1d(links)]

    def y(self, costs) -> list[float | None]:
        """Excess costs floored at the axis' floor; None where the cost is infinite or NaN (a gap)."""
        values = excess(np.atleast_1d(np.asarray(costs, dtype=float)), self.floor)
        return [float(v) if np.isfinite(v) else None for v in values]

    def above(self, costs) -> np.ndarray:
        values = np.atleast_1d(np.asarray(costs, dtype=float))
        return np.isfinite(values) & (values - 1.0 > self.top)


def _links_ticks(ax: _Axes) -> tuple[list[float], list[str]]:
    """Tick positions and texts (link counts, or links per node) of a links axis: the static axis' 1-2-5 steps
    (:func:`compare.report.figures.links_ticks`), thinned on this axis' own log scale."""
    lo, hi = math.log10(ax.offset), math.log10(ax.right)
    ticks = links_ticks(ax.right - ax.offset, ax.per_node, lambda t: (math.log10(t + ax.offset) - lo) / (hi - lo))
    return [t + ax.offset for t in ticks], [f"{t:g}" for t in ticks]


def _percent(value: float) -> str:
    return f"{value * 100:.4g} %"


def _cost_ticks(floor: float, top: float) -> tuple[list[float], list[str]]:
    """Tick positions and texts of a log excess-cost axis: :func:`compare.report.figures.cost_ticks`."""
    return cost_ticks(floor, top)


def _new_figure(panels: list[tuple], titles: dict) -> tuple[go.Figure, dict, int, int]:
    rows, cols, cells = _cells(panels)
    ordered = [[None] * cols for _ in range(rows)]
    for p, (r, c) in cells.items():
        ordered[r - 1][c - 1] = titles[p]
    fig = make_subplots(rows=rows, cols=cols, subplot_titles=[t or "" for row in ordered for t in row],
                        horizontal_spacing=0.08, vertical_spacing=0.16 if rows > 1 else 0.1)
    return fig, cells, rows, cols


def _axis_names(cell: tuple[int, int], cols: int) -> tuple[str, str]:
    k = (cell[0] - 1) * cols + cell[1]
    return ("xaxis", "yaxis") if k == 1 else (f"xaxis{k}", f"yaxis{k}")


def _finish(fig: go.Figure, axes: dict, cells: dict, rows: int, cols: int, per_node: bool, *, y_title: str,
            key: str, legend: list, titles: dict, notes: dict | None = None, title: str | None = None) -> go.Figure:
    x_title = (f"links per node (log scale of L/N + {X_OFFSET_PER_NODE:g})" if per_node
               else f"links L (log scale of L + {X_OFFSET:g})")
    panels_meta = []
    for panel, ax in axes.items():
        row, col = cells[panel]
        xname, yname = _axis_names(cells[panel], cols)
        tickvals, ticktext = _links_ticks(ax)
        pad = 0.05 * math.log10(ax.right / ax.offset)  # room for the markers at 0 links and at the largest count
        fig.layout[xname].update(type="log", range=[math.log10(ax.offset) - pad, math.log10(ax.right) + pad / 2],
                                 tickvals=tickvals, ticktext=ticktext, title={"text": x_title, "font": {"size": 11}},
                                 showgrid=True, gridcolor="#eeeeee", zeroline=False, automargin=True,
                                 showline=True, linecolor="#888888", ticks="outside", ticklen=3)
        yvals, ytext = _cost_ticks(ax.floor, ax.top)
        fig.layout[yname].update(type="log", range=_log_range(ax.floor, ax.top), tickvals=yvals,
                                 ticktext=ytext, title={"text": y_title, "font": {"size": 11}}, gridcolor="#eeeeee",
                                 zeroline=False, automargin=True, showline=True, linecolor="#888888",
                                 ticks="outside", ticklen=3)
        panels_meta.append({"panel": _panel_json(panel), "title": titles[panel], "row": row, "col": col,
                            "xaxis": xname, "yaxis": yname, "floor": ax.floor, "top": ax.top,
                            "notes": list((notes or {}).get(panel, [])),
                            # room above the plot for the off-scale values written there (FIGURE_JS reads it)
                            "margin_top": _MARGIN_TOP + _ROW_PX * ax.label_rows})
    fig.update_layout(
        title={"text": title} if title else None, template="plotly_white", height=330 * rows + 120,
        width=None, margin={"t": 90 if title else 60, "r": 10},
        legend={"traceorder": "grouped", "tracegroupgap": 0, "groupclick": "togglegroup", "font": {"size": 11}},
        hoverlabel={"align": "left"}, hovermode="closest",
        meta={"x_offset": X_OFFSET_PER_NODE if per_node else X_OFFSET, "x_per_node": per_node,
              "y": "excess cost J - 1 over centralized LQR, floored at the panel's floor",
              "off_scale": OFF_SCALE, "grid": {"rows": rows, "cols": cols}, "panels": panels_meta,
              "legend": legend, "key": key})
    return fig


def _log_range(floor: float, top: float) -> list[float]:
    """A log axis' range on [floor, top], a hair wider: plotly hides an unclipped marker a rounding error outside."""
    return [math.log10(floor) - _RANGE_PAD, math.log10(top) + _RANGE_PAD]


def _panel_json(panel: tuple) -> list:
    family, n, a_norm = panel
    a = float(a_norm) if a_norm is not None and np.isfinite(a_norm) else None
    return [family, n, a]


def _meta(kind: str, label: str, panel: tuple) -> dict:
    return {"kind": kind, "label": label, "panel": _panel_json(panel)}


# --- legend -----------------------------------------------------------------------------------------------------


def _legend_entry(label: str, styles: Mapping, order: list[str], shown: set) -> dict:
    """Trace properties that tie a trace to its label's legend entry (one group per label: a click toggles it
    in every panel); the information model's title heads the group of its first label."""
    info = styles[label].info_model
    first_of_info = next(lb for lb in order if styles[lb].info_model == info) == label
    entry = {"legendgroup": label, "legendrank": 1000 + order.index(label), "showlegend": label not in shown,
             "name": label}
    if first_of_info and label not in shown:
        entry["legendgrouptitle"] = {"text": _info_title(info), "font": {"size": 12}}
    shown.add(label)
    return entry


def _info_title(info: str) -> str:
    return INFO_MODELS[info][2] if info in INFO_MODELS else info


def _legend_meta(order: list[str], styles: Mapping, boundary: bool) -> list[dict]:
    out, last = [], None
    for label in order:
        s = styles[label]
        heading = _info_title(s.info_model) if s.info_model != last else None
        out.append({"group": label, "name": label, "heading": heading,
                    "colour": s.colour, "symbol": s.plotly_symbol, "dash": s.dash, "hollow": s.face == "none"})
        last = s.info_model
    if boundary:
        out.append({"group": _BOUNDARY_GROUP, "name": BOUNDARY_LABEL, "heading": "for delayed designs",
                    "colour": _BOUNDARY_COLOUR, "symbol": None, "dash": "dot", "hollow": False})
    return out


def _marker(style, size: float, **extra) -> dict:
    """A setting's marker as on the static figure: filled (white ring) or hollow, edge-only symbols in colour."""
    hollow = style.face == "none"
    edge = "#ffffff" if style.edge == "white" else style.colour
    return {"color": "rgba(0, 0, 0, 0)" if hollow else style.colour, "symbol": style.plotly_symbol, "size": size,
            "line": {"width": 1.0 if edge == "#ffffff" else 1.4, "color": edge}, **extra}


def _boundary_trace(ax: _Axes, links: float, shown: set) -> go.Scatter:
    x = ax.x(links)[0]
    first = _BOUNDARY_GROUP not in shown
    shown.add(_BOUNDARY_GROUP)
    return go.Scatter(
        x=[x, x], y=[ax.floor, ax.top], mode="lines", name=BOUNDARY_LABEL, legendgroup=_BOUNDARY_GROUP,
        legendrank=5000, showlegend=first, line={"color": _BOUNDARY_COLOUR, "dash": "dot", "width": 1.2},
        hovertemplate=f"QI boundary: {links:g} plant-graph links<br>(below it no delayed graph is quadratically "
                      "invariant)<extra></extra>",
        meta=_meta("boundary", BOUNDARY_LABEL, ax.panel),
        **({"legendgrouptitle": {"text": "for delayed designs", "font": {"size": 12}}} if first else {}))


def _text_position(ax: _Axes, x: float) -> str:
    """Where a value is written above its triangle: inwards near either edge of the axis."""
    lo, hi = math.log10(ax.offset), math.log10(ax.right)
    where = (math.log10(x) - lo) / (hi - lo)
    return "top right" if where < 0.2 else "top left" if where > 0.8 else "top center"


#: The narrowest panel plot's width, in px, and a digit's width at the labels' 11 px font: for stacking labels.
_NARROW_PX, _CHAR_PX = 290.0, 6.4
#: A panel plot's top margin in px (FIGURE_JS's default), and what each row of off-scale values above it adds.
_MARGIN_TOP, _ROW_PX = 14, 15


def _stacked_labels(ax: _Axes, items: list[tuple[float, float]]) -> dict[tuple[float, float], str]:
    """(x, cost) -> its value as written above its triangle on the top edge, outside the plot where no line runs
    (inside, fronts struck "J = 68.4" through); labels that would touch on the narrowest panel go one line higher
    (as the static figure does); "J = " before the only one. Sets ``ax.label_rows``."""
    items = sorted(set(items))
    texts = {item: (f"J = {item[1]:.3g}" if len({f"{c:.3g}" for _, c in items}) == 1 else f"{item[1]:.3g}")
             for item in items}
    lo, hi = math.log10(ax.offset), math.log10(ax.right)
    rows: list[float] = []
    out = {}
    for item in items:
        px = (math.log10(item[0]) - lo) / (hi - lo) * _NARROW_PX
        width = _CHAR_PX * len(texts[item])
        where = _text_position(ax, item[0])
        left = px if where.endswith("right") else px - width if where.endswith("left") else px - width / 2
        row = next((i for i, end in enumerate(rows) if end + 6 <= left), len(rows))
        rows[row:row + 1] = [left + width]
        out[item] = texts[item] + "<br>" * row  # empty lines under it lift a "top" text one row each
    ax.label_rows = max(ax.label_rows, len(rows))
    return out


def _off_scale_trace(ax: _Axes, label: str, style, x: list, values: list, hover: list, sizes: list,
                     opacity: list, labels: list, legend: dict) -> go.Scatter:
    """Triangles on the top edge for what lies above the axis, the medians' values written under theirs;
    customdata holds the true excess costs, and hovering gives them."""
    return go.Scatter(
        x=x, y=[ax.top] * len(x), customdata=[float(v) for v in values], cliponaxis=False,
        mode="markers+text" if any(labels) else "markers", text=labels,
        textposition=[_text_position(ax, v) for v in x],
        textfont={"size": 11, "color": style.colour},
        marker={"color": style.colour, "symbol": _TOP_TRIANGLE, "size": sizes, "opacity": opacity,
                "line": {"width": 0}},
        hovertext=hover, hovertemplate="%{hovertext}<extra></extra>", meta=_meta("off-scale", label, ax.panel),
        **legend)


def _group(entry: dict) -> dict:
    """A further trace of a label: in its legend group, without an entry of its own."""
    return {"legendgroup": entry["legendgroup"], "legendrank": entry["legendrank"], "showlegend": False,
            "name": entry["name"]}


# --- hover texts ------------------------------------------------------------------------------------------------


def _varying_params(records) -> dict[str, list[str]]:
    """Label -> the names of the hyperparameters whose value differs between its designs (e.g. a γ path)."""
    out = {}
    for label, rs in records.by_label.items():
        names = sorted({k for r in rs for k in r.params})
        out[label] = [k for k in names
                      if len({json.dumps(r.params.get(k), sort_keys=True, default=str) for r in rs}) > 1]
    return out


def _value(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _params_hover(params, varying: list[str]) -> str:
    return ", ".join(f"{k} = {_value(params.get(k))}" for k in varying) or "the one setting"


def _design_hover(r, varying: list[str]) -> str:
    inst = r.instance
    where = [inst.family, f"N = {inst.spec.get('n', '?')}"]
    if inst.a_norm is not None:
        where.append(f"‖A‖₂ = {inst.a_norm:g}")
    where.append(f"seed {inst.seed}")
    cost = f"{r.cost:.5g}" + (f" ± {r.cost_stderr:.2g}" if np.isfinite(r.cost_stderr) else "")
    lines = [f"<b>{r.label}</b>", ", ".join(where)]
    if varying:
        lines.append(", ".join(f"{k} = {_value(r.params.get(k))}" for k in varying))
    lines += [f"links {r.links}", f"cost J = {cost} (excess {_percent(r.cost - 1.0)})", f"status {r.status}"]
    return "<br>".join(lines)


def _front_hover(label: str, budgets, cost) -> list[str]:
    out = []
    for b, (q1, med, q3) in zip(budgets, np.asarray(cost).T):
        band = "–".join("∞" if not np.isfinite(v) else f"{v:.4g}" for v in (q1, q3))
        median = f"{med:.4g}" if np.isfinite(med) else "∞ (half of the instances or more have no design within it)"
        out.append(f"<b>{label}</b><br>best cost within ≤ {b:g} links<br>median J = {median}<br>25–75 %: {band}")
    return out


# --- the figures ------------------------------------------------------------------------------------------------


#: What the marks of :func:`cost_links_figure` mean (the page writes it above the panels).
_COST_LINKS_KEY = ("line: each method's budget front, the median over instances of its best cost within L links · "
                   "marker: one setting's medians, where on or above its method's front · faint: every design "
                   "· ▲ on the top edge: above the axis (hover for the value)")
#: What :func:`budget_fronts_figure`'s marks mean.
_BUDGET_FRONTS_KEY = ("line: median over instances of the best cost within L links, from the budget where more "
                      "than half of the instances have a design (marker) · band: 25–75 % across instances · ▲ on "
                      "the top edge: a front above the axis (hover for the value)")
#: The key where no bands are drawn (:func:`compare.report.figures.bands_drawn`).
_BUDGET_FRONTS_KEY_NO_BANDS = ("line: median over instances of the best cost within L links, from the budget where "
                               "more than half of the instances have a design (marker) · no 25–75 % bands: more "
                               f"than {MAX_BANDS} methods on a panel · ▲ on the top edge: a front above the axis "
                               "(hover for the value)")
#: Added to either key where some panel draws the QI boundary.
_BOUNDARY_KEY = " · dotted: QI boundary"


def cost_links_figure(records, styles: Mapping, *, boundaries: Mapping | None = None, title: str | None = None,
                      instances: Mapping | None = None) -> go.Figure:
    """Every design, each method's budget front and its settings' medians, one subplot per panel.

    What :func:`compare.report.cost_links.plot_cost_vs_links` draws: every usable design faintly
    (hover names it), each method's budget front (:func:`compare.report.statistics.budget_fronts`)
    as a step line in its information model's dash, with gaps where its median is
    infinite, and each setting's median (links, cost) as an unconnected marker where
    :attr:`~compare.report.cost_links.Point.reached`. The cost axis is clipped as the static
    one: it spans the medians and fronts at or below :data:`~compare.report.figures.OFF_SCALE`;
    what lies above is a triangle on its top edge. The traces and ``layout.meta`` are
    described in the module's docstring.

    Parameters
    ----------
    records : :class:`~compare.run.records.Records` or rows
        The designs; those that are not :attr:`~compare.run.records.DesignRecord.ok` are left out.
    styles : dict
        Label -> :class:`~compare.report.styles.Style`, from :func:`compare.report.styles.label_styles`.
    boundaries : dict, optional
        Panel -> plant-graph link count (:func:`compare.report.plant_links`): the QI boundary,
        drawn on panels with a delayed method.
    title : str, optional
    instances : dict, optional
        Panel -> number of instances, for the panel titles (default: counted from ``records``).

    Returns
    -------
    plotly.graph_objects.Figure
    """
    records = as_records(records)
    usable = records.filter(lambda r: r.ok and r.links is not None)
    points = [p for p in aggregate(records) if p.ok > 0]
    fronts = budget_fronts(records)
    panels = _panel_order(p.panel for p in points)
    per_node = per_node_axis(panels)
    counts = dict(instances) if instances else {p: len(rs.by_instance) for p, rs in records.by_panel.items()}
    titles = {p: panel_heading(p, counts.get(p)) for p in panels}
    order = _label_order(usable.by_label, styles)
    varying = _varying_params(records)

    limits = cost_range(axis_costs(points, fronts), COST_PAD) if shared_y(panels) else None
    fig, cells, rows, cols = _new_figure(panels, titles)
    axes, shown_legend = {}, set()
    any_boundary = False
    for panel in panels:
        mine_points = [p for p in points if p.panel == panel]
        mine_fronts = {f.label: f for f in fronts if f.panel == panel}
        bottom, top = limits or cost_range(axis_costs(mine_points, mine_fronts.values()), COST_PAD)
        right = max((r.links for r in usable if r.instance.panel == panel), default=1)
        ax = axes[panel] = _Axes(panel, per_node, bottom, top, right)
        traces = _cost_links_panel(ax, mine_points, mine_fronts, usable.by_panel_label, order, styles, varying,
                                   shown_legend)
        boundary = _boundary_traces(ax, boundaries, any(p.info_model == "delayed" for p in mine_points),
                                    shown_legend)
        any_boundary |= bool(boundary)
        _add_traces(fig, traces + boundary, cells[panel])
    return _finish(fig, axes, cells, rows, cols, per_node, y_title="excess cost over LQR (J − 1)",
                   key=_COST_LINKS_KEY.replace("its method's front", f"its method's front ({settings_drawn(points)})")
                   + (_BOUNDARY_KEY if any_boundary else ""),
                   legend=_legend_meta(order, styles, any_boundary), titles=titles, title=title)


def _add_traces(fig: go.Figure, traces: list, cell: tuple[int, int]) -> None:
    for trace in traces:
        fig.add_trace(trace, row=cell[0], col=cell[1])


def _boundary_traces(ax: _Axes, boundaries: Mapping | None, delayed: bool, shown: set) -> list:
    """The QI boundary, on a panel with a delayed method where the plant graph's link count is known."""
    if boundaries and ax.panel in boundaries and delayed:
        return [_boundary_trace(ax, float(boundaries[ax.panel]), shown)]
    return []


def _cost_links_panel(ax: _Axes, points: list, fronts: dict, designs: Mapping, order: list[str], styles: Mapping,
                      varying: dict, shown: set) -> list:
    """One panel's traces of :func:`cost_links_figure`, method by method in legend order.

    ``points`` and ``fronts`` (label -> front) are the panel's, ``designs`` the usable
    records by (panel, label) and ``shown`` the labels that already have a legend entry.
    """
    written = _stacked_labels(ax, [(ax.x(p.x)[0], p.cost[1]) for p in points if p.reached and p.cost[1] > OFF_SCALE])
    traces = []
    for label in order:
        rs = designs.get((ax.panel, label))
        if not rs:
            continue
        entry = _legend_entry(label, styles, order, shown)
        settings = sorted((p for p in points if p.label == label and p.reached),
                          key=lambda p: (p.x, p.cost[1], p.params_key))
        traces += _method_traces(ax, label, styles[label], entry, rs, fronts.get(label), settings, varying[label],
                                 written)
    return traces


def _method_traces(ax: _Axes, label: str, style, entry: dict, rs, front, settings: list, varying: list[str],
                   written: dict) -> list:
    """A method's traces on a panel: its designs, its budget front where it has one, its reached settings'
    medians on the axis, and what lies above the axis."""
    traces = [_designs_trace(ax, label, style, entry, rs, varying)]
    if front is not None and np.isfinite(front.cost[1]).any():
        traces.append(_front_line_trace(ax, label, style, _group(entry), front))
    inside = [p for p in settings if p.cost[1] <= OFF_SCALE]  # at or below the axis' top, by its choice
    if inside:
        traces.append(_settings_trace(ax, label, style, _group(entry), inside, varying))
    up = _above_axis(ax, label, rs, settings, varying, written)
    if up:
        traces.append(_off_scale_trace(ax, label, style, ax.x([u[0] for u in up]), [u[1] - 1.0 for u in up],
                                       [u[2] for u in up], [u[3] for u in up], [u[4] for u in up],
                                       [u[5] for u in up], _group(entry)))
    return traces


def _designs_trace(ax: _Axes, label: str, style, entry: dict, rs, varying: list[str]) -> go.Scatter:
    """Every usable design of a method, faintly; hovering one names it."""
    open_symbol = style.plotly_symbol.endswith("-open")
    return go.Scatter(
        x=ax.x([r.links for r in rs]), y=ax.y([r.cost for r in rs]), mode="markers",
        marker={"color": style.colour, "symbol": style.plotly_symbol, "size": 6, "opacity": 0.3,
                "line": {"width": 1, "color": style.colour} if open_symbol else {"width": 0}},
        text=[_design_hover(r, varying) for r in rs], hovertemplate="%{text}<extra></extra>",
        meta=_meta("designs", label, ax.panel), **entry)


def _front_line_trace(ax: _Axes, label: str, style, group: dict, front) -> go.Scatter:
    """A budget front's median as a step line to the axis' right edge."""
    x = ax.x(front.budgets) + [ax.right]
    hover = _front_hover(label, front.budgets, front.cost)
    median = np.append(front.cost[1], front.cost[1][-1])
    return go.Scatter(
        x=x, y=_cut(ax.y(median), median), mode="lines", connectgaps=False,
        line={"color": style.colour, "dash": style.dash, "shape": "hv", "width": 1.8},
        text=hover + hover[-1:], hovertemplate="%{text}<extra></extra>",
        meta=_meta("front", label, ax.panel), **group)


def _settings_trace(ax: _Axes, label: str, style, group: dict, settings: list, varying: list[str]) -> go.Scatter:
    """The settings' median (links, cost) as unconnected markers."""
    return go.Scatter(
        x=ax.x([p.x for p in settings]), y=ax.y([p.cost[1] for p in settings]), mode="markers",
        cliponaxis=False,
        marker=_marker(style, 10 if style.plotly_symbol == "star" else 8),
        text=[f"<b>{label}</b><br>median of {p.ok} designs: {_params_hover(p.params, varying)}"
              f"<br>links {p.x:g} (median)<br>cost J = {p.cost[1]:.5g} (median; excess "
              f"{_percent(p.cost[1] - 1.0)})<br>reached on {p.reach:.0%} of the instances"
              for p in settings],
        hovertemplate="%{text}<extra></extra>", meta=_meta("setting", label, ax.panel), **group)


def _above_axis(ax: _Axes, label: str, rs, settings: list, varying: list[str], written: dict) -> list[tuple]:
    """What of a method lies above the axis, as (links, cost, hover, size, opacity, text) of its triangle on the
    top edge: its designs (faint) and its settings' medians above OFF_SCALE (their values written under)."""
    up = [(r.links, r.cost, _design_hover(r, varying), 6, 0.35, "") for r in rs if ax.above(r.cost)[0]]
    up += [(p.x, p.cost[1], f"<b>{label}</b><br>median of {p.ok} designs: "
            f"{_params_hover(p.params, varying)}<br>links {p.x:g}<br>cost J = {p.cost[1]:.4g}, "
            "above the axis", 11, 1.0, written[(ax.x(p.x)[0], p.cost[1])]) for p in settings
           if p.cost[1] > OFF_SCALE]
    return up


def budget_fronts_figure(fronts, styles: Mapping, *, boundaries: Mapping | None = None,
                         title: str | None = None) -> go.Figure:
    """Best cost within each link budget: the median step line and the 25–75 % band, per panel.

    What :func:`compare.report.figures.plot_budget_fronts` draws: the median over instances
    (a step line in the information model's dash, a gap where it is infinite, the
    method's marker where it starts) and the 25–75 % band (a quartile at infinity runs
    the band to the top of the axis), with the cost axis clipped as the static one; a
    front wholly above :data:`~compare.report.figures.OFF_SCALE` is a triangle on the top edge.
    The traces and ``layout.meta`` are described in the module's docstring.

    Parameters
    ----------
    fronts : list of :class:`compare.report.statistics.Front`
    styles : dict
        Label -> :class:`~compare.report.styles.Style`.
    boundaries : dict, optional
        Panel -> plant-graph link count: the QI boundary, drawn on panels with a delayed method.
    title : str, optional

    Returns
    -------
    plotly.graph_objects.Figure
    """
    fronts = [f for f in fronts if np.isfinite(f.cost[1]).any()]
    panels = _panel_order(f.panel for f in fronts)
    per_node = per_node_axis(panels)
    order = _label_order({f.label for f in fronts}, styles)
    titles, notes = _fronts_titles(panels, fronts)
    bands = bands_drawn(fronts)

    limits = cost_range(_shown_medians(fronts), BUDGET_PAD) if shared_y(panels) else None
    fig, cells, rows, cols = _new_figure(panels, titles)
    axes, shown_legend = {}, set()
    any_boundary = False
    for panel in panels:
        mine = {f.label: f for f in fronts if f.panel == panel}
        bottom, top = limits or cost_range(_shown_medians(mine.values()), BUDGET_PAD)
        ax = axes[panel] = _Axes(panel, per_node, bottom, top, max(float(f.budgets[-1]) for f in mine.values()))
        traces = _budget_fronts_panel(ax, mine, order, styles, shown_legend, bands)
        boundary = _boundary_traces(ax, boundaries, any(f.info_model == "delayed" for f in mine.values()),
                                    shown_legend)
        any_boundary |= bool(boundary)
        _add_traces(fig, traces + boundary, cells[panel])
    return _finish(fig, axes, cells, rows, cols, per_node, y_title="best excess cost over LQR within ≤ L links",
                   key=(_BUDGET_FRONTS_KEY if bands else _BUDGET_FRONTS_KEY_NO_BANDS)
                   + (_BOUNDARY_KEY if any_boundary else ""),
                   legend=_legend_meta(order, styles, any_boundary), titles=titles, notes=notes,
                   title=title)


def _shown_medians(fronts) -> list[float]:
    """The costs a budget-front axis must show: the fronts' finite medians up to OFF_SCALE."""
    finite = [c for f in fronts for c in f.cost[1] if np.isfinite(c)]
    return [c for c in finite if c <= OFF_SCALE]


def _fronts_titles(panels: list[tuple], fronts) -> tuple[dict, dict]:
    """Panel -> its title, and panel -> its notes: the static panel's (:func:`compare.report.figures.title_notes`:
    the fronts above the axis, the methods with designs on some instances only)."""
    titles, notes = {}, {}
    for panel in panels:
        mine = [f for f in fronts if f.panel == panel]
        titles[panel] = panel_heading(panel, max(f.instances for f in mine))
        above = [f"{f.label} ({np.min(f.cost[1]):.3g})" for f in mine
                 if f.start is not None and np.min(f.cost[1]) > OFF_SCALE]
        lines = [line.replace("\n", " ") for line in title_notes(mine, above)]
        if lines:
            notes[panel] = lines
    return titles, notes


def _budget_fronts_panel(ax: _Axes, fronts: dict, order: list[str], styles: Mapping, shown: set,
                         bands: bool = True) -> list:
    """One panel's traces of :func:`budget_fronts_figure` (``fronts``: label -> the panel's front), in legend
    order; ``shown`` holds the labels that already have a legend entry; ``bands``: whether to draw them."""
    traces = []
    for label in order:
        if label in fronts:
            entry = _legend_entry(label, styles, order, shown)
            traces += _front_traces(ax, label, fronts[label], styles[label], entry, bands)
    return traces


def _front_traces(ax: _Axes, label: str, f, style, entry: dict, bands: bool = True) -> list:
    """A front's traces: its 25–75 % band (where ``bands``), its median step line with its start marked, and a
    triangle on the top edge where the whole front lies above the axis (named in the panel's notes, as the
    static panel names it under its title)."""
    x = ax.x(f.budgets) + [ax.right]
    hover = _front_hover(label, f.budgets, f.cost)
    hover.append(hover[-1])
    q1, med, q3 = (np.append(row, row[-1]) for row in f.cost)
    traces = _band_traces(ax, label, style, _group(entry), x, q1, q3) if bands else []
    y = _cut(ax.y(med), med)
    # The start's marker where the static one is: at the budget it starts, if its median is on the axis.
    start = int(np.searchsorted(f.budgets, f.start)) if f.start is not None else -1
    if start >= 0 and y[start] is None:
        start = -1
    traces.append(go.Scatter(
        x=x, y=y, mode="lines+markers", connectgaps=False, cliponaxis=False,
        line={"color": style.colour, "dash": style.dash, "shape": "hv", "width": 2},
        marker=_marker(style, [(10 if style.plotly_symbol == "star" else 8) if i == start else 0
                               for i in range(len(y))]),
        text=hover, hovertemplate="%{text}<extra></extra>", meta=_meta("front", label, ax.panel), **entry))
    lowest = float(np.min(f.cost[1]))
    if lowest > OFF_SCALE and f.start is not None:
        traces.append(_off_scale_trace(
            ax, label, style, [ax.x(f.start)[0]], [lowest - 1.0],
            [f"<b>{label}</b><br>its whole front is above the axis<br>from ≤ {f.start:g} links: median "
             f"J = {lowest:.4g} at best"], [11], [1.0], [""], _group(entry)))
    return traces


def _cut(y: list, costs) -> list:
    """Drawn excess costs with None (a gap) where the cost is above OFF_SCALE: what lies above the axis is a
    triangle on its top edge, never also a line (:func:`compare.report.figures.draw_front_line`)."""
    return [None if v is None or c > OFF_SCALE else v for v, c in zip(y, np.asarray(costs, dtype=float))]


def _band_traces(ax: _Axes, label: str, style, group: dict, x: list, q1, q3) -> list:
    """The 25 % and 75 % quantile lines, filled between; a 75 % quantile at infinity at the axis' top."""
    low = ax.y(q1)
    high = [None if lo is None else (ax.top if not np.isfinite(v) else hi)
            for lo, v, hi in zip(low, q3, ax.y(np.where(np.isfinite(q3), q3, 1.0)))]
    band = {"x": x, "mode": "lines", "line": {"width": 0, "shape": "hv"}, "hoverinfo": "skip",
            "connectgaps": False, **group}
    return [go.Scatter(y=low, meta=_meta("band", label, ax.panel), **band),
            go.Scatter(y=high, fill="tonexty", fillcolor=_rgba(style.colour, 0.1),
                       meta=_meta("band", label, ax.panel), **band)]


def _rgba(colour: str, alpha: float) -> str:
    r, g, b = (int(colour.lstrip("#")[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r}, {g}, {b}, {alpha})"


# --- the page ---------------------------------------------------------------------------------------------------


def _plain(obj):
    """``obj`` with numpy values as Python ones and non-finite floats as None (JSON null), for :mod:`json`."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_plain(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


#: Characters a JSON text inside a <script> must not hold as they are (plotly's own rules, one set for every engine).
_UNSAFE = (("<", "\\u003c"), (">", "\\u003e"), ("/", "\\u002f"), ("\u2028", "\\u2028"), ("\u2029", "\\u2029"))


def _json(obj) -> str:
    """Compact JSON by Python's :mod:`json` alone: the same bytes whether or not orjson is installed."""
    text = json.dumps(_plain(obj), ensure_ascii=False, separators=(",", ":"), allow_nan=False)
    for unsafe, safe in _UNSAFE:
        text = text.replace(unsafe, safe)
    return text


#: Layout keys of the figure the page leaves out: plotly's template (the panels are styled by FIGURE_JS) and
#: the subplot titles (the panels' titles are HTML).
_LAYOUT_DROP = ("template", "annotations")


def _polygon(sides: int, radius: float, rotation: float = -90.0, cx: float = 17.0, cy: float = 7.0,
             inner: float | None = None) -> str:
    points = []
    steps = sides * (2 if inner else 1)
    for i in range(steps):
        r = inner if inner and i % 2 else radius
        angle = math.radians(rotation + 360.0 * i / steps)
        points.append(f"{cx + r * math.cos(angle):.2f},{cy + r * math.sin(angle):.2f}")
    return " ".join(points)


def _cross(rotation: float) -> str:
    arm, half = 4.6, 1.5
    base = [(half, -arm), (half, -half), (arm, -half), (arm, half), (half, half), (half, arm),
            (-half, arm), (-half, half), (-arm, half), (-arm, -half), (-half, -half), (-half, -arm)]
    c, s = math.cos(math.radians(rotation)), math.sin(math.radians(rotation))
    return " ".join(f"{17 + x * c - y * s:.2f},{7 + x * s + y * c:.2f}" for x, y in base)


_SYMBOL_POINTS = {
    "square": lambda: _polygon(4, 5.0, 45.0), "diamond": lambda: _polygon(4, 5.2),
    "diamond-tall": lambda: "17,1.5 20.2,7 17,12.5 13.8,7", "triangle-up": lambda: _polygon(3, 5.4),
    "triangle-down": lambda: _polygon(3, 5.4, 90.0), "triangle-left": lambda: _polygon(3, 5.4, 180.0),
    "triangle-right": lambda: _polygon(3, 5.4, 0.0), "cross": lambda: _cross(0.0), "x": lambda: _cross(45.0),
    "star": lambda: _polygon(5, 6.0, inner=2.6), "pentagon": lambda: _polygon(5, 4.9),
    "hexagon": lambda: _polygon(6, 4.8), "hexagon2": lambda: _polygon(6, 4.8, 0.0),
    "octagon": lambda: _polygon(8, 4.8, 22.5),
}
_DASHES = {"solid": "", "dash": "5 3", "dot": "1.5 2.5", "dashdot": "5 2 1.5 2"}


def _key_svg(entry: Mapping) -> str:
    """The legend's sample of an entry: its line in its dash, its marker on it."""
    colour = html.escape(entry["colour"])
    dash = _DASHES.get(entry["dash"], "")
    parts = [f'<line x1="1" y1="7" x2="33" y2="7" stroke="{colour}" stroke-width="1.8"'
             + (f' stroke-dasharray="{dash}"' if dash else "") + "/>"]
    symbol = entry["symbol"]
    fill, stroke = ("#ffffff", colour) if entry["hollow"] else (colour, "#ffffff")
    paint = f'fill="{fill}" stroke="{stroke}" stroke-width="{1.3 if entry["hollow"] else 0.7}"'
    if symbol == "x-thin-open":
        parts.append(f'<path d="M13.5,3.5 L20.5,10.5 M13.5,10.5 L20.5,3.5" stroke="{colour}" stroke-width="1.6"/>')
    elif symbol in _SYMBOL_POINTS:
        parts.append(f'<polygon points="{_SYMBOL_POINTS[symbol]()}" {paint}/>')
    elif symbol:
        parts.append(f'<circle cx="17" cy="7" r="4.2" {paint}/>')
    return (f'<svg class="cl-sample" width="34" height="14" viewBox="0 0 34 14" aria-hidden="true">'
            f'{"".join(parts)}</svg>')


def _legend_html(entries: list[Mapping]) -> str:
    groups: list[list[str]] = []
    for entry in entries:
        if entry["heading"] or not groups:
            groups.append([f'<span class="cl-head">{html.escape(entry["heading"] or "")}:</span>'])
        groups[-1].append(f'<button type="button" class="cl-key" data-group="{html.escape(entry["group"])}" '
                          f'aria-pressed="true" title="click to hide or show it in every panel">'
                          f'{_key_svg(entry)}<span>{html.escape(entry["name"])}</span></button>')
    return "\n".join(f'<div class="cl-group">{"".join(g)}</div>' for g in groups)


def figure_div(fig: go.Figure, div_id: str) -> str:
    """The HTML of a figure of this module, with id ``div_id``: a legend, two scale buttons, and one plotly plot
    per panel (ids ``{div_id}-p0``, ``-p1``, ...) in a grid that reflows.

    The figure's own traces and layout (less plotly's template and the subplot titles)
    are written as the arguments of a ``Plotly.newPlot("div_id", data, layout, config)``
    call, which the page's :data:`FIGURE_JS` (``comparePanels.newPlot``) draws panel by
    panel; so a reader of the page finds the figure's JSON where plotly's own HTML puts
    it. The page loads plotly.js, :data:`FIGURE_JS` and :data:`FIGURE_CSS` once
    (:func:`compare.report.html.render_html` does). The JSON is written by :mod:`json` alone,
    so that the HTML is the same whichever plotly JSON engine is installed.
    """
    full = fig.to_plotly_json()
    layout = {k: v for k, v in full["layout"].items() if k not in _LAYOUT_DROP}
    meta = layout["meta"]
    cells = []
    for i, p in enumerate(meta["panels"]):
        notes = "".join(f'<div class="cl-note">{html.escape(n)}</div>' for n in p.get("notes", []))
        cells.append(f'<div class="cl-panel" style="--row: {p["row"]}; --col: {p["col"]}">'
                     f'<div class="cl-title">{html.escape(p["title"])}</div>{notes}'
                     f'<div class="cl-plot" id="{div_id}-p{i}"></div></div>')
    config = {"responsive": True, "displaylogo": False,
              "modeBarButtonsToRemove": ["select2d", "lasso2d", "autoScale2d"],
              "toImageButtonOptions": {"format": "svg", "filename": div_id}}
    buttons = "".join(f'<button type="button" data-scale="{s}" aria-pressed="{str(s == "log").lower()}">{s}</button>'
                      for s in ("log", "linear"))
    return (f'<div class="cl-figure" id="{div_id}">\n'
            f'<div class="cl-bar"><div class="cl-legend" role="group" aria-label="methods: click to hide or show">\n'
            f'{_legend_html(meta["legend"])}\n</div>\n'
            f'<div class="cl-scale" role="group" aria-label="cost axis scale">cost axis: {buttons}</div>\n'
            f'<div class="cl-key-text">{html.escape(meta["key"])}</div></div>\n'
            f'<div class="cl-panels" style="--cols: {meta["grid"]["cols"]}">\n' + "\n".join(cells) + "\n</div>\n"
            f'<script>(function (Plotly) {{ Plotly.newPlot("{div_id}", {_json(full["data"])}, {_json(layout)}, '
            f'{_json(config)}); }})(comparePanels);</script>\n</div>')


#: The style of :func:`figure_div`'s markup: panels in a grid of the figure's columns, one column below 900 px.
FIGURE_CSS = """
.cl-figure { margin: 0.5em 0; }
.cl-bar { font-size: 0.85em; margin-bottom: 0.4em; }
.cl-group { display: flex; flex-wrap: wrap; align-items: center; gap: 0.1em 0.3em; margin: 0.1em 0; }
.cl-head { font-weight: 600; margin-right: 0.3em; color: #444; }
.cl-key { display: inline-flex; align-items: center; gap: 0.25em; border: 1px solid transparent; border-radius: 4px;
          background: none; font: inherit; color: inherit; padding: 0.05em 0.35em; cursor: pointer; }
.cl-key:hover { border-color: #ccc; background: #f6f6f6; }
.cl-key[aria-pressed="false"] { opacity: 0.35; text-decoration: line-through; }
.cl-sample { flex: none; }
.cl-scale { margin: 0.35em 0 0.2em; color: #444; }
.cl-scale button { font: inherit; border: 1px solid #ccc; background: #f6f6f6; padding: 0.05em 0.6em;
                   cursor: pointer; }
.cl-scale button[aria-pressed="true"] { background: #dde7f3; border-color: #0b5cad; }
.cl-key-text { color: #666; }
.cl-panels { display: grid; grid-template-columns: repeat(var(--cols), minmax(0, 1fr)); gap: 1.2em 1.2em; }
.cl-panel { grid-row: var(--row); grid-column: var(--col); min-width: 0; }
.cl-title { text-align: center; font-weight: 600; font-size: 0.9em; }
.cl-note { text-align: center; font-size: 0.78em; color: #666; }
.cl-plot { width: 100%; aspect-ratio: 4 / 3; min-height: 300px; max-height: 430px; }
@media (max-width: 900px) {
  .cl-panels { grid-template-columns: minmax(0, 1fr); }
  .cl-panel { grid-row: auto; grid-column: auto; }
}
"""

#: The script that draws :func:`figure_div`'s figures: ``comparePanels.newPlot(id, data, layout, config)`` takes a
#: figure of this module (its subplots named in ``layout.meta.panels``) and draws each panel as its own plotly plot
#: in the figure's grid, then ties the legend and the scale buttons to all of them.
FIGURE_JS = """
var comparePanels = (function () {
  var PANEL = {autosize: true, showlegend: false, hovermode: 'closest', dragmode: 'zoom',
               margin: {l: 8, r: 14, t: 14, b: 8, pad: 0}, font: {size: 11, color: '#333333'},
               paper_bgcolor: '#ffffff', plot_bgcolor: '#ffffff', hoverlabel: {align: 'left'}};
  var AXIS_DROP = ['domain', 'anchor', 'matches', 'scaleanchor'];
  function axis(spec) {
    var out = {};
    Object.keys(spec || {}).forEach(function (k) { if (AXIS_DROP.indexOf(k) < 0) out[k] = spec[k]; });
    return out;
  }
  function newPlot(id, data, layout, config) {
    var root = document.getElementById(id), meta = layout.meta;
    var panels = meta.panels.map(function (p, i) {
      var xname = p.xaxis.replace('axis', ''), yname = p.yaxis.replace('axis', '');
      var traces = data.filter(function (t) { return (t.xaxis || 'x') === xname && (t.yaxis || 'y') === yname; })
        .map(function (t) { return Object.assign({}, t, {xaxis: 'x', yaxis: 'y', showlegend: false}); });
      var own = Object.assign({}, PANEL, {xaxis: axis(layout[p.xaxis]), yaxis: axis(layout[p.yaxis]),
        margin: Object.assign({}, PANEL.margin, {t: p.margin_top || PANEL.margin.t}),
        meta: {x_offset: meta.x_offset, x_per_node: meta.x_per_node, panel: p.panel, floor: p.floor, top: p.top}});
      var div = document.getElementById(id + '-p' + i);
      Plotly.newPlot(div, traces, own, config);
      return div;
    });
    root.querySelectorAll('.cl-key').forEach(function (key) {
      key.addEventListener('click', function () {
        var group = key.getAttribute('data-group');
        var show = key.getAttribute('aria-pressed') === 'false';
        key.setAttribute('aria-pressed', show ? 'true' : 'false');
        panels.forEach(function (div) {
          var traces = [];
          div.data.forEach(function (t, k) { if (t.legendgroup === group) traces.push(k); });
          if (traces.length) Plotly.restyle(div, {visible: show ? true : 'legendonly'}, traces);
        });
      });
    });
    var scales = root.querySelectorAll('.cl-scale button');
    scales.forEach(function (button) {
      button.addEventListener('click', function () {
        var log = button.getAttribute('data-scale') === 'log';
        scales.forEach(function (b) { b.setAttribute('aria-pressed', b === button ? 'true' : 'false'); });
        panels.forEach(function (div) {
          var m = div.layout.meta;
          Plotly.relayout(div, log
            ? {'yaxis.type': 'log', 'yaxis.range': [Math.log10(m.floor) - 1e-6, Math.log10(m.top) + 1e-6],
               'yaxis.tickmode': 'array'}
            : {'yaxis.type': 'linear', 'yaxis.range': [0, m.top], 'yaxis.tickmode': 'auto',
               'yaxis.tickformat': '.3~%'});
        });
      });
    });
  }
  return {newPlot: newPlot};
})();
"""
