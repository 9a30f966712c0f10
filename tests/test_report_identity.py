"""The shipped reports: one visual identity, and no figure point where no design is."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from compare.report.styles import METHOD_STYLES, style_for

REPORTS = Path(__file__).resolve().parents[1] / "reports"
SHIPPED = ("quick", "scale", "systems", "table1", "tradeoff", "small", "benchmark-systems", "scale-large", "power",
           "learned-class")


def _label_kinds(folder: Path) -> dict:
    """Label -> (method, params, info model) of its first design in the folder's runs.csv."""
    kinds = {}
    with (folder / "runs.csv").open() as handle:
        for row in csv.DictReader(handle):
            kinds.setdefault(row["label"], (row["method"], json.loads(row["params"]), row["info_model"]))
    return kinds


def test_every_report_is_shipped_with_the_data_that_rebuild_it():
    for name in SHIPPED:
        for file in ("report.md", "report.html", "runs.csv", "report.json", "plotly.min.js"):
            assert (REPORTS / name / file).is_file(), f"reports/{name}/{file}"


@pytest.mark.parametrize("name", SHIPPED)
def test_a_method_has_the_same_colour_and_marker_in_every_figure_of_every_report(name):
    """What each figure drew (read back from its artists when it was saved) is the method's one style."""
    folder = REPORTS / name
    figures = json.loads((folder / "report.json").read_text())["figures"]
    kinds = _label_kinds(folder)
    assert {"cost_vs_links", "budget_fronts"} <= set(figures)
    checked = 0
    for stem, drawn in figures.items():
        for label, pairs in drawn.items():
            method, params, info = kinds[label]
            style = style_for(method, params, info)
            assert [list(p) for p in pairs] == [[style.colour.lower(), style.marker]], (stem, label)
            checked += 1
    assert checked >= 2 * len(kinds) - 2
    # Built-in methods take their colours from the one table, not from their position in a list.
    assert all(style_for(method, params).colour in {c for c, _, _ in METHOD_STYLES.values()}
               for method, params, _ in kinds.values() if "plugin" not in method)


def test_colours_are_grouped_by_information_model_and_pairs_are_unique():
    pairs = [(c, m) for c, m, _ in METHOD_STYLES.values()]
    assert len(set(pairs)) == len(pairs)
    by_colour = {}
    for colour, _, info in METHOD_STYLES.values():
        by_colour.setdefault(colour, set()).add(info)
    assert all(len(models) == 1 for models in by_colour.values())  # a colour never spans two models
    plugin = style_for("my_plugin:design")
    assert plugin == style_for("my_plugin:design") and plugin.colour not in {c for c, _, _ in METHOD_STYLES.values()}


def test_no_marker_of_the_cost_figure_stands_at_a_link_count_no_design_has():
    """Rebuild quick's cost-versus-links figure from its folder: every marker sits at a link count some design of
    the same method and panel has."""
    from compare.report.cost_links import aggregate, plot_cost_vs_links
    from compare.report.folder import read_folder
    from compare.report.write import report_records

    records = report_records(read_folder(REPORTS / "quick").records)
    points = aggregate(records)
    fig, axes = plot_cost_vs_links(points, records=records)
    checked = 0
    for panel, ax in axes.items():
        by_label = records.filter(lambda r, p=panel: r.instance.panel == p).by_label
        for line in ax.lines:
            gid = line.get_gid() or ""
            if not gid.startswith("method:"):
                continue
            label = gid[len("method:"):]
            counts = {r.links for r in by_label[label] if r.ok}
            for x in np.asarray(line.get_xdata(), dtype=float):
                assert x in counts, (panel, label, x)
                checked += 1
    # Every setting drawn (on or above its method's front, within the axis) was checked, and there are some.
    from compare.report.figures import OFF_SCALE

    assert checked == sum(p.ok > 0 and p.reached and p.cost[1] <= OFF_SCALE for p in points) >= 10


def test_compare_report_rebuilds_quick_from_the_shipped_folder_alone(tmp_path):
    """No store is shipped: runs.csv, curves.csv and report.json rebuild the report, every table identical."""
    import shutil

    from click.testing import CliRunner

    from compare.cli import main

    folder = tmp_path / "quick"
    shutil.copytree(REPORTS / "quick", folder)
    assert not (folder / "results.sqlite").exists()
    result = CliRunner().invoke(main, ["report", "--out", str(folder)])
    assert result.exit_code == 0, result.output
    assert "rebuilt from the folder" in result.output
    for name in ("runs.csv", "curves.csv", "report.json"):
        assert (folder / name).read_bytes() == (REPORTS / "quick" / name).read_bytes(), name

    def body(path):
        # The one line that names the folder it was rebuilt in.
        return [line for line in path.read_text().splitlines() if "compare report --out" not in line]

    shipped, rebuilt = body(REPORTS / "quick" / "report.md"), body(folder / "report.md")
    assert [line for line in rebuilt if line.startswith("|")] == [line for line in shipped if line.startswith("|")]
    assert rebuilt == shipped
    assert sum(line.startswith("|") for line in shipped) > 100
