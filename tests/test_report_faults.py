"""Reports of failed runs: never an instance rebuilt to draw them, never a crash.

The records are made by hand, as a store holds them after runs whose instances
could not be built (``a_norm = NaN``, ``n = 100000``): failed designs and no
instance facts. Building any instance here raises, so a report that tries fails
the test instead of allocating tens of GiB.
"""

import json

import pytest

from compare.report.folder import read_folder
from compare.run.records import Records, canonical_key
from compare.report.write import plant_links, write_report

BASE = {"family": "paper", "degree": 4, "b_norm": 1.0, "hops": 3, "horizon": 10}
HUGE = {**BASE, "n": 100000, "a_norm": 0.995, "seed": 0}
NAN = {**BASE, "n": 8, "a_norm": float("nan"), "seed": 0}
GOOD = [{**BASE, "n": 8, "a_norm": 1.05, "seed": s} for s in range(3)]
NO_FACTS = [{**BASE, "n": 12, "a_norm": 1.05, "seed": s} for s in range(2)]

HUGE_MESSAGE = "MemoryError: Unable to allocate 74.5 GiB for an array with shape (100000, 100000)"
NAN_MESSAGE = "InstanceError: a_norm must be finite, got nan"


@pytest.fixture(autouse=True)
def no_instance_is_built(forbid_instance_builds):
    """Every way of building an instance raises (the runner's helper and each registered family's build)."""
    forbid_instance_builds()


def _row(inst, method, *, status="optimal", cost=None, links=None, info="instantaneous", message="", params=None):
    """A stored design; a failed one as ``codesign.Design.failure`` makes it (no cost, 0 links, info "none")."""
    ok = status == "optimal"
    return {"instance": inst, "method": method, "label": method, "params": params or {},
            "run_key": f"{method}-{canonical_key(inst)}-{json.dumps(params or {}, sort_keys=True)}", "idx": 0,
            "experiment": "faults", "status": status, "message": message, "cost": cost if ok else float("nan"),
            "cost_stderr": 0.0 if ok else None, "cost_kind": "exact" if ok else None, "links": links if ok else 0,
            "self_loops": 8 if ok else 0, "info_model": info if ok else "none", "seconds": 0.01,
            "controller_kind": None, "extras": {}, "fingerprint": "f", "run_seconds": 0.02, "run_designs": 1,
            "run_peak_mb": None}


def _failed(inst, message):
    return [_row(inst, m, status="failed", message=message) for m in ("lqr", "sparse_delayed", "sls")]


def _working(inst, k):
    return [_row(inst, "lqr", cost=1.0, links=56),
            *(_row(inst, "sparse_delayed", cost=1.0 + 0.1 * g + 0.01 * k, links=40 - 10 * g, info="delayed",
                   params={"gamma": float(g)}) for g in range(4)),
            _row(inst, "sls", cost=1.02 + 0.01 * k, links=30, info="delayed", params={"graph": "plant"})]


def _report(records, out, **kwargs):
    files = write_report(records, out, title="Faults", commands=["compare report --out o"],
                         meta={"sections:faults": ["compute", "table1", "training_curves"]},
                         members={"faults": {r.run_key for r in records}}, **kwargs)
    return files["md"].read_text()


def test_a_store_whose_every_run_failed_gives_a_report_naming_the_failures(tmp_path):
    records = Records.from_rows(_failed(HUGE, HUGE_MESSAGE) + _failed(NAN, NAN_MESSAGE))
    assert plant_links(records) == {}
    text = _report(records, tmp_path / "report")
    assert "| failed | 6 |" in text
    assert HUGE_MESSAGE in text and NAN_MESSAGE in text
    assert "6 runs on 2 instances" in text
    assert "dotted vertical line" not in text  # no plant graph known, so no QI boundary either
    assert "has no usable design on" in text


def test_instances_without_facts_draw_no_boundary_and_their_failures_are_named(tmp_path):
    facts = {canonical_key(inst): {"n": 8, "plant_links": 20 + i, "comm_links": 30} for i, inst in enumerate(GOOD)}
    facts[canonical_key(NAN)] = {"n": None, "plant_links": None, "comm_links": None}  # what a failed build leaves
    rows = [row for k, inst in enumerate(GOOD) for row in _working(inst, k)]
    rows += [row for k, inst in enumerate(NO_FACTS) for row in _working(inst, k)]
    rows += _failed(HUGE, HUGE_MESSAGE) + _failed(NAN, NAN_MESSAGE)
    records = Records.from_rows(rows, facts)

    boundaries = plant_links(records)
    assert boundaries == {("paper", 8, 1.05): 21.0}  # the panels of n = 12, 100000 and NaN have no stored links
    text = _report(records, tmp_path / "report")
    assert HUGE_MESSAGE in text and NAN_MESSAGE in text and "| failed | 6 |" in text
    assert "dotted vertical line" in text
    assert (tmp_path / "report" / "cost_vs_links.png").stat().st_size > 0

    # The folder rebuilds the same report without a store, and without building anything either.
    data = read_folder(tmp_path / "report")
    assert plant_links(data.records) == boundaries
    again = _report(data.records, tmp_path / "again", software=data.software)
    assert again.count("| failed |") == text.count("| failed |") and HUGE_MESSAGE in again


def test_the_compute_section_takes_n_from_the_spec_and_lists_every_size_that_failed(tmp_path):
    rows = [_row(inst, "lqr", cost=1.0, links=56) for inst in NO_FACTS]
    rows += [_row(inst, "lqr", status="failed", message=message) for inst, message in ((NAN, NAN_MESSAGE),
                                                                                         (HUGE, HUGE_MESSAGE))]
    text = _report(Records.from_rows(rows), tmp_path / "report")
    compute = text.split("## Compute against network size", 1)[1].split("\n## ", 1)[0]
    # rows stored without scoring seconds or a memory baseline: unknown, not the wall time less the design's
    assert ("| lqr | 8 | – | – | – | none of 1 runs completed |\n| lqr | 12 | 0.01 | ? | ? | 2 |\n"
            "| lqr | 100000 | – | – | – | none of 1 runs completed |") in compute
    assert f"- lqr, N = 8: 1 of 1: {NAN_MESSAGE}" in compute
    assert f"- lqr, N = 100000: 1 of 1: {HUGE_MESSAGE}" in compute


def _path_rows(inst):
    return [_row(inst, "path_method", cost=1.1 - 0.01 * b, links=10 * b, info="delayed", params={"beta": b})
            for b in (1.0, 2.0, 3.0)]


PATH_META = {"method:path_method": {"produces": ["topology_path"], "path_param": "beta"}}


def _ring_drawing(n: int) -> dict:
    """A stored drawing (:func:`compare.report.topologies.drawing_facts`) of a ring of ``n`` nodes, made without a build."""
    from types import SimpleNamespace

    import numpy as np

    from compare.run.drawing import drawing_facts

    ring = np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1) + np.eye(n, k=n - 1) + np.eye(n, k=1 - n)
    A = 0.4 * ring + 0.01 * np.diag(np.arange(n))
    return drawing_facts(SimpleNamespace(A=A, plant_adj=ring, comm_adj=ring, nodes=n, state_nodes=np.arange(n)))


@pytest.mark.parametrize("facts", [None, {"n": 12, "plant_links": 24, "comm_links": 24}],
                         ids=["no facts", "facts of a store before drawings"])
def test_the_topology_figure_is_left_out_for_an_instance_without_a_stored_drawing(tmp_path, facts):
    """The one figure that needs an instance's graphs does not build an instance the store has no drawing of."""
    import numpy as np

    support = type("Controller", (), {"support": np.eye(12, dtype=bool)})()
    records = Records.from_rows(_path_rows(NO_FACTS[0]), {canonical_key(NO_FACTS[0]): facts} if facts else None)
    files = write_report(records, tmp_path / "report", meta=PATH_META, load_controller=lambda run_key, idx: support)
    text = files["md"].read_text()
    assert "Designed topologies" not in text and "topologies.png" not in files


def test_the_topology_figure_is_drawn_from_the_stored_drawing_and_again_from_the_folder(tmp_path):
    """Every build refuses (the fixture): the figure comes from the facts, then from report.json alone."""
    import numpy as np

    n = NO_FACTS[0]["n"]
    facts = {canonical_key(NO_FACTS[0]): {"n": n, "plant_links": 2 * n, "comm_links": 2 * n,
                                          "drawing": _ring_drawing(n)}}
    records = Records.from_rows(_path_rows(NO_FACTS[0]), facts)
    supports = {r.run_key: np.eye(n, dtype=bool) | np.eye(n, k=int(r.params["beta"]), dtype=bool) for r in records}
    controller = type("Controller", (), {})

    def load_controller(run_key, idx):
        loaded = controller()
        loaded.support = supports[run_key]
        return loaded

    files = write_report(records, tmp_path / "report", meta=PATH_META, load_controller=load_controller)
    text = files["md"].read_text()
    assert "## Designed topologies along the β path (paper Fig. 4)" in text
    assert "![designed topologies](topologies.png)" in text and "circle" in text  # a 12-node node-link drawing
    stored = json.loads((tmp_path / "report" / "report.json").read_text())["drawings"]
    assert stored == {canonical_key(NO_FACTS[0]): _ring_drawing(n)}

    data = read_folder(tmp_path / "report")
    drawing = data.records[0].instance.drawing
    assert np.array_equal(drawing.colours, records[0].instance.drawing.colours)
    again = write_report(data.records, tmp_path / "again", meta=data.meta, software=data.software,
                         load_controller=data.load_controller)
    assert "![designed topologies](topologies.png)" in again["md"].read_text()
    for name in ("topologies.png", "topologies.svg", "report.json"):
        assert (tmp_path / "again" / name).read_bytes() == (tmp_path / "report" / name).read_bytes(), name


def test_a_nan_a_norm_is_one_panel_that_sorts_after_every_number():
    from compare.run.records import panel_key

    specs = [dict(NAN, seed=s, a_norm=float("nan")) for s in range(2)]  # two NaN objects
    records = Records.from_rows([_row(spec, "lqr", status="failed", message=NAN_MESSAGE) for spec in specs]
                                + [_row(GOOD[0], "lqr", cost=1.0, links=56)])
    assert len(records.by_panel) == 2  # both NaN instances in one panel
    nan_panel = panel_key(json.loads(json.dumps(NAN)))
    assert len(records.by_panel[nan_panel]) == 2
    assert sorted(records.by_panel) == [("paper", 8, 1.05), nan_panel]
    assert f"{nan_panel[2]:g}" == "nan"
