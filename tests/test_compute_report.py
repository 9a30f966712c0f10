import math

import pytest

from compare.compute_report import ComputeCell, compute_cells, compute_markdown, growth_exponent, plot_compute
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


def _row(label, n, run_key, seconds, designs, peak, status="optimal", cost=1.0, message="", extras=None):
    inst = {"family": "paper", "seed": 0, "n": n, "a_norm": 1.05}
    return {"instance": inst, "label": label, "method": label, "params": {}, "links": 0, "cost": cost,
            "status": status, "message": message, "run_key": run_key, "idx": 0, "run_seconds": seconds,
            "run_designs": designs, "run_peak_mb": peak, "extras": extras or {}}


def test_growth_exponent_recovers_a_power_law_and_needs_two_sizes():
    assert growth_exponent([10, 20, 40], [3 * n**2.5 for n in (10, 20, 40)]) == pytest.approx(2.5)
    assert growth_exponent([10, 10], [1.0, 2.0]) is None
    assert growth_exponent([10, 20], [1.0, math.nan]) is None


def test_cells_time_per_design_over_usable_runs_only_and_keep_the_largest_peak():
    rows = [_row("m", 10, "a", 4.0, 2, 300.0), _row("m", 10, "b", 8.0, 2, 350.0),
            # a size guard: refused at once, no usable design; its 0.01 s must not count as a fast design
            _row("m", 20, "c", 0.01, 1, 310.0, status="failed", cost=math.nan, message="too large"),
            _row("m", 20, "d", 0.02, 1, None, status="failed", cost=math.nan, message="too large")]
    a, b = compute_cells(Records.from_rows(rows))
    assert (a.n, a.runs, a.completed, a.seconds_per_design, a.seconds_per_run, a.peak_mb) == (10, 2, 2, 3.0, 6.0, 350.0)
    assert (b.n, b.completed, b.why_not, b.peak_mb) == (20, 0, "too large", 310.0) and math.isnan(b.seconds_per_design)
    text = compute_markdown([a, b])
    assert "none of 2 runs completed" in text and "m, N = 20: 2 of 2: too large" in text


def test_plot_compute_draws_one_line_per_method_with_its_exponent():
    cells = [ComputeCell("m", n, 1, 1, 0.1 * n**2, 0.1 * n**2, 300.0 + n) for n in (10, 20, 40)]
    fig, (time_ax, memory_ax) = plot_compute(cells)
    (line,) = time_ax.get_lines()
    assert "N^2.0" in line.get_label() and list(line.get_xdata()) == [10, 20, 40]
    assert len(memory_ax.get_lines()) == 1 and time_ax.get_xscale() == "log"


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
    assert "N = 6: s/design, s/run, MB" in table and "N = 12: s/design, s/run, MB" in table
    # the SDP's size guard (12 states > max_states = 8) is reported, not timed
    assert "none of 2 runs completed" in table and "max_states = 8" in table
