"""One axis rule for the static and the interactive figures (issue 61).

The same cost axis (clip, floor, ticks) in both, what lies above OFF_SCALE a triangle on
the top edge and never also a line, the off-scale values written outside the plot where no
line runs, the panels in the same grid, and every marker inside its axes. learned-class's
interactive random_network panel once reached 500 % (the static one stopped at 60 %) and
drew the diagonal gain twice: a line at 130 % and a triangle above the axis.
"""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from compare.report.cost_links import aggregate, plot_cost_vs_links  # noqa: E402
from compare.report.figures import (MAX_COLUMNS, OFF_SCALE, cost_ticks, grid_cells, per_node_axis,  # noqa: E402
                                    plot_budget_fronts)
from compare.report.interactive import budget_fronts_figure, cost_links_figure  # noqa: E402
from compare.report.statistics import budget_fronts  # noqa: E402
from compare.report.styles import label_styles  # noqa: E402
from compare.report.write import plant_links  # noqa: E402
from compare.run.records import Records, canonical_key, panel_key  # noqa: E402


def _row(spec, method, label, params, cost, links, info, idx):
    return {"run_key": f"{label}-{canonical_key(spec)}-{idx}", "idx": idx, "experiment": "axis", "instance": spec,
            "method": method, "label": label, "params": params, "cost": cost, "cost_stderr": 0.001,
            "cost_kind": "exact", "links": links, "self_loops": spec["n"], "info_model": info, "status": "optimal",
            "message": None, "seconds": 0.1, "controller_kind": "static", "extras": {}, "fingerprint": "f"}


def axis_records() -> Records:
    """Three panels of five instances; on the last, everything but two paths costs more than twice LQR's (the
    diagonal gain at 2.3 × LQR, u = 0 at 1e10), and four single designs share the last link count."""
    rows, facts = [], {}
    for panel, (family, a_norm, far) in enumerate((("paper", 0.995, False), ("paper", 1.05, False),
                                                    ("paper", 1.2, True))):
        for seed in range(5):
            spec = {"family": family, "n": 8, "a_norm": a_norm, "seed": seed}
            facts[canonical_key(spec)] = {"n": 8, "plant_links": 56, "comm_links": 20}
            rows.append(_row(spec, "lqr", "LQR (centralized)", {}, 1.0, 56, "instantaneous", 0))
            rows.append(_row(spec, "autonomous", "Autonomous (u = 0)", {}, 1e10 if far else 3.0, 0, "none", 0))
            rows.append(_row(spec, "decentralized", "Decentralized (diagonal K)", {}, 2.3 if far else 1.3, 0,
                             "none", 0))
            for graph, cost in (("complete", 1.5), ("plant", 1.5), ("plant^2", 1.5), ("plant^3", 1.5)):
                rows.append(_row(spec, "sls_topologies", f"SLS ({graph})", {"graph": graph},
                                 cost + (0.2 if far else 0.0), 56, "delayed", 0))
            for i in range(4):
                rows.append(_row(spec, "sparse_admm", "Sparse K (l1 ADMM)", {"gamma": 10.0 ** -i},
                                 1.9 - 0.2 * i - 0.01 * seed, 5 + 15 * i, "instantaneous", i))
                rows.append(_row(spec, "sparse_delayed", "Sparse delayed K (l1)", {"gamma": 10.0 ** -i},
                                 1.95 - 0.2 * i - 0.01 * seed, 6 + 15 * i, "delayed", i))
    return Records.from_rows(rows, facts=facts)


@pytest.fixture(scope="module")
def figures():
    records = axis_records()
    styles, boundaries = label_styles(records), plant_links(records)
    fronts = budget_fronts(records)
    static = {"cost": plot_cost_vs_links(aggregate(records), records=records, styles=styles, boundaries=boundaries),
              "fronts": plot_budget_fronts(fronts, styles=styles, boundaries=boundaries)}
    interactive = {"cost": cost_links_figure(records, styles, boundaries=boundaries),
                   "fronts": budget_fronts_figure(fronts, styles, boundaries=boundaries)}
    yield static, interactive
    for fig, _ in static.values():
        plt.close(fig)


@pytest.mark.parametrize("name", ["cost", "fronts"])
def test_static_and_interactive_share_the_cost_axis_and_the_grid(figures, name):
    static, interactive = figures
    fig, axes = static[name]
    meta = interactive[name].layout.meta
    assert meta["grid"]["cols"] <= MAX_COLUMNS
    for p in meta["panels"]:
        panel = tuple(p["panel"])
        ax = axes[panel]
        low, high = ax.get_ylim()
        assert (p["floor"], p["top"]) == pytest.approx((low, high), rel=1e-9), panel
        assert p["top"] <= (OFF_SCALE - 1.0) * 1.3 + 1e-12  # the clip: never a decade forced upwards
        # the same ticks, and the same place in the grid
        yaxis = interactive[name].layout[p["yaxis"]]
        assert list(yaxis.tickvals) == pytest.approx(cost_ticks(low, high)[0])
        assert [t for t in ax.get_yticks() if low <= t <= high] == pytest.approx(list(yaxis.tickvals))
        rows, cols, cells = grid_cells(axes)
        assert (p["row"] - 1, p["col"] - 1) == cells[panel]


@pytest.mark.parametrize("name", ["cost", "fronts"])
def test_nothing_above_the_axis_is_drawn_twice(figures, name):
    """A front wholly above OFF_SCALE is a triangle on the top edge, never also a line on the axis."""
    static, interactive = figures
    fig, axes = static[name]
    far = ("paper", 8, 1.2)
    for line in axes[far].lines:
        gid = line.get_gid() or ""
        if gid.startswith("front:"):
            y = np.asarray(line.get_ydata(), float)
            assert not np.isfinite(y).any() or np.nanmax(y) <= axes[far].get_ylim()[1], gid
            if gid.endswith("Decentralized (diagonal K)"):
                assert not np.isfinite(y).any()
    up = [line for line in axes[far].lines if (line.get_gid() or "").startswith("off-scale")]
    assert up  # the triangles on the top edge
    top = next(p["top"] for p in interactive[name].layout.meta["panels"] if tuple(p["panel"]) == far)
    for t in interactive[name].data:
        if t.meta["kind"] == "front" and tuple(t.meta["panel"]) == far:
            assert all(y is None or y <= top for y in t.y), t.meta["label"]
            if t.meta["label"] == "Decentralized (diagonal K)":
                assert all(y is None for y in t.y)
    assert any(t.meta["kind"] == "off-scale" and t.meta["label"] == "Decentralized (diagonal K)"
               for t in interactive[name].data)


def test_off_scale_values_are_written_outside_the_plot(figures):
    """Inside the axes, fronts struck "J = 5.18" through: the values stand above the frame, in both figures."""
    static, interactive = figures
    fig, axes = static["cost"]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    written = 0
    for ax in axes.values():
        frame = ax.get_window_extent(renderer)
        for text in ax.texts:
            box = text.get_window_extent(renderer)
            assert box.y0 >= frame.y1 - 0.5, text.get_text()
            written += 1
    assert written
    labelled = [t for t in interactive["cost"].data if t.meta["kind"] == "off-scale" and any(t.text or ())]
    assert labelled and all(pos.startswith("top") for t in labelled for pos in t.textposition)
    margins = {tuple(p["panel"]): p["margin_top"] for p in interactive["cost"].layout.meta["panels"]}
    assert margins[("paper", 8, 1.2)] > margins[("paper", 8, 0.995)] or min(margins.values()) > 14


def test_every_marker_is_inside_its_axes(figures):
    """Four single designs at the last link count are dodged apart inwards, not out of the frame (tradeoff's SLS
    hexagons), and a marker alone there (LQR, on the bottom edge) stays at its count."""
    static, _ = figures
    for fig, axes in static.values():
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        for ax in axes.values():
            frame = ax.get_window_extent(renderer)
            for line in ax.lines:
                gid = line.get_gid() or ""
                if not gid.startswith("method:") or line.get_marker() in (None, "None", "none", ""):
                    continue
                xy = line.get_transform().transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
                for x, y in xy:
                    assert frame.x0 - 0.5 <= x <= frame.x1 + 0.5 and frame.y0 - 0.5 <= y <= frame.y1 + 0.5, (gid, x, y)
            lqr = [line for line in ax.lines if line.get_gid() == "method:LQR (centralized)"]
            for line in lqr:  # alone at 56 links on the bottom edge: not moved
                (x, _), = line.get_transform().transform(np.column_stack([line.get_xdata(), line.get_ydata()]))
                assert x == pytest.approx(ax.transData.transform((56, 1.0))[0])


def test_links_are_counted_per_node_only_for_one_family_at_several_n():
    assert per_node_axis([("paper", 20, 0.995), ("paper", 50, 0.995)])
    assert not per_node_axis([("paper", 20, 0.995), ("paper", 20, 1.05)])
    power = [panel_key({"family": "power_grid", "case": c, "n": n, "damping": d})
             for c, n, d in (("ieee39", 10, 2.0), ("ieee39", 10, "case"), ("wecc", 29, 2.0), ("npcc", 48, 2.0))]
    assert len(set(power)) == 4  # each system its own panel, ieee39's dampings apart
    assert {p[0] for p in power} == {"ieee39 (d = 2)", "ieee39 (case damping)", "wecc (d = 2)", "npcc (d = 2)"}
    assert not per_node_axis(power)  # each grid's links, where its claim of one link can be read


def test_the_links_axis_names_one_two_and_five_links():
    fig, ax = plt.subplots(figsize=(4.1, 3.3))
    from compare.report.figures import links_axis

    links_axis(ax, 90.0)
    ticks = list(ax.xaxis.get_major_locator()())
    assert {0, 1, 2, 5, 10} <= set(ticks)
    plt.close(fig)
    fig = cost_links_figure(axis_records(), label_styles(axis_records()))
    texts = fig.layout[fig.layout.meta["panels"][0]["xaxis"]].ticktext
    assert {"0", "1", "2", "5", "10"} <= set(texts)
    assert not math.isnan(float(texts[-1]))
