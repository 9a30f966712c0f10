"""Findings: which comparisons are asked, their sign tests and Holm adjustment, the text, and the forest plot."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

from dataclasses import replace  # noqa: E402

from compare.report.findings import BOUND_LABEL, Comparison, holm, is_sls_bound, select_comparisons, unresolved  # noqa: E402
from compare.report.findings_text import findings_markdown  # noqa: E402
from compare.report.forest import plot_forest  # noqa: E402
from compare.run.records import Records  # noqa: E402
from compare.report.statistics import Paired  # noqa: E402
from compare.report.styles import label_styles  # noqa: E402

SD, TANH, LINEAR, GRNN = "Sparse K, delayed (l1)", "GRNN-Sparse", "Linear GRNN-Sparse", "GRNN"
ADMM, DEC, SLS = "Sparse K (l1 ADMM)", "Decentralized", "SLS (topology family)"
SLS_PARAMS = {"act_delay": 1, "fir": None, "horizon": 50, "speed": 1.0}


def _inst(seed, a_norm=1.05):
    return {"family": "paper", "n": 20, "a_norm": a_norm, "seed": seed}


def _rec(inst, method, label, links, cost, *, info="delayed", params=None, kind="exact", stderr=0.0):
    return {"instance": inst, "method": method, "label": label, "params": params or {}, "links": links,
            "self_loops": 8, "cost": cost, "cost_stderr": stderr, "cost_kind": kind, "status": "optimal",
            "info_model": info, "run_key": f"{label}|{inst['seed']}|{links}|{cost}", "idx": 0}


def _designs(inst, i):
    """One instance's designs: the delayed static gain beats GRNN-Sparse by 0.1 everywhere; linear and tanh
    GRNN-Sparse alternate by 0.01; SLS on the complete graph is 0.05 below the static gain."""
    base = 0.01 * i
    return [
        _rec(inst, "grnn_sparse", TANH, 10, 1.20 + base, kind="simulated", stderr=1e-5),
        _rec(inst, "grnn_sparse", LINEAR, 10, 1.20 + base + (0.01 if i % 2 else -0.01),
             params={"activation": "identity"}),
        _rec(inst, "grnn", GRNN, 30, 1.15 + base, kind="simulated", stderr=1e-5),
        _rec(inst, "sparse_delayed", SD, 10, 1.10 + base),
        # Two graphs of one topology family under one label: the bound is told apart by its params.
        _rec(inst, "sls_topologies", SLS, 56, 1.05 + base, params={**SLS_PARAMS, "graph": "complete"}),
        _rec(inst, "sls_topologies", SLS, 20, 1.08 + base, params={**SLS_PARAMS, "graph": "plant"}),
        _rec(inst, "decentralized", DEC, 0, 1.30 + base, info="none"),
        _rec(inst, "sparse_admm", ADMM, 10, 1.00 + base, info="instantaneous"),
    ]


N = 12


@pytest.fixture(scope="module")
def records():
    rows = []
    for i in range(N):
        rows += _designs(_inst(i), i)
    # Unresolved costs: on seed 0 a GRNN-Sparse design that would beat the static gain; on seed 1 GRNN's only design.
    rows.append(_rec(_inst(0), "grnn_sparse", TANH, 15, 0.90, kind="simulated", stderr=0.05 * 0.90))
    rows = [r for r in rows if not (r["label"] == GRNN and r["instance"]["seed"] == 1)]
    rows.append(_rec(_inst(1), "grnn", GRNN, 30, 1.16, kind="simulated", stderr=0.02 * 1.16))
    return Records.from_rows(rows)


@pytest.fixture(scope="module")
def comparisons(records):
    return select_comparisons(records)


def _find(comparisons, a, b, budget="all"):
    out = [c for c in comparisons if c.a == a and c.b == b and (budget == "all" or c.budget == budget)]
    assert out, f"no comparison {a} − {b}"
    return out


def test_holm_matches_a_hand_computation():
    # sorted: 0.005 (x4 = 0.02), 0.01 (x3 = 0.03), 0.03 (x2 = 0.06), 0.04 (x1 = 0.04, kept monotone: 0.06)
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])  # capped at 1
    assert holm([]) == []


def test_a_design_better_on_every_instance_is_better_with_exact_and_holm_adjusted_p(comparisons):
    cells = _find(comparisons, TANH, SD)
    assert [c.budget for c in cells] == [20, 60, 140, None]
    k = len(comparisons)
    for c in cells:
        assert c.relation == "same" and c.info_a == c.info_b == "delayed"
        assert c.paired.instances == N and c.paired.b_wins == N
        assert c.paired.median == pytest.approx(0.1)
        assert c.p_value == pytest.approx(2 * 0.5 ** N)  # exact two-sided sign test, 12 of 12
        # the smallest p of the report, tied K-fold at most: Holm multiplies it by K
        assert c.p_holm == pytest.approx(min(1.0, k * 2 * 0.5 ** N))
        assert c.verdict == "worse" and c.significant
    assert [c.p_holm for c in comparisons] == pytest.approx(holm([c.p_value for c in comparisons]))


def _bullets(lines):
    return [line for line in lines if line.startswith("- ")]


NB = "\u00a0"


def _table(lines, first="| first − second |"):
    """The findings table after its header ``first``: row label (its first line) -> column -> cell."""
    i = next(k for k, line in enumerate(lines) if line.startswith(first))
    header = [c.strip() for c in lines[i].split("|")[1:-1]]
    rows = {}
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.split("|")[1:-1]]
        rows[cells[0].split("<br>")[0]] = dict(zip(header[1:], cells[1:]))
    return rows


def test_the_first_finding_is_the_delayed_result(comparisons, records):
    lines = findings_markdown(comparisons, excluded_total=len(unresolved(records)))
    # the table first, shown open however long (no sign test is out of reach here: no note before it)
    assert lines[:4] == ["## Findings", "", "<!-- table: open -->", ""]
    assert "![forest plot](forest.png)" in lines  # the figure the cells come from, after them
    rows = _table(lines)
    # rows are the pairs, columns the budgets; each cell the median [interval], k/n and a mark
    first = f"{TANH} − {SD}"
    assert list(rows)[0] == first
    assert list(rows[first]) == ["≤ 20 links", "≤ 60 links", "≤ 140 links", "any"]
    for cell in rows[first].values():
        assert cell == f"+0.1000<br>[+0.1000, +0.1000]<br>12/12{NB}▲"  # the learned design costs more, beaten
    # one row per pair, the bound after same-model rows, cross-model rows last
    labels = list(rows)
    order = [i for i, x in enumerate(labels) if x.endswith(BOUND_LABEL)]
    cross = [i for i, line in enumerate(lines[4:]) if "<br>information:" in line]
    assert order and cross and len(labels) == len({(c.a, c.b) for c in comparisons})
    assert max(order) < min(i for i, x in enumerate(labels) if x.startswith(f"{TANH} − {ADMM}"))
    # one panel: no pooled rows and no per-panel detail; bullets only for what the table cannot say
    assert not any("table: folded" in line for line in lines)
    assert _bullets(lines) == [f"- **{SLS}: plant graph − {BOUND_LABEL}**: The gap is what restricting "
                               "communication to the plant graph costs."]
    statistics = lines[-2]
    assert statistics.startswith("Statistics:") and len(statistics.split()) <= 135
    assert "2 unresolved simulated costs" in statistics and f"K = {len(comparisons)} comparisons" in statistics
    # equal and mixed are defined there, once, the margin with its reasons; the marks under the table
    assert statistics.count("**Equal within 0.1 % of LQR's cost**") == 1 and statistics.count("**Mixed**") == 1
    assert "third decimal" in statistics and "tolerances" in statistics
    legend = next(line for line in lines if line.startswith("Each cell:"))
    assert all(mark in legend for mark in ("▲", "▼", "△", "▽", "○", "=", "±", "?"))
    # without the count, the line still says that unresolved costs were dropped, never that there were none;
    # exact counts: (panel, budget, instance) pairings, and with the records over how many instances
    changed = sum(c.excluded for c in comparisons)
    assert f"changing {changed} (panel, budget, instance) pairings." in findings_markdown(comparisons)[-2]
    assert (f"changing {changed} (panel, budget, instance) pairings over 2 instances."
            in findings_markdown(comparisons, records=records)[-2])


def test_no_clear_difference_where_wins_split(comparisons):
    cells = _find(comparisons, LINEAR, TANH)
    assert all(c.paired.a_wins == c.paired.b_wins == N // 2 for c in cells[1:])
    assert all(c.verdict == "no significant difference" for c in cells)
    row = _table(findings_markdown(comparisons))[f"{LINEAR} − {TANH}"]
    assert all(cell.endswith("○") and cell.startswith("0<br>[") for cell in row.values())


def test_an_unresolved_cost_is_excluded_and_counted(records, comparisons):
    assert len(unresolved(records)) == 2
    # GRNN-Sparse's unresolved 0.90 would have won on seed 0: dropped, its resolved 1.20 is compared instead
    for c in _find(comparisons, TANH, SD):
        assert c.excluded == 1 and c.paired.a_wins == 0
    # GRNN's only design on seed 1 is unresolved: that instance leaves the comparison
    for c in _find(comparisons, GRNN, SD):
        assert c.paired.instances == N - 1 and c.excluded == 1
    assert [c.budget for c in _find(comparisons, GRNN, SD)] == [60, 140, None]  # none within 20 links
    # a pair untouched by unresolved costs counts none
    assert all(c.excluded == 0 for c in _find(comparisons, SD, BOUND_LABEL))


def test_the_bound_is_recognised_by_its_params_under_a_shared_label(records, comparisons):
    assert sum(is_sls_bound(r) for r in records) == N
    assert not any(SLS == c.a or SLS == c.b for c in comparisons)  # the mixed label is never compared whole
    (bound,) = _find(comparisons, SD, BOUND_LABEL)
    assert bound.budget is None and bound.paired.median == pytest.approx(0.05)
    assert bound.group.endswith("against the SLS bound")
    (plant,) = _find(comparisons, f"{SLS}: plant graph", BOUND_LABEL)
    assert plant.paired.median == pytest.approx(0.03)
    for a in (TANH, LINEAR, GRNN):
        assert _find(comparisons, a, BOUND_LABEL)[0].verdict == "worse"
    row = _table(findings_markdown(comparisons))[f"{SD} − {BOUND_LABEL}"]
    assert {k: v for k, v in row.items() if v} == {"any": f"+0.0500<br>[+0.0500, +0.0500]<br>12/12{NB}▲"}


def test_cross_model_comparisons_are_marked_cross(comparisons):
    for b, info in ((ADMM, "instantaneous"), (DEC, "none")):
        cells = _find(comparisons, TANH, b)
        assert len(cells) == 4 and all(c.relation == "cross" and c.info_b == info for c in cells)
    assert not [c for c in comparisons if c.a == LINEAR and c.b in (ADMM, DEC)]  # tanh only
    text = "\n".join(findings_markdown(comparisons))
    # the models under the pair, in the order the row names the designs
    assert f"| {TANH} − {ADMM}<br>information: delayed vs instantaneous |" in text
    assert f"| {TANH} − {DEC}<br>information: delayed vs none |" in text
    rows = _table(text.splitlines())
    assert all(cell.endswith("▲") for cell in rows[f"{TANH} − {ADMM}"].values())
    assert all(cell.endswith("▼") for cell in rows[f"{TANH} − {DEC}"].values())


def test_pairs_a_spec_asks_for_resolve_method_names_and_skip_absent_methods(records):
    comparisons = select_comparisons(records, pairs=[("decentralized", "sparse_admm"), ("gcnn", "lqr")])
    cells = _find(comparisons, DEC, ADMM)
    assert [c.budget for c in cells] == [20, 60, 140, None] and cells[0].relation == "cross"
    assert not [c for c in comparisons if "gcnn" in (c.a, c.b)]
    # asking for a pair already compared adds nothing
    again = select_comparisons(records, pairs=[(SD, TANH)])
    assert len(again) == len(select_comparisons(records))


def _unanimous(n, budgets=(20, 60, 140, None)):
    """GRNN-Sparse costs 0.1 more than the delayed static gain on each of ``n`` instances."""
    rows = []
    for i in range(n):
        rows += [_rec(_inst(i), "grnn_sparse", TANH, 10, 1.2 + 0.01 * i),
                 _rec(_inst(i), "sparse_delayed", SD, 10, 1.1 + 0.01 * i)]
    return select_comparisons(Records.from_rows(rows), budgets=budgets)


def test_an_interval_excluding_0_is_no_claim_unless_the_holm_adjusted_test_agrees():
    comparisons = _unanimous(7)  # 7 of 7 wins: p = 2 / 128 = 0.016, four budgets: Holm 4 p = 0.0625
    assert len(comparisons) == 4
    for c in comparisons:
        assert c.paired.low > 0 and not c.too_few and c.p_value == pytest.approx(2 / 128)
        assert c.p_holm == pytest.approx(4 * 2 / 128) and c.verdict == "no significant difference"
    lines = findings_markdown(comparisons)
    (row,) = _table(lines).values()
    # the direction, and the mark says it is no claim: △, not ▲
    assert all(cell == f"+0.1000<br>[+0.1000, +0.1000]<br>7/7{NB}△" for cell in row.values())
    assert not _bullets(lines)
    # no sign test on 7 instances passes Holm over 4: said once, before the table
    assert lines[2] == ("No test can show significance here: with at most 7 instances per budget the smallest sign-test "
                        "p is 0.016, and Holm's correction over the K = 4 tests asks for p < 0.013.")
    fig, axes = plot_forest(comparisons, {})
    assert all(to_hex(m.get_markerfacecolor()) == "#ffffff" for m in axes[0].lines if m.get_gid() == "forest-median")
    plt.close(fig)


def test_ten_of_ten_over_many_comparisons_gives_the_direction_never_no_difference():
    rows = []
    for i in range(10):
        rows += _designs(_inst(i), i)
    comparisons = select_comparisons(Records.from_rows(rows))
    k = len(comparisons)
    assert k >= 26 and all(c.p_holm >= 0.05 for c in comparisons)  # 10 of 10: p = 2 / 1024, and 26 × p > 0.05
    text = "\n".join(findings_markdown(comparisons))
    rows = _table(text.splitlines())
    assert all(cell.endswith(f"10/10{NB}△") for cell in rows[f"{TANH} − {SD}"].values())
    assert rows[f"{TANH} − {BOUND_LABEL}"]["any"].endswith(f"10/10{NB}△")
    assert f"Holm-corrected over the K = {k} comparisons" in text
    assert "▲" not in text.split("Each cell:")[0] and "▼" not in text.split("Each cell:")[0]


def _cell(a_norm, budget, median, low, high, p_holm, *, n=30, a="A", b="B"):
    """A hand-made comparison: ``a`` against ``b`` on one panel and budget, its differences spread over the interval."""
    import numpy as np

    a_wins = n if high < 0 else 0
    paired = Paired(a, b, budget, n, a_wins, n - a_wins, median, low, high, 0.99)
    return Comparison(("paper", 8, a_norm), a, b, budget, paired, "same", "delayed", "delayed", p_holm / 10, p_holm,
                      group="same information model: delayed", panel_instances=n,
                      differences=tuple(np.linspace(low, high, n)))


def _detail(lines):
    """The per-panel table: (pair, panel) -> column -> cell."""
    i = next(k for k, line in enumerate(lines) if line.startswith("| first − second, per panel |"))
    header = [c.strip() for c in lines[i].split("|")[1:-1]]
    out, pair = {}, None
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.split("|")[1:-1]]
        if cells[0].startswith("**"):
            pair = cells[0].strip("*")
            continue
        out[(pair, cells[0])] = dict(zip(header[1:], cells[1:]))
    return out


def test_a_claim_that_fails_in_one_cell_keeps_its_own_mark_in_the_detail():
    cells = [_cell(norm, budget, 0.05, 0.03, 0.07, 1e-6) for norm in (0.995, 1.1, 1.2) for budget in (20, None)]
    cells[-2] = _cell(1.2, 20, 0.08, 0.026, 0.19, 0.13)  # interval excludes 0, Holm does not
    cells[2] = _cell(1.1, 20, 0.018, 0.011, 0.023, 1e-4)  # the weakest claim
    lines = findings_markdown(cells)
    detail = _detail(lines)
    assert detail[("A − B", "‖A‖₂ = 1.2")]["≤ 20 links"] == f"+0.08<br>[+0.03, +0.19]<br>30/30{NB}△"
    # two significant digits in the interval's width, no more: +0.018 [+0.011, +0.023]
    assert detail[("A − B", "‖A‖₂ = 1.1")]["≤ 20 links"] == f"+0.018<br>[+0.011, +0.023]<br>30/30{NB}▲"
    # pooled over the three panels: 90 instances, one test per budget, Holm over the two
    row = _table(lines)["A − B"]
    assert row["≤ 20 links"].endswith(f"90/90{NB}▲") and row["any"].endswith(f"90/90{NB}▲")
    assert "folded: the same, panel by panel" in "\n".join(lines)


def test_cells_against_the_pooled_row_make_it_mixed_and_get_a_bullet():
    cells = [_cell(norm, None, -0.05, -0.07, -0.03, 1e-6) for norm in (0.995, 1.1)]
    cells += [_cell(1.2, None, 0.04, 0.02, 0.06, 0.01),  # significant the other way
              _cell(0.995, 20, 0.01, -0.01, 0.02, 1.0),  # interval contains 0
              _cell(1.1, 20, 0.01, 0.005, 0.02, 0.2),  # the other way, not significant
              replace(_cell(1.2, 20, 0.0, -0.1, 0.1, 1.0, n=4), paired=Paired("A", "B", 20, 4, 1, 3, 0.0, -0.1, 0.1,
                                                                                0.88))]
    lines = findings_markdown(cells)
    detail = _detail(lines)
    marks = {(panel, budget): cell[-1] for (_, panel), row in detail.items() for budget, cell in row.items() if cell}
    assert marks == {("‖A‖₂ = 0.995", "any"): "▼", ("‖A‖₂ = 1.1", "any"): "▼", ("‖A‖₂ = 1.2", "any"): "▲",
                     ("‖A‖₂ = 0.995", "≤ 20 links"): "○", ("‖A‖₂ = 1.1", "≤ 20 links"): "△",
                     ("‖A‖₂ = 1.2", "≤ 20 links"): "?"}
    # pooled with any number of links, A costs less on 60 of 90, but on ‖A‖₂ = 1.2 B beats A: mixed, said why
    assert _table(lines)["A − B"]["any"].endswith(f"60/90{NB}±")
    (bullet,) = _bullets(lines)
    assert bullet.startswith("- **A − B, mixed (±)**: pooled with any number of links, A costs less on 60 of 90 "
                             "instances, yet on ‖A‖₂ = 1.2 B costs less (median +0.040)")
    assert len(bullet.split()) <= 60


def test_too_few_instances_give_counts_only():
    rows = []
    for i in range(3):
        rows += [_rec(_inst(i), "grnn_sparse", TANH, 10, 1.2 + 0.01 * i),
                 _rec(_inst(i), "sparse_delayed", SD, 10, 1.1 + 0.01 * i)]
    comparisons = select_comparisons(Records.from_rows(rows), budgets=(None,))
    (c,) = comparisons
    assert c.too_few and c.verdict == "too few" and not c.significant
    lines = findings_markdown(comparisons)
    (row,) = _table(lines).values()
    assert row == {"any": f"+0.10<br>3/3{NB}?"}  # the median alone: no interval, counts only
    assert not _bullets(lines)
    fig, axes = plot_forest(comparisons, {})
    (marker,) = [line for line in axes[0].lines if line.get_gid() == "forest-median"]
    assert to_hex(marker.get_markeredgecolor()) == "#999999" and to_hex(marker.get_markerfacecolor()) == "#ffffff"
    plt.close(fig)


def test_forest_has_one_row_per_comparison_filled_where_significant(records, comparisons):
    two_panels = list(records) + [r for i in range(N) for r in _designs(_inst(i, a_norm=1.2), i)]
    comparisons = select_comparisons(Records(Records.from_rows(two_panels)))
    styles = label_styles(Records.from_rows(two_panels))
    fig, axes = plot_forest(comparisons, styles)
    assert len(axes) == 2
    for ax, panel in zip(axes, (("paper", 20, 1.05), ("paper", 20, 1.2))):
        mine = [c for c in comparisons if c.panel == panel]
        markers = [line for line in ax.lines if line.get_gid() == "forest-median"]
        assert len(markers) == len(mine)
        filled = [m for m in markers if to_hex(m.get_markerfacecolor()) != "#ffffff"]
        assert len(filled) == sum(c.significant for c in mine) > 0
        assert len(markers) - len(filled) == sum(not c.significant for c in mine) > 0
        assert f"{N} instances" in ax.get_title()
    # one y row per (pair, budget), shared by the panels
    assert len(axes[0].get_yticks()) == len({(c.a, c.b, c.budget) for c in comparisons})
    # colour is a's style; the bound's own colour where it is the first
    tanh = [m for m in axes[0].lines if m.get_gid() == "forest-median" and m.get_marker() == styles[TANH].marker]
    assert tanh and all(to_hex(m.get_markeredgecolor()) == styles[TANH].colour.lower() for m in tanh)
    plt.close(fig)


def test_panels_are_compared_in_numeric_order_of_n():
    """Instance keys are JSON text, where "n": 100 sorts before "n": 20; the comparisons follow N as a number."""
    rows = []
    for n in (100, 20, 50):
        for i in range(6):
            rows += _designs(dict(_inst(i), n=n), i)
    comparisons = select_comparisons(Records.from_rows(rows))
    seen = list(dict.fromkeys(c.panel[1] for c in comparisons))
    assert seen == [20, 50, 100]


def test_budgets_are_links_per_node_in_each_panel():
    """1, 3 and 7 links per node, then any: the budget tables' columns, at every N (a fixed 140 links
    would be every link at N = 8 and almost none at N = 1000)."""
    small = [r for i in range(N) for r in _designs({**_inst(i), "n": 8}, i)]
    large = [{**r, "links": 100 * r["links"]} for i in range(N) for r in _designs({**_inst(i), "n": 1000}, i)]
    comparisons = select_comparisons(Records.from_rows(small + large))
    by_panel = {}
    for c in comparisons:
        if c.a == TANH and c.b == SD:
            by_panel.setdefault(c.panel[1], []).append(c.budget)
    # At N = 8 both designs (10 links) first fit within 24 (56 = N(N - 1) would repeat "any");
    # at N = 1000 (1000 links) within 1000.
    assert by_panel == {8: [24, None], 1000: [1000, 3000, 7000, None]}
    # The forest's rows are then budgets per node, each panel at its own link count.
    fig, axes = plot_forest(comparisons, label_styles(Records.from_rows(small + large)))
    labels = [t.get_text() for t in axes[0].get_yticklabels()]
    assert {"≤ 1/node", "≤ 3/node", "≤ 7/node", "any"} <= set(labels) and not any("≤ 24" in x for x in labels)
    plt.close(fig)


@pytest.mark.parametrize("panel_inches", [1.6, 4.0])
def test_forest_tick_labels_never_overlap_and_stay_inside_their_panel(panel_inches):
    """Four narrow panels side by side (scale-large) once printed "+0.001+0.01" as one word."""
    from compare.report.forest import _symlog_axis

    fig, axes = plt.subplots(1, 4, figsize=(1.0 + 4 * panel_inches, 2.0))
    fig.subplots_adjust(left=0.5 / fig.get_figwidth(), right=0.98, wspace=0.06)
    values = [-0.015, -0.012, -0.002, 0.0004, 0.02]
    for ax in axes:
        _symlog_axis(ax, values)
        ax.tick_params(axis="both", labelsize=8)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in axes:
        labels = sorted((t for t in ax.get_xticklabels() if t.get_text()), key=lambda t: t.get_position()[0])
        boxes = [t.get_window_extent(renderer) for t in labels]
        texts = [t.get_text() for t in labels]
        assert "0" in texts and "-0.01" in texts and "+0.01" in texts
        for left, right in zip(boxes, boxes[1:]):
            assert left.x1 < right.x0, texts
        frame = ax.get_window_extent(renderer)
        reach = 0.06 * fig.dpi + 1  # a label may overhang its panel by under half the gap between panels
        assert frame.x0 - reach <= boxes[0].x0 and boxes[-1].x1 <= frame.x1 + reach, texts
    if panel_inches > 3:  # room for every decade: nothing is dropped but ±linthresh
        assert {"-0.001", "+0.001"} <= set(texts)
    plt.close(fig)


def test_forest_pair_names_end_before_the_budget_labels(comparisons):
    """Long labels ("Linear GRNN-Sparse (β path, 150 steps)") once ran into "≤ 3/node": widths are measured."""
    # Six panels, as in the scale report: the old layout placed the names at a fraction of the figure's width.
    long = [replace(c, a=f"LINEAR {c.a.upper()} (WIDE CAPITALS, 150 STEPS)", panel=(c.panel[0], n, a_norm),
                    budget=None if c.budget is None else c.budget * n // 20)
            for n in (20, 50, 100) for a_norm in (0.995, 1.05) for c in comparisons]
    fig, axes = plot_forest(long, {})
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    budgets = [t.get_window_extent(renderer) for t in axes[0].get_yticklabels() if t.get_text()]
    names = [t.get_window_extent(renderer) for t in axes[0].texts if "\n− " in t.get_text()]
    assert budgets and names
    assert any("/node" in t.get_text() for t in axes[0].get_yticklabels())
    assert max(box.x1 for box in names) < min(box.x0 for box in budgets)
    plt.close(fig)


def test_a_findings_row_pools_no_median_over_panels_that_are_different_systems():
    """A chain, a platoon and a ring are different systems: a pair compared on all three gets a row for each, whose
    cells are each panel's own, never one median over all their instances (#61); panels of the paper's family at
    two ‖A‖₂ are one kind of system and still pool."""
    gaps = {"chain": (0.020, 0.021, 0.022), "platoon": (0.050, 0.052, 0.054), "ring": (0.110, 0.111, 0.112, 0.113)}
    rows = []
    for family, values in gaps.items():
        for s, gap in enumerate(values):
            inst = {"family": family, "n": 20, "seed": s}
            rows += [_rec(inst, "grnn_sparse", TANH, 10, 1.1 + gap), _rec(inst, "sparse_delayed", SD, 10, 1.1)]
    records = Records.from_rows(rows)
    comparisons = select_comparisons(records, budgets=(None,))
    assert len(comparisons) == 3
    lines = findings_markdown(comparisons, records=records)
    i = lines.index("| first − second | any |")
    table = [line for line in lines[i + 2:i + 10] if line.startswith("|")]
    labels = [line.split("|")[1].strip() for line in table]
    assert labels == [f"{TANH} − {SD}<br>on {f}" for f in gaps]
    # each row is its system's median over its own instances (3/3, 3/3, 4/4): none over all 10 of them (+0.052)
    cells = [line.split("|")[2].strip() for line in table]
    assert cells == [f"+0.021<br>3/3{NB}?", f"+0.052<br>3/3{NB}?", f"+0.11<br>4/4{NB}?"]
    assert not any("10/10" in line for line in lines)
    legend = next(line for line in lines if line.startswith("Each cell:"))
    assert "pools every panel" not in legend and "different systems" in legend
    # the paper's family at two ‖A‖₂ is one kind of system: one row, pooled over both panels
    paper = []
    for a_norm in (0.995, 1.05):
        for s in range(3):
            paper += [_rec(_inst(s, a_norm=a_norm), "grnn_sparse", TANH, 10, 1.2),
                      _rec(_inst(s, a_norm=a_norm), "sparse_delayed", SD, 10, 1.1)]
    records = Records.from_rows(paper)
    lines = findings_markdown(select_comparisons(records, budgets=(None,)), records=records)
    (row,) = _table(lines).values()
    assert row["any"].endswith(f"6/6{NB}▲")
    assert any("A row pools every panel where the pair is compared" in line for line in lines)
