"""The budget ladder a report opens with where its spec asks for one (``[report] ladder``), as the `power` preset does.

Synthetic records shaped like the power preset's: each system a published grid (one instance,
no seed), the ℓ1 paths at a few link counts, SLS only on the complete graph, GRNN-Sparse
with no design within one link.
"""

from __future__ import annotations

import math
import re

import pytest

from compare.report.answer import MAX_SENTENCES, answer_lines
from compare.report.findings import select_comparisons
from compare.report.ladder import ladder_table, system_names
from compare.run.records import Records, canonical_key

ADMM, DELAYED, GRNN_SPARSE = "Sparse K (l1 ADMM)", "Sparse delayed K (l1)", "GRNN-Sparse (β path)"
CLAIM = "One wide-area link gives almost centralized performance (Dörfler et al. 2014)"
SPEC = f"""name = "power"
[[instances]]
family = "power_grid"
case = ["ieee39"]
[[methods]]
method = "lqr"
[report]
ladder = {{ budgets = [1, 2, 5], methods = ["sparse_admm", "sparse_delayed", "sls_topologies", "grnn_sparse"], \
near = 5.0, claim = "{CLAIM}" }}
"""


def _inst(case, damping=2.0, n=10):
    return {"family": "power_grid", "case": case, "n": n, "damping": damping, "input": "power", "dt": 0.1,
            "cost": "coherency", "r": 1.0, "neighbours": 4, "horizon": 50, "sha256": "0" * 16}


def _rec(inst, method, label, cost, links, *, status="optimal", info="instantaneous", params=None,
         experiment="power"):
    ok = status in ("optimal", "inaccurate")
    params = params or {}
    return {"instance": inst, "method": method, "label": label, "params": params, "links": links,
            "self_loops": inst["n"], "cost": cost if ok else float("nan"), "cost_stderr": 0.0, "cost_kind": "exact",
            "status": status, "info_model": info, "experiment": experiment,
            "run_key": f"{method}|{canonical_key(inst)}|{canonical_key(params)}", "idx": links or 0}


def _system(inst, *, zero=1.036, admm=((4, 1.021), (12, 1.012)), delayed=((2, 1.031), (8, 1.023)),
            grnn=((3, 1.05), (6, 1.04))):
    """One grid's designs: LQR, u = 0, the diagonal gain, two ℓ1 paths, SLS on two graphs, GRNN-Sparse."""
    rows = [_rec(inst, "lqr", "LQR (centralized)", 1.0, inst["n"] * (inst["n"] - 1)),
            _rec(inst, "autonomous", "Autonomous (u = 0)", 3.5, 0, info="none"),
            _rec(inst, "decentralized", "Decentralized (diagonal K)", zero, 0, info="none")]
    for i, (links, cost) in enumerate(((0, zero), *admm)):
        rows.append(_rec(inst, "sparse_admm", ADMM, cost, links, params={"gamma": 10.0 ** -i}))
    for i, (links, cost) in enumerate(((0, zero), *delayed)):
        rows.append(_rec(inst, "sparse_delayed", DELAYED, cost, links, info="delayed", params={"gamma": 10.0 ** -i}))
    full = inst["n"] * (inst["n"] - 1)
    rows += [_rec(inst, "sls_topologies", "SLS", math.nan, 0, status="infeasible", info="delayed",
                  params={"graph": "given"}),
             _rec(inst, "sls_topologies", "SLS", 1.007, full, info="delayed", params={"graph": "complete"})]
    for i, (links, cost) in enumerate(grnn):
        rows.append(_rec(inst, "grnn_sparse", GRNN_SPARSE, cost, links, info="delayed", params={"beta": 10.0 ** i}))
    return rows


def _answer(rows, spec=SPEC):
    records = Records.from_rows(rows)
    lines = answer_lines(records, select_comparisons(records), meta={"spec:power": spec})
    assert lines[-1] == ""
    return lines


def _power_rows():
    return (_system(_inst("ieee39", 2.0)) + _system(_inst("ieee39", "case"), zero=1.042)
            + _system(_inst("wecc", 2.0, n=29), zero=1.02, admm=((1, 1.015), (5, 1.01))))


def _ladder(lines):
    """The ladder's table: row label -> system -> cell."""
    i = next(k for k, line in enumerate(lines) if line.startswith("| method |"))
    systems = [c.strip() for c in lines[i].split("|")[2:-1]]
    out = {}
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.split("|")[1:-1]]
        out[cells[0]] = dict(zip(systems, cells[1:]))
    return out


def test_the_ladder_opens_the_answer_with_the_claim_checked_system_by_system():
    from compare.report.answer import MAX_WORDS, words

    lines = _answer(_power_rows())
    assert lines[:3] == [
        f"{CLAIM}, read as some design within 1 link costing at most 5 % more than LQR, holds on all 3 systems.",
        "It holds without any link: Decentralized (diagonal K) is already +2 to +4.2 % above LQR on ieee39 (d = 2), "
        "ieee39 (case damping) and wecc.",
        "1 link closes 0–25 % of the gap between the best design with no link and LQR."]
    assert all(words(x) <= MAX_WORDS for x in lines[:3]) and lines[3] == ""
    # then a table, one column per system named by what tells them apart, not a list of long items
    assert not any(x.startswith("- ") for x in lines)
    table = _ladder(lines)
    assert list(table["with no link: Decentralized (diagonal K)"]) == ["ieee39 (d = 2)", "ieee39 (case damping)", "wecc"]
    assert table["with no link: Decentralized (diagonal K)"] == {"ieee39 (d = 2)": "+3.6", "ieee39 (case damping)": "+4.2",
                                                                 "wecc": "+2"}
    # the ℓ1 paths at their best within each budget: ADMM's path jumps from 0 to 4 links
    assert table["Sparse K (l1 ADMM)"]["ieee39 (d = 2)"] == "+3.6 / +3.6 / +2.1"
    assert table["Sparse delayed K (l1)"]["ieee39 (d = 2)"] == "+3.6 / +3.1 / +3.1"
    # SLS: only the complete graph is feasible here, so nothing within 1, 2 or 5 links; said why
    assert table["SLS"]["ieee39 (d = 2)"] == "none (sparsest: 90 links)"
    # GRNN-Sparse: no design within 1 or 2 links
    assert table["GRNN-Sparse"]["ieee39 (d = 2)"] == "none / none / +5 (sparsest: 3 links)"
    assert table["Sparse K (l1 ADMM)"]["wecc"] == "+1.5 / +1.5 / +1"
    # the best of any method and the share of the gap closed: every number of the sentences is in the table
    assert table["best of any method"]["wecc"] == "+1.5 / +1.5 / +1"
    assert table["gap to LQR closed within 1 link"] == {"ieee39 (d = 2)": "0 %", "ieee39 (case damping)": "0 %",
                                                        "wecc": "25 %"}


def test_a_claim_that_fails_on_a_system_says_where_and_by_how_much():
    npcc = _inst("npcc", 2.0, n=48)
    rows = _power_rows() + _system(npcc, zero=1.2, admm=((1, 1.15), (5, 1.08)), delayed=((3, 1.1),),
                                   grnn=((2, 1.3),))
    lines = _answer(rows)
    assert lines[0].endswith("holds on 3 of the 4 systems.")
    assert lines[1].endswith("already +2 to +4.2 % above LQR on ieee39 (d = 2), ieee39 (case damping) and wecc.")
    assert lines[2].startswith("On npcc it fails: within 1 link the best design costs +15 % above LQR "
                               "(Sparse K (l1 ADMM)), against +20 % with no link")
    # the claim is about the best design within the budget, whichever method found it, in the ladder or not
    rows.append(_rec(npcc, "truncated_lqr", "Truncated LQR K", 1.14, 1, params={"links": [1]}))
    lines = _answer(rows)
    assert "+14 % above LQR (Truncated LQR K)" in lines[2]
    assert "1 link closes 0–30 % of the gap" in lines[2]  # npcc: (1.2 - 1.14) / 0.2
    assert _ladder(lines)["best of any method"]["npcc"] == "+14 / +14 / +8"


def test_no_design_within_the_first_budget_is_none_with_the_sparsest_design_named():
    # Without the diagonal gain (a design with no link is within any budget), only SLS on the complete graph.
    rows = [r for r in _system(_inst("ieee39")) if r["method"] in ("lqr", "sls_topologies")]
    spec = SPEC.replace('"sparse_admm", "sparse_delayed", "sls_topologies", "grnn_sparse"', '"sls_topologies"')
    lines = _answer(rows, spec)
    assert lines[0].endswith("holds on no system.") and lines[1] == "On ieee39 no usable design lies within 1 link."
    table = _ladder(lines)
    assert table["with no link"] == {"ieee39": "none"} and table["SLS"] == {"ieee39": "none (sparsest: 90 links)"}


def test_a_method_with_no_usable_design_or_not_run_is_said_so():
    inst = _inst("ieee39")
    rows = [r for r in _system(inst) if r["method"] != "grnn_sparse"]
    rows = [r for r in rows if not (r["method"] == "sls_topologies" and r["params"]["graph"] == "complete")]
    table = _ladder(_answer(rows))
    assert table["SLS"]["ieee39"] == "no usable design (infeasible 1)"
    assert table["GRNN-Sparse"]["ieee39"] == "not run"


def test_the_ladder_comes_first_and_the_other_sentences_follow_within_the_limit():
    rows = _power_rows()
    lines = _answer(rows)
    sentences = lines[:lines.index("")]
    assert len(sentences) <= MAX_SENTENCES
    assert sentences[0].startswith(CLAIM)
    # a report without a ladder has none of it
    plain = answer_lines(Records.from_rows(rows), [], meta={"spec:power": SPEC.split("[report]")[0]})
    assert not any(x.startswith("|") or CLAIM in x for x in plain)
    assert answer_lines(Records.from_rows(rows), []) == []


def test_seeds_of_one_system_are_summarized_by_their_median():
    rows = []
    for seed, admm in ((0, 1.01), (1, 1.02), (2, 1.05)):
        inst = {"family": "chain", "n": 10, "seed": seed}
        rows += [_rec(inst, "lqr", "LQR (centralized)", 1.0, 90),
                 _rec(inst, "decentralized", "Decentralized (diagonal K)", 1.3, 0),
                 _rec(inst, "sparse_admm", ADMM, admm, 1, params={"gamma": 1.0})]
    spec = ('name = "power"\n[instances]\nfamily = "chain"\n[[methods]]\nmethod = "lqr"\n[report]\n'
            'ladder = { methods = ["sparse_admm"] }\n')
    lines = _answer(rows, spec)
    assert lines[0] == "Some design within 1 link costs at most 5 % more than LQR on its one system."
    table = _ladder(lines)
    assert table["with no link: Decentralized (diagonal K)"] == {"chain": "+30"}
    assert table["Sparse K (l1 ADMM)"] == {"chain": "+2 / +2 / +2"}


def test_systems_are_named_by_what_tells_them_apart():
    specs = {"a": _inst("ieee39", 2.0), "b": _inst("ieee39", "case"), "c": _inst("wecc", 2.0, n=29)}
    assert system_names(specs) == {"a": "ieee39 (d = 2)", "b": "ieee39 (case damping)", "c": "wecc"}


def test_the_ladder_table_keeps_infinite_costs_for_budgets_without_a_design():
    table = ladder_table(Records.from_rows(_system(_inst("ieee39"))),
                         {"budgets": [1, 2, 5], "methods": ["grnn_sparse"], "near": 5.0, "claim": ""})
    (system, _), = table["systems"]
    rung = table["rungs"][(system, "GRNN-Sparse")]
    assert rung.costs[:2] == (math.inf, math.inf) and rung.costs[2] == pytest.approx(1.05) and rung.sparsest == 3


@pytest.mark.parametrize("ladder, message", [
    ("ladder = 3", "report.ladder: expected a table"),
    ("ladder = { budgets = [2, 1] }", "report.ladder.budgets: must increase, got [2, 1]"),
    ("ladder = { budgets = [-1] }", "report.ladder.budgets: expected a non-empty list of link counts >= 0"),
    ("ladder = { near = 0 }", "report.ladder.near: expected a percentage > 0, got 0"),
    ("ladder = { methods = [\"nope\"] }", "report.ladder.methods: 'nope' is no method entry's label or method name"),
    ("ladder = { rungs = 3 }", "report.ladder.rungs: unknown key (allowed: budgets, claim, methods, near)"),
])
def test_bad_ladders_are_named(ladder, message):
    from compare import SpecError, parse_spec

    with pytest.raises(SpecError, match=re.escape(message)):
        parse_spec(f'name = "p"\n[instances]\nfamily = "paper"\n[[methods]]\nmethod = "lqr"\n[report]\n{ladder}\n')


def test_the_power_preset_asks_for_the_ladder_of_every_method_it_runs():
    from compare.run.spec import load_spec

    spec = load_spec("power")
    assert spec.ladder["budgets"] == [1, 2, 5] and spec.ladder["claim"]
    run = {m.method for m in spec.methods}
    assert set(spec.ladder["methods"]) <= run
    assert {"lqr", "autonomous", "decentralized", "sparse_admm", "sparse_newton", "sparse_sdp", "truncated_lqr",
            "sparse_budget", "sparse_delayed", "grnn", "grnn_sparse", "gcnn"} <= run
    assert run & {"sls", "sls_topologies"}
    cases = {(s["case"], s["damping"]) for s in spec.instances.expand()}
    assert {c for c, _ in cases} == {"ieee39", "wecc", "npcc"} and len({d for c, d in cases if c == "ieee39"}) == 2


def test_the_no_link_design_is_named_after_the_diagonal_gain_where_a_path_ends_on_the_same_gain():
    rows = _system(_inst("ieee39"))
    first = [r for r in rows if r["method"] == "decentralized"]
    rows = [r for r in rows if r["method"] != "decentralized"] + first  # a path's 0-link end comes first
    assert _ladder(_answer(rows))["with no link: Decentralized (diagonal K)"] == {"ieee39": "+3.6"}


def test_a_written_report_opens_with_the_ladder_and_a_rebuilt_one_says_the_same(tmp_path):
    from compare.report.write import write_report

    rows = _power_rows()
    write_report(rows, tmp_path / "a", meta={"spec:power": SPEC}, title="power")
    text = (tmp_path / "a" / "report.md").read_text()
    head = text.split("## Findings")[0]
    assert head.startswith(f"# power\n\n{CLAIM}, read as") and "| method | ieee39 (d = 2) |" in head
    assert "<th>ieee39 (case damping)</th>" in (tmp_path / "a" / "report.html").read_text()
    # rebuilt from the folder alone (runs.csv, report.json with the stored spec), without a store
    import shutil

    from click.testing import CliRunner

    from compare.cli import main

    (tmp_path / "b").mkdir()
    for name in ("runs.csv", "curves.csv", "report.json"):
        shutil.copy(tmp_path / "a" / name, tmp_path / "b" / name)
    result = CliRunner().invoke(main, ["report", "--out", str(tmp_path / "b")])
    assert result.exit_code == 0, result.output
    rebuilt = (tmp_path / "b" / "report.md").read_text().split("## Findings")[0]
    assert rebuilt.split("\n", 1)[1] == head.split("\n", 1)[1]
