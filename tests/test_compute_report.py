import math

import pytest

from compare.compute_report import (ComputeCell, compute_cells, compute_markdown, growth_exponent, instances_per_size,
                                    plot_compute)
from compare.records import Records

SPEC = """
name = "sizes"
[report]
sections = ["compute"]
[instances]
n = [6, 12]
a_norms = [1.05]
seeds = 2
degree = 4
horizon = 10
[[methods]]
method = "lqr"
[[methods]]
method = "decentralized"
[[methods]]
method = "sparse_sdp"
params = { gammas = [0.01], max_states = 8 }
"""


def _row(label, n, run_key, seconds, designs, peak, status="optimal", cost=1.0, message="", extras=None,
         design_seconds=None, seed=0):
    inst = {"family": "paper", "seed": seed, "n": n, "a_norm": 1.05}
    return {"instance": inst, "label": label, "method": label, "params": {}, "links": 0, "cost": cost,
            "status": status, "message": message, "run_key": run_key, "idx": 0, "run_seconds": seconds,
            "run_designs": designs, "run_peak_mb": peak, "extras": extras or {}, "seconds": design_seconds}


def test_growth_exponent_recovers_a_power_law_and_needs_four_sizes():
    ns = (10, 20, 40, 80)
    assert growth_exponent(ns, [3 * n**2.5 for n in ns]) == pytest.approx(2.5)
    # three sizes are too few to tell a power law from anything else
    assert growth_exponent(ns[:3], [3 * n**2.5 for n in ns[:3]]) is None
    assert growth_exponent([10, 10, 20, 20], [1.0, 2.0, 3.0, 4.0]) is None
    assert growth_exponent(ns, [1.0, 2.0, 3.0, math.nan]) is None


def test_cells_split_design_and_scoring_seconds_over_usable_runs_only_and_keep_the_largest_peak():
    # run a: 2 designs of 1.5 s each in a 4 s run (1 s scoring); run b: 2 designs of 3 s in an 8 s run (2 s scoring)
    rows = [_row("m", 10, "a", 4.0, 2, 300.0, design_seconds=1.5),
            _row("m", 10, "a", 4.0, 2, 300.0, design_seconds=1.5),
            _row("m", 10, "b", 8.0, 2, 350.0, design_seconds=3.0),
            _row("m", 10, "b", 8.0, 2, 350.0, design_seconds=3.0),
            # a size guard: refused at once, no usable design; its 0.01 s must not count as a fast design
            _row("m", 20, "c", 0.01, 1, 310.0, status="failed", cost=math.nan, message="too large"),
            _row("m", 20, "d", 0.02, 1, None, status="failed", cost=math.nan, message="too large")]
    for row, idx in zip(rows[:4], (0, 1, 0, 1)):
        row["idx"] = idx
    a, b = compute_cells(Records.from_rows(rows))
    assert (a.n, a.runs, a.completed, a.seconds_per_run, a.peak_mb) == (10, 2, 2, 6.0, 350.0)
    # medians per design of (1.5, 3.0) and of (0.5, 1.0): design and scoring kept apart, not the run's wall time
    assert a.design_seconds == pytest.approx(2.25) and a.scoring_seconds == pytest.approx(0.75)
    assert (b.n, b.completed, b.why_not, b.peak_mb) == (20, 0, "too large", 310.0) and math.isnan(b.design_seconds)
    text = compute_markdown([a, b])
    assert "none of 2 runs completed" in text and "m, N = 20: 2 of 2: too large" in text
    assert "| 2.25, 0.75, 350 (2) |" in text and "too few sizes (1)" in text


def test_scoring_never_negative_and_unknown_design_seconds_stay_unknown():
    rows = [_row("m", 10, "a", 1.0, 1, 300.0, design_seconds=1.2),  # timer noise: designs longer than the run
            _row("u", 10, "b", 1.0, 1, 300.0, design_seconds=None)]
    m, u = sorted(compute_cells(Records.from_rows(rows)), key=lambda c: c.label)
    assert m.scoring_seconds == 0.0 and m.design_seconds == pytest.approx(1.2)
    assert math.isnan(u.design_seconds) and math.isnan(u.scoring_seconds)


def test_table_fits_growth_only_from_four_sizes_and_counts_runs_and_instances():
    rows = [_row("four", n, f"f{n}{s}", 2e-3 * n**2, 1, 300.0, design_seconds=1e-3 * n**2, seed=s)
            for n in (10, 20, 40, 80) for s in range(3)]
    rows += [_row("three", n, f"t{n}{s}", 1.0, 1, 300.0, design_seconds=0.5, seed=s)
             for n in (10, 20, 40) for s in range(3 if n < 40 else 1)]
    rows += [_row("free", n, f"z{n}", 1.0, 1, 300.0, design_seconds=0.0) for n in (10, 20, 40, 80)]
    records = Records.from_rows(rows)
    text = compute_markdown(compute_cells(records))
    lines = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    assert lines["four"].rstrip(" |").endswith("2.00")
    assert "too few sizes (3)" in lines["three"] and "0.5, 0.5, 300 (1)" in lines["three"]
    assert "no measurable design time" in lines["free"]
    assert instances_per_size(records) == {10: 3, 20: 3, 40: 3, 80: 3}


def _cells(label, values, runs=6):
    return [ComputeCell(label, n, runs, runs, v, v / 10, 2 * v, 300.0 + n) for n, v in values.items()]


def test_plot_compute_has_design_scoring_and_memory_panels_with_grouped_legend():
    from compare.styles import style_for

    cells = _cells("GRNN-Sparse", {n: 0.1 * n**2 for n in (10, 20, 40, 80)})
    cells += _cells("LQR", {n: 0.01 * n for n in (10, 20, 40)}, runs=2)
    styles = {"GRNN-Sparse": style_for("grnn_sparse"), "LQR": style_for("lqr")}
    fig, (design_ax, scoring_ax, memory_ax) = plot_compute(cells, styles=styles, instances={10: 6, 20: 6, 40: 6, 80: 6})
    sparse = [ln for ln in design_ax.get_lines() if ln.get_label() == "GRNN-Sparse"]
    assert len(sparse) == 1 and list(sparse[0].get_xdata()) == [10, 20, 40, 80]
    assert sparse[0].get_color() == styles["GRNN-Sparse"].colour and sparse[0].get_linestyle() == "--"
    assert len(scoring_ax.get_lines()) >= 2 and design_ax.get_xscale() == "log" == scoring_ax.get_yscale()
    # LQR rests on 2 runs at every size: hollow markers and a run count beside each
    hollow = [ln for ln in design_ax.get_lines() if ln.get_markerfacecolor() == "white"]
    assert len(hollow) == 1 and [t.get_text() for t in design_ax.texts] == ["2 runs"] * 3
    legend = fig.legends[0]
    texts = [t.get_text() for t in legend.get_texts()]
    # one column per information model, headed by it; the fit only where four sizes were timed
    assert texts[0].startswith("delayed") and "GRNN-Sparse  (∝ N^2.0)" in texts
    assert any(t.startswith("instantaneous") for t in texts) and "LQR" in texts
    title = fig._suptitle.get_text()
    assert "6 instances at each N" in title and "hollow marker: fewer than 3 runs" in title


def test_coinciding_lines_both_stay_visible():
    from compare.styles import style_for

    same = {n: 0.1 * n for n in (10, 20, 40)}
    cells = _cells("A", same) + _cells("B", same)
    styles = {"A": style_for("grnn_sparse"), "B": style_for("grnn_sparse", {"activation": "identity"})}
    fig, (design_ax, _, _) = plot_compute(cells, styles=styles)
    a, b = (next(ln for ln in design_ax.get_lines() if ln.get_label() == lb) for lb in "AB")
    assert a.get_marker() != b.get_marker() and a.get_color() != b.get_color()
    # the later one smaller, on top, translucent and dashed out of phase with the one beneath
    assert b.get_markersize() < a.get_markersize() and b.get_zorder() > a.get_zorder() and b.get_alpha() < 1
    assert b._unscaled_dash_pattern != a._unscaled_dash_pattern  # no public getter for the dash pattern


def test_compute_section_in_a_report_that_asks_for_it(tmp_path):
    from compare import Store, parse_spec, run_experiment
    from compare.cli import _write_report

    out = tmp_path / "sizes"
    with Store(out / "results.sqlite") as store:
        run_experiment(parse_spec(SPEC), store, progress=False)
        _write_report(store, out)
    text = (out / "report.md").read_text()
    assert "## Compute against network size" in text and (out / "compute.png").exists()
    table = text.split("## Compute against network size", 1)[1]
    assert "N = 6: design s, scoring s, MB (runs)" in table and "N = 12: design s, scoring s, MB (runs)" in table
    assert "too few sizes" in table and "2 instances at each N" in table
    # the SDP's size guard (12 states > max_states = 8) is reported, not timed
    assert "none of 2 runs completed" in table and "max_states = 8" in table


def test_when_every_point_rests_on_the_same_few_runs_the_title_says_it_once():
    cells = _cells("A", {10: 1.0, 20: 2.0}, runs=2) + _cells("B", {10: 3.0, 20: 5.0}, runs=2)
    fig, (design_ax, _, _) = plot_compute(cells, instances={10: 2, 20: 2})
    assert not design_ax.texts and "every point rests on 2 runs" in fig._suptitle.get_text()
