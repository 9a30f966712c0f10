"""What a new user still trips on (issue #49): each case is a one-line exit-2 error or a recorded status.

Bad input gets one ``Error:`` line naming the problem and exit code 2, no traceback, and
leaves stored results as they were (checked by hash); a method's failure is its run's
``failed`` status, on every executor.
"""

from __future__ import annotations

import csv
import random
import re
import shutil
import sqlite3
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from compare import Store, StoreError, parse_spec, run_experiment
from compare.run.spec import SpecError
from compare.cli import main

from cli_checks import error_line, file_sha  # tests/cli_checks.py

HERE = Path(__file__).resolve().parent

INSTANCES = """
[instances]
n = [6]
a_norms = [0.995, 1.05]
seeds = 1
degree = 3
horizon = 10
"""

SPEC = f'name = "newuser"\n{INSTANCES}\n[[methods]]\nmethod = "lqr"\n'




def _invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def good_store(tmp_path_factory) -> Path:
    """A small store of two LQR runs, made once (in this process: no workers to start)."""
    path = tmp_path_factory.mktemp("store") / "results.sqlite"
    with Store(path) as store:
        run_experiment(parse_spec(SPEC), store, progress=False)
    return path


# -- 1. a damaged store ---------------------------------------------------------------------------
def _damage(path: Path) -> Path:
    """4 KB of garbage a third of the way into the file (the same garbage every time)."""
    garbage = random.Random(49).randbytes(4096)
    with path.open("r+b") as handle:
        handle.seek(path.stat().st_size // 3)
        handle.write(garbage)
    return path


def test_a_damaged_store_is_refused_by_name_and_left_byte_identical(good_store, tmp_path):
    path = _damage(shutil.copy(good_store, tmp_path / "damaged.sqlite"))
    before = file_sha(path)
    spec = tmp_path / "s.toml"
    spec.write_text(SPEC)
    for args in (["report", "--out", tmp_path / "rep", "--store", path],
                 ["run", spec, "--out", tmp_path / "out", "--store", path, "--workers", "1", "--no-progress"],
                 ["export", "--out", tmp_path / "exp", "--store", path]):
        line = error_line(_invoke(*args))
        assert f"the result store {path} is damaged" in line, line
        assert file_sha(path) == before, f"{args[0]} changed the damaged store"
    assert not (tmp_path / "rep" / "report.md").exists() and not (tmp_path / "out" / "report.md").exists()


def test_damage_found_after_opening_is_a_store_error(good_store, tmp_path):
    path = shutil.copy(good_store, tmp_path / "r.sqlite")
    with Store(path) as store:
        _damage(path)
        with pytest.raises(StoreError, match="is damaged"):
            store.records()


# -- 3. a foreign database in WAL mode --------------------------------------------------------------
def test_a_foreign_wal_database_gets_no_files_beside_it(tmp_path):
    path = tmp_path / "w.sqlite"
    con = sqlite3.connect(path)
    con.execute("PRAGMA journal_mode=WAL")
    with con:
        con.execute("CREATE TABLE photos (id INTEGER PRIMARY KEY, name TEXT)")
    con.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.sqlite"]
    before = file_sha(path)
    spec = tmp_path / "s.toml"
    spec.write_text(SPEC)
    for args in (["export", "--out", tmp_path / "exp", "--store", path],
                 ["report", "--out", tmp_path / "rep", "--store", path],
                 ["run", spec, "--out", tmp_path / "out", "--store", path, "--workers", "1", "--no-progress"]):
        line = error_line(_invoke(*args))
        assert "not a result store" in line and "left untouched" in line, line
        assert file_sha(path) == before
        assert not list(tmp_path.glob("w.sqlite-*")), f"{args[0]} left {list(tmp_path.glob('w.sqlite-*'))}"


# -- 2. a design that cannot leave its worker, on every executor ----------------------------------------
UNSENDABLE_SPEC = (f'name = "unsendable"\nplugins = ["{HERE / "new_user_methods.py"}"]\n{INSTANCES}'
                   '\n[[methods]]\nmethod = "lqr"\nwhere = { a_norm = [0.995] }\n'
                   '\n[[methods]]\nmethod = "newuser_lock_extras"\nwhere = { a_norm = [0.995] }\n'
                   '\n[[methods]]\nmethod = "newuser_set_extras"\nwhere = { a_norm = [0.995] }\n')
UNSENDABLE = {"newuser_lock_extras": "could not be sent back from the worker process (TypeError: cannot pickle "
                                     "'_thread.lock' object)",
              "newuser_set_extras": "could not be stored (TypeError: not JSON-serializable: set)"}


def _statuses(path: Path) -> dict:
    with Store(path) as store:
        return {r.method: (r.status, r.message) for r in store.records()}


@pytest.fixture(scope="module")
def dask_client():
    """A one-worker dask LocalCluster (worker processes: results cross a process boundary), started once."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as cluster, distributed.Client(cluster) as client:
        yield client


def _run_on(executor: str, request, spec, path: Path):
    """Run ``spec`` into ``path`` in this process, on a local pool of one worker, or on dask."""
    if executor == "this process":
        return _run_within(60, spec, path, workers=1)
    if executor == "process pool":
        return _run_within(60, spec, path, workers=1, executor="process")
    client = request.getfixturevalue("dask_client")
    return _run_within(60, spec, path, executor=client.get_executor(pure=False))


def _run_within(seconds: float, spec, path: Path, **kwargs):
    """run_experiment in a thread: a sweep that retries for ever fails the test instead of hanging it."""
    done = {}

    def run():
        with Store(path) as store:  # an SQLite connection belongs to the thread that opened it
            done["summary"] = run_experiment(spec, store, progress=False, **kwargs)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"nothing recorded after {seconds} s: the executor retries the run"
    return done["summary"]


@pytest.mark.parametrize("executor", ["this process", "process pool", "dask"])
def test_an_unserializable_design_is_its_runs_failure_on_every_executor(tmp_path, request, executor):
    path = tmp_path / "r.sqlite"
    summary = _run_on(executor, request, parse_spec(UNSENDABLE_SPEC), path)
    assert summary.computed == 3
    got = _statuses(path)
    assert got["lqr"] == ("optimal", "")
    for name, words in UNSENDABLE.items():
        status, message = got[name]
        assert status == "failed" and words in message, (executor, name, message)


# -- 4. a `where` that selects nothing --------------------------------------------------------------------
@pytest.mark.parametrize("methods, words", [
    # the only entry selects nothing: the run would have said "0 runs" and written an empty report
    ('[[methods]]\nmethod = "lqr"\nwhere = { a_norm = ["0.995"] }\n',
     "methods[0].where: a_norm = ['0.995'] matches no instance of experiment w; a_norm takes 0.995, 1.05"),
    # a second entry selects nothing: it would have been dropped without a word
    ('[[methods]]\nmethod = "lqr"\n[[methods]]\nmethod = "decentralized"\nwhere = { a_norm = [2.0] }\n',
     "methods[1].where: a_norm = [2.0] matches no instance of experiment w; a_norm takes 0.995, 1.05"),
    # of several keys, the one that matches nothing is named
    ('[[methods]]\nmethod = "lqr"\nwhere = { a_norm = [1.05], seed = [0] }\n[[methods]]\nmethod = "lqr"\n'
     'label = "other"\nwhere = { n = [7], seed = [0] }\n',
     "methods[1].where: n = [7] and seed = [0] matches no instance of experiment w; n takes 6"),
])
def test_a_where_that_selects_no_instance_is_refused_naming_the_key_and_its_values(tmp_path, methods, words):
    spec = tmp_path / "w.toml"
    spec.write_text(f'name = "w"\n{INSTANCES}\n{methods}')
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--no-progress"))
    assert words in line, line
    assert not (tmp_path / "out").exists()


# -- 5. a hand-edited runs.csv ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def report_folder(good_store, tmp_path_factory) -> Path:
    """A report folder (runs.csv, curves.csv, report.json) without a store in it."""
    out = tmp_path_factory.mktemp("report")
    result = _invoke("report", "--out", out, "--store", good_store)
    assert result.exit_code == 0, result.output
    return out


def _edit_runs_csv(folder: Path, column: str, value: str) -> int:
    """Set ``column`` of the second design row of runs.csv to ``value``; returns that row's line number."""
    path = folder / "runs.csv"
    with path.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    rows[2][rows[0].index(column)] = value
    with path.open("w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerows(rows)
    return 3


@pytest.mark.parametrize("column, value, words", [
    ("status", "banana", "status 'banana' is not a design status (optimal, inaccurate, infeasible, diverged, failed)"),
    ("cost", "-5", "cost -5: a design with status 'optimal' has a finite cost > 0"),
    ("cost", "nan", "cost nan: a design with status 'optimal' has a finite cost > 0"),
    ("links", "-3", "links -3 is not a count (a whole number >= 0)"),
    ("seconds", "-1.0", "seconds -1.0 is not a number >= 0"),
])
def test_a_hand_edited_runs_csv_is_refused_naming_the_file_line_and_field(report_folder, tmp_path, column, value,
                                                                          words):
    folder = shutil.copytree(report_folder, tmp_path / "rep")
    line = _edit_runs_csv(folder, column, value)
    before = {p.name: file_sha(p) for p in folder.iterdir()}
    error = error_line(_invoke("report", "--out", folder))
    assert f"{folder / 'runs.csv'} line {line}: {words}" in error, error
    assert {p.name: file_sha(p) for p in folder.iterdir()} == before


def test_the_store_refuses_its_own_rows_by_the_same_check(good_store, tmp_path):
    path = shutil.copy(good_store, tmp_path / "r.sqlite")
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE designs SET links = -3 WHERE idx = 0")
    con.close()
    with Store(path) as store, pytest.raises(StoreError, match=r"links -3 is not a count"):
        store.records()
    line = error_line(_invoke("report", "--out", tmp_path / "rep", "--store", path))
    assert "links -3 is not a count" in line and str(path) in line


# -- 6. a spec file with a byte-order mark -----------------------------------------------------------------
def test_a_spec_file_with_a_byte_order_mark_is_read(tmp_path):
    from compare.run.spec import load_spec

    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + SPEC.encode("utf-8"))
    spec = load_spec(path)
    assert spec.name == "newuser" and len(spec.runs()) == 2
    assert not spec.source.startswith("\ufeff")


# -- 7. warnings before a one-line error ------------------------------------------------------------------
def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "compare", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def _print_warning(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))


def test_a_library_warning_while_checking_a_spec_does_not_precede_the_error_line(tmp_path):
    # Q ~ 1e-300: scipy warns ("invalid value encountered in cast") before the DARE fails.
    np.savez(tmp_path / "q.npz", A=np.diag([1.2, 0.5]), B=np.eye(2), Q=1e-300 * np.eye(2))
    spec = tmp_path / "m.toml"
    spec.write_text('name = "m"\n[instances]\nfamily = "matrices"\nfiles = ["q.npz"]\n[[methods]]\nmethod = "lqr"\n')
    with warnings.catch_warnings():
        # Printed on stderr as outside pytest, which otherwise records warnings instead.
        warnings.simplefilter("default")
        warnings.showwarning = _print_warning
        result = _invoke("run", spec, "--out", tmp_path / "out", "--no-progress")
    line = error_line(result)
    assert "not stabilizable" in line and result.stderr.strip() == line


def test_a_workers_warning_does_not_precede_the_error_line(tmp_path, capfd):
    plugin = tmp_path / "worker_only.py"
    plugin.write_text("import multiprocessing, warnings\n"
                      "if multiprocessing.parent_process() is not None:  # a worker, not the planning process\n"
                      "    warnings.warn('newuser: a worker warns', RuntimeWarning)\n"
                      "    raise ImportError('this plug-in is not installed on the worker')\n")
    spec = tmp_path / "s.toml"
    spec.write_text(f'name = "wk"\nplugins = ["{plugin}"]\n{INSTANCES}\n[[methods]]\nmethod = "lqr"\n')
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--workers", "1", "--no-progress"))
    assert line.startswith("Error: a worker could not load method"), line
    # The worker process writes to the real stderr (file descriptor 2), which capfd holds.
    assert "a worker warns" not in capfd.readouterr().err


@pytest.mark.parametrize("executor", ["process pool", "dask"])
def test_a_workers_warnings_come_back_to_the_client_once(tmp_path, request, executor):
    spec = parse_spec(f'name = "wn"\nplugins = ["{HERE / "new_user_methods.py"}"]\n{INSTANCES}'
                      '\n[[methods]]\nmethod = "newuser_warns"\n')
    if executor == "dask":
        request.getfixturevalue("dask_client")  # started before the warnings are recorded
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        summary = _run_on(executor, request, spec, tmp_path / "r.sqlite")
    assert summary.statuses == {"optimal": 2}
    ours = [w for w in caught if "newuser: overflow in a rollout" in str(w.message)]
    assert len(ours) == 1 and ours[0].category is RuntimeWarning, [str(w.message) for w in caught]


def test_a_warning_in_a_command_that_succeeds_is_shown_once_at_its_end(tmp_path):
    plugin = tmp_path / "warns.py"
    plugin.write_text("import warnings\nwarnings.warn('newuser: a plug-in warns', RuntimeWarning)\n")
    result = _invoke("methods", "--plugin", plugin)
    assert result.exit_code == 0, result.output
    assert result.stderr.count("RuntimeWarning: newuser: a plug-in warns") == 1, result.stderr
    assert "lqr  (" in result.stdout


# -- 8. planning: a size guard on the number of instances, batched commits, progress ---------------------------
def test_a_million_seeds_is_refused_up_front_naming_the_limit_and_the_key_that_raises_it(tmp_path):
    spec = tmp_path / "big.toml"
    spec.write_text('name = "big"\n[instances]\nn = [6]\nseeds = 1000000\n[[methods]]\nmethod = "lqr"\n')
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--no-progress"))
    assert ("instances: at least 1000000 instances, more than the 50000 an experiment plans by default" in line
            and "set max_instances = at least 1000000 at the top of the spec" in line), line
    assert not (tmp_path / "out").exists()


def test_a_seed_count_is_refused_before_the_family_lists_its_instances(monkeypatch):
    """1e9 seeds: listing them first would take tens of GB; the count alone is refused at once."""
    import dataclasses

    import compare.run.families as families

    paper = families.get_family("paper")
    listed = []
    monkeypatch.setitem(families._FAMILIES, "paper", dataclasses.replace(
        paper, parse=lambda *a, **k: listed.append(1) or paper.parse(*a, **k)))
    text = 'name = "huge"\nmax_instances = 10\n[instances]\nn = [6, 8]\nseeds = 1000000000\n[[methods]]\nmethod = "lqr"\n'
    with pytest.raises(SpecError, match=r"instances: at least 1000000000 instances, more than max_instances = 10"):
        parse_spec(text)
    assert not listed
    # Seeds within the limit: the family lists them and the exact count, seeds times sizes, is refused.
    with pytest.raises(SpecError, match=r"instances: 12 instances, more than max_instances = 10"):
        parse_spec(text.replace("1000000000", "6"))
    assert listed


def test_max_instances_raises_or_lowers_the_limit():
    text = 'name = "few"\n{limit}[instances]\nn = [6, 8]\nseeds = 2\n[[methods]]\nmethod = "lqr"\n'
    assert len(parse_spec(text.format(limit="max_instances = 4\n")).instances.specs) == 4
    with pytest.raises(SpecError, match=r"instances: 4 instances, more than max_instances = 3; raise max_instances"):
        parse_spec(text.format(limit="max_instances = 3\n"))
    with pytest.raises(SpecError, match=r"max_instances: must be >= 1, got 0"):
        parse_spec(text.format(limit="max_instances = 0\n"))


def test_planning_shows_progress_and_writes_the_instance_facts_in_batches(tmp_path, monkeypatch):
    from compare.run import runner

    bars, writes = [], []
    real_tqdm, real_set_metas = runner.tqdm, Store.set_metas

    def tqdm(*args, **kwargs):
        bars.append(kwargs)
        return real_tqdm(*args, **kwargs)

    def set_metas(store, entries):
        writes.append(sorted(key.split(":", 1)[0] for key in entries))
        return real_set_metas(store, entries)

    monkeypatch.setattr(runner, "tqdm", tqdm)
    monkeypatch.setattr(Store, "set_metas", set_metas)
    monkeypatch.setattr(runner, "PLAN_BATCH", 2)
    spec = parse_spec('name = "plan"\n[instances]\nn = [6]\nseeds = 5\ndegree = 3\nhorizon = 10\n'
                      '[[methods]]\nmethod = "lqr"\n')
    with Store(tmp_path / "r.sqlite") as store:
        runner._record_meta(spec, spec.runs(), store, progress=True)
        assert len(store.instance_facts()) == 5
    assert any(bar.get("desc") == "plan: planning" and bar.get("disable") is False for bar in bars), bars
    # One transaction for the spec's entries, then the five instances' facts two by two (not five commits).
    assert writes[0] == ["fingerprint", "method", "pairs", "sections", "spec"]
    assert writes[1:] == [["instance", "instance"], ["instance", "instance"], ["instance"]]


# -- 9. `python -m compare`, whatever `compare` the PATH finds first --------------------------------------------
def test_python_m_compare_is_the_compare_command():
    done = _cli("--help", timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("Usage: compare [OPTIONS] COMMAND [ARGS]...")
    for command in ("run", "report", "export", "methods", "presets", "families"):
        assert f"  {command} " in done.stdout
    bad = _cli("run", "no-such-preset", timeout=60)
    assert bad.returncode == 2 and bad.stderr.startswith("Error: unknown preset 'no-such-preset'"), bad.stderr


# -- 10. a renamed .npz keeps its runs and takes its new name -------------------------------------------------------
def test_a_renamed_matrices_file_keeps_its_runs_under_its_new_name_and_path(tmp_path):
    np.savez(tmp_path / "sys1.npz", A=np.diag([1.1, 0.5, 0.9]) + 0.1 * np.eye(3, k=1), B=np.eye(3))
    text = ('name = "mine"\n[instances]\nfamily = "matrices"\nfiles = ["{file}"]\n'
            '[[methods]]\nmethod = "lqr"\nwhere = {{ name = ["{name}"] }}\n')
    path = tmp_path / "r.sqlite"
    with Store(path) as store:
        first = run_experiment(parse_spec(text.format(file="sys1.npz", name="sys1"), base=tmp_path), store,
                               progress=False)
    (tmp_path / "sys1.npz").rename(tmp_path / "sys2.npz")
    with Store(path) as store:
        again = run_experiment(parse_spec(text.format(file="sys2.npz", name="sys2"), base=tmp_path), store,
                               progress=False)
        (record,) = store.records()
    assert (first.computed, again.computed, again.already_stored) == (1, 0, 1)
    assert record.instance.spec["name"] == "sys2" and Path(record.instance.spec["file"]) == tmp_path / "sys2.npz"
    assert record.instance.has_facts  # the facts follow the new description too


# -- 10. what the docs say is what happens ---------------------------------------------------------------------------
DOCS = HERE.parent / "docs"


def _doc_trunc10():
    """The ``trunc10`` of docs/extending.md, as written there."""
    text = (DOCS / "extending.md").read_text()
    code = re.search(r"```python\n(import numpy as np\nfrom codesign import StaticGain, score\n\ndef trunc10.*?)```",
                     text, re.S).group(1)
    scope: dict = {}
    exec(compile(code, "extending.md", "exec"), scope)
    return scope["trunc10"], text


def test_the_docs_trunc10_runs_on_multi_state_nodes_only_when_registered_for_them():
    from codesign.methods import Method
    from compare.run.families import get_family

    trunc10, text = _doc_trunc10()
    family = get_family("mass_spring")
    instance = family.build(family.parse({"family": "mass_spring", "n": [4]})[0])
    assert instance.n == 2 * instance.nodes  # two states per node
    (plain,) = Method.from_function(trunc10, name="doc_trunc10")(instance)
    assert plain.status == "failed" and "does not handle nodes with several states or inputs" in plain.message
    (blocks,) = Method.from_function(trunc10, name="doc_trunc10_blocks", node_blocks=True)(instance)
    assert blocks.status == "optimal"
    assert "works on both" not in text and '`@method("trunc10", node_blocks=True)`' in text
    assert "`u` of shape `(batch, m)`" in text and "`x`, `u` of\nshape `(batch, n)`" not in text


def test_a_plugin_named_by_module_and_by_file_is_the_documented_already_registered_error(tmp_path):
    (tmp_path / "nu_double.py").write_text(
        "import numpy as np\nfrom codesign import StaticGain, method, score\n\n"
        "@method('nu_double_lqr')\ndef lqr_again(instance, *, seed: int = 0):\n"
        "    return score(instance, StaticGain(np.asarray(instance.K_lqr)))\n\n"
        "def plain(instance, *, seed: int = 0):\n    return lqr_again(instance)\n")
    spec = tmp_path / "s.toml"
    spec.write_text(f'name = "dbl"\nplugins = ["nu_double"]\n{INSTANCES}\n[[methods]]\nmethod = "nu_double.py:plain"\n')
    line = error_line(_invoke("run", spec, "--out", tmp_path / "out", "--no-progress"))
    assert "method 'nu_double_lqr' is already registered (from nu_double)" in line, line
    assert "is already registered (from\nmy_methods)" in (DOCS / "extending.md").read_text()


def test_the_docs_say_what_a_hang_without_timeout_and_another_processor_do():
    cli = (DOCS / "cli.md").read_text()
    assert "a run that hangs, when no time limit is set" in cli and "never finishes and writes no\nreport" in cli
    store = " ".join((DOCS / "store.md").read_text().split())
    assert "Classical methods' designs and every exact baseline agreed to the bit" not in store
    assert "relative tolerance (1e-13 is ample), not for equality" in store
