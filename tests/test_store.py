import sqlite3
import sys

import numpy as np
import pytest
from tiny_specs import tiny_spec  # tests/tiny_specs.py

from codesign import Design
from compare import Store, StoreError, parse_spec, run_experiment

SPEC = tiny_spec("s", a_norms=(1.05,), seeds=3)


def test_run_store_and_resume(tmp_path):
    spec = parse_spec(SPEC)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_experiment(spec, store, progress=False)
        assert (summary.computed, summary.already_stored) == (9, 0)
        again = run_experiment(spec, store, progress=False)
        assert (again.computed, again.already_stored) == (0, 9)
        records = store.records()
        assert len(records) == 9
        lqr = [r for r in records if r.method == "lqr"]
        assert all(r.cost == pytest.approx(1.0, abs=1e-9) for r in lqr)
        # controllers come back as arrays, not pickles
        controller = store.controller(lqr[0].run_key)
        assert controller.K.shape == (8, 8)
        assert "spec:s" in store.meta()
        # every run records its wall time and its process's peak resident memory (Linux)
        assert all(r.run_seconds > 0 and r.run_designs == 1 for r in records)
        # the scoring is timed inside the run, apart from the method: the two fit in its wall time
        assert all(0 <= r.run_scoring_seconds and r.seconds + r.run_scoring_seconds <= r.run_seconds + 1e-3
                   for r in records)
        if sys.platform.startswith("linux"):
            assert all(50 < r.run_peak_mb < 1e5 for r in records)
            # and the memory the run started from, which the peak never falls below
            assert all(50 < r.run_baseline_mb <= r.run_peak_mb for r in records)


_FREED_THEN_MEASURED = """
from compare.run import execution
blocks = [bytearray(100_000) for _ in range(5000)]  # 500 MB in blocks malloc keeps on its heap
del blocks[:-1]  # the last one stays, so the heap cannot simply shrink from its end
with execution._measured() as watch:
    pass
print(watch["peak_mb"])
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="peak memory is measured on Linux")
def test_a_runs_peak_memory_does_not_count_what_earlier_runs_freed():
    """A worker keeps freed memory in malloc's lists; the next run's peak must not include it."""
    import subprocess

    out = subprocess.run([sys.executable, "-c", _FREED_THEN_MEASURED], capture_output=True, text=True, check=True)
    assert float(out.stdout) < 300, out.stdout  # the interpreter and numpy, not the 500 MB freed


def test_a_store_from_before_peak_memory_gains_the_column_and_keeps_its_runs(tmp_path):
    path = tmp_path / "old.sqlite"
    spec = parse_spec(SPEC)
    with Store(path) as store:
        run_experiment(spec, store, progress=False)
    con = sqlite3.connect(path)
    with con:  # the runs table as stores had it before peak_mb (SQLite >= 3.35 drops columns), unmarked
        con.execute("ALTER TABLE runs DROP COLUMN peak_mb")
        con.execute("PRAGMA application_id = 0")
        con.execute("PRAGMA user_version = 0")
    con.close()
    with Store(path) as store:
        records = store.records()
        assert len(records) == 9 and all(r.run_peak_mb is None for r in records)
        assert run_experiment(spec, store, progress=False).computed == 0


def test_a_store_from_before_scoring_seconds_and_baselines_gains_them_unknown(tmp_path):
    from compare.report.compute_report import NOT_MEASURED, compute_cells, compute_markdown
    from compare.run.store import SCHEMA_VERSION

    path = tmp_path / "old.sqlite"
    spec = parse_spec(SPEC)
    with Store(path) as store:
        run_experiment(spec, store, progress=False)
    con = sqlite3.connect(path)
    with con:  # the runs table of schema 2
        con.execute("ALTER TABLE runs DROP COLUMN scoring_seconds")
        con.execute("ALTER TABLE runs DROP COLUMN baseline_mb")
        con.execute("PRAGMA user_version = 2")
    con.close()
    with Store(path) as store:
        records = store.records()
        assert len(records) == 9 and all(r.run_scoring_seconds is None and r.run_baseline_mb is None for r in records)
        assert all(r.run_seconds > 0 for r in records)  # what the store did hold is kept
        assert NOT_MEASURED in compute_markdown(compute_cells(records))
        assert run_experiment(spec, store, progress=False).computed == 0
    con = sqlite3.connect(path)
    assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    assert {"scoring_seconds", "baseline_mb"} <= {row[1] for row in con.execute("PRAGMA table_info(runs)")}
    con.close()


def test_a_new_label_renames_stored_runs_without_recomputing(tmp_path):
    with Store(tmp_path / "r.sqlite") as store:
        run_experiment(parse_spec(SPEC), store, progress=False)
        renamed = parse_spec(SPEC.replace('method = "lqr"', 'method = "lqr"\nlabel = "Central"'))
        summary = run_experiment(renamed, store, progress=False)
        assert summary.computed == 0
        assert {r.label for r in store.records() if r.method == "lqr"} == {"Central"}


def test_add_run_is_atomic_and_idempotent(tmp_path):
    spec = parse_spec(SPEC)
    run = spec.runs()[0]
    design = Design("lqr", {}, None, 1.0, 56, 8, "instantaneous")
    with Store(tmp_path / "r.sqlite") as store:
        assert store.add_run(run, [design, design], experiment="s", seconds=0.1)
        assert not store.add_run(run, [design], experiment="s", seconds=0.1)
        assert len(store) == 1 and len(store.records()) == 2


def test_failed_designs_store_nan_not_numbers(tmp_path):
    spec = parse_spec(SPEC)
    with Store(tmp_path / "r.sqlite") as store:
        store.add_run(spec.runs()[1], [Design.failure("lqr", {}, "infeasible", "no")], experiment="s", seconds=0)
        (record,) = store.records()
        assert record.status == "infeasible" and np.isnan(record.cost)


def test_not_a_store(tmp_path):
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"this is not sqlite at all" * 100)
    with pytest.raises(StoreError, match="not a usable result store"):
        Store(bad)


def test_noise_scenario_is_recorded(tmp_path):
    spec = parse_spec(SPEC.replace("horizon = 10", "horizon = 10\n[evaluation]\nnoise_std = 0.5"))
    with Store(tmp_path / "r.sqlite") as store:
        run_experiment(spec, store, progress=False)
        for r in store.records():
            assert r.extras["noise_cost"] > r.cost


def test_method_exception_becomes_failed_design(tmp_path, monkeypatch):
    import compare.run.execution as execution

    def boom(*args, **kwargs):
        raise RuntimeError("solver exploded")

    monkeypatch.setattr(execution, "build_instance", boom)
    with Store(tmp_path / "r.sqlite") as store:
        summary = run_experiment(parse_spec(SPEC), store, progress=False)
        assert summary.statuses["failed"] == 9
        assert all("solver exploded" in r.message for r in store.records())


def test_batched_methods_get_grouped_runs_and_store_per_run(tmp_path, monkeypatch):
    import baselines
    from codesign import methods as registry

    calls = []

    def batch(pairs):
        calls.append(len(pairs))
        return [baselines.decentralized(inst, **params) for inst, params in pairs]

    monkeypatch.setitem(registry._REGISTRY, "decentralized_batched", registry.Method.from_function(
        baselines.decentralized, name="decentralized_batched", label="D", batch=batch, batch_size=4))
    spec = parse_spec(SPEC.replace('method = "decentralized"', 'method = "decentralized_batched"')
                      .replace("seeds = 3", "seeds = 6"))
    with Store(tmp_path / "b.sqlite") as store:
        run_experiment(spec, store, progress=False)
        batched = sorted(r.cost for r in store.records() if r.method == "decentralized_batched")
    assert sorted(calls) == [2, 4]
    with Store(tmp_path / "p.sqlite") as store:
        run_experiment(parse_spec(SPEC.replace("seeds = 3", "seeds = 6")), store, progress=False)
        plain = sorted(r.cost for r in store.records() if r.method == "decentralized")
    assert batched == plain and len(plain) == 6
    # A batch holds one instance size: its seconds are shared among its runs, and the compute
    # section times each size on its own.
    calls.clear()
    sizes = parse_spec(SPEC.replace('method = "decentralized"', 'method = "decentralized_batched"')
                       .replace("n = [8]", "n = [6, 8]"))
    with Store(tmp_path / "n.sqlite") as store:
        run_experiment(sizes, store, progress=False)
    assert sorted(calls) == [3, 3]
