"""The example notebooks run (reduced size) and show what they say."""

import runpy
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "first_steps.py"


def test_first_steps_notebook_runs_and_plots_four_methods(tmp_path, monkeypatch):
    monkeypatch.setenv("EXAMPLES_SMALL", "1")
    monkeypatch.chdir(tmp_path)
    namespace = runpy.run_path(str(EXAMPLE), run_name="__main__")
    _, labels = namespace["ax"].get_legend_handles_labels()
    assert len(labels) >= 4, labels
    # Run as a script, the figure goes to results/ (git-ignored), never beside the checkout's tracked files.
    assert (tmp_path / "results" / "first_steps.png").stat().st_size > 10_000
    assert [p.name for p in tmp_path.iterdir()] == ["results"]
    design = namespace["d"]
    assert design.method == "nearest_lqr" and design.cost_kind == "exact" and design.cost >= 1 - 1e-9


GRAPHS = EXAMPLE.parent / "graph_against_controller.py"


def test_graph_against_controller_notebook_splits_every_excess(monkeypatch, tmp_path):
    monkeypatch.setenv("EXAMPLES_SMALL", "1")
    monkeypatch.chdir(tmp_path)
    namespace = runpy.run_path(str(GRAPHS), run_name="__main__")
    gaps = namespace["gaps"]
    assert len(gaps) >= 3
    # The value of a design's graph is at most its own cost, and no graph within its budget is worth less
    # than the best: both gaps are non-negative, and the densest design's graph is the best within its budget.
    assert (gaps[:, 2] >= -1e-12).all() and (gaps[:, 3] >= -1e-12).all()
    assert gaps[gaps[:, 0].argmax(), 2] == 0


WEIGHTING = EXAMPLE.parent / "disturbance_weighting.py"


def test_disturbance_weighting_notebook_poses_the_h2_problem(monkeypatch, tmp_path):
    monkeypatch.setenv("EXAMPLES_SMALL", "1")
    monkeypatch.chdir(tmp_path)
    namespace = runpy.run_path(str(WEIGHTING), run_name="__main__")
    h2, B1 = namespace["h2"], namespace["B1"]
    # The normalizer is LQR's H2 cost, and the decentralized gain's cost its closed-form Lyapunov value.
    assert h2.trace_P == pytest.approx(np.trace(B1.T @ h2.P @ B1), rel=1e-12)
    design = namespace["design"]
    assert design.cost == pytest.approx(namespace["closed_form"], rel=1e-9)
    # The weighting changes the problem: the same gain search under x(0) ~ N(0, I) gives another number.
    assert abs(namespace["plain"].trace_P - h2.trace_P) > 1e-3
    # The l1 path runs from near-centralized gains down to the decentralized end (0 links).
    rows = namespace["rows"]
    assert rows[-1, 1] == 0 and rows[-1, 2] == pytest.approx(design.cost, rel=1e-6)
    assert rows[0, 2] < rows[-1, 2]
