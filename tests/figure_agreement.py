"""Read a report's cost-versus-links figures back, and check them against the records and the findings.

Everything here reads what a figure holds: the artists of the static figures (lines by
their gid, :func:`compare.report.figures.front_gid` and :func:`compare.report.figures.method_gid`) and
the plotly JSON embedded in ``report.html``. Whether a drawn point is *reached* is then
recomputed from the records alone, without the code that chose what to draw:

- (a) every summary point (a budget front's step, a setting's marker) is reached on at
  least half of the instances its method ran on in the panel: on each of them some
  usable design of the method has no more links and no more cost;
- (a') no setting marker stands below its own method's drawn front at its link count;
- (b) for every finding "A beats B within L links on panel P", the budget fronts as
  drawn order A at or below B at L on P.
"""

from __future__ import annotations

import json
import math
import re
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

#: Drawn costs are excess costs J − 1 floored at the axis bottom: a point on the floor stands for any cost below it.
_TOL = 1e-12


@dataclass(frozen=True)
class Drawn:
    """One summary point as a figure draws it: ``links`` in links (not per node), ``excess`` = cost − 1."""

    figure: str
    kind: str  # "front" or "setting"
    panel: tuple
    label: str
    links: float
    excess: float


def _index(records) -> dict:
    """(panel, label) -> (instance keys run on, usable designs as (instance key, links, cost − 1))."""
    key = id(records)
    if _INDEX.get("key") != key:
        out: dict = {}
        for r in records:
            runs, usable = out.setdefault((r.instance.panel, r.label), (set(), []))
            runs.add(r.instance.key)
            if r.ok:
                usable.append((r.instance.key, r.links, r.cost - 1.0))
        _INDEX.update(key=key, records=records, index=out)
    return _INDEX["index"]


_INDEX: dict = {}


def reach(records, panel, label, links: float, excess: float) -> float:
    """Share of the instances ``label`` ran on in ``panel`` with a usable design of at most ``links`` and cost − 1 ≤ ``excess``."""
    runs, usable = _index(records).get((panel, label), (set(), []))
    hits = {inst for inst, k, e in usable if k <= links + _TOL and e <= excess * (1 + _TOL) + _TOL}
    return len(hits) / len(runs) if runs else 0.0


# --------------------------------------------------------------------------- static figures


def _per_node(ax) -> bool:
    return "per node" in ax.get_xlabel()


def static_points(name: str, axes: dict) -> list[Drawn]:
    """Budget-front steps and setting markers of a static figure: ``axes`` maps panel -> Axes."""
    out = []
    for panel, ax in axes.items():
        scale = panel[1] if _per_node(ax) and panel[1] else 1.0
        for line in ax.lines:
            gid = line.get_gid() or ""
            kind = "front" if gid.startswith("front:") else "setting" if gid.startswith("method:") else None
            if kind is None or (kind == "setting" and line.get_marker() in (None, "None", "none", "")):
                continue
            label = gid.split(":", 1)[1]
            xs, ys = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            if kind == "front":
                xs, ys = xs[:-1], ys[:-1]  # the last vertex only holds the last step to the right edge
            out += [Drawn(name, kind, panel, label, float(x) * scale, float(y))
                    for x, y in zip(xs, ys) if np.isfinite(y)]
    return out


def static_fronts(axes: dict) -> dict[tuple, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Panel -> label -> (links, excess) of each drawn budget front (NaN where not drawn)."""
    out: dict = defaultdict(dict)
    for panel, ax in axes.items():
        scale = panel[1] if _per_node(ax) and panel[1] else 1.0
        for line in ax.lines:
            gid = line.get_gid() or ""
            if gid.startswith("front:"):
                xs = np.asarray(line.get_xdata(), float)[:-1] * scale
                out[panel][gid.split(":", 1)[1]] = (xs, np.asarray(line.get_ydata(), float)[:-1])
    return out


# --------------------------------------------------------------------------- interactive figures


def plotly_figures(page: str) -> dict[str, dict]:
    """Div id -> {"data": [...], "layout": {...}} of every ``Plotly.newPlot`` call in a page."""
    decoder = json.JSONDecoder()
    out = {}
    for match in re.finditer(r'Plotly\.newPlot\(\s*"([^"]+)",\s*', page):
        data, end = decoder.raw_decode(page, match.end())
        rest = page[end:].lstrip()
        assert rest.startswith(","), rest[:40]
        layout, _ = decoder.raw_decode(rest[1:].lstrip())
        out[match.group(1)] = {"data": data, "layout": layout}
    return out


def _links(x: float, layout: dict, panel: tuple) -> float:
    meta = layout.get("meta") or {}
    links = float(x) - float(meta.get("x_offset", 1.0))
    return links * (panel[1] if meta.get("x_per_node") and panel[1] else 1.0)


def _panel(trace: dict) -> tuple:
    family, n, a_norm = trace["meta"]["panel"]
    return (family, n, a_norm)


def plotly_points(name: str, figure: dict) -> list[Drawn]:
    """Budget-front steps and setting markers of an interactive figure (traces tagged by their ``meta``)."""
    out = []
    for trace in figure["data"]:
        meta = trace.get("meta")
        if not isinstance(meta, dict) or meta.get("kind") not in ("front", "setting"):
            continue
        panel = _panel(trace)
        xs, ys = list(trace["x"]), list(trace["y"])
        if meta["kind"] == "front":
            xs, ys = xs[:-1], ys[:-1]
        out += [Drawn(name, meta["kind"], panel, meta["label"], _links(x, figure["layout"], panel), float(y))
                for x, y in zip(xs, ys) if y is not None and math.isfinite(float(y))]
    return out


def plotly_fronts(figure: dict) -> dict[tuple, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """Panel -> label -> (links, excess) of each budget front an interactive figure draws."""
    out: dict = defaultdict(dict)
    for trace in figure["data"]:
        meta = trace.get("meta")
        if isinstance(meta, dict) and meta.get("kind") == "front":
            panel = _panel(trace)
            xs = np.array([_links(x, figure["layout"], panel) for x in trace["x"][:-1]])
            ys = np.array([np.nan if y is None else float(y) for y in trace["y"][:-1]])
            out[panel][meta["label"]] = (xs, ys)
    return out


# --------------------------------------------------------------------------- the checks


def unreached(records, points: list[Drawn], share: float = 0.5) -> list[tuple[Drawn, float]]:
    """The drawn points reached on fewer than ``share`` of their method's instances, with their share."""
    out = []
    for p in points:
        got = reach(records, p.panel, p.label, p.links, p.excess)
        if got < share:
            out.append((p, got))
    return out


def _at(front: tuple[np.ndarray, np.ndarray], budget: float | None) -> float:
    """The drawn step value within ``budget`` links (None: any), NaN where the front is not drawn there."""
    xs, ys = front
    if budget is None:
        return float(ys[-1]) if len(ys) else math.nan
    k = int(np.searchsorted(xs, budget + _TOL, side="right")) - 1
    return float(ys[k]) if k >= 0 else math.nan


def contradictions(comparisons, fronts: dict) -> list[str]:
    """Findings whose winner's drawn front lies above the loser's at the finding's budget and panel."""
    out = []
    for c in comparisons:
        if not c.significant or c.label_a is None or c.label_b is None:
            continue
        drawn = fronts.get(c.panel, {})
        if c.label_a not in drawn or c.label_b not in drawn:
            continue
        ya, yb = _at(drawn[c.label_a], c.budget), _at(drawn[c.label_b], c.budget)
        if not (math.isfinite(ya) and math.isfinite(yb)):
            continue
        winner, loser = (ya, yb) if c.paired.high < 0 else (yb, ya)
        if winner > loser * (1 + 1e-9):
            out.append(f"{c.a} vs {c.b} on {c.panel} within {c.budget}: drawn {ya:.6g} and {yb:.6g}, "
                       f"finding {c.verdict}")
    return out


def below_their_front(points: list[Drawn], fronts: dict) -> list[tuple[Drawn, float]]:
    """Setting markers drawn below their own method's front at their link count, with the front's value there."""
    out = []
    for p in points:
        front = fronts.get(p.panel, {}).get(p.label)
        if p.kind != "setting" or front is None:
            continue
        value = _at(front, p.links)
        if math.isfinite(value) and p.excess < value * (1 - 1e-9):
            out.append((p, value))
    return out
