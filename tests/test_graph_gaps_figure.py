"""The shipped topology report's graph-gap figure and opening, read back against its tables (#59, item 4).

Every bar of ``graph_gaps.png`` (a method's median graph or controller gap within a budget) is the
median its table prints, and every table cell has its bar; the opening quotes GRNN-Sparse's graph
and controller gaps within 20 and 60 links on the paper family, and the l1 paths' controller gaps,
as those cells print them.
"""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from compare.report.folder import read_folder  # noqa: E402
from compare.report.graph_gaps import graph_gaps, plot_graph_gaps  # noqa: E402
from compare.report.styles import label_styles  # noqa: E402

FOLDER = Path(__file__).resolve().parent.parent / "reports" / "topology"
_NUMBER = re.compile(r"^([+−-]?\d+(?:\.\d+)?) %|^0 %")


def _section_tables(text: str) -> dict:
    """(system title, label, budget text, part) -> the cell's text, from the section's per-system tables."""
    section = text.split("## Graph against controller", 1)[1].split("\n## ", 1)[0]
    section = section.split("### The learned controller", 1)[0]  # the per-system gap tables only
    cells, system = {}, None
    for line in section.splitlines():
        if line.startswith("### "):
            system = line[4:].strip()
        elif line.startswith("| ") and system and not line.startswith(("| method", "|---")) and line.count("|") == 8:
            label, _model, budget, _n, _excess, graph, controller = [c.strip() for c in line.strip("|").split("|")]
            cells[(system, label, budget, "graph")] = graph
            cells[(system, label, budget, "controller")] = controller
    return cells


def _median(cell: str) -> float:
    match = _NUMBER.match(cell)
    assert match, cell
    return 0.0 if match.group(1) is None else float(match.group(1).replace("−", "-"))


@pytest.fixture(scope="module")
def shipped():
    if not (FOLDER / "report.md").is_file():
        pytest.fail(f"{FOLDER} is not shipped: compare run topology writes it")
    return read_folder(FOLDER), (FOLDER / "report.md").read_text()


def test_every_bar_is_its_table_cell(shipped):
    folder, text = shipped
    cells = _section_tables(text)
    assert cells, "the report has no graph-gap tables"
    fig, axes = plot_graph_gaps(graph_gaps(folder.records), styles=label_styles(folder.records))
    try:
        bars = {p.get_gid(): p.get_height() for ax in axes for p in ax.patches if p.get_gid()}
    finally:
        plt.close(fig)
    by_key = {f"graph_gaps:{s}:{label}:{part}:{budget}": cell for (s, label, budget, part), cell in cells.items()
              if cell != "–"}
    assert set(bars) == set(by_key)
    for gid, height in bars.items():
        assert height == pytest.approx(_median(by_key[gid]), abs=0.005 + 1e-9), gid  # the cell's two decimals


def test_the_opening_quotes_grnn_sparse_cells_at_20_and_60_links(shipped):
    _, text = shipped
    opening = text.split("\n## ", 1)[0]
    cells = _section_tables(text)
    system = next(s for s, *_ in cells if s.startswith("paper"))
    for budget in ("≤ 20", "≤ 60"):
        for part in ("graph", "controller"):
            cell = next(c for (s, label, b, p), c in cells.items()
                        if s == system and label.startswith("GRNN-Sparse") and b == budget and p == part)
            quoted = cell.split(" (")[0]  # without a coverage note
            assert quoted in opening, (budget, part, quoted)
    for label in ("Sparse delayed K (l1)", "Sparse K (l1 ADMM)"):  # the l1 paths' controller gaps, as printed
        for budget in ("≤ 20", "≤ 60"):
            cell = cells[(system, label, budget, "controller")].split(" (")[0]
            assert cell in opening or cell.startswith("0 % [0 %, 0 %]"), (label, budget, cell)
    assert re.search(r"GRNN (beats|costs more than|does not clearly beat) the static gain", opening)
