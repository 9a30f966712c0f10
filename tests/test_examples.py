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
    assert (tmp_path / "first_steps.png").stat().st_size > 10_000
    design = namespace["d"]
    assert design.method == "nearest_lqr" and design.cost_kind == "exact" and design.cost >= 1 - 1e-9
