"""Experiment metadata: one key format (compare.run.meta), a typed view that gives the raw mapping back exactly."""

import json
import re
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from compare.run.meta import MetaError, MetaKind, StoreMeta, entries_of, meta_key, parse_meta_key

ROOT = Path(__file__).resolve().parents[1]
QUICK = ROOT / "reports" / "quick"

SPEC = """
name = "meta-tiny"
[report]
sections = ["compute"]
pairs = [["lqr", "decentralized"]]
[instances]
n = [4]
a_norms = [1.05]
seeds = 2
degree = 2
horizon = 5
[[methods]]
method = "lqr"
[[methods]]
method = "decentralized"
"""


@pytest.fixture(scope="module")
def store_meta(tmp_path_factory):
    """The meta of a real store (a tiny experiment, about a second) and its instance facts."""
    from compare import Store, parse_spec, run_experiment

    with Store(tmp_path_factory.mktemp("store") / "results.sqlite") as store:
        run_experiment(parse_spec(SPEC), store, progress=False, workers=1)
        store.set_meta(meta_key(MetaKind.COMMAND, "meta-tiny"), "compare run meta-tiny.toml")
        return store.meta(), store.instance_facts()


def test_a_key_is_its_kind_and_name_and_reads_back():
    assert meta_key(MetaKind.SPEC, "quick") == "spec:quick"
    assert meta_key("fingerprint", "ab12") == "fingerprint:ab12"
    for kind in MetaKind:
        assert parse_meta_key(meta_key(kind, "x")) == (kind, "x")
    # An instance key is JSON, colons and all: only the first colon separates.
    name = json.dumps({"family": "paper", "n": 4})
    assert parse_meta_key(meta_key(MetaKind.INSTANCE, name)) == (MetaKind.INSTANCE, name)
    assert parse_meta_key("note") is None and parse_meta_key("later:thing") is None
    with pytest.raises(ValueError):
        meta_key("specs", "quick")


def test_a_real_stores_meta_parses_into_every_kind_and_back_exactly(store_meta):
    raw, facts = store_meta
    meta = StoreMeta.parse(raw)
    back = meta.to_mapping()
    assert back == raw and list(back) == list(raw)
    assert json.dumps(back, sort_keys=True) == json.dumps(raw, sort_keys=True)
    assert meta.specs["meta-tiny"] == SPEC
    assert meta.sections == {"meta-tiny": ("compute",)}
    assert meta.pairs == {"meta-tiny": (("lqr", "decentralized"),)}
    assert meta.commands == {"meta-tiny": "compare run meta-tiny.toml"}
    assert meta.environments["meta-tiny"]["workers"] == 1
    assert set(meta.methods) == {"lqr", "decentralized"}
    lqr = meta.methods["lqr"]
    assert lqr.label == raw["method:lqr"]["label"] and lqr.produces == () and lqr.path_param is None
    assert set(meta.fingerprints) == {m.fingerprint for m in meta.methods.values()}
    assert all("numpy" in fp.versions for fp in meta.fingerprints.values())
    assert len(meta.instances) == 2 and not meta.unknown
    # The store reads its instance facts through the same key format.
    assert facts == entries_of(raw, MetaKind.INSTANCE) == {k: raw[meta_key(MetaKind.INSTANCE, k)] for k in facts}


def test_a_shipped_report_folders_meta_parses_and_back_exactly():
    raw = json.loads((QUICK / "report.json").read_text())["meta"]
    meta = StoreMeta.parse(raw)
    back = meta.to_mapping()
    assert back == raw and list(back) == list(raw)
    assert json.dumps(back, sort_keys=True, indent=1, ensure_ascii=False) == json.dumps(
        raw, sort_keys=True, indent=1, ensure_ascii=False)
    assert meta.specs["quick"].startswith('name = "quick"') and not meta.unknown
    assert meta.methods["grnn_sparse"].path_param == "beta"
    assert "topology_path" in meta.methods["grnn_sparse"].produces
    assert sum(len(getattr(meta, kind)) for kind in ("specs", "sections", "pairs", "commands", "environments",
                                                     "methods", "fingerprints", "instances")) == len(raw)


def test_unknown_keys_are_kept_aside_and_written_back():
    raw = {"note": "by hand", "later:thing": {"a": [1, {"b": None}]}, "spec:x": "name = 'x'",
           "method:partial": {"produces": ["topology_path"], "path_param": "beta"}}
    meta = StoreMeta.parse(raw)
    assert set(meta.unknown) == {"note", "later:thing"} and meta.specs == {"x": "name = 'x'"}
    # A declaration stored without some fields reads with their defaults, and is written back without them.
    assert meta.methods["partial"].label is None and meta.methods["partial"].path_param == "beta"
    assert meta.to_mapping() == raw and StoreMeta.parse(None) == StoreMeta.parse({}) == StoreMeta()
    assert StoreMeta.of(meta) is meta and StoreMeta.of(raw) == meta


def test_the_view_is_read_only_and_independent_of_the_mappings_around_it():
    raw = {"environment:x": {"cpu": "c", "cores": 2}, "sections:x": ["table1"]}
    meta = StoreMeta.parse(raw)
    with pytest.raises(TypeError):
        meta.sections["y"] = ("compute",)
    with pytest.raises(TypeError):
        meta.environments["x"]["cpu"] = "d"
    with pytest.raises(AttributeError):
        meta.sections = {}
    raw["sections:x"].append("compute")
    out = meta.to_mapping()
    out["environment:x"]["cpu"] = "d"
    assert meta.sections["x"] == ("table1",) and meta.environments["x"]["cpu"] == "c"


@pytest.mark.parametrize("key, value, says", [
    ("sections:x", "table1", "must be a list of section names"),
    ("pairs:x", [["lqr"]], "must be a list of [first, second] name pairs"),
    ("spec:x", {"name": "x"}, "must be text, got dict"),
    ("method:lqr", ["lqr"], "must be a JSON object, got list"),
])
def test_a_value_of_the_wrong_shape_names_its_key(key, value, says):
    with pytest.raises(MetaError, match=re.escape(f"meta entry {key!r} {says}")):
        StoreMeta.parse({key: value})


def test_compare_report_says_which_meta_entry_of_a_folder_is_malformed(tmp_path):
    from compare.cli import main

    for name in ("runs.csv", "curves.csv", "report.json"):
        shutil.copy(QUICK / name, tmp_path / name)
    document = json.loads((tmp_path / "report.json").read_text())
    document["meta"]["pairs:quick"] = "lqr"
    (tmp_path / "report.json").write_text(json.dumps(document))
    result = CliRunner().invoke(main, ["report", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert "Error: cannot write the report: meta entry 'pairs:quick' must be a list of [first, second]" in result.output
    assert not (tmp_path / "report.md").exists()


# Lines that split or match a "<word>:" that is no meta key: a CPU model line, a figure artist's gid.
_NOT_META = {("environment.py", 'return line.split(":", 1)[1].strip()'),
             ("figures.py", 'if not gid.startswith("method:"):')}


def test_no_module_but_compare_meta_spells_the_key_format():
    kinds = "|".join(kind.value for kind in MetaKind)
    # A key split at its colon, matched by its kind's prefix, or written as a literal or f-string.
    spelled = re.compile(r"""\.(split|partition)\(\s*["']:["']"""
                         rf"""|startswith\(\s*f?["']({kinds}):|set_meta\(\s*f?["']""")
    found = []
    for path in sorted((ROOT / "compare").rglob("*.py")):
        if path == ROOT / "compare" / "run" / "meta.py":
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if spelled.search(line) and (path.name, line.strip()) not in _NOT_META:
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert found == []
