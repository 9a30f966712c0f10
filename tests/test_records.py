"""The typed records layer: Store.records() gives frozen records with keys, groupings and instance facts."""

import dataclasses
import json
import math

import pytest

from codesign import Design
from compare import Store
from compare.run.records import DesignRecord, InstanceRecord, Records, as_records, canonical_key

INST = [{"family": "paper", "seed": s, "n": 8, "degree": 4, "a_norm": a, "b_norm": 1.0, "hops": 3, "horizon": 10}
        for a in (0.995, 1.05) for s in range(2)]


def _row(inst, label, cost, *, links=4, params=None, status="optimal", run_key=None):
    return {"run_key": run_key or f"{label}-{inst['a_norm']}-{inst['seed']}", "idx": 0, "experiment": "x",
            "instance": inst, "method": label.lower(), "label": label, "params": params or {}, "cost": cost,
            "cost_stderr": None, "cost_kind": "exact", "links": links, "self_loops": 8, "info_model": "delayed",
            "status": status, "message": "", "seconds": 0.5, "controller_kind": None, "extras": {"x": 1.0},
            "fingerprint": "fp"}


class _Run:
    """Just what Store.add_run reads of a run."""

    def __init__(self, key, instance, params):
        self.key, self.instance, self.method, self.label = key, instance, "m", "M"
        self.params, self.fingerprint = params, "fp"


def _store(path, *, facts: bool) -> Store:
    store = Store(path)
    for i, inst in enumerate(INST[:2]):
        design = Design("m", {"gamma": 0.1}, None, 1.0 + i, 3, 8, "instantaneous", extras={"curve": [1, 2]})
        store.add_run(_Run(f"k{i}", inst, {"gamma": 0.1}), [design], experiment="x", seconds=1.0 + i,
                      peak_mb=300.0 if i else None, scoring_seconds=0.25 if i else None,
                      baseline_mb=200.0 if i else None)
        if facts:
            store.set_instance_facts(inst, {"n": 8, "plant_links": 11 + i, "comm_links": 20})
    return store


def test_store_records_are_typed_with_canonical_keys_and_stored_facts(tmp_path):
    with _store(tmp_path / "s.sqlite", facts=True) as store:
        records = store.records()
    assert isinstance(records, Records) and len(records) == 2
    first = records[0]
    assert isinstance(first, DesignRecord) and isinstance(first.instance, InstanceRecord)
    assert [f.name for f in dataclasses.fields(DesignRecord)] == [
        "run_key", "idx", "experiment", "instance", "method", "label", "params", "params_key", "cost", "cost_stderr",
        "cost_kind", "links", "self_loops", "info_model", "status", "message", "seconds", "controller_kind",
        "extras", "fingerprint", "run_seconds", "run_designs", "run_peak_mb", "run_scoring_seconds",
        "run_baseline_mb"]
    assert (first.run_seconds, first.run_designs, first.run_peak_mb) == (1.0, 1, None)
    assert (records[1].run_seconds, records[1].run_peak_mb) == (2.0, 300.0)
    assert (first.run_scoring_seconds, first.run_baseline_mb) == (None, None)
    assert (records[1].run_scoring_seconds, records[1].run_baseline_mb) == (0.25, 200.0)
    assert first.instance.key == json.dumps(INST[0], sort_keys=True) == canonical_key(first.instance.spec)
    assert first.params == {"gamma": 0.1} and first.params_key == '{"gamma": 0.1}'
    assert first.extras == {"curve": [1, 2]} and first.fingerprint == "fp" and first.ok
    assert (first.instance.n, first.instance.plant_links, first.instance.comm_links) == (8, 11, 20)
    assert records[1].instance.plant_links == 12
    assert first.instance.panel == ("paper", 8, 0.995) and first.instance.seed == 0


def test_records_are_read_only(tmp_path):
    with _store(tmp_path / "s.sqlite", facts=True) as store:
        records = store.records()
    r = records[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.cost = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.instance.plant_links = 0
    with pytest.raises(TypeError):
        r.params["gamma"] = 1.0
    with pytest.raises(TypeError):
        r.instance.spec["seed"] = 5
    with pytest.raises(TypeError):
        records[0] = r
    assert isinstance(records[:1], Records) and list(records[:1]) == [r]


def test_designs_on_one_instance_share_it_and_instances_key_dicts():
    records = Records.from_rows([_row(INST[0], "A", 1.0), _row(INST[0], "B", 2.0), _row(INST[1], "A", 3.0)])
    assert records[0].instance is records[1].instance
    assert InstanceRecord.from_spec(dict(reversed(list(INST[0].items())))) == records[0].instance
    assert {records[0].instance: 1}[InstanceRecord.from_spec(INST[0])] == 1
    assert records.instances == (records[0].instance, records[2].instance)


def test_groupings_keep_the_order_of_first_appearance():
    rows = [_row(INST[2], "B", 1.0), _row(INST[0], "A", 2.0), _row(INST[2], "A", 3.0), _row(INST[3], "B", 4.0)]
    records = Records.from_rows(rows)
    assert list(records.by_label) == ["B", "A"]
    assert [r.cost for r in records.by_label["A"]] == [2.0, 3.0]
    assert list(records.by_panel) == [("paper", 8, 1.05), ("paper", 8, 0.995)]
    assert [len(rs) for rs in records.by_panel.values()] == [3, 1]
    assert list(records.by_instance) == [json.dumps(i, sort_keys=True) for i in (INST[2], INST[0], INST[3])]
    assert {k: len(v) for k, v in records.by_panel_label.items()} == {
        (("paper", 8, 1.05), "B"): 2, (("paper", 8, 0.995), "A"): 1, (("paper", 8, 1.05), "A"): 1}
    assert all(isinstance(rs, Records) for rs in records.by_label.values())
    assert records.by_label is records.by_label  # computed once
    assert [r.cost for r in records.filter(lambda r: r.cost > 2)] == [3.0, 4.0]


def test_from_dict_fills_missing_columns_and_treats_a_missing_cost_as_nan():
    record = DesignRecord.from_dict({"instance": INST[0], "label": "A", "params": {"b": 1, "a": [1, 2]}})
    assert record.status is None and record.links is None and record.extras == {}
    assert math.isnan(record.cost) and math.isnan(record.cost_stderr) and not record.ok
    assert record.params_key == '{"a": [1, 2], "b": 1}'
    assert record.params_key_without("b") == '{"a": [1, 2]}'
    assert not record.instance.has_facts and record.instance.plant_links is None


def test_as_records_passes_records_through_and_converts_dicts_and_designs():
    records = Records.from_rows([_row(INST[0], "A", 1.0)])
    assert as_records(records) is records
    mixed = as_records([records[0], _row(INST[1], "B", 2.0)])
    assert isinstance(mixed, Records) and mixed[0] is records[0] and mixed[1].label == "B"


def test_old_store_without_facts_leaves_them_none_and_nothing_is_rebuilt(tmp_path, monkeypatch):
    import compare.run.execution
    from compare.report.write import plant_links

    with _store(tmp_path / "old.sqlite", facts=False) as store:
        records = store.records()
    inst = records[0].instance
    assert not inst.has_facts and inst.plant_links is None and inst.nodes == 8
    monkeypatch.setattr(compare.run.execution, "build_instance", lambda spec: pytest.fail("the report built an instance"))
    assert plant_links(records) == {}


def test_report_boundary_uses_the_stored_facts_without_rebuilding(tmp_path, monkeypatch):
    import compare.run.execution
    from compare.report.write import plant_links

    with _store(tmp_path / "s.sqlite", facts=True) as store:
        records = store.records()

    def fail(spec):
        raise AssertionError("the report rebuilt an instance whose facts are stored")

    monkeypatch.setattr(compare.run.execution, "build_instance", fail)
    assert plant_links(records) == {("paper", 8, 0.995): 11.5}


def test_designs_frame_of_records_has_the_columns_of_the_store_and_of_dict_rows(tmp_path):
    pytest.importorskip("pandas")
    from compare.run.export import designs_frame

    with _store(tmp_path / "s.sqlite", facts=True) as store:
        records = store.records()
        frame = designs_frame(records, store.members())
        assert list(frame.columns) == list(store.to_pandas().columns)
    # The columns the export gave when records were dicts.
    rows = [{f.name: getattr(r, f.name) for f in dataclasses.fields(r)}
            | {"instance": dict(r.instance.spec), "params": dict(r.params), "extras": dict(r.extras)} for r in records]
    assert list(frame.columns) == list(designs_frame(rows).columns)
    assert list(frame.columns[:14]) == ["experiment", "experiments", "run_key", "idx", "method", "label", "family",
                                        "n", "degree", "a_norm", "b_norm", "hops", "horizon", "seed"]
    assert list(frame["gamma"]) == [0.1, 0.1] and list(frame["params"]) == ['{"gamma": 0.1}'] * 2
    assert list(frame["cost"]) == [1.0, 2.0]
