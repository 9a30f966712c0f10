"""Wording and counting in a report: equal and mixed verdicts, premises of notes, pair order, exact counts,
plurals, one name per method, and instance counts per cell."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

from compare.report.findings import select_comparisons, unresolved  # noqa: E402
from compare.report.findings_text import EQUAL_WORDS, complete_plant_panels, findings_markdown  # noqa: E402
from compare.report.forest import plot_forest  # noqa: E402
from compare.report.pattern_gaps import pattern_gap_section  # noqa: E402
from compare.run.records import Records, canonical_key  # noqa: E402
from compare.report.write import report_records  # noqa: E402
from compare.report.tables import canonical_label  # noqa: E402

SD, TANH = "Sparse delayed K (l1)", "GRNN-Sparse"
SLS_PARAMS = {"act_delay": 1, "fir": None, "horizon": 50, "speed": 1.0}


def _inst(seed, n=8, a_norm=1.05):
    return {"family": "paper", "n": n, "a_norm": a_norm, "seed": seed}


def _rec(inst, method, label, cost, *, links=10, info="delayed", params=None, kind="exact", stderr=0.0):
    return {"instance": inst, "method": method, "label": label, "params": params or {}, "links": links,
            "self_loops": 8, "cost": cost, "cost_stderr": stderr, "cost_kind": kind, "status": "optimal",
            "info_model": info, "run_key": f"{label}|{canonical_key(inst)}|{links}|{cost}", "idx": 0}


def _bullets(lines):
    return [line for line in lines if line.startswith("- ")]


NB = "\u00a0"


def _rows(lines, first="| first − second |"):
    """Row label (its first line) -> column -> cell, of the table whose header starts with ``first``."""
    i = next(k for k, line in enumerate(lines) if line.startswith(first))
    header = [c.strip() for c in lines[i].split("|")[1:-1]]
    out = {}
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.split("|")[1:-1]]
        out[cells[0].split("<br>")[0]] = dict(zip(header[1:], cells[1:]))
    return out


def _pair(costs_a, costs_b):
    """GRNN-Sparse (a) against the delayed l1 gain (b) with any number of links: one comparison."""
    rows = []
    for s, (a, b) in enumerate(zip(costs_a, costs_b)):
        rows += [_rec(_inst(s), "grnn_sparse", TANH, a), _rec(_inst(s), "sparse_delayed", SD, b)]
    records = Records.from_rows(rows)
    (cell,) = select_comparisons(records, budgets=(None,))
    return records, cell


# --------------------------------------------------------------------------- equal and mixed


def test_an_equal_cell_is_marked_equal_never_beats():
    base = [1.0 + 0.01 * s for s in range(10)]
    records, cell = _pair([c + 2e-6 for c in base], base)  # 10 of 10 by 2e-6: tested, but within the margin
    assert cell.verdict == "equal" and cell.tested
    lines = findings_markdown([cell])
    # a difference of 2e-6 prints at the precision the costs resolve: 0, never "+0.0000"
    assert _rows(lines)[f"{TANH} − {SD}"] == {"any": f"0<br>[0, 0]<br>10/10{NB}="}
    assert EQUAL_WORDS == "equal within 0.1 % of LQR's cost"
    assert f"=: {EQUAL_WORDS}" in next(line for line in lines if line.startswith("Each cell:"))
    assert not _bullets(lines) and "▲" not in "\n".join(lines[:6])
    # drawn hollow, and the legend says what hollow means
    fig, axes = plot_forest([cell], {})
    (marker,) = [m for m in axes[0].lines if m.get_gid() == "forest-median"]
    assert to_hex(marker.get_markerfacecolor()) == "#ffffff"
    legend = " ".join(t.get_text() for t in fig.legends[0].get_texts())
    assert "hollow" in legend and EQUAL_WORDS in legend and "mixed" in legend
    plt.close(fig)


def _mixed():
    """GRNN-Sparse costs 0.002 less on 10 of 12 instances, but far more on the two where the static gain is
    cheapest: the typical instance favours GRNN-Sparse, the median costs the static gain."""
    b = [1.0 + 0.01 * s for s in range(12)]
    a = [1.5, 1.5] + [x - 0.002 for x in b[2:]]
    return _pair(a, b)


def test_a_mixed_cell_gives_both_the_typical_instance_and_the_median_costs():
    _, cell = _mixed()
    assert cell.verdict == "mixed" and not cell.significant
    assert cell.drawn_a > cell.drawn_b and cell.paired.median < 0
    lines = findings_markdown([cell])
    assert _rows(lines)[f"{TANH} − {SD}"]["any"].endswith(f"10/12{NB}±")
    (bullet,) = _bullets(lines)
    assert bullet == (f"- **{TANH} − {SD}, mixed (±)**: on ‖A‖₂ = 1.05, with any number of links, {TANH} costs less "
                      "on 10 of 12 instances (median −0.0020), yet Sparse delayed K has the lower median cost "
                      "(1.0550 against 1.0730).")
    assert "beats" not in bullet
    fig, axes = plot_forest([cell], {})
    (marker,) = [m for m in axes[0].lines if m.get_gid() == "forest-median"]
    assert to_hex(marker.get_markerfacecolor()) == "#ffffff"
    plt.close(fig)


def test_the_statistics_line_defines_equal_and_mixed_once_with_the_margin_and_why():
    _, cell = _mixed()
    statistics = findings_markdown([cell])[-2]
    assert statistics.count(f"**{EQUAL_WORDS[0].upper() + EQUAL_WORDS[1:]}**") == 1
    assert statistics.count("**Mixed**") == 1
    assert "third decimal" in statistics and "tolerances" in statistics and "standard errors" in statistics
    assert "the figures draw" in statistics


def test_a_mixed_cell_beside_a_claim_gets_a_bullet_of_its_own():
    from dataclasses import replace

    _, mixed = _mixed()
    claim = replace(mixed, panel=("paper", 8, 1.2), paired=replace(mixed.paired, median=-0.01, low=-0.02,
                                                                   high=-0.005, a_wins=12, b_wins=0),
                    drawn_a=1.0, drawn_b=1.1, p_holm=0.001, differences=tuple(-0.01 - 0.001 * k for k in range(12)))
    assert claim.significant
    lines = findings_markdown([claim, mixed])
    detail = "\n".join(lines[lines.index("<!-- table: folded: the same, panel by panel -->"):])
    assert f"| ‖A‖₂ = 1.2 | −0.010<br>[−0.020, −0.005]<br>12/12{NB}▼ |" in detail
    (bullet,) = _bullets(lines)
    assert bullet.startswith(f"- **{TANH} − {SD}, mixed (±)**: ")
    assert f"on ‖A‖₂ = 1.05, with any number of links, {TANH} costs less on 10 of 12 instances" in bullet


# --------------------------------------------------------------------------- notes and pair order


def _sls(plant_links: int, n: int = 4, same: bool = True):
    """SLS on the plant graph and the bound on 8 instances of N nodes, with the plant graph's link count stored."""
    rows, facts = [], {}
    for s in range(8):
        inst = _inst(s, n=n)
        facts[canonical_key(inst)] = {"n": n, "plant_links": plant_links, "comm_links": plant_links, "nodes": n}
        bound = 1.1 + 0.01 * s
        rows += [_rec(inst, "sls_topologies", "SLS", bound, links=n * (n - 1),
                      params={**SLS_PARAMS, "graph": "complete"}),
                 _rec(inst, "sls_topologies", "SLS", bound if same else bound + 0.01, links=plant_links,
                      params={**SLS_PARAMS, "graph": "plant"})]
    return report_records(Records.from_rows(rows, facts))


def test_the_plant_graph_note_is_printed_only_where_the_plant_graph_is_not_complete():
    complete = _sls(plant_links=12)  # N = 4: 12 = N(N - 1) links, the complete graph
    assert complete_plant_panels(complete) == {("paper", 4, 1.05)}
    for records in (complete, None):  # from the instance facts, or from identical costs without them
        text = "\n".join(findings_markdown(select_comparisons(complete), records=records))
        assert "restricting communication to the plant graph" not in text
        assert "Here the plant graph is the complete graph, so the two are one design." in text
    sparse = _sls(plant_links=6, same=False)
    assert not complete_plant_panels(sparse)
    text = "\n".join(findings_markdown(select_comparisons(sparse), records=sparse))
    assert "The gap is what restricting communication to the plant graph costs." in text


def test_a_cross_model_row_names_the_models_in_the_order_it_names_the_designs():
    rows = []
    for s in range(12):
        inst = _inst(s, n=20)
        rows += [_rec(inst, "gcnn", "GCNN", 1.3 + 0.01 * s, links=100, info="instantaneous"),
                 _rec(inst, "grnn", "GRNN", 1.1 + 0.01 * s, links=100)]
    # table1 asks for ("gcnn", "grnn"): GCNN first, and GRNN wins
    comparisons = select_comparisons(Records.from_rows(rows), pairs=[("gcnn", "grnn")], budgets=(None,))
    lines = findings_markdown(comparisons)
    assert "| GCNN − GRNN<br>information: instantaneous vs delayed |" in "\n".join(lines)
    assert _rows(lines)["GCNN − GRNN"]["any"].endswith(f"12/12{NB}▲")  # GCNN costs more: GRNN beats it


# --------------------------------------------------------------------------- exact counts and plurals


def test_unresolved_costs_are_counted_as_cell_instance_pairings_over_instances():
    rows = []
    for s in range(12):
        rows += [_rec(_inst(s), "grnn_sparse", TANH, 1.2 + 0.01 * s, kind="simulated", stderr=1e-5),
                 _rec(_inst(s), "sparse_delayed", SD, 1.1 + 0.01 * s)]
    # one unresolved design on instance 0 that would have won every budget's cell
    rows.append(_rec(_inst(0), "grnn_sparse", TANH, 0.9, links=5, kind="simulated", stderr=0.05))
    records = Records.from_rows(rows)
    comparisons = select_comparisons(records)
    changed = sum(c.excluded for c in comparisons)
    assert changed == len(comparisons) > 1  # one instance, counted once per cell
    statistics = findings_markdown(comparisons, excluded_total=len(unresolved(records)), records=records)[-2]
    assert (f"1 unresolved simulated cost (standard error > 1 % of the cost) was dropped, changing {changed} "
            "(panel, budget, instance) pairings over 1 instance.") in statistics
    assert "re-pairing" not in statistics
    assert not _bullets(findings_markdown(comparisons))  # said once, not per pair


def test_counts_of_one_are_singular():
    records, cell = _pair([1.2], [1.1])
    lines = findings_markdown([cell])
    text = "\n".join(lines)
    assert "1 instances" not in text and "K = 1 comparisons" not in text and "K = 1 tests" not in text
    assert "with at most 1 instance per budget" in text and "K = 1 comparison" in text
    fig, axes = plot_forest([cell], {})
    assert axes[0].get_title().endswith("\n1 instance")
    plt.close(fig)


# --------------------------------------------------------------------------- names and per-cell counts


def test_a_reworded_registered_label_gets_the_registered_name_in_every_report():
    registry = {"sparse_delayed": SD, "grnn_sparse": "GRNN-Sparse"}
    assert canonical_label("sparse_delayed", "Sparse K, delayed (l1)", registry) == SD
    assert canonical_label("sparse_delayed", "Sparse K, delayed (ℓ1)", registry) == SD
    # labels that name a setting or a variant are kept
    assert canonical_label("grnn_sparse", "GRNN-Sparse (β path, 150 steps)", registry) == \
        "GRNN-Sparse (β path, 150 steps)"
    assert canonical_label("grnn_sparse", "Linear GRNN-Sparse (β path)", registry) == "Linear GRNN-Sparse (β path)"
    assert canonical_label("plugin", "My design", registry) == "My design"
    # report_records applies it with the method registry: one name, whichever a spec gave
    records = report_records(Records.from_rows([_rec(_inst(0), "sparse_delayed", "Sparse K, delayed (l1)", 1.1),
                                                _rec(_inst(1), "sparse_delayed", SD, 1.1)]))
    assert {r.label for r in records} == {SD}


def test_a_pattern_gap_resting_on_fewer_instances_than_its_row_gives_its_count():
    rows = []
    for s in range(4):
        inst = _inst(s, n=3)
        rows += [_rec(inst, "best_pattern", "Best pattern found", c, links=k, info="instantaneous",
                      params={"budget": k})
                 for k, c in ((0, 1.3), (2, 1.1), (6, 1.0))]
        # the method has a design within 0 links on half of the instances only
        rows.append(_rec(inst, "sparse_admm", "Sparse K (l1 ADMM)", 1.12, links=2, info="instantaneous"))
        if s < 2:
            rows.append(_rec(inst, "sparse_admm", "Sparse K (l1 ADMM)", 1.35, links=0, info="instantaneous"))
    section = "\n".join(pattern_gap_section(Records.from_rows(rows)))
    (row,) = [line for line in section.splitlines() if line.startswith("| Sparse K (l1 ADMM)")]
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[1] == "4"  # the row: instances with any gap
    assert cells[2] == "+3.8 % (2)"  # ≤ 0 links: on 2 of them only
    assert cells[3] == "+1.8 %"  # ≤ 2 links: on all 4, no count
    assert "A count in parentheses: the median rests on that many instances" in section
