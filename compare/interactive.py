"""Interactive (plotly) versions of the report's figures, for the HTML page.

The static PNG/SVG figures stay the reference; these add what a page can do and
paper cannot: hovering a point names the design (instance, hyperparameters,
cost ± standard error), clicking a method in the legend hides it in every
panel, and two buttons switch the cost axes between linear and log. Costs are excess
costs over centralized LQR (J − 1, in percent), as on the static figures.

Colours, markers and dashes come from :mod:`compare.styles`, so a method looks
the same here as in the static figures.

Link counts are drawn on a log axis of ``links + 1`` (plotly has no symlog
scale), labelled with the link counts themselves: designs without any link
stay visible at the left edge, and 1, 10 and 100 links are spread as evenly as
on the static figures' symlog axis.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping

import numpy as np
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from .cost_links import aggregate
from .figures import excess
from .records import as_records
from .statistics import panel_title
from .styles import INFO_MODELS, INFO_ORDER

__all__ = ["cost_links_figure", "budget_fronts_figure", "figure_div", "LINKS_AXIS_TITLE"]

#: The x axis title of both figures: says how 0 links is kept on a log axis.
LINKS_AXIS_TITLE = "links L (log scale of L + 1, so 0 links shows)"
_MAX_COLUMNS = 3
_ROW_HEIGHT = 400


def _panel_order(panels: Iterable[tuple]) -> list[tuple]:
    """Panels sorted by (family, n, a_norm); a_norm may be None, which plain tuple sorting refuses."""
    return sorted(set(panels), key=lambda p: (str(p[0]), p[1] or 0, -math.inf if p[2] is None else p[2]))


def _label_order(labels: Iterable[str], styles: Mapping) -> list[str]:
    """Labels grouped by information model (in :data:`INFO_ORDER`), alphabetical within a group."""
    def rank(label):
        info = styles[label].info_model
        return (INFO_ORDER.index(info) if info in INFO_ORDER else len(INFO_ORDER), info, label)

    return sorted(set(labels), key=rank)


def _grid(panels: list[tuple], **kwargs) -> tuple[go.Figure, list[tuple[int, int]]]:
    """A subplot grid of at most three columns, one titled panel per cell; returns (figure, [(row, col)])."""
    cols = min(_MAX_COLUMNS, max(1, len(panels)))
    rows = -(-max(1, len(panels)) // cols)
    fig = make_subplots(rows=rows, cols=cols, subplot_titles=[panel_title(p) for p in panels],
                        horizontal_spacing=0.07, vertical_spacing=0.14 if rows > 1 else 0.1, **kwargs)
    cells = [(i // cols + 1, i % cols + 1) for i in range(len(panels))]
    return fig, cells


def _links_ticks(largest: float) -> tuple[list[float], list[str]]:
    """Tick positions (L + 1) and texts (L) of the links axis up to ``largest`` links."""
    ticks, decade = [0], 1
    while decade <= max(largest, 1) * 1.5:
        ticks += [decade * m for m in (1, 2, 5) if decade * m <= max(largest, 1) * 1.5]
        decade *= 10
    return [t + 1.0 for t in ticks], [f"{t:g}" for t in ticks]


def _legend_entry(label: str, styles: Mapping, order: list[str], shown: set) -> dict:
    """Trace properties that tie a trace to its label's legend entry.

    One legend group per label, so a click toggles the label in every panel. The
    information model's title is put on the group of its first label only: plotly
    titles legend groups, and a label cannot be in two groups, so the title heads
    the run of labels of that information model (they are ranked together).
    """
    info = styles[label].info_model
    first_of_info = next(lb for lb in order if styles[lb].info_model == info) == label
    title = INFO_MODELS[info][2] if info in INFO_MODELS else info
    entry = {"legendgroup": label, "legendrank": 1000 + order.index(label), "showlegend": label not in shown}
    if first_of_info:
        entry["legendgrouptitle"] = {"text": title, "font": {"size": 12}}
    shown.add(label)
    return entry


def _scale_buttons(fig: go.Figure, axes: int, initial: str) -> None:
    """Two buttons that switch every cost (y) axis between linear and log."""
    names = ["yaxis"] + [f"yaxis{i}" for i in range(2, axes + 1)]
    buttons = [{"label": f"{scale} cost", "method": "relayout",
                "args": [{f"{name}.type": scale for name in names} | {f"{name}.autorange": True for name in names}]}
               for scale in ("linear", "log")]
    fig.update_layout(updatemenus=[{"type": "buttons", "direction": "left", "buttons": buttons,
                                    "active": 0 if initial == "linear" else 1, "showactive": True,
                                    "x": 0.0, "xanchor": "left", "y": 1.0, "yanchor": "bottom",
                                    "pad": {"b": 30}, "bgcolor": "#f3f3f3"}])


def _finish(fig: go.Figure, cells, largest_links: float, y_title: str, scale: str, title: str | None) -> go.Figure:
    tickvals, ticktext = _links_ticks(largest_links)
    fig.update_xaxes(type="log", tickvals=tickvals, ticktext=ticktext, title_text=LINKS_AXIS_TITLE,
                     title_font_size=11, showgrid=True, gridcolor="#eeeeee", zeroline=False)
    # Excess cost over centralized LQR, in percent: LQR is the axis' origin, as on the static figures.
    fig.update_yaxes(type=scale, title_text=y_title, title_font_size=11, gridcolor="#eeeeee", zeroline=False,
                     tickformat=".2~%")
    rows = max((r for r, _ in cells), default=1)
    _scale_buttons(fig, max(1, len(cells)), scale)
    fig.update_layout(title={"text": title} if title else None, template="plotly_white",
                      height=_ROW_HEIGHT * rows + 120, margin={"t": 110 if title else 90, "r": 10},
                      legend={"traceorder": "grouped", "tracegroupgap": 0, "groupclick": "togglegroup",
                              "font": {"size": 11}},
                      hoverlabel={"align": "left"})
    return fig


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
    lines += [f"links {r.links}", f"cost {cost}", f"status {r.status}"]
    return "<br>".join(lines)


def cost_links_figure(records, styles: Mapping, *, title: str | None = None) -> go.Figure:
    """Every usable design at (links, cost), one subplot per panel.

    Parameters
    ----------
    records : :class:`~compare.records.Records` or rows
        The designs; those that are not :attr:`~compare.records.DesignRecord.ok` are left out.
    styles : dict
        Label -> :class:`~compare.styles.Style`, from :func:`compare.styles.label_styles`.
    title : str, optional

    Returns
    -------
    plotly.graph_objects.Figure
        One trace per (panel, label); a legend entry per label toggles it in every panel.
    """
    records = as_records(records)
    usable = records.filter(lambda r: r.ok and r.links is not None)
    points = aggregate(records)
    panels = _panel_order(records.by_panel)
    order = _label_order(usable.by_label, styles)  # labels drawn: one of them carries its group's title
    varying = _varying_params(records)
    fig, cells = _grid(panels)
    shown: set = set()
    by_panel_label = usable.by_panel_label
    for panel, (row, col) in zip(panels, cells):
        for label in order:
            rs = by_panel_label.get((panel, label))
            if not rs:
                continue
            style = styles[label]
            entry = _legend_entry(label, styles, order, shown)
            fig.add_trace(go.Scatter(
                x=[r.links + 1.0 for r in rs], y=list(excess([r.cost for r in rs])), mode="markers", name=label,
                marker={"color": style.colour, "symbol": style.plotly_symbol, "size": 6, "opacity": 0.35,
                        "line": {"width": 0}},
                text=[_design_hover(r, varying[label]) for r in rs], hovertemplate="%{text}<extra></extra>",
                meta="designs", **entry), row=row, col=col)
            # The settings' medians where some design reaches them, as on the static figure.
            medians = sorted(((p.x, p.cost[1], p) for p in points if p.panel == panel and p.label == label and p.reached),
                             key=lambda m: (m[0], m[1], m[2].params_key))
            if medians:
                fig.add_trace(go.Scatter(
                    x=[m[0] + 1.0 for m in medians], y=list(excess([m[1] for m in medians])),
                    mode="lines+markers" if len(medians) > 1 else "markers", showlegend=False,
                    legendgroup=label, legendrank=entry["legendrank"],
                    line={"color": style.colour, "dash": style.dash, "width": 1.5},
                    marker={"color": "rgba(0, 0, 0, 0)" if style.face == "none" else style.face, "symbol": style.plotly_symbol, "size": 10,
                            "line": {"width": 1.2, "color": style.colour}},
                    text=[f"<b>{label}</b><br>median of {m[2].ok} designs: {_params_hover(m[2].params, varying[label])}"
                          f"<br>links {m[0]:g}<br>cost {m[1]:.5g}" for m in medians],
                    hovertemplate="%{text}<extra></extra>", meta="medians"), row=row, col=col)
    largest = max((r.links for r in usable), default=1)
    return _finish(fig, cells, largest, "excess cost over LQR (J − 1)", "log", title)


def _params_hover(params, varying: list[str]) -> str:
    return ", ".join(f"{k} = {_value(params.get(k))}" for k in varying) or "the one setting"


def _finite(values) -> list:
    """Values with inf and NaN as None: plotly leaves a gap there instead of drawing off the axis."""
    return [float(v) if np.isfinite(v) else None for v in values]


def _front_hover(label: str, budgets, cost) -> list[str]:
    out = []
    for b, (q1, med, q3) in zip(budgets, np.asarray(cost).T):
        band = "–".join("∞" if not np.isfinite(v) else f"{v:.4g}" for v in (q1, q3))
        out.append(f"<b>{label}</b><br>budget ≤ {b:g} links<br>median {med:.4g}<br>25–75 %: {band}")
    return out


def budget_fronts_figure(fronts, styles: Mapping, *, title: str | None = None) -> go.Figure:
    """Best cost within each link budget: the median step line and the 25–75 % band, per panel.

    Parameters
    ----------
    fronts : list of :class:`compare.statistics.Front`
        ``inf`` entries (the budget fits too few instances' designs) are not drawn.
    styles : dict
        Label -> :class:`~compare.styles.Style`; the line's dash is its information model's.
    title : str, optional

    Returns
    -------
    plotly.graph_objects.Figure
    """
    panels = _panel_order(f.panel for f in fronts)
    order = _label_order({f.label for f in fronts}, styles)
    fig, cells = _grid(panels)
    shown: set = set()
    right = max((float(f.budgets[-1]) for f in fronts), default=1.0)
    for panel, (row, col) in zip(panels, cells):
        mine = {f.label: f for f in fronts if f.panel == panel}
        for label in order:
            if label not in mine:
                continue
            f, style = mine[label], styles[label]
            # The last step holds to the right edge, as on the static figure.
            x = np.append(f.budgets, max(right, f.budgets[-1]) * 1.15 + 1) + 1.0
            q1, med, q3 = (_finite(excess(np.append(row_, row_[-1]))) for row_ in f.cost)
            hover = _front_hover(label, f.budgets, f.cost)
            hover.append(hover[-1])
            entry = _legend_entry(label, styles, order, shown)
            band = {"x": x, "mode": "lines", "line": {"width": 0, "shape": "hv"}, "hoverinfo": "skip",
                    "legendgroup": label, "legendrank": entry["legendrank"], "showlegend": False,
                    "connectgaps": False}
            fig.add_trace(go.Scatter(y=q1, **band), row=row, col=col)
            fig.add_trace(go.Scatter(y=q3, fill="tonexty", fillcolor=_rgba(style.colour, 0.1), **band),
                          row=row, col=col)
            reached = [i for i, v in enumerate(med) if v is not None]
            sizes = [9 if reached and i == reached[0] else 0 for i in range(len(med))]
            fig.add_trace(go.Scatter(
                x=x, y=med, mode="lines+markers", name=label, connectgaps=False,
                line={"color": style.colour, "dash": style.dash, "shape": "hv", "width": 2},
                marker={"color": style.colour, "symbol": style.plotly_symbol, "size": sizes},
                text=hover, hovertemplate="%{text}<extra></extra>", **entry), row=row, col=col)
    return _finish(fig, cells, right, "best excess cost over LQR with ≤ L links", "log", title)


def _rgba(colour: str, alpha: float) -> str:
    r, g, b = (int(colour.lstrip("#")[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r}, {g}, {b}, {alpha})"


def figure_div(fig: go.Figure, div_id: str) -> str:
    """The figure's HTML ``<div>`` and script, without plotly.js (the page loads it once), with id ``div_id``."""
    return fig.to_html(include_plotlyjs=False, full_html=False, div_id=div_id,
                       config={"responsive": True, "displaylogo": False,
                               "toImageButtonOptions": {"format": "svg", "filename": div_id}})
