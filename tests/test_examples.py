"""The example notebook runs (reduced size) and its figure shows at least four methods."""

import runpy
from pathlib import Path

import matplotlib

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
