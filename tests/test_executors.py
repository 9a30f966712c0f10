import sqlite3

import pytest
from tiny_specs import tiny_spec  # tests/tiny_specs.py

from compare import Store, parse_spec, run_experiment
from compare.run.runner import ExecutorError, open_executor

SPEC = tiny_spec("dask", methods=("lqr", "decentralized"), seeds=3)


def _dump(path):
    con = sqlite3.connect(path)
    rows = con.execute("SELECT run_key, idx, cost, links, self_loops, status FROM designs ORDER BY run_key, idx").fetchall()
    con.close()
    return rows


def _local_and_dask_cluster(spec_text, tmp_path):
    """Run a spec in one local process and on a 2-worker dask LocalCluster: (local rows, dask rows, dask summary)."""
    distributed = pytest.importorskip("distributed")
    spec = parse_spec(spec_text)
    with Store(tmp_path / "local.sqlite") as store:
        run_experiment(spec, store, workers=1, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client, Store(tmp_path / "dask.sqlite") as store:
            summary = run_experiment(spec, store, executor=client.get_executor(pure=False), progress=False)
    return _dump(tmp_path / "local.sqlite"), _dump(tmp_path / "dask.sqlite"), summary


def test_dask_local_cluster_matches_local_executor(tmp_path):
    local, remote, summary = _local_and_dask_cluster(SPEC, tmp_path)
    assert summary.computed == 12
    assert len(local) == 12 and local == remote


def test_unknown_executor_is_a_clear_error(tmp_path):
    with pytest.raises(ExecutorError, match="unknown executor 'spark'"):
        with open_executor("spark", 2):
            pass


def _thread_settings():
    import os

    import numpy as np
    from threadpoolctl import threadpool_info

    from compare.run.runner import THREAD_VARS

    env = {var: os.environ.get(var) for var in THREAD_VARS}

    np.linalg.eigh(np.eye(300) + 1.0)  # BLAS in use, as in a run
    return env, {(pool["internal_api"], pool["num_threads"]) for pool in threadpool_info()}


def test_local_workers_are_single_threaded_for_every_thread_pool(monkeypatch):
    """BLAS, OpenMP, MKL and rayon (Clarabel's faer) pools: one thread each, so N workers use N cores.

    The BLAS pools are checked as loaded, not through the environment: numpy loads before the
    pool's initializer runs, and OpenBLAS ignores variables set after it started.
    """
    from compare.run.runner import THREAD_VARS, make_executor

    for var in THREAD_VARS:  # as in a user's shell (conftest sets them for the test process)
        monkeypatch.delenv(var, raising=False)
    pool = make_executor(1)
    try:
        env, pools = pool.submit(_thread_settings).result(timeout=120)
    finally:
        pool.shutdown()
    assert env == {var: "1" for var in env}
    assert pools and all(threads == 1 for _, threads in pools), pools


def _wait_for(path, seconds=60.0):
    import time

    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if path.exists() and path.stat().st_size:
            return
        time.sleep(0.2)
    raise TimeoutError(f"{path} did not appear in {seconds} s")


# Slow: 26 s, most of it dask's own command-line tools starting up; the local-cluster test above
# runs the same executor path in the default suite.
@pytest.mark.slow
def test_separate_process_dask_cluster_matches_the_process_pool(tmp_path):
    """`dask scheduler` + `dask worker` started by dask's own command-line tools, `compare run --executor dask://...`.

    Everything as a user would start it, in separate processes; the store is the
    same as the local process pool's, run for run.
    """
    import json
    import os
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    pytest.importorskip("distributed")
    dask = shutil.which("dask")
    if dask is None:
        pytest.skip("the `dask` command is not on PATH")
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")])))
    spec = tmp_path / "dask.toml"
    spec.write_text(SPEC)
    scheduler_file = tmp_path / "scheduler.json"
    started = []
    try:
        started.append(subprocess.Popen(
            [dask, "scheduler", "--scheduler-file", str(scheduler_file), "--port", "0", "--no-dashboard",
             "--host", "127.0.0.1"], cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        _wait_for(scheduler_file)
        started.append(subprocess.Popen(
            [dask, "worker", "--scheduler-file", str(scheduler_file), "--nworkers", "2", "--nthreads", "1",
             "--no-dashboard"], cwd=root, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        address = json.loads(scheduler_file.read_text())["address"]
        cli = [sys.executable, "-m", "compare.cli", "run", str(spec), "--no-progress"]
        remote = subprocess.run(cli + ["--out", str(tmp_path / "remote"), "--executor",
                                       address.replace("tcp://", "dask://")],
                                cwd=root, env=env, capture_output=True, text=True, timeout=300)
        assert remote.returncode == 0, remote.stderr[-2000:]
        assert "12 computed" in remote.stdout, remote.stdout
    finally:
        for process in reversed(started):
            process.terminate()
        for process in reversed(started):
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
    local = subprocess.run(cli + ["--out", str(tmp_path / "local"), "--workers", "1"],
                           cwd=root, env=env, capture_output=True, text=True, timeout=300)
    assert local.returncode == 0, local.stderr[-2000:]
    rows = _dump(tmp_path / "local" / "results.sqlite")
    assert len(rows) == 12 and rows == _dump(tmp_path / "remote" / "results.sqlite")


SLS_LOCAL_SPEC = """
name = "columns"
[instances]
n = [60]
seeds = 1
horizon = 10
[[methods]]
method = "sls_local"
params = { locality = 3, fir = 8 }
"""


def test_localized_sls_spreads_its_columns_over_the_dask_cluster(tmp_path):
    """Run as a task of a dask cluster, sls_local solves its columns in tasks of 50 over the workers:
    the same design as in a local process, to the last bit."""
    import json

    local, remote, _ = _local_and_dask_cluster(SLS_LOCAL_SPEC, tmp_path)
    assert len(local) == 1 and local == remote and local[0][-1] == "optimal"

    def tasks(path):
        con = sqlite3.connect(path)
        (extras,), = con.execute("SELECT extras FROM designs").fetchall()
        con.close()
        return json.loads(extras)["column_tasks"]

    assert tasks(tmp_path / "local.sqlite") == 1 and tasks(tmp_path / "dask.sqlite") == 2


LEARNED_SPREAD_SPEC = """
name = "spread"
[instances]
n = [24]
seeds = 2
horizon = 20
[[methods]]
method = "grnn"
params = { steps = 30, ensemble = 2, stability_steps = 0 }
"""


def test_learned_batch_spreads_its_models_and_scoring_over_the_dask_cluster(tmp_path, monkeypatch):
    """Above SPREAD_ABOVE states (lowered here to 10, so that N = 24 stands for a large instance), a
    GRNN batch on a dask cluster trains each fused-engine model as a task of its own and scores each
    design as another: the same designs as in one local process, to the last bit."""
    distributed = pytest.importorskip("distributed")
    from codesign.learned import trainer

    seen = {}
    real = distributed.Client.submit

    def counting_submit(self, function, *args, **kwargs):
        seen[function.__name__] = seen.get(function.__name__, 0) + 1
        return real(self, function, *args, **kwargs)

    # The workers are threads of this process (processes=False), so both patches reach them: the
    # threshold, and the count of the tasks the design submits from its worker.
    monkeypatch.setattr(trainer, "SPREAD_ABOVE", 10)
    monkeypatch.setattr(distributed.Client, "submit", counting_submit)
    spec = parse_spec(LEARNED_SPREAD_SPEC)
    with Store(tmp_path / "local.sqlite") as store:
        run_experiment(spec, store, workers=1, progress=False)
    assert not seen
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client, Store(tmp_path / "dask.sqlite") as store:
            run_experiment(spec, store, executor=client.get_executor(pure=False), progress=False)
    local, remote = _dump(tmp_path / "local.sqlite"), _dump(tmp_path / "dask.sqlite")
    assert len(local) == 2 and local == remote and all(row[-1] == "optimal" for row in local)
    assert seen.get("_timed_stack") == 4 and seen.get("_call") == 2, seen


def test_a_dying_plug_in_fails_its_run_at_once_on_the_local_dask_cluster(tmp_path):
    """A plug-in calling os._exit under `--executor dask-local`: its run is `failed` saying its worker died,
    the other runs are stored, and nothing reaches stderr (the scheduler's log of the death stays off it)."""
    import subprocess
    import sys
    from pathlib import Path

    pytest.importorskip("distributed")
    plugin = Path(__file__).resolve().parent / "fault_methods.py"
    spec = tmp_path / "s.toml"
    spec.write_text(f'name = "daskfault"\nplugins = ["{plugin}"]\n[instances]\nn = [8]\na_norms = [1.05]\nseeds = 1\n'
                    '\n[[methods]]\nmethod = "lqr"\n\n[[methods]]\nmethod = "fault_os_exit"\n')
    done = subprocess.run([sys.executable, "-m", "compare.cli", "run", str(spec), "--out", str(tmp_path / "out"),
                           "--executor", "dask-local", "--workers", "2", "--no-progress"],
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    with Store(tmp_path / "out" / "results.sqlite") as store:
        records = {r.method: r for r in store.records()}
    assert records["lqr"].status == "optimal"
    dead = records["fault_os_exit"]
    assert dead.status == "failed" and "its dask worker died" in dead.message
