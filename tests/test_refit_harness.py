"""Refits in the harness: planned from stored designs, keyed by graph, resumed, and split in the report."""

from __future__ import annotations

import numpy as np
import pytest

from compare import Store, parse_spec, run_experiment
from compare.report.graph_gaps import graph_gap_section, graph_gaps, graph_values
from compare.run.parsing import SpecError

from tiny_specs import tiny_spec

REFITS = """
[[methods]]
method = "sparse_delayed"
params = { gammas = [0.0, 0.003, 0.03] }

[[methods]]
method = "sparse_admm"
params = { gammas = [0.001, 0.01] }

[[methods]]
method = "refit"
label = "Refit: delayed"
params = { controller = "delayed" }
sources = ["sparse_delayed", "sparse_admm"]

[[methods]]
method = "refit"
label = "Refit: static"
params = { controller = "instantaneous" }
sources = ["sparse_delayed", "sparse_admm"]
budgets = [4, "any"]
"""


@pytest.fixture(scope="module")
def refitted(tmp_path_factory):
    spec = parse_spec(tiny_spec("refits", methods=("lqr", "decentralized"), seeds=1, tail=REFITS))
    path = tmp_path_factory.mktemp("refits") / "r.sqlite"
    with Store(path) as store:
        first = run_experiment(spec, store, progress=False)
        again = run_experiment(spec, store, progress=False)
        records = store.records()
    return spec, first, again, records


def test_refits_are_planned_from_the_stored_graphs_and_resume(refitted):
    spec, first, again, records = refitted
    assert first.computed == first.total and again.computed == 0 and again.total == first.total
    refits = [r for r in records if r.method == "refit"]
    sources = [r for r in records if r.method in ("sparse_delayed", "sparse_admm") and r.ok]
    assert refits and all(r.extras.get("graph") for r in sources)  # the harness stamps every graph
    delayed = {(r.instance.key, r.extras["graph"]) for r in refits if r.label == "Refit: delayed"}
    # One refit per distinct graph and instance, whichever sources found it.
    assert delayed == {(r.instance.key, r.extras["graph"]) for r in sources}
    assert len(delayed) == sum(r.label == "Refit: delayed" for r in refits)
    # With budgets, per source and budget only the cheapest design's graph within it.
    static = [r for r in refits if r.label == "Refit: static"]
    assert 0 < len(static) <= 2 * 2 * len(records.instances)
    for r in refits:
        assert r.extras["graph_links"] == r.params["graph"].count("-") and r.fingerprint


def test_every_design_splits_into_a_graph_and_a_controller_gap(refitted):
    *_, records = refitted
    rows = graph_gaps(records)
    assert {r.label for r in rows} >= {"sparse_delayed", "sparse_admm"} or rows
    values = graph_values(records)
    for (instance, model, graph), (links, value) in values.items():
        mine = [r for r in records if r.instance.key == instance and r.ok and r.extras.get("graph") == graph
                and (r.info_model == model or r.info_model == "none")]
        assert value == pytest.approx(min(r.cost for r in mine))  # V is the lowest cost on that graph
    for row in rows:
        assert row.graph.median >= -1e-12 and row.controller.median >= -1e-12, row
        assert row.graph.low >= -1e-12 and row.controller.low >= -1e-12
    lines = graph_gap_section(records)
    assert lines[0] == "## Graph against controller" and any("graph gap" in line for line in lines)


def test_the_parts_add_up_instance_by_instance(refitted):
    *_, records = refitted
    rows = [r for r in graph_gaps(records) if r.excess.instances == 1]
    for row in rows:  # one instance: the medians are the values, and they add exactly
        assert row.excess.median == pytest.approx(row.graph.median + row.controller.median, abs=1e-12)


@pytest.mark.parametrize("tail, match", [
    ('[[methods]]\nmethod = "refit"\nsources = ["nothing"]\n', "names no entry"),
    ('[[methods]]\nmethod = "lqr"\nsources = ["lqr"]\n', "takes no graph"),
    ('[[methods]]\nmethod = "refit"\nbudgets = [3]\n', "only with sources"),
    ('[[methods]]\nmethod = "refit"\nsources = ["lqr"]\nbudgets = [-1]\n', "non-negative"),
    ('[[methods]]\nmethod = "refit"\nsources = ["lqr"]\nparams = { graph = "0-1" }\n', "either sources or a graph"),
])
def test_bad_refit_entries_name_the_problem(tail, match):
    with pytest.raises(SpecError, match=match):
        parse_spec(tiny_spec("bad", tail=tail))


def test_a_graphless_source_is_counted_not_refit(tmp_path):
    # On the chain, SLS's maps spread over every hop of the plant graph it is constrained to: its links
    # are that graph's edges, not its support, so its graph is not recovered. u = 0 reads the empty graph.
    tail = '[[methods]]\nmethod = "sls"\nparams = { graph = "plant" }\n' \
           '[[methods]]\nmethod = "refit"\nsources = ["sls", "autonomous"]\n'
    text = ('name = "graphless"\n[instances]\nfamily = "chain"\nn = [6]\nrho = 1.05\nalpha = 0.2\n'
            '[[methods]]\nmethod = "autonomous"\n' + tail)
    spec = parse_spec(text)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_experiment(spec, store, progress=False)
        records = store.records()
    refits = [r for r in records if r.method == "refit"]
    assert len(refits) == 1 and refits[0].params["graph"] == "" and refits[0].ok
    assert summary.graphless == 1 and "no graph to refit" in str(summary)
    assert np.isfinite(refits[0].cost)


EXACT = """
[[methods]]
method = "sparse_budget"
params = { links = [2, 6, 12], info_model = "delayed", rounds = 1 }

[[methods]]
method = "refit"
label = "Refit: linear GRNN"
params = { controller = "grnn", activation = "identity", steps = 5, ensemble = 1 }
sources = ["sparse_budget"]
"""


def test_a_learned_controller_at_every_exact_budget(tmp_path):
    """sparse_budget's designs as sources with no budgets: the GRNN refit on each one's graph, so every exact
    link budget has a learned design on exactly the best static graph found there, kept only below its start."""
    spec = parse_spec(tiny_spec("exact", methods=("lqr",), seeds=1, a_norms=(1.05,), tail=EXACT))
    with Store(tmp_path / "r.sqlite") as store:
        run_experiment(spec, store, progress=False)
        records = store.records()
    budgets = [r for r in records if r.method == "sparse_budget" and r.ok]
    learned = {r.extras["graph"]: r for r in records if r.method == "refit"}
    assert len({r.extras["graph"] for r in budgets}) >= 2
    for r in budgets:
        grnn = learned[r.extras["graph"]]
        assert grnn.extras["graph_links"] == r.links <= r.params["budget"]
        assert grnn.ok and grnn.info_model == "delayed"
        assert grnn.cost <= grnn.extras["start_cost"] * (1 + 1e-9)  # the delayed refit it started from, or lower
