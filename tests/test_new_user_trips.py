"""What a new user still tripped on (issue #60, item 5): each case is refused at once, labelled right, or said.

Bad input gets one ``Error:`` line naming the problem and exit code 2, no traceback, before
any run and without an output folder; stored results keep their bytes; a failure's message
says what happened.
"""

from __future__ import annotations

import csv
import shutil
import sqlite3
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from compare import Store, parse_spec, run_experiment
from compare.cli import main
from compare.run.spec import SpecError

from cli_checks import error_line, file_sha  # tests/cli_checks.py

ROOT = Path(__file__).resolve().parent.parent

INSTANCES = """
[instances]
n = [6]
a_norms = [0.995]
seeds = 1
degree = 3
horizon = 10
"""


def _invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _spec(path: Path, body: str, *, top: str = "") -> Path:
    path.write_text(f'name = "trip"\n{top}{INSTANCES}\n{body}')
    return path


# -- 1. GRNN settings that do not go together: refused when the spec is loaded ------------------------------
GRNN_CLASHES = [
    ("grnn", {"readout": "per_node", "engine": "fused"},
     "engine 'fused' supports readout 'shared' only, got readout 'per_node'"),
    ("grnn_fixed", {"init": "delayed", "readout": "per_node"}, "init 'delayed' does not apply to variant 'fixed'"),
    ("grnn", {"init": "diagonal"}, "init 'diagonal' needs readout 'per_node'"),
    ("grnn_sparse", {"init": "delayed", "readout": "per_node", "l1_hops": 2, "beta": 1.0},
     "init 'delayed' needs l1_hops None"),
]


def _toml(params: dict) -> str:
    return "{ " + ", ".join(f"{k} = {v!r}".replace("'", '"') for k, v in params.items()) + " }"


@pytest.mark.parametrize("method, params, words", GRNN_CLASHES)
def test_grnn_settings_that_do_not_go_together_are_refused_when_the_spec_is_loaded(tmp_path, method, params, words):
    spec = _spec(tmp_path / "s.toml", f'[[methods]]\nmethod = "{method}"\nparams = {_toml(params)}\n')
    with pytest.raises(SpecError) as refused:
        parse_spec(spec.read_text())
    assert str(refused.value).startswith(f"methods[0].params: {words}")
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--workers", "1", "--no-progress"))
    assert line.startswith(f"Error: methods[0].params: {words}"), line
    assert not (tmp_path / "out").exists()


def test_a_grid_point_that_clashes_is_refused_naming_it_and_one_that_does_not_is_accepted():
    entry = '[[methods]]\nmethod = "grnn"\nparams = {{ readout = "per_node" }}\ngrid = {{ {} }}\n'
    # init "diagonal" needs the per-node readout that params set: each grid value alone would not pass.
    parse_spec(f'name = "g"\n{INSTANCES}\n' + entry.format('init = ["diagonal", "random"]'))
    with pytest.raises(SpecError, match=r"methods\[0\]\.params \(grid point engine = 'fused'\): engine 'fused' "
                                        r"supports readout 'shared' only"):
        parse_spec(f'name = "g"\n{INSTANCES}\n' + entry.format('engine = ["torch", "fused"]'))


@pytest.mark.parametrize("method, params, words", GRNN_CLASHES)
def test_the_python_api_raises_before_any_training(monkeypatch, method, params, words):
    import importlib
    import re

    from codesign import paper_instance
    from codesign.methods import get_method

    grnn_module = importlib.import_module("codesign.learned.grnn")

    def no_training(*args, **kwargs):
        raise AssertionError("training started")

    monkeypatch.setattr(grnn_module, "train_jobs", no_training)
    inst = paper_instance(0, n=6, degree=3, horizon=10)
    with pytest.raises(ValueError, match=re.escape(words)):
        get_method(method)(inst, **params)  # the registry's call: checked before the method runs
    variant = {"grnn": "given", "grnn_fixed": "fixed", "grnn_sparse": "sparse"}[method]
    with pytest.raises(ValueError, match=re.escape(words)):
        grnn_module.grnn(inst, variant=variant, **params)


# -- 2. a validation set that can never fit: refused when the spec is loaded ------------------------------
def test_a_validation_set_larger_than_memory_is_refused_at_load(tmp_path):
    spec = _spec(tmp_path / "s.toml", '[evaluation]\nvalidation_size = 1000000000\n\n[[methods]]\nmethod = "grnn"\n')
    started = time.perf_counter()
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--workers", "1", "--no-progress"))
    assert time.perf_counter() - started < 30  # before any run (one took 41.6 s, then stored a MemoryError)
    assert line.startswith("Error: evaluation.validation_size: 1000000000 draws at n = 6 need about")
    assert "the largest validation_size that fits is" in line
    assert not (tmp_path / "out").exists()


def test_the_validation_guard_names_the_largest_size_that_fits():
    from compare.run.spec import VALIDATION_NUMBERS, _check_validation_memory

    spec = parse_spec(f'name = "v"\n{INSTANCES}\n[[methods]]\nmethod = "lqr"\n')
    memory = 10 ** 9
    largest = memory // (VALIDATION_NUMBERS * 8 * 6)
    fits = type(spec.evaluation)(validation_size=largest)
    _check_validation_memory(fits, spec.instances, memory)
    with pytest.raises(SpecError, match=f"the largest validation_size that fits is {largest}$"):
        _check_validation_memory(type(spec.evaluation)(validation_size=largest + 1), spec.instances, memory)


# -- 3. a timeout no run can reach ----------------------------------------------------------------------
@pytest.mark.parametrize("top, entry, where", [
    ("timeout = 1e10\n", "", "timeout"),
    ("timeout = 1e300\n", "", "timeout"),
    ("", "timeout = 1e10\n", "methods[0].timeout"),
])
def test_a_timeout_above_the_largest_is_refused_and_leaves_no_folder(tmp_path, top, entry, where):
    spec = _spec(tmp_path / "s.toml", f'[[methods]]\nmethod = "lqr"\n{entry}', top=top)
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--workers", "1", "--no-progress"))
    assert line.startswith(f"Error: {where}: ") and "more than the largest time limit, 1e+07 s" in line, line
    assert "leave timeout out for no limit" in line
    assert not (tmp_path / "out").exists()


def test_the_pool_never_waits_longer_than_the_os_can(monkeypatch):
    from compare.run import pool as pool_module

    class Busy:
        task = (1, [], 0.0, time.monotonic() + 1e10)

    workers = pool_module.WorkerPool(1)
    workers._busy.append(Busy())
    wait = workers._wait_time()
    assert 0 < wait <= pool_module._LONGEST_WAIT
    # What the pool waits with: a second's wait for a pipe that never speaks, the limit of 1e10 s accepted.
    import multiprocessing

    reader, writer = multiprocessing.Pipe(duplex=False)
    monkeypatch.setattr(pool_module, "_LONGEST_WAIT", 0.05)
    assert pool_module.wait_ready([reader], workers._wait_time()) == []
    reader.close()
    writer.close()


# -- 4. an interrupt before the first run, and a failed first run -------------------------------------
def test_an_interrupt_before_any_run_names_no_missing_file_and_leaves_no_folder(tmp_path, monkeypatch):
    from compare.run import runner

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "run_experiment", interrupted)
    spec = _spec(tmp_path / "s.toml", '[[methods]]\nmethod = "lqr"\n')
    out = tmp_path / "new" / "out"
    result = _invoke("run", spec, "--out", out, "--workers", "1", "--no-progress")
    assert result.exit_code == 130, result.output
    assert "interrupted before any run was stored; nothing was kept" in result.output
    assert "results.sqlite" not in result.output
    assert not (tmp_path / "new").exists()


def test_an_interrupt_after_stored_runs_names_the_store_that_holds_them(tmp_path, monkeypatch):
    from compare.run import runner

    spec = _spec(tmp_path / "s.toml", '[[methods]]\nmethod = "lqr"\n')
    out = tmp_path / "out"
    with Store(out / "results.sqlite") as store:
        run_experiment(parse_spec(spec.read_text()), store, progress=False)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "run_experiment", interrupted)
    result = _invoke("run", spec, "--out", out, "--workers", "1", "--no-progress")
    assert result.exit_code == 130, result.output
    assert f"interrupted: 1 runs are stored in {out / 'results.sqlite'}" in result.output
    assert (out / "results.sqlite").is_file()


def test_a_run_that_fails_before_storing_anything_leaves_no_empty_folder(tmp_path, monkeypatch):
    from compare.run import runner

    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(runner, "run_experiment", broken)
    spec = _spec(tmp_path / "s.toml", '[[methods]]\nmethod = "lqr"\n')
    result = _invoke("run", spec, "--out", tmp_path / "a" / "b", "--workers", "1", "--no-progress")
    assert isinstance(result.exception, RuntimeError)
    assert not (tmp_path / "a").exists()
    # A folder that was there before is kept, whatever happens.
    (tmp_path / "kept").mkdir()
    _invoke("run", spec, "--out", tmp_path / "kept", "--workers", "1", "--no-progress")
    assert (tmp_path / "kept").is_dir() and not list((tmp_path / "kept").iterdir())


# -- 5. report and export leave a WAL store's bytes as they were -------------------------------------
@pytest.fixture(scope="module")
def good_store(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("store") / "results.sqlite"
    text = f'name = "trip"\n{INSTANCES}\n[[methods]]\nmethod = "lqr"\n[[methods]]\nmethod = "decentralized"\n'
    with Store(path) as store:
        run_experiment(parse_spec(text), store, progress=False)
    return path


def _wal(path: Path) -> Path:
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA journal_mode=WAL").fetchone()[0] == "wal"
    con.close()
    assert path.read_bytes()[18:20] == b"\x02\x02"  # the header's WAL marks
    return path


def test_report_and_export_leave_a_wal_store_byte_identical(good_store, tmp_path):
    pytest.importorskip("pandas")
    path = _wal(shutil.copy(good_store, tmp_path / "r.sqlite"))
    before = file_sha(path)
    for args in (["report", "--out", tmp_path / "rep", "--store", path],
                 ["export", "--out", tmp_path / "exp", "--store", path]):
        result = _invoke(*args)
        assert result.exit_code == 0, result.output
        assert file_sha(path) == before, f"{args[0]} changed the store"
        assert sorted(p.name for p in tmp_path.glob("r.sqlite*")) == ["r.sqlite"]
    assert (tmp_path / "rep" / "report.md").is_file() and (tmp_path / "exp" / "designs.csv").is_file()


OLDER_STORES = {
    "schema 2": ["ALTER TABLE runs DROP COLUMN scoring_seconds", "ALTER TABLE runs DROP COLUMN baseline_mb",
                 "PRAGMA user_version = 2"],
    # Before the mark: no peak_mb, and no members or claims table (a migration would create them).
    "unmarked": ["DROP TABLE members", "DROP TABLE claims", "ALTER TABLE runs DROP COLUMN peak_mb",
                 "ALTER TABLE runs DROP COLUMN scoring_seconds", "ALTER TABLE runs DROP COLUMN baseline_mb",
                 "PRAGMA application_id = 0", "PRAGMA user_version = 0"],
}


@pytest.mark.parametrize("older", sorted(OLDER_STORES))
def test_an_older_store_is_read_without_being_migrated(good_store, tmp_path, older):
    path = shutil.copy(good_store, tmp_path / "old.sqlite")
    con = sqlite3.connect(path)
    with con:
        for statement in OLDER_STORES[older]:
            con.execute(statement)
    con.close()
    before = file_sha(path)
    with Store(path, read_only=True) as store:
        records = store.records()
        assert len(records) == 2 and all(r.run_scoring_seconds is None for r in records)
        with pytest.raises(Exception, match="read-only"):
            store.set_meta("x", 1)
    result = _invoke("report", "--out", tmp_path / "rep", "--store", path)
    assert result.exit_code == 0, result.output
    assert file_sha(path) == before


# -- 6. a hand-edited runs.csv --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def report_folder(good_store, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("report")
    result = _invoke("report", "--out", out, "--store", good_store)
    assert result.exit_code == 0, result.output
    return out


@pytest.mark.parametrize("column, value, words", [
    ("info_model", "telepathic", "info_model 'telepathic' is not one of instantaneous, delayed, none"),
    ("cost_kind", "guessed", "cost_kind 'guessed' is not one of exact, simulated, none"),
    ("links", "100000", "links 100000 is more than an instance of 6 nodes can have (at most 30)"),
    ("self_loops", "7", "self_loops 7 is more than an instance of 6 nodes can have (at most 6)"),
    ("instance_n", "twenty", "instance_n 'twenty' is not the instance's n (6 in column instance)"),
    ("instance_a_norm", "1.05", "instance_a_norm '1.05' is not the instance's a_norm (0.995 in column instance)"),
])
def test_a_hand_edited_runs_csv_is_refused_naming_file_line_and_field(report_folder, tmp_path, column, value, words):
    folder = shutil.copytree(report_folder, tmp_path / "rep")
    path = folder / "runs.csv"
    with path.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    rows[2][rows[0].index(column)] = value
    with path.open("w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows(rows)
    before = {p.name: file_sha(p) for p in folder.iterdir()}
    line = error_line(_invoke("report", "--out", folder))
    assert f"{path} line 3: {words}" in line, line
    assert {p.name: file_sha(p) for p in folder.iterdir()} == before


def test_the_shipped_report_folders_pass_the_new_checks():
    from compare.report.folder import read_folder

    for folder in ("quick", "power", "systems"):
        assert len(read_folder(ROOT / "reports" / folder).records) > 0


# -- 7. the warm start's fallback chain in a failure's message; a NaN gain is failed -----------------------
def test_a_delayed_start_that_falls_back_says_the_chain_in_a_diverged_message(monkeypatch):
    from codesign import paper_instance
    from codesign.design import Design
    import importlib

    from baselines import grnn
    warm = importlib.import_module("baselines.grnn")  # the module (baselines.grnn the name is the function)

    def no_design(self, instance, *args, **kwargs):
        return Design.failure("source", {}, "diverged", "no stabilizing gain found")

    for source in ("diagonal", "delayed_given", "delayed_path"):
        monkeypatch.setattr(warm.StartCache, source, no_design)
    inst = paper_instance(0, n=6, a_norm=3.0, degree=2, horizon=50)  # the random draw's GRNN blows up here
    design = grnn(inst, init="delayed", readout="per_node", steps=1, ensemble=1)
    assert design.status == "diverged"
    chain = ("sparse_delayed on the given graph gave no usable design (no stabilizing gain found), so the "
             "diagonal gain; decentralized gave no usable design (no stabilizing gain found), so the random "
             "initialization")
    assert design.extras["init_note"] == chain
    assert design.message.endswith(f"; {chain}") and "unbounded" in design.message, design.message


def test_a_nan_gain_is_failed_not_diverged():
    from codesign import paper_instance
    from codesign.controllers import StaticGain
    from codesign.scoring import score

    inst = paper_instance(0, n=6, degree=3, horizon=10)
    for bad in (np.nan, np.inf):
        K = np.zeros((inst.m, inst.n))
        K[0, 1] = bad
        design = score(inst, StaticGain(K))
        assert design.status == "failed" and design.controller is None and np.isnan(design.cost)
        assert design.message == "the controller's K has NaN or infinite entries: no controller to score"
    assert score(inst, StaticGain(np.zeros((inst.m, inst.n)))).status == "optimal"


# -- 8. the stated run times say on what machine ---------------------------------------------------------
def test_the_stated_run_times_name_the_machine_they_were_measured_on():
    readme = (ROOT / "README.md").read_text()
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert "Its 280 runs take one to three minutes on a 2-core machine\n(64 s measured on one and 175 s" in readme
    assert "on a 2-core machine about 10 to 13 minutes: 578 s and 745 s measured on\ntwo machines on 2026-12-07" in readme
    assert "578 s and 745 s with warm\n# caches on 2026-12-07" in pyproject
    assert "(about 4 minutes on 2 cores: 234 s measured from an empty store)" in readme
    assert "about 4.5 minutes" not in pyproject
