import math
import sys
import time

import numpy as np
import pytest

from compare.report.compute_report import (NOT_MEASURED, ComputeCell, compute_cells, compute_markdown, growth_exponent,
                                    growth_sentences, instances_per_size, plot_compute)
from compare.report.figures import plt
from compare.run.records import Records

LINUX = sys.platform.startswith("linux")

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
         design_seconds=None, seed=0, scoring=None, baseline=None):
    """A stored design; ``scoring`` and ``baseline`` None as in runs stored before they were measured."""
    inst = {"family": "paper", "seed": seed, "n": n, "a_norm": 1.05}
    return {"instance": inst, "label": label, "method": label, "params": {}, "links": 0, "cost": cost,
            "status": status, "message": message, "run_key": run_key, "idx": 0, "run_seconds": seconds,
            "run_designs": designs, "run_peak_mb": peak, "extras": extras or {}, "seconds": design_seconds,
            "run_scoring_seconds": scoring, "run_baseline_mb": baseline}


def test_growth_exponent_recovers_a_power_law_and_needs_four_sizes():
    ns = (10, 20, 40, 80)
    assert growth_exponent(ns, [3 * n**2.5 for n in ns]) == pytest.approx(2.5)
    # three sizes are too few to tell a power law from anything else
    assert growth_exponent(ns[:3], [3 * n**2.5 for n in ns[:3]]) is None
    assert growth_exponent([10, 10, 20, 20], [1.0, 2.0, 3.0, 4.0]) is None
    assert growth_exponent(ns, [1.0, 2.0, 3.0, math.nan]) is None


def test_cells_split_design_and_scoring_seconds_over_usable_runs_only_and_keep_the_largest_peak():
    # run a: 2 designs of 1.5 s each in a 4 s run (1 s scoring); run b: 2 designs of 3 s in an 8 s run (2 s scoring)
    rows = [_row("m", 10, "a", 4.0, 2, 300.0, design_seconds=1.5, scoring=1.0, baseline=280.0),
            _row("m", 10, "a", 4.0, 2, 300.0, design_seconds=1.5, scoring=1.0, baseline=280.0),
            _row("m", 10, "b", 8.0, 2, 350.0, design_seconds=3.0, scoring=2.0, baseline=290.0),
            _row("m", 10, "b", 8.0, 2, 350.0, design_seconds=3.0, scoring=2.0, baseline=290.0),
            # a size guard: refused at once, no usable design; its 0.01 s must not count as a fast design
            _row("m", 20, "c", 0.01, 1, 310.0, status="failed", cost=math.nan, message="too large"),
            _row("m", 20, "d", 0.02, 1, None, status="failed", cost=math.nan, message="too large")]
    for row, idx in zip(rows[:4], (0, 1, 0, 1)):
        row["idx"] = idx
    a, b = compute_cells(Records.from_rows(rows))
    assert (a.n, a.runs, a.completed, a.seconds_per_run, a.peak_mb) == (10, 2, 2, 6.0, 350.0)
    # medians per design of (1.5, 3.0) and of (0.5, 1.0): design and scoring kept apart, not the run's wall time
    assert a.design_seconds == pytest.approx(2.25) and a.scoring_seconds == pytest.approx(0.75)
    # memory: the median of what each run added over its start (20 and 60 MB), not the whole peak
    assert a.memory_mb == pytest.approx(40.0)
    assert (b.n, b.completed, b.why_not, b.peak_mb) == (20, 0, "too large", 310.0) and math.isnan(b.design_seconds)
    text = compute_markdown([a, b])
    assert "none of 2 runs completed" in text and "m, N = 20: 2 of 2: too large" in text
    assert "| m | 10 | 2.25 | 0.75 | 40 | 2 |" in text and "too few sizes (1)" in text and NOT_MEASURED not in text


def test_scoring_seconds_are_the_measured_ones_and_unmeasured_ones_stay_unknown():
    # a path whose designs recorded more seconds than its run took (a shared step counted twice): the measured
    # scoring is kept as it is, not the wall time less the designs' seconds (which would be clipped at 0)
    rows = [_row("m", 10, "a", 1.0, 1, 300.0, design_seconds=1.2, scoring=0.3, baseline=250.0),
            _row("u", 10, "b", 1.0, 1, 300.0, design_seconds=None, scoring=0.1, baseline=300.0),
            _row("old", 10, "c", 4.0, 1, 300.0, design_seconds=1.0)]  # stored before scoring was measured
    m, old, u = sorted(compute_cells(Records.from_rows(rows)), key=lambda c: c.label)
    assert m.scoring_seconds == pytest.approx(0.3) and m.design_seconds == pytest.approx(1.2)
    assert m.memory_mb == pytest.approx(50.0) and u.memory_mb == 0.0
    assert math.isnan(u.design_seconds) and u.scoring_seconds == pytest.approx(0.1)
    assert old.design_seconds == 1.0 and math.isnan(old.scoring_seconds) and math.isnan(old.memory_mb)
    assert old.peak_mb == 300.0  # the whole peak is still known; it is just not what the report draws
    text = compute_markdown([m, old, u])
    assert "| old | 10 | 1 | ? | ? | 1 |" in text
    # a store mixing runs from before the measurements with later ones says so
    assert "? : scoring seconds and memory added were not measured in some of this report's runs" in text


def test_a_learned_designs_own_simulation_counts_as_scoring_not_design():
    # a GRNN run: 3 s of training recorded as the design's seconds, 2 s simulating it to precision recorded
    # in its extras, 0.01 s of harness scoring (the design came back with its cost)
    rows = [_row("grnn", 10, "a", 5.2, 1, 300.0, design_seconds=3.0, scoring=0.01, baseline=250.0,
                 extras={"scoring_seconds": 2.0}),
            _row("old", 10, "b", 5.2, 1, 300.0, design_seconds=3.0, extras={"scoring_seconds": 2.0})]
    grnn, old = compute_cells(Records.from_rows(rows))
    assert grnn.design_seconds == pytest.approx(3.0) and grnn.scoring_seconds == pytest.approx(2.01)
    assert math.isnan(old.scoring_seconds)  # a run whose harness scoring was not measured stays unknown


def test_a_trained_grnn_records_its_simulation_seconds():
    from codesign import paper_instance
    from codesign.learned import grnn

    design = grnn(paper_instance(0, n=6, horizon=10), variant="given", steps=2, ensemble=1, seed=0)
    assert design.extras["scoring_seconds"] > 0 and design.seconds > 0


def test_table_fits_growth_only_from_four_sizes_and_counts_runs_and_instances():
    rows = [_row("four", n, f"f{n}{s}", 2e-3 * n**2, 1, 300.0 + 0.01 * n, design_seconds=1e-3 * n**2, seed=s,
                 scoring=1e-3 * n**2, baseline=300.0) for n in (10, 20, 40, 80) for s in range(3)]
    rows += [_row("three", n, f"t{n}{s}", 1.0, 1, 300.0, design_seconds=0.5, seed=s, scoring=0.5, baseline=290.0)
             for n in (10, 20, 40) for s in range(3 if n < 40 else 1)]
    rows += [_row("free", n, f"z{n}", 1.0, 1, 300.0, design_seconds=0.0, scoring=1.0, baseline=300.0)
             for n in (10, 20, 40, 80)]
    records = Records.from_rows(rows)
    text = compute_markdown(compute_cells(records))
    lines = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    cells = [c.strip() for c in lines["four"].strip(" |").split("|")]
    assert cells[-2:] == ["2.00", "1.00"]  # design time ∝ N^2, memory added (0.01 MB per node) ∝ N
    assert "too few sizes (3)" in lines["three"] and "| three | 40 | 0.5 | 0.5 | 10 | 1 |" in text
    assert "no measurable design time" in lines["free"] and "no measurable memory added" in lines["free"]
    assert instances_per_size(records) == {10: 3, 20: 3, 40: 3, 80: 3}


def test_growth_is_stated_in_words_from_four_sizes_and_not_from_three():
    rows = [_row("Four", n, f"f{n}", 1.0, 1, 200.0 + n**1.5, design_seconds=1e-3 * n**3, scoring=0.1,
                 baseline=200.0) for n in (10, 20, 40, 80)]
    rows += [_row("Three", n, f"t{n}", 1.0, 1, 300.0, design_seconds=1e-3 * n, scoring=0.1, baseline=250.0)
             for n in (10, 20, 40)]
    text = "\n".join(growth_sentences(compute_cells(Records.from_rows(rows))))
    assert "- Four: design time grows as N^3.0; memory added grows as N^1.5." in text
    assert "Three: design time grows" not in text
    assert "Completed at fewer than 4 sizes, so no growth is stated: Three." in text
    # three sizes only: no sentence at all
    assert growth_sentences(compute_cells(Records.from_rows(rows[4:]))) == []
    # four sizes of runs stored before memory was measured: the design time's growth, the memory's unknown
    old = [dict(row, run_baseline_mb=None, run_scoring_seconds=None) for row in rows[:4]]
    text = "\n".join(growth_sentences(compute_cells(Records.from_rows(old))))
    assert f"- Four: design time grows as N^3.0; memory added was {NOT_MEASURED}." in text


def _cells(label, values, runs=6):
    return [ComputeCell(label, n, runs, runs, v, v / 10, 2 * v, 300.0 + n, memory_mb=float(n))
            for n, v in values.items()]


def test_plot_compute_has_design_scoring_and_memory_panels_with_grouped_legend():
    from compare.report.styles import style_for

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


@pytest.mark.parametrize("methods", [2, 15, 40])
def test_the_legend_keeps_to_the_fourth_place_of_the_two_by_two_grid(methods):
    """Three panels and the legend in a 2 x 2 grid (readable at 800 px); a long legend shrinks, it does not spill."""
    cells = []
    for k in range(methods):
        cells += _cells(f"method {k} with a long descriptive label (x)", {n: (k + 1) * 0.01 * n for n in (10, 20, 40, 80)})
    fig, axes = plot_compute(cells)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(renderer)
    figure = fig.bbox
    assert figure.x0 <= legend.x0 and legend.x1 <= figure.x1 and figure.y0 <= legend.y0 and legend.y1 <= figure.y1
    for ax in axes:
        assert not legend.overlaps(ax.get_tightbbox(renderer)), ax.get_title()
    top_right, bottom_left = axes[1].get_position(), axes[2].get_position()
    assert top_right.y0 > bottom_left.y1 - 1e-9 and top_right.x0 > bottom_left.x1 - 1e-9  # a 2 x 2 grid
    plt.close(fig)


def test_coinciding_lines_both_stay_visible():
    from compare.report.styles import style_for

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
    assert "| method | N | design s | scoring s | MB added | runs |" in table
    assert {line.split("|")[2].strip() for line in table.splitlines()
            if line.startswith("| ") and line.count("|") == 7} >= {"6", "12"}
    assert "too few sizes" in table and "2 instances at each N" in table
    assert NOT_MEASURED not in table and "grows as N^" not in table  # measured; two sizes state no growth
    # the SDP's size guard (12 states > max_states = 8) is reported, not timed
    assert "none of 2 runs completed" in table and "max_states = 8" in table


def test_when_every_point_rests_on_the_same_few_runs_the_title_says_it_once():
    cells = _cells("A", {10: 1.0, 20: 2.0}, runs=2) + _cells("B", {10: 3.0, 20: 5.0}, runs=2)
    fig, (design_ax, _, _) = plot_compute(cells, instances={10: 2, 20: 2})
    assert not design_ax.texts and "every point rests on 2 runs" in fig._suptitle.get_text()


def test_a_panel_without_measurements_says_so_instead_of_drawing():
    old = [ComputeCell("A", n, 2, 2, 0.1 * n, math.nan, 0.2 * n, 900.0) for n in (10, 20)]
    _, (design_ax, scoring_ax, memory_ax) = plot_compute(old)
    assert design_ax.get_lines() and not scoring_ax.get_lines() and not memory_ax.get_lines()
    assert [t.get_text() for t in scoring_ax.texts] == [NOT_MEASURED] == [t.get_text() for t in memory_ax.texts]
    assert "Memory added" in memory_ax.get_title()


# -- what the runner measures --------------------------------------------------------------

INSTANCE = {"family": "paper", "seed": 0, "n": 6, "degree": 4, "a_norm": 0.995, "b_norm": 1.0, "hops": 3,
            "horizon": 8}


def _run(method, instance=INSTANCE):
    from compare.run.spec import EvaluationSpec, Run

    return Run(instance, method, method, {}, EvaluationSpec(), "f")


def _slow_scoring(monkeypatch, pause):
    """Make the harness's scoring take ``pause`` seconds per design more."""
    import compare.run.execution

    scored = compare.run.execution.evaluate

    def slow(*args, **kwargs):
        time.sleep(pause)
        return scored(*args, **kwargs)

    monkeypatch.setattr(compare.run.execution, "evaluate", slow)


def test_a_run_measures_its_scoring_apart_from_the_method(monkeypatch):
    from compare.run.execution import execute_run

    plain = execute_run(_run("lqr"))
    assert plain.designs[0].status == "optimal" and plain.scoring_seconds >= 0
    # the parts are timed inside the run: together they fit in its wall time
    assert plain.designs[0].seconds + plain.scoring_seconds <= plain.seconds + 1e-3
    _slow_scoring(monkeypatch, 0.25)
    slow = execute_run(_run("lqr"))
    assert slow.scoring_seconds >= 0.25 and slow.seconds >= slow.scoring_seconds
    assert slow.designs[0].seconds < 0.25  # the method's own time does not take the scoring in


def test_a_batch_gives_each_run_its_own_scoring_seconds(monkeypatch):
    from baselines import lqr
    from codesign import methods
    from codesign.methods import Method
    from compare.run.execution import execute_task

    def one(instance):
        return lqr(instance)

    def batch(pairs):  # the second run gets two designs
        return [[lqr(instance)] * (1 + i) for i, (instance, _) in enumerate(pairs)]

    monkeypatch.setitem(methods._REGISTRY, "lqr_batch", Method.from_function(one, name="lqr_batch", batch=batch))
    _slow_scoring(monkeypatch, 0.2)
    first, second = execute_task([_run("lqr_batch"), _run("lqr_batch", dict(INSTANCE, seed=1))])
    assert (len(first.designs), len(second.designs)) == (1, 2)
    # one design scored against two: each run's scoring is its own, the batch's wall time shared equally
    assert 0.2 <= first.scoring_seconds < 0.4 <= second.scoring_seconds
    assert first.seconds == second.seconds >= (first.scoring_seconds + second.scoring_seconds) / 2
    assert first.baseline_mb == second.baseline_mb and first.peak_mb == second.peak_mb


@pytest.mark.skipif(not LINUX, reason="resident memory is measured on Linux")
def test_memory_added_is_the_peak_above_the_runs_start(monkeypatch):
    from baselines import lqr
    from codesign import methods
    from codesign.methods import Method
    from compare.run.execution import execute_run

    def hungry(instance):
        block = np.ones(200 * 2**20 // 8)  # 200 MB, touched
        assert block.sum() > 0
        return lqr(instance)

    monkeypatch.setitem(methods._REGISTRY, "hungry", Method.from_function(hungry, name="hungry"))
    small, large = execute_run(_run("lqr")), execute_run(_run("hungry"))
    for result in (small, large):
        assert result.baseline_mb > 20 and result.peak_mb - result.baseline_mb >= 0
    assert small.peak_mb - small.baseline_mb < 50  # the interpreter and its libraries are the baseline, not added
    assert 190 <= large.peak_mb - large.baseline_mb < 260


def test_a_report_folder_from_before_the_measurements_rebuilds_saying_they_were_not_measured(tmp_path):
    from compare.report.folder import read_folder
    from compare.report.write import write_report

    rows = [_row("m", n, f"r{n}{s}", 1.0, 1, 900.0, design_seconds=0.01 * n, seed=s)
            for n in (10, 20, 40, 80) for s in range(2)]
    for row in rows:
        row.update(experiment="old", cost_kind="exact", info_model="instantaneous", fingerprint="f")

    def report(records, out):
        files = write_report(records, out, title="Old", commands=["compare report --out o"],
                             meta={"sections:old": ["compute"]}, members={"old": {r.run_key for r in records}})
        return files["md"].read_text()

    text = report(Records.from_rows(rows), tmp_path / "first")
    header = (tmp_path / "first" / "runs.csv").read_text().splitlines()[0]
    assert "run_scoring_seconds" not in header and "run_baseline_mb" not in header  # written as before them
    again = report(read_folder(tmp_path / "first").records, tmp_path / "again")
    for page in (text, again):
        compute = page.split("## Compute against network size", 1)[1]
        assert f"scoring seconds and memory added were {NOT_MEASURED}" in compute
        assert "| m | 10 | 0.1 | ? | ? | 2 |" in compute
        assert f"- m: design time grows as N^1.0; memory added was {NOT_MEASURED}." in compute
    assert (tmp_path / "again" / "runs.csv").read_bytes() == (tmp_path / "first" / "runs.csv").read_bytes()


def test_one_timer_adds_up_its_blocks_also_when_one_raises():
    from codesign.design import Timer

    timer = Timer()
    assert timer.seconds == 0.0
    with timer:
        time.sleep(0.01)
    first = timer.seconds
    with pytest.raises(RuntimeError), timer:
        time.sleep(0.01)
        raise RuntimeError
    assert first >= 0.01 and timer.seconds >= first + 0.01
