"""Every figure a report shows is legible where the page shows it (issue 61).

At an 800 px window the report's column is 768 px wide and a wider PNG shrinks to it;
its smallest text must still be 9 px tall there, and no PNG is wider than 1,700 px. The
text sizes are read from each figure's SVG (``figure_legibility.py``), the widths from
its PNG. Checked on a report written here and on every shipped report; the page itself,
in Chromium at 800 and 1400 px, is ``test_page_layout.py``'s.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from figure_legibility import MAX_PNG_PX, SCREEN_PX, legibility, shown_figures, svg_text_sizes  # noqa: E402

from compare.report.figures import DPI, MAX_WIDTH, MIN_POINTS, PAGE_PX  # noqa: E402
from compare.report.forest import FOREST_ROWS  # noqa: E402
from compare.run.records import Records, canonical_key  # noqa: E402

REPORTS = Path(__file__).resolve().parents[1] / "reports"
SHIPPED = sorted(p.name for p in REPORTS.iterdir() if (p / "report.md").is_file())


def _problems(folder: Path) -> list[str]:
    out = []
    for png in shown_figures(folder):
        seen = legibility(png)
        if seen is None:
            continue
        if seen.width > MAX_PNG_PX:
            out.append(f"{png.name}: {seen.width} px wide (at most {MAX_PNG_PX})")
        if seen.at_800 < SCREEN_PX:
            out.append(f"{png.name}: {seen.text!r} at {seen.points:g} pt is {seen.at_800:.1f} px tall at 800 px "
                       f"({seen.width} px shown {min(seen.width, PAGE_PX)} px wide)")
    return out


def test_the_rule_leaves_room():
    """The smallest type and the widest figure the code allows meet the rule with room to spare."""
    assert MIN_POINTS * PAGE_PX / (72 * MAX_WIDTH) >= SCREEN_PX - 1e-9
    assert MAX_WIDTH * DPI <= MAX_PNG_PX


def test_text_sizes_are_read_from_the_svg(tmp_path):
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.set_yscale("log")
    ax.set_ylim(1e-3, 10)
    ax.tick_params(labelsize=10)  # 10^k: the exponent at 7 points
    ax.text(0.5, 0.5, "eight", fontsize=8, transform=ax.transAxes)
    ax.annotate("boxed", (0.2, 0.2), xycoords="axes fraction", fontsize=8.5, color="red")
    with plt.rc_context({"svg.fonttype": "path"}):
        fig.savefig(tmp_path / "f.png", dpi=DPI, bbox_inches="tight")
        fig.savefig(tmp_path / "f.svg", bbox_inches="tight")
    plt.close(fig)
    _, sizes = svg_text_sizes((tmp_path / "f.svg").read_text())
    by_text = {text: pt for pt, text in sizes}
    assert by_text["eight"] == pytest.approx(8) and by_text["boxed"] == pytest.approx(8.5)
    seen = legibility(tmp_path / "f.png")
    assert seen.points == pytest.approx(7.0) and "10^" in seen.text  # the exponent, 70 % of 10 points
    assert seen.px == pytest.approx(7.0 * DPI / 72, rel=0.02)


def _row(spec, method, label, params, cost, links, info, idx):
    return {"run_key": f"{method}-{canonical_key(spec)}-{canonical_key(params)}", "idx": idx, "experiment": "legible",
            "instance": spec, "method": method, "label": label, "params": params, "cost": cost,
            "cost_stderr": 0.001 * cost, "cost_kind": "exact", "links": links, "self_loops": spec["n"],
            "info_model": info, "status": "optimal", "message": None, "seconds": 0.1, "controller_kind": "static",
            "extras": {}, "fingerprint": "f"}


def wide_records() -> Records:
    """Five panels (five ‖A‖₂) of eight instances, a delayed path with a linear twin, its SLS bound, an ℓ1 path,
    the diagonal gain, LQR and u = 0: a budget-front row of five panels, a delayed-fronts figure and a long forest."""
    rows, facts = [], {}
    for a_norm in (0.995, 1.005, 1.05, 1.1, 1.2):
        for seed in range(8):
            spec = {"family": "paper", "n": 8, "a_norm": a_norm, "seed": seed}
            facts[canonical_key(spec)] = {"n": 8, "plant_links": 20, "comm_links": 20}
            s = 0.01 * seed + (a_norm - 1.0)
            rows.append(_row(spec, "lqr", "LQR (centralized)", {}, 1.0, 56, "instantaneous", 0))
            rows.append(_row(spec, "autonomous", "Autonomous (u = 0)", {}, 40.0 + seed, 0, "none", 0))
            rows.append(_row(spec, "decentralized", "Decentralized (diagonal K)", {}, 1.3 + s, 0, "none", 0))
            rows.append(_row(spec, "sls", "SLS bound (complete graph)", {"graph": "complete"}, 1.02 + s, 56,
                             "delayed", 0))
            for i, links in enumerate((4, 12, 30)):
                rows.append(_row(spec, "sparse_admm", "Sparse K (l1 ADMM)", {"gamma": 10.0 ** -i},
                                 1.2 - 0.05 * i + s, links, "instantaneous", i))
                rows.append(_row(spec, "sparse_delayed", "Sparse delayed K (l1)", {"gamma": 10.0 ** -i},
                                 1.25 - 0.05 * i + s, links, "delayed", i))
                for activation, label, extra in (("tanh", "GRNN-Sparse (β path)", 0.0),
                                                 ("identity", "Linear GRNN-Sparse (β path)", 0.01)):
                    rows.append(_row(spec, "grnn_sparse", label, {"beta": 10.0 ** -i, "activation": activation},
                                     1.22 - 0.05 * i + s + extra + 0.003 * seed * (i - 1), links + 2, "delayed", i))
    return Records.from_rows(rows, facts=facts)


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> Path:
    from compare.report.write import write_report

    out = tmp_path_factory.mktemp("legible")
    write_report(wide_records(), out, title="Legible")
    return out


def test_a_written_report_shows_every_figure_legibly(written):
    shown = [p.name for p in shown_figures(written)]
    assert {"budget_fronts.png", "cost_vs_links.png", "delayed_fronts.png", "forest.png"} <= set(shown)
    assert _problems(written) == []


def test_every_part_of_the_forest_is_shown(written):
    from PIL import Image

    from compare.report.findings import select_comparisons
    from compare.report.forest import forest_parts, forest_stem

    parts = forest_parts(select_comparisons(wide_records()))
    files = sorted(p.name for p in written.glob("forest*.png"))
    assert files == sorted(f"{forest_stem(k)}.png" for k in range(len(parts)))
    text = (written / "report.md").read_text()
    for name in files:
        assert f"({name})" in text  # each part shown
        assert Image.open(written / name).size[0] <= MAX_WIDTH * DPI + 1


@pytest.mark.parametrize("max_rows", [FOREST_ROWS, 6])
def test_forest_parts_keep_pairs_whole_and_rows_few(max_rows):
    from compare.report.findings import budgets_per_node, select_comparisons
    from compare.report.forest import forest_parts

    comparisons = select_comparisons(wide_records())
    by_node = budgets_per_node(comparisons)
    total = len({(c.group, c.a, c.b, c.budget_tier(by_node)) for c in comparisons})
    parts = forest_parts(comparisons, max_rows)
    assert sum(len(p) for p in parts) == len(comparisons)
    assert len(parts) >= -(-total // max_rows)
    seen = set()
    for part in parts:
        pairs = {(c.group, c.a, c.b) for c in part}
        assert not pairs & seen  # a pair is never split between parts
        seen |= pairs
        rows = {(c.group, c.a, c.b, c.budget_tier(by_node)) for c in part}
        assert len(rows) <= max_rows or len(pairs) == 1


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_figure_is_legible_at_800_px(name):
    problems = _problems(REPORTS / name)
    assert not problems, f"reports/{name} (rebuild it with `compare report --out reports/{name}`):\n" + "\n".join(
        problems)
