"""Every cost-versus-links figure agrees with its records and its findings, static and interactive.

Reads the figures back (artists, the page's plotly JSON; see ``figure_agreement.py``):
(a) every summary point is reached on at least half of its method's instances in the
panel, and no setting marker stands below its own method's front; (b) for every finding "A beats B within L links on P" the drawn budget fronts
order A at or below B at L on P. On the reports shipped before these rules, 381 of the
1,366 summary markers of the interactive figures failed (a).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from figure_agreement import (Drawn, below_their_front, contradictions, plotly_figures, plotly_fronts,  # noqa: E402
                              plotly_points, reach, static_fronts, static_points, unreached)  # tests/figure_agreement.py

from compare.report.cost_links import aggregate, plot_cost_vs_links  # noqa: E402
from compare.report.figures import plot_budget_fronts  # noqa: E402
from compare.report.findings import select_comparisons  # noqa: E402
from compare.report.folder import read_folder  # noqa: E402
from compare.run.meta import StoreMeta  # noqa: E402
from compare.run.records import Records  # noqa: E402
from compare.report.write import plant_links, report_records, write_report  # noqa: E402
from compare.report.tables import asked_pairs  # noqa: E402
from compare.report.statistics import budget_fronts  # noqa: E402
from compare.report.styles import label_styles  # noqa: E402

REPORTS = Path(__file__).resolve().parents[1] / "reports"
SHIPPED = sorted(p.name for p in REPORTS.iterdir() if (p / "runs.csv").exists())
FIGURES = {"fig-cost-vs-links": "cost_vs_links", "fig-budget-fronts": "budget_fronts"}


@lru_cache(maxsize=None)
def _shipped(name: str):
    data = read_folder(REPORTS / name)
    records = report_records(data.records)
    comparisons = select_comparisons(records, pairs=asked_pairs(records, StoreMeta.of(data.meta)))
    return records, comparisons


def _static(records) -> dict[str, dict]:
    """The two cost-versus-links figures drawn from ``records``: name -> panel -> Axes (figures closed after reading)."""
    styles, boundaries = label_styles(records), plant_links(records)
    fronts = budget_fronts(records)
    cost_fig, cost_axes = plot_cost_vs_links(aggregate(records), records=records, styles=styles, boundaries=boundaries)
    front_fig, front_axes = plot_budget_fronts(fronts, styles=styles, boundaries=boundaries)
    return {"cost_vs_links": (cost_fig, cost_axes), "budget_fronts": (front_fig, front_axes)}


def _check_static(records, comparisons):
    for name, (fig, axes) in _static(records).items():
        points = static_points(name, axes)
        assert any(p.kind == "front" for p in points), f"{name}: no budget front drawn"
        missed = unreached(records, points)
        assert not missed, f"{name}: {len(missed)} of {len(points)} points reached on fewer than half: {missed[:3]}"
        low = below_their_front(points, static_fronts(axes))
        assert not low, f"{name}: {len(low)} markers below their method's front: {low[:3]}"
        wrong = contradictions(comparisons, static_fronts(axes))
        assert not wrong, f"{name}: " + "; ".join(wrong[:3])
        plt.close(fig)


def _check_page(records, comparisons, page: str):
    figures = plotly_figures(page)
    assert set(FIGURES) <= set(figures), sorted(figures)
    for div, name in FIGURES.items():
        points = plotly_points(name, figures[div])
        assert any(p.kind == "front" for p in points), f"interactive {name}: no budget front tagged"
        missed = unreached(records, points)
        assert not missed, f"interactive {name}: {len(missed)} of {len(points)} points unreached: {missed[:3]}"
        low = below_their_front(points, plotly_fronts(figures[div]))
        assert not low, f"interactive {name}: {len(low)} markers below their method's front: {low[:3]}"
        wrong = contradictions(comparisons, plotly_fronts(figures[div]))
        assert not wrong, f"interactive {name}: " + "; ".join(wrong[:3])


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_static_figures_agree_with_their_records_and_findings(name):
    _check_static(*_shipped(name))


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_interactive_figures_agree_with_their_records_and_findings(name):
    records, comparisons = _shipped(name)
    _check_page(records, comparisons, (REPORTS / name / "report.html").read_text(encoding="utf-8"))


# --------------------------------------------------------------------------- a generated report


def _inst(seed, a_norm=1.05):
    return {"family": "paper", "n": 8, "a_norm": a_norm, "seed": seed}


def _rec(inst, method, label, links, cost, *, info="delayed", params=None):
    return {"instance": inst, "method": method, "label": label, "params": params or {}, "links": links,
            "self_loops": 8, "cost": cost, "cost_stderr": 0.0, "cost_kind": "exact", "status": "optimal",
            "info_model": info, "run_key": f"{label}|{inst['seed']}|{links}|{cost}|{params}", "idx": 0}


def _trap_records(n: int = 10) -> Records:
    """The shape that fooled per-setting medians: one β gives 0 links on most instances at a high cost and
    many links at a low cost elsewhere, so its medians (0 links, low cost) describe no instance."""
    rows = []
    for s in range(n):
        inst = _inst(s)
        zero = s < 6
        rows.append(_rec(inst, "grnn_sparse", "GRNN-Sparse", 0 if zero else 30, 1.30 + 0.01 * s if zero else 1.05,
                         params={"beta": 10.0}))
        rows.append(_rec(inst, "grnn_sparse", "GRNN-Sparse", 40, 1.08 + 0.001 * s, params={"beta": 1.0}))
        rows.append(_rec(inst, "decentralized", "Decentralized (diagonal K)", 0, 1.20 + 0.01 * s, info="none"))
        rows += [_rec(inst, "sparse_delayed", "Sparse K, delayed (l1)", k, c + 0.002 * s,
                      params={"gamma": g}) for k, c, g in ((0, 1.20, 10.0), (12, 1.10, 1.0), (40, 1.06, 0.1))]
        rows.append(_rec(inst, "lqr", "LQR (centralized)", 56, 1.0, info="instantaneous"))
    return Records.from_rows(rows)


def test_the_medians_of_a_setting_that_describe_no_instance_are_not_drawn():
    records = report_records(_trap_records())
    beta10 = next(p for p in aggregate(records) if p.params.get("beta") == 10.0)
    # The old marker: lower-median links 0 and median cost about 1.3; reached by a 0-link design on 6 of 10
    # instances only where the cost is at most the median, so on fewer than half.
    assert beta10.x == 0 and reach(records, beta10.panel, beta10.label, 0, beta10.cost[1] - 1) < 0.5
    assert not beta10.reached


def test_a_generated_report_agrees_with_its_records_and_findings(tmp_path):
    records = report_records(_trap_records())
    comparisons = select_comparisons(records)
    assert any(c.significant for c in comparisons)  # a report with claims, so (b) is tested
    _check_static(records, comparisons)
    write_report(records, tmp_path, title="agreement")
    _check_page(records, comparisons, (tmp_path / "report.html").read_text(encoding="utf-8"))


def test_the_checks_catch_an_unreached_marker_and_a_reversed_front():
    records = report_records(_trap_records())
    panel = records[0].instance.panel
    # A marker at (0 links, 1 % excess): no GRNN-Sparse design is there on any instance.
    assert unreached(records, [Drawn("x", "setting", panel, "GRNN-Sparse", 0.0, 0.01)])
    # A marker at 10 % below its method's front at 20 %, and one on it.
    front = {panel: {"GRNN-Sparse": (np.array([0.0, 30.0]), np.array([0.2, 0.05]))}}
    assert below_their_front([Drawn("x", "setting", panel, "GRNN-Sparse", 0.0, 0.1)], front)
    assert not below_their_front([Drawn("x", "setting", panel, "GRNN-Sparse", 0.0, 0.2)], front)
    # A finding (GRNN-Sparse beats the diagonal gain, any number of links) with fronts drawn the other way round.
    c = next(c for c in select_comparisons(records) if c.significant and c.label_a and c.label_b)
    winner, loser = (c.label_a, c.label_b) if c.paired.high < 0 else (c.label_b, c.label_a)
    fronts = {c.panel: {winner: (np.array([0.0, 40.0]), np.array([0.5, 0.2])),
                        loser: (np.array([0.0, 40.0]), np.array([0.5, 0.1]))}}
    assert contradictions([c], fronts)
    fronts[c.panel][loser] = (np.array([0.0, 40.0]), np.array([0.5, 0.3]))
    assert not contradictions([c], fronts)
