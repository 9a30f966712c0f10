"""A report folder that rebuilds itself: compare.report.folder's files read back exactly what the store holds."""

import inspect
import json
import math
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from compare.cli import main
from compare.report.folder import FOLDER_FILES, FolderError, read_folder, topology_supports, write_folder
from compare.run.records import Records

SPEC = """
name = "folder-tiny"
[report]
sections = ["training_curves"]
[instances]
family = "paper"
n = [6]
a_norms = [0.995]
seeds = 2
degree = 3
horizon = 10
[evaluation]
validation_size = 200
[[methods]]
method = "lqr"
[[methods]]
method = "decentralized"
[[methods]]
method = "sparse_admm"
params = { gammas = [0.01, 0.1, 1.0] }
[[methods]]
method = "grnn_sparse"
params = { steps = 20, ensemble = 1, refine_ensemble = 1 }
grid = { beta = [0.3, 3.0] }
[[methods]]
method = "sls"
params = { graph = "complete" }
"""

SOFTWARE = {"python": "3.11.7", "numpy": "9.9.9", "cvxpy": "1.0"}  # not sorted: the report prints them in order


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """A real store of the tiny experiment (about 8 s): its path and what write_report is given."""
    from compare import Store, parse_spec, run_experiment

    path = tmp_path_factory.mktemp("store") / "results.sqlite"
    with Store(path) as store:
        run_experiment(parse_spec(SPEC), store, progress=False, workers=1)
        store.set_meta("command:folder-tiny", "compare run tiny.toml")
        records = store.records()
        data = dict(meta=store.meta(), members=store.members(), superseded=store.superseded(),
                    supports=topology_supports(records, store.meta(), store.controller))
        truth = {key: store.controller(*key).support != 0 for key in data["supports"]}
    return path, records, data, truth


def _same(a, b) -> bool:
    """Equal values of equal types, NaN equal to NaN, mappings and lists compared item by item."""
    if isinstance(a, Mapping) and isinstance(b, Mapping):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if type(a) is not type(b):
        return False
    if isinstance(a, float) and math.isnan(a):
        return math.isnan(b)
    return a == b


def _assert_same_records(expected: Records, got: Records) -> None:
    assert len(got) == len(expected)
    for a, b in zip(expected, got):
        for f in fields(a):
            if f.name == "instance":
                for attr in ("key", "n", "plant_links", "comm_links"):
                    assert getattr(a.instance, attr) == getattr(b.instance, attr), (a.run_key, attr)
                assert _same(a.instance.spec, b.instance.spec)
            else:
                assert _same(getattr(a, f.name), getattr(b, f.name)), (a.run_key, a.idx, f.name)


def _write(records, out, data, software=SOFTWARE):
    return write_folder(records, out, meta=data["meta"], members=data["members"], superseded=data["superseded"],
                        software=software, supports=data["supports"])


def _snapshot(folder: Path) -> dict:
    return {name: (folder / name).read_bytes() for name in FOLDER_FILES.values()}


def test_round_trip_of_a_real_store(stored, tmp_path):
    _, records, data, truth = stored
    files = _write(records, tmp_path, data)
    assert {p.name for p in files.values()} == set(FOLDER_FILES.values())
    back = read_folder(tmp_path)
    _assert_same_records(records, back.records)
    assert back.meta == data["meta"] and back.members == data["members"]
    assert back.superseded == data["superseded"]
    assert list(back.software.items()) == list(SOFTWARE.items())
    # What the report reads: timings, facts, curves.
    assert all(r.run_seconds > 0 and r.run_designs >= 1 for r in back.records)
    assert all(r.instance.has_facts for r in back.records)
    learned = back.records.filter(lambda r: r.method == "grnn_sparse")
    assert len(learned) == 4 and all({"curve", "l1_curve"} <= set(r.extras) for r in learned)
    assert "l1_curve" in (tmp_path / "curves.csv").read_text()
    # The topology figure's controllers: two designs along the beta path, supports as the store's.
    assert len(truth) == 2
    for (run_key, idx), support in truth.items():
        loaded = back.load_controller(run_key, idx).support
        assert loaded.dtype == bool and np.array_equal(loaded, support)
    with pytest.raises(KeyError):
        back.load_controller(records[0].run_key, 99)
    # The drawing of the path's instance, as the store holds it; no other instance's (the figure draws one).
    drawn = {r.instance for r in records if (r.run_key, r.idx) in truth}
    assert len(drawn) == 1 and all(inst.drawing is not None for inst in records.instances)
    (instance,) = drawn
    assert list(json.loads((tmp_path / "report.json").read_text())["drawings"]) == [instance.key]
    for inst in back.records.instances:
        if inst.key != instance.key:
            assert inst.drawing is None
            continue
        for name in ("plant_adj", "comm_adj", "colours"):
            assert np.array_equal(getattr(inst.drawing, name), getattr(instance.drawing, name)), name


def test_old_columns_come_first_in_their_order(stored, tmp_path):
    _, records, data, _ = stored
    _write(records, tmp_path, data)
    header = (tmp_path / "runs.csv").read_text().splitlines()[0].split(",")
    old = ["label", "method", "params", "status", "cost", "cost_stderr", "cost_kind", "links", "self_loops",
           "info_model", "seconds", "message", "extras", "run_key", "idx", "fingerprint"]
    new = ["instance", "instance_nodes", "plant_links", "comm_links", "experiment", "controller_kind",
           "run_seconds", "run_designs", "run_peak_mb"]
    later = ["nodes", "inputs", "actuated_nodes", "open_loop_radius"]  # the systems table's facts, when stored
    measured = ["run_scoring_seconds", "run_baseline_mb"]  # the runs' later measurements, when recorded
    fields_ = sorted(records[0].instance.spec)
    assert header == [f"instance_{k}" for k in fields_] + old + new + later + measured
    # The extras column keeps the scalar extras only, as before.
    grnn = next(r for r in records if r.method == "grnn_sparse")
    row = next(line for line in (tmp_path / "runs.csv").read_text().splitlines() if grnn.run_key in line)
    assert '""curve""' not in row and '""spectral_radius""' in row


def test_writing_again_gives_byte_identical_files(stored, tmp_path):
    _, records, data, _ = stored
    _write(records, tmp_path / "a", data)
    _write(records, tmp_path / "b", data)
    first = _snapshot(tmp_path / "a")
    assert first == _snapshot(tmp_path / "b")
    # Rewriting from the folder's own data (as `compare report` does without a store) changes nothing.
    back = read_folder(tmp_path / "a")
    supports = topology_supports(back.records, back.meta, back.load_controller)
    write_folder(back.records, tmp_path / "a", meta=back.meta, members=back.members, superseded=back.superseded,
                 software=back.software, supports=supports)
    assert _snapshot(tmp_path / "a") == first


def _record(**changes) -> dict:
    row = dict(run_key="k1", idx=0, experiment="e", instance={"family": "paper", "n": 4, "a_norm": 1.05, "seed": 3},
               method="m", label="M (β)", params={"beta": 0.1, "tag": "x"}, cost=1.25, cost_stderr=0.0,
               cost_kind="exact", links=3, self_loops=1, info_model="delayed", status="optimal", message="",
               seconds=0.5, controller_kind="grnn", extras={}, fingerprint="fp", run_seconds=2.0, run_designs=2,
               run_peak_mb=None)
    row.update(changes)
    return row


def test_hand_made_records_round_trip_exactly(tmp_path):
    """None against empty text, NaN, ints against floats, numpy floats, odd extras and messages survive."""
    rows = [
        _record(),
        _record(idx=1, cost=float("nan"), cost_stderr=float("nan"), status="failed", links=None, self_loops=None,
                message="line one\nline two\r\n\"quoted\", ünïcode", cost_kind=None, info_model=None,
                controller_kind=None, experiment=None, seconds=0.1 + 0.2, run_seconds=None,
                run_designs=None,
                extras={"curve": {"step": [0, 5], "cost": [1.5, float("nan")]}, "empty_curve": {"step": [], "cost": []},
                        "costs": [1.0, 2], "nested": {"a": [1, {"b": None}]}, "none": None, "flag": True,
                        "count": 3, "ratio": 1e-300, "inf": float("inf"), "name": "s"}),
        _record(run_key="k2", instance={"family": "paper", "n": 4, "a_norm": 1.05, "seed": 4}, message=None,
                label="", seconds=0, cost=2),
    ]
    facts = {json.dumps(rows[0]["instance"], sort_keys=True): {"n": 4, "plant_links": 6, "comm_links": 8}}
    records = Records.from_rows(rows, facts)
    figures = {"cost_vs_links": {"M (β)": [["#1f77b4", "o"]]}}
    write_folder(records, tmp_path, meta={"spec:x": "toml"}, members={"x": {"k2", "k1"}}, superseded=2,
                 software={"numpy": "2.0"}, supports={("k1", 0): np.eye(4) * 0.5, ("k2", 0): None}, figures=figures)
    back = read_folder(tmp_path)
    _assert_same_records(records, back.records)
    assert back.records[2].instance.n is None and back.records[0].instance.plant_links == 6
    assert back.members == {"x": {"k1", "k2"}} and back.superseded == 2 and back.figures == figures
    assert np.array_equal(back.load_controller("k1", 0).support, np.eye(4, dtype=bool))
    assert back.load_controller("k2", 0) is None


def test_numpy_floats_are_written_as_plain_reprs(tmp_path):
    write_folder(Records.from_rows([_record(seconds=np.float64(0.1) + 0.2)]), tmp_path, meta={}, members={},
                 superseded=0, software={})
    assert ",0.30000000000000004," in (tmp_path / "runs.csv").read_text()
    assert read_folder(tmp_path).records[0].seconds == 0.1 + 0.2


GOOD_INSTANCE = json.dumps(_record()["instance"], sort_keys=True)
GOOD_DRAWING = {"plant": [[0, 1], [0, 1, 2], [1, 2, 3], [2, 3]], "comm": [[0], [1], [2], [3]],
                "colours": [0.5, 0.25, 0.125, 1.0]}


def _good_folder(tmp_path) -> Path:
    rows = [_record(extras={"curve": {"step": [0, 1], "cost": [2.0, 1.5]}}), _record(idx=1)]
    facts = {GOOD_INSTANCE: {"n": 4, "plant_links": 6, "comm_links": 0, "drawing": GOOD_DRAWING}}
    write_folder(Records.from_rows(rows, facts), tmp_path, meta={}, members={"x": {"k1"}}, superseded=0,
                 software={}, supports={("k1", 0): np.ones((2, 2))})
    return tmp_path


def test_the_drawn_instances_drawing_round_trips(tmp_path):
    drawing = read_folder(_good_folder(tmp_path)).records[0].instance.drawing
    assert drawing.to_facts() == GOOD_DRAWING and drawing.nodes == 4


def _edit_csv(name, old, new):
    def edit(folder):
        text = (folder / name).read_text()
        assert old in text, (name, old)
        (folder / name).write_text(text.replace(old, new, 1))
    return edit


def _edit_json(change):
    def edit(folder):
        document = json.loads((folder / "report.json").read_text())
        change(document)
        (folder / "report.json").write_text(json.dumps(document))
    return edit


MALFORMED = [
    (lambda f: (f / "runs.csv").unlink(), "runs.csv", "no runs.csv"),
    (lambda f: (f / "report.json").unlink(), "report.json", "no report.json"),
    (lambda f: (f / "curves.csv").unlink(), "curves.csv", "no curves.csv"),
    (lambda f: (f / "runs.csv").write_text(""), "runs.csv", "empty file"),
    (_edit_csv("runs.csv", ",run_seconds,", ",seconds_of_run,"), "runs.csv", "missing columns run_seconds"),
    (_edit_csv("runs.csv", ",1.25,", ",1.2.5,"), "runs.csv", "line 2: column cost"),
    (_edit_csv("runs.csv", ",k1,0,", ",k1,zero,"), "runs.csv", "line 2: column idx"),
    (_edit_csv("runs.csv", '""tag""', '""tag"'), "runs.csv", "line 2: column params"),
    (_edit_csv("runs.csv", ",k1,1,", ",k1,0,"), "runs.csv", "design (k1, 0) again"),
    (_edit_csv("runs.csv", ",fp,", ",fp,extra,"), "runs.csv", "fields, the header has"),
    (_edit_csv("curves.csv", "k1,0,curve", "k9,0,curve"), "curves.csv", "no design (k9, 0)"),
    (_edit_csv("curves.csv", ",2.0\n", ",two\n"), "curves.csv", "line 2"),
    (lambda f: (f / "report.json").write_text("{not json"), "report.json", "not valid JSON"),
    (lambda f: (f / "report.json").write_text("[]"), "report.json", "expected a JSON object"),
    (_edit_json(lambda d: d.pop("meta")), "report.json", "missing keys meta"),
    (_edit_json(lambda d: d.update(format=2)), "report.json", "format 2"),
    (_edit_json(lambda d: d.update(members={"x": "k1"})), "report.json", "members"),
    (_edit_json(lambda d: d.update(superseded=-1)), "report.json", "superseded"),
    (_edit_json(lambda d: d.update(software={"numpy": "2.0"})), "report.json", "software must be"),
    (_edit_json(lambda d: d.update(figures=[])), "report.json", "figures must be an object"),
    (_edit_json(lambda d: d["supports"]["k1/0"].update(nonzero=[[0, 2]])), "report.json", "nonzero"),
    (_edit_json(lambda d: d["supports"].update({"k7/0": None})), "report.json", "'k7/0' is no design"),
    (_edit_json(lambda d: d.update(drawings=[])), "report.json", "drawings must be an object"),
    (_edit_json(lambda d: d["drawings"].update({'{"n": 5}': GOOD_DRAWING})), "report.json",
     "drawings: '{\"n\": 5}' is no instance in runs.csv"),
    (_edit_json(lambda d: d["drawings"][GOOD_INSTANCE].update(colours=[1.0])), "report.json",
     "drawings: a stored drawing's plant must list the sending nodes of each of its 1 nodes"),
    (_edit_json(lambda d: d["drawings"][GOOD_INSTANCE].pop("comm")), "report.json", "drawings: a stored drawing must"),
]


@pytest.mark.parametrize("damage, name, problem", MALFORMED)
def test_malformed_folders_give_one_line_errors_naming_the_file(tmp_path, damage, name, problem):
    folder = _good_folder(tmp_path)
    read_folder(folder)  # intact, it reads
    damage(folder)
    with pytest.raises(FolderError) as caught:
        read_folder(folder)
    message = str(caught.value)
    assert name in message and problem in message, message
    assert "\n" not in message


def test_report_without_store_or_folder_files_exits_2_with_one_line(tmp_path):
    result = CliRunner().invoke(main, ["report", "--out", str(tmp_path)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "no result store" in lines[0] and "runs.csv" in lines[0], result.output


def test_report_from_a_malformed_folder_exits_2_with_one_line(tmp_path):
    folder = _good_folder(tmp_path)
    (folder / "runs.csv").unlink()
    result = CliRunner().invoke(main, ["report", "--out", str(folder)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "no runs.csv" in lines[0], result.output


def test_report_without_store_hands_the_folder_data_to_write_report(tmp_path, monkeypatch):
    import compare.report.write

    folder = _good_folder(tmp_path)
    calls = []

    def fake_write_report(records, out, **kwargs):
        calls.append((records, Path(out), kwargs))
        return {"md": Path(out) / "report.md"}

    monkeypatch.setattr(compare.report.write, "write_report", fake_write_report)
    result = CliRunner().invoke(main, ["report", "--out", str(folder)])
    assert result.exit_code == 0, result.output
    assert "rebuilt from the folder's runs.csv and report.json" in result.output
    (records, out, kwargs), = calls
    assert out == folder and [r.idx for r in records] == [0, 1]
    assert kwargs["software"] == {} and kwargs["members"] == {"x": {"k1"}} and kwargs["superseded"] == 0
    assert kwargs["commands"] == [f"compare report --out {folder}"]
    assert kwargs["load_controller"]("k1", 0).support.all()


@pytest.mark.skipif("software" not in inspect.signature(
    __import__("compare.report.write").report.write.write_report).parameters,
                    reason="write_report does not yet take software= (and write the folder's files)")
def test_compare_report_rebuilds_the_same_report_without_its_store(stored, tmp_path, forbid_instance_builds):
    from compare import Store
    from compare.cli import _write_report

    path, _, _, _ = stored
    out = tmp_path / "out"
    with Store(path) as store:
        _write_report(store, out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(FOLDER_FILES.values()) | {"topologies.png", "topologies.svg"} <= set(before)
    forbid_instance_builds()  # the topology figure is drawn from report.json, as from the store
    result = CliRunner().invoke(main, ["report", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "rebuilt from the folder's runs.csv and report.json" in result.output
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_folder_written_before_drawings_were_kept_rebuilds_without_the_figure(stored, tmp_path,
                                                                                forbid_instance_builds):
    from compare import Store
    from compare.cli import _write_report

    path, _, _, _ = stored
    out = tmp_path / "out"
    with Store(path) as store:
        _write_report(store, out)
    assert "![designed topologies](topologies.png)" in (out / "report.md").read_text()
    document = json.loads((out / "report.json").read_text())
    assert document.pop("drawings")
    (out / "report.json").write_text(json.dumps(document))
    forbid_instance_builds()
    result = CliRunner().invoke(main, ["report", "--out", str(out)])
    assert result.exit_code == 0, result.output
    text = (out / "report.md").read_text()
    assert "Designed topologies" not in text and "## Medians by method" in text
