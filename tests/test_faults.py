"""Faults: foreign files left untouched, workers that die with their run, a plug-in's fault kept to its own run.

Each case ends in exit code 2 with one ``Error:`` line, or in a recorded status; a
foreign file's hash is unchanged; no process of a run survives it; the other runs'
stored results equal those of a clean run.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from compare import Store, StoreError, parse_spec, run_experiment
from compare.cli import main
from compare.run.store import APPLICATION_ID, SCHEMA_VERSION
from cli_checks import error_line, file_sha  # tests/cli_checks.py

PLUGIN = Path(__file__).resolve().parent / "fault_methods.py"

INSTANCES = """
[instances]
n = [6]
a_norms = [0.995]
seeds = 1
degree = 3
horizon = 10
"""


def _spec(path: Path, methods: list[str], *, name: str = "faults", extra: str = "",
          timeouts: dict | None = None) -> Path:
    timeouts = timeouts or {}
    entries = "".join(f'\n[[methods]]\nmethod = "{m}"\n' + (f"timeout = {timeouts[m]}\n" if m in timeouts else "")
                      for m in methods)
    path.write_text(f'name = "{name}"\nplugins = ["{PLUGIN}"]\n{extra}{INSTANCES}{entries}')
    return path




# -- foreign files ------------------------------------------------------------------------------
def _foreign_with_runs_table(path: Path) -> Path:
    con = sqlite3.connect(path)
    with con:
        con.execute("CREATE TABLE runs (id INTEGER PRIMARY KEY, who TEXT)")
        con.execute("INSERT INTO runs (who) VALUES ('someone else')")
    con.close()
    return path


def _foreign_unrelated(path: Path) -> Path:
    con = sqlite3.connect(path)
    with con:
        con.execute("CREATE TABLE photos (id INTEGER PRIMARY KEY, name TEXT)")
        con.execute("INSERT INTO photos (name) VALUES ('cat.jpg')")
    con.close()
    return path


def _foreign_empty_database(path: Path) -> Path:
    con = sqlite3.connect(path)
    with con:
        con.execute("CREATE TABLE t (x)")
        con.execute("DROP TABLE t")
    con.close()
    assert path.stat().st_size > 0
    return path


def _foreign_application(path: Path) -> Path:
    con = sqlite3.connect(path)
    con.execute("PRAGMA application_id = 1234")
    with con:
        con.execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
    con.close()
    return path


def _newer_store(path: Path) -> Path:
    with Store(path):
        pass
    con = sqlite3.connect(path)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.close()
    return path


FOREIGN = {
    "runs table": (_foreign_with_runs_table, "not a result store"),
    "unrelated tables": (_foreign_unrelated, "not a result store"),
    "empty database": (_foreign_empty_database, "not a result store"),
    "another application": (_foreign_application, "another program"),
    "newer store": (_newer_store, "newer version"),
    "not sqlite": (lambda p: (p.write_bytes(b"not a database at all " * 200), p)[1], "not a usable result store"),
}


@pytest.mark.parametrize("case", list(FOREIGN))
def test_a_foreign_file_is_refused_and_left_untouched(tmp_path, case):
    make, words = FOREIGN[case]
    path = make(tmp_path / "other.sqlite")
    before = file_sha(path)
    with pytest.raises(StoreError, match=words):
        Store(path)
    spec = _spec(tmp_path / "s.toml", ["lqr"])
    for args in (["run", str(spec), "--out", str(tmp_path / "out"), "--store", str(path), "--workers", "1",
                  "--no-progress"],
                 ["report", "--out", str(tmp_path / "rep"), "--store", str(path)],
                 ["export", "--out", str(tmp_path / "exp"), "--store", str(path)]):
        line = error_line(CliRunner().invoke(main, args))
        assert words in line, line
        assert file_sha(path) == before, f"{case}: {args[0]} changed the file"
    assert not (tmp_path / "out" / "report.md").exists()


def test_reading_commands_do_not_adopt_an_empty_file(tmp_path):
    empty = tmp_path / "empty.sqlite"
    empty.touch()
    for args in (["report", "--out", str(tmp_path), "--store", str(empty)],
                 ["export", "--out", str(tmp_path / "x"), "--store", str(empty)]):
        error_line(CliRunner().invoke(main, args))
        assert empty.stat().st_size == 0


def test_a_new_store_is_marked_and_an_unmarked_old_store_is_migrated_atomically(tmp_path):
    path = tmp_path / "r.sqlite"
    with Store(path):
        pass
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    with con:  # as stores were before they marked themselves
        con.execute("ALTER TABLE runs DROP COLUMN peak_mb")
        con.execute("PRAGMA application_id = 0")
        con.execute("PRAGMA user_version = 0")
    con.close()
    with Store(path):
        pass
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert "peak_mb" in {row[1] for row in con.execute("PRAGMA table_info(runs)")}
    con.close()


def test_bogus_executor_is_refused_before_a_store_exists(tmp_path):
    spec = _spec(tmp_path / "s.toml", ["lqr"])
    out = tmp_path / "out"
    line = error_line(CliRunner().invoke(main, ["run", str(spec), "--out", str(out), "--executor", "spark",
                                                 "--no-progress"]))
    assert "unknown executor 'spark'" in line
    assert not (out / "results.sqlite").exists()


def test_an_unwritable_report_folder_is_exit_2(tmp_path, monkeypatch):
    import compare.report.write

    spec = _spec(tmp_path / "s.toml", ["lqr"])

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(compare.report.write, "write_report", refuse)
    store = tmp_path / "elsewhere" / "r.sqlite"
    result = CliRunner().invoke(main, ["run", str(spec), "--out", str(tmp_path / "out"), "--store", str(store),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    summary, line = result.output.strip().splitlines()  # what was computed, then why there is no report
    assert "1 computed" in summary and line.startswith("Error: cannot write the report") and "Permission denied" in line
    with Store(store) as kept:
        assert len(kept) == 1  # the run was stored before the report failed


def test_an_unwritable_folder_is_refused_before_any_work(tmp_path, monkeypatch):
    spec = _spec(tmp_path / "s.toml", ["lqr"])
    out = tmp_path / "locked"
    out.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: False if Path(p) == out and mode & os.W_OK else real(p, mode))
    line = error_line(CliRunner().invoke(main, ["run", str(spec), "--out", str(out), "--no-progress"]))
    assert "not writable" in line
    assert not (out / "results.sqlite").exists()


# -- a plug-in's fault is its own run's status ---------------------------------------------------
FAULTS = {
    "fault_unpicklable": "could not be sent back",
    "fault_segfault": "killed by SIGSEGV",
    "fault_os_exit": "exited with code 5",
    "fault_sys_exit": "sys.exit(3)",
    "fault_hang": "time limit of 4 s",
    "fault_empty": "returned no design",
}


def _cli(*args, timeout=240, **kwargs):
    return subprocess.run([sys.executable, "-m", "compare.cli", *args], capture_output=True, text=True,
                          timeout=timeout, **kwargs)


def test_each_fault_is_its_runs_failed_status_and_the_other_runs_are_kept(tmp_path):
    # Only the hanging run gets the short limit: under a loaded test machine a healthy run can
    # take longer than 4 s to start and finish.
    spec = _spec(tmp_path / "s.toml", ["lqr", *FAULTS], timeouts={"fault_hang": 4})
    out = tmp_path / "out"
    done = _cli("run", str(spec), "--out", str(out), "--workers", "2", "--no-progress")
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    with Store(out / "results.sqlite") as store:
        records = {r.method: r for r in store.records()}
    assert set(records) == {"lqr", *FAULTS}
    for name, words in FAULTS.items():
        assert records[name].status == "failed" and words in records[name].message, (name, records[name].message)
    clean = parse_spec(_spec(tmp_path / "clean.toml", ["lqr"]).read_text())
    with Store(tmp_path / "clean.sqlite") as store:
        run_experiment(clean, store, progress=False)
        (reference,) = store.records()
    assert records["lqr"].status == "optimal" and records["lqr"].cost == reference.cost
    again = _cli("run", str(spec), "--out", str(out), "--workers", "2", "--no-progress")
    assert again.returncode == 0 and "0 computed" in again.stdout, again.stdout + again.stderr


# -- workers die with their run ------------------------------------------------------------------
def _descendants(pid: int) -> set[int]:
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(entry.name))
    found, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def _alive(pids) -> set[int]:
    alive = set()
    for pid in pids:
        try:
            state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.add(pid)
    return alive


def _start_hanging_run(tmp_path) -> tuple[subprocess.Popen, set[int]]:
    spec = _spec(tmp_path / "s.toml", ["fault_hang"], extra="")
    spec.write_text(spec.read_text().replace("seeds = 1", "seeds = 2"))
    # As from a terminal's foreground: Ctrl-C not ignored. (A shell starts background jobs with SIGINT
    # ignored, and a process keeps an ignored SIGINT ignored: run from one, the run could not be interrupted.)
    started = tmp_path / "started"
    started.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "compare.cli", "run", str(spec), "--out", str(tmp_path / "o"),
                             "--workers", "2", "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env={**os.environ, "FAULT_HANG_STARTED": str(started)},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(started.iterdir())) < 2:  # both workers inside their runs
        if proc.poll() is not None:
            pytest.fail(f"the run ended early ({proc.returncode}): {proc.communicate()[1]}")
        time.sleep(0.2)
    in_runs = {int(p.name) for p in started.iterdir()}
    workers = _descendants(proc.pid)
    assert len(in_runs) == 2 and in_runs <= workers, (in_runs, workers)
    return proc, workers


def _gone_within(pids, seconds: float) -> set[int]:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and _alive(pids):
        time.sleep(0.2)
    return _alive(pids)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc to find the run's processes")
@pytest.mark.parametrize("how", ["SIGKILL", "SIGTERM", "SIGINT"])
def test_no_worker_outlives_its_run(tmp_path, how):
    proc, workers = _start_hanging_run(tmp_path)
    if how == "SIGINT":  # Ctrl-C in a terminal: the whole foreground process group
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(getattr(signal, how))
    _, stderr = proc.communicate(timeout=60)
    assert not _gone_within(workers, 10), f"{how}: processes outlived the run"
    if how != "SIGKILL":
        assert proc.returncode == 130, (proc.returncode, stderr)
        assert "Traceback" not in stderr and "interrupted" in stderr, stderr


def test_a_run_stopped_at_its_time_limit_reruns_only_when_given_longer(tmp_path):
    from compare.run.pool import WorkerPool
    from compare.run.spec import load_spec

    def spec(limit):
        return load_spec(_spec(tmp_path / f"t{limit}.toml", ["fault_hang"], name="t", extra=f"timeout = {limit}\n"))

    with Store(tmp_path / "r.sqlite") as store, WorkerPool(1) as pool:
        assert run_experiment(spec(1), store, executor=pool, progress=False).computed == 1
        assert run_experiment(spec(1), store, executor=pool, progress=False).computed == 0
        assert run_experiment(spec(2), store, executor=pool, progress=False).computed == 1
        (record,) = store.records()
        assert record.status == "failed" and "time limit of 2 s" in record.message
        assert record.extras["timeout_s"] == 2
        assert run_experiment(spec(1.5), store, executor=pool, progress=False).computed == 0


def test_a_bad_timeout_is_refused(tmp_path):
    from compare.run.spec import SpecError, load_spec

    for bad in ("0", "-3", "nan", '"long"'):
        with pytest.raises(SpecError, match="timeout: must be a positive number of seconds"):
            load_spec(_spec(tmp_path / "b.toml", ["lqr"], extra=f"timeout = {bad}\n"))


def test_a_plugin_that_exits_at_import_is_a_one_line_error(tmp_path):
    plugin = tmp_path / "exits.py"
    plugin.write_text("import sys\nsys.exit(3)\n")
    spec = tmp_path / "s.toml"
    spec.write_text(f'name = "x"\nplugins = ["{plugin}"]\n{INSTANCES}\n[[methods]]\nmethod = "lqr"\n')
    line = error_line(CliRunner().invoke(main, ["run", str(spec), "--out", str(tmp_path / "o"), "--no-progress"]))
    assert "importing" in line and "SystemExit: 3" in line
    assert not (tmp_path / "o").exists()


def test_an_unreachable_scheduler_is_refused_before_a_store_exists(tmp_path):
    pytest.importorskip("distributed")
    spec = _spec(tmp_path / "s.toml", ["lqr"])
    out = tmp_path / "out"
    line = error_line(CliRunner().invoke(main, ["run", str(spec), "--out", str(out), "--executor",
                                                 "dask://127.0.0.1:1", "--no-progress"]))
    assert "cannot reach the dask scheduler at tcp://127.0.0.1:1" in line
    assert not (out / "results.sqlite").exists()


def test_a_locked_store_and_an_unwritable_folder_are_told_apart(tmp_path, monkeypatch):
    from compare.run.store import _explain

    path = tmp_path / "r.sqlite"
    locked = _explain(path, sqlite3.OperationalError("database is locked"))
    assert "locked by another process" in locked
    (tmp_path / "sub").mkdir()
    monkeypatch.setattr(os, "access", lambda p, mode: False)
    unwritable = _explain(tmp_path / "sub" / "r.sqlite", sqlite3.OperationalError("unable to open database file"))
    assert "is not writable" in unwritable and "by another process" not in unwritable
