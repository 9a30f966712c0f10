"""Bring your own method: plug-ins from specs and the CLI, fingerprints, concurrent runs."""

import csv
import os
import subprocess
import sys
import textwrap
import time

import pytest
from click.testing import CliRunner
from tiny_specs import tiny_spec  # tests/tiny_specs.py

from compare import Store, parse_spec, run_experiment
from compare.cli import main

PLUGIN = textwrap.dedent('''
    import os
    import numpy as np
    from codesign import StaticGain, score

    def trunc10(instance, *, links: int = 10):
        """LQR truncated to its largest off-diagonal entries."""
        if os.environ.get("COUNT_FILE"):
            with open(os.environ["COUNT_FILE"], "a") as handle:
                handle.write("x")
        K = np.array(instance.K_lqr)
        off = np.abs(K) * (1 - np.eye(instance.n))
        mask = np.eye(instance.n, dtype=bool)
        mask.flat[np.argsort(off, axis=None)[::-1][:links]] = True
        return score(instance, StaticGain(np.where(mask, K, 0.0)))
''')

SPEC = tiny_spec("mine", methods=("lqr", "my_methods:trunc10"), tail="grid = { links = [2, 6] }\n")


@pytest.fixture(autouse=True)
def _forget_plugins():
    """Each test writes its own ``my_methods.py``: forget the one a previous test imported."""
    from compare.run import plugins

    yield
    sys.modules.pop("my_methods", None)
    plugins._LOADED.clear()


def _setup(tmp_path, spec=SPEC, plugin=PLUGIN):
    (tmp_path / "my_methods.py").write_text(plugin)
    path = tmp_path / "spec.toml"
    path.write_text(spec)
    return path


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _cli(*args):
    """``compare`` in a fresh process, as a user runs it (a process sees the code as it was at import)."""
    done = subprocess.run([sys.executable, "-m", "compare.cli", *map(str, args)], capture_output=True, text=True)
    return done.returncode, done.stdout + done.stderr


def _counts(out):
    with Store(out / "results.sqlite") as store:
        runs = {r.run_key: r.method for r in store.records()}
    return runs


def test_plain_function_from_a_spec_runs_reruns_nothing_and_edits_rerun_only_it(tmp_path):
    spec = _setup(tmp_path)
    out = tmp_path / "out"
    code, output = _cli("run", spec, "--out", out, "--workers", "1", "--no-progress")
    assert code == 0, output
    assert "12 runs: 12 computed" in output
    rows = list(csv.DictReader((out / "runs.csv").open()))
    mine = [r for r in rows if r["method"] == "my_methods:trunc10"]
    assert len(mine) == 8 and {r["label"] for r in mine} == {"trunc10"}
    assert {int(r["links"]) for r in mine} == {2, 6} and all(r["fingerprint"] for r in rows)
    report = (out / "report.md").read_text()
    assert "trunc10" in report and "## Code fingerprints" in report

    assert "0 computed, 12 already stored" in _cli("run", spec, "--out", out, "--workers", "1", "--no-progress")[1]

    # Editing the plug-in reruns its 8 runs and nothing else.
    (tmp_path / "my_methods.py").write_text(PLUGIN + "\n# edited\n")
    edited = _cli("run", spec, "--out", out, "--workers", "1", "--no-progress")[1]
    assert "12 runs: 8 computed, 4 already stored" in edited
    rows = list(csv.DictReader((out / "runs.csv").open()))
    assert len(rows) == 12 and len({r["fingerprint"] for r in rows if r["method"] == "my_methods:trunc10"}) == 1
    assert "also holds 8 runs made by code that has changed since" in (out / "report.md").read_text()
    with Store(out / "results.sqlite") as store:
        assert len(store) == 20 and store.superseded() == 8


def test_user_method_in_worker_processes(tmp_path):
    spec = _setup(tmp_path)
    with Store(tmp_path / "w.sqlite") as store:
        summary = run_experiment(parse_spec(spec.read_text(), base=tmp_path), store, workers=2, progress=False)
        assert summary.computed == 12 and set(summary.statuses) == {"optimal"}
        costs = sorted(r.cost for r in store.records() if r.method == "my_methods:trunc10")
    with Store(tmp_path / "one.sqlite") as store:
        run_experiment(parse_spec(spec.read_text(), base=tmp_path), store, progress=False)
        assert costs == sorted(r.cost for r in store.records() if r.method == "my_methods:trunc10")


def test_user_method_on_dask_local(tmp_path):
    pytest.importorskip("distributed")
    spec = _setup(tmp_path, spec=SPEC.replace("seeds = 2", "seeds = 1"))
    out = tmp_path / "dask"
    result = _run("run", spec, "--out", out, "--executor", "dask-local", "--workers", "1", "--no-progress")
    assert result.exit_code == 0, result.output
    assert "6 runs: 6 computed" in result.output
    assert "non-optimal" not in result.output


def test_plugin_files_and_decorated_methods(tmp_path):
    (tmp_path / "more.py").write_text(textwrap.dedent('''
        import numpy as np
        from codesign import StaticGain, method, score

        @method("half_lqr_test", label="Half LQR")
        def half(instance, *, scale: float = 0.5):
            """The LQR gain times scale."""
            return score(instance, StaticGain(scale * np.asarray(instance.K_lqr)))
    '''))
    spec = _setup(tmp_path, spec='plugins = ["more.py"]\n' + SPEC.replace('method = "lqr"', 'method = "half_lqr_test"'))
    listed = _run("methods", "--plugin", tmp_path / "more.py")
    assert "half_lqr_test  (Half LQR): The LQR gain times scale." in listed.output
    assert "scale: float = 0.5" in listed.output
    out = tmp_path / "o"
    result = _run("run", spec, "--out", out, "--workers", "1", "--no-progress")
    assert result.exit_code == 0, result.output
    assert "Half LQR" in (out / "report.md").read_text()


@pytest.mark.parametrize("plugin, text, message", [
    ("my_methodz:trunc10", PLUGIN, "no module named 'my_methodz'"),
    ("my_methods:trunc11", PLUGIN, "has no function 'trunc11'"),
    ("my_methods:trunc10", PLUGIN.replace("*, links", "links"), "exactly one positional argument"),
    ("my_methods:trunc10", "raise RuntimeError('broken on purpose')\n", "RuntimeError: broken on purpose"),
    ("missing.py:trunc10", PLUGIN, "file not found"),
])
def test_bad_plugins_are_one_line_errors(tmp_path, plugin, text, message):
    spec = _setup(tmp_path, spec=SPEC.replace("my_methods:trunc10", plugin), plugin=text)
    result = _run("run", spec, "--out", tmp_path / "o", "--no-progress")
    assert result.exit_code == 2
    line = result.output.strip()
    assert "\n" not in line and message in line and plugin in line and "methods[1].method" in line
    assert not (tmp_path / "o" / "results.sqlite").exists() or len(Store(tmp_path / "o" / "results.sqlite")) == 0


def test_bad_plugin_flag(tmp_path):
    result = _run("methods", "--plugin", "no_such_module_here")
    assert result.exit_code == 2 and "no module named 'no_such_module_here'" in result.output


def test_mistyped_hyperparameter_with_none_default_is_exit_2(tmp_path):
    spec = _setup(tmp_path, spec=SPEC.replace('method = "lqr"', 'method = "truncated_lqr"\nparams = { links = "20" }'))
    result = _run("run", spec, "--out", tmp_path / "o", "--no-progress")
    assert result.exit_code == 2
    assert "methods[0].params.links: expected non-empty list of int >= 0 or None, got str '20'" in result.output


def test_key_order_in_a_spec_does_not_change_keys(tmp_path):
    (tmp_path / "my_methods.py").write_text(PLUGIN)
    first = textwrap.dedent('''
        [instances]
        n = [8]
        seeds = 1
        degree = 4
        [[methods]]
        method = "decentralized"
        params = { start = "zero" }
    ''')
    second = textwrap.dedent('''
        [[methods]]
        params = { start = "zero" }
        method = "decentralized"
        [instances]
        degree = 4
        seeds = 1
        n = [8]
    ''')
    assert [r.key for r in parse_spec(first).runs()] == [r.key for r in parse_spec(second).runs()]


def test_validation_size_reaches_learned_methods(tmp_path):
    spec = textwrap.dedent('''
        [instances]
        n = [8]
        seeds = 1
        degree = 3
        horizon = 12
        [evaluation]
        validation_size = 4000
        [[methods]]
        method = "gcnn"
        params = { steps = 2, ensemble = 1, stability_steps = 0, curve_size = 10 }
    ''')
    from codesign.evaluation import simulate_to_precision
    from compare.run.runner import build_instance

    with Store(tmp_path / "v.sqlite") as store:
        run_experiment(parse_spec(spec), store, progress=False)
        (record,) = store.records()
        controller = store.controller(record.run_key)
        instance = build_instance(dict(record.instance.spec))
    # The GCNN scores itself on 2000 draws; the spec asks for at least 4000: the harness re-scores.
    assert record.extras["validation_size"] >= 4000
    assert record.cost == pytest.approx(simulate_to_precision(instance, controller, 4000).cost, rel=1e-12)


def test_two_runs_at_once_never_compute_a_run_twice(tmp_path):
    plugin = PLUGIN.replace('handle.write("x")', 'handle.write("x")\n        import time; time.sleep(0.3)')
    spec = _setup(tmp_path, spec=SPEC.replace("seeds = 2", "seeds = 3"), plugin=plugin)
    out = tmp_path / "out"
    count = tmp_path / "count.txt"
    env = {**os.environ, "COUNT_FILE": str(count)}
    command = [sys.executable, "-m", "compare.cli", "run", str(spec), "--out", str(out), "--workers", "1",
               "--no-progress"]
    first = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    time.sleep(0.5)
    second = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    outputs = [p.communicate(timeout=300)[0] for p in (first, second)]
    assert [p.returncode for p in (first, second)] == [0, 0], outputs
    assert count.read_text() == "x" * 12  # 12 runs of the plug-in, each computed once
    with Store(out / "results.sqlite") as store:
        assert len(store) == 18 and store.claims() == {}
        assert len(store.records()) == 18


def test_no_wait_stops_with_exit_2_when_another_process_holds_runs(tmp_path):
    spec = _setup(tmp_path)
    out = tmp_path / "out"
    parsed = parse_spec(spec.read_text(), base=tmp_path)
    keys = [r.key for r in parsed.runs()]
    with Store(out / "results.sqlite") as store:
        # A live process (this one, under another owner name) holds every run.
        assert store.claim(keys, "someone-else") == keys
        result = _run("run", spec, "--out", out, "--no-wait", "--no-progress")
        assert result.exit_code == 2
        assert "being computed by another process" in result.output and "\n" not in result.output.strip()
        assert len(store) == 0 and len(store.claims()) == 12
        store.release("someone-else")


def test_claims_of_a_dead_process_are_taken_over(tmp_path):
    spec = _setup(tmp_path)
    parsed = parse_spec(spec.read_text(), base=tmp_path)
    keys = [r.key for r in parsed.runs()]
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    with Store(tmp_path / "s.sqlite") as store:
        store.claim(keys, "ghost")
        store._conn.execute("UPDATE claims SET pid = ?", (pid,))
        store._conn.commit()
        summary = run_experiment(parsed, store, progress=False)
        assert summary.computed == 12 and store.claims() == {}


def test_a_worker_that_cannot_load_a_plugin_stops_the_run_with_a_message(tmp_path):
    """A worker lacking a plug-in is the environment's fault, not the run's: no failed run is stored."""
    from compare.run.plugins import Plugin
    from compare.run.runner import WorkerSetupError, execute_task
    from compare.run.spec import parse_spec

    spec = parse_spec('name = "x"\n[instances]\nn = [6]\ndegree = 3\nhorizon = 5\n[[methods]]\nmethod = "lqr"\n')
    missing = Plugin(ref="gone.py", target=str(tmp_path / "gone.py"))
    with pytest.raises(WorkerSetupError, match=r"could not load method 'lqr' \(plug-ins: gone.py\).*every worker"):
        execute_task(spec.runs(), [missing])


def test_a_solver_only_one_method_uses_enters_only_its_fingerprint():
    import compare.run.registry  # noqa: F401  (the built-ins)
    from codesign import get_method
    from compare.run.fingerprint import NUMERIC_PACKAGES, fingerprint_details

    sdp = fingerprint_details(get_method("sparse_sdp").modules)["versions"]
    admm = fingerprint_details(get_method("sparse_admm").modules)["versions"]
    assert "scs" in sdp and "scs" not in NUMERIC_PACKAGES
    assert set(admm) == set(NUMERIC_PACKAGES)
    # A plug-in module can name its own solver the same way.
    import types

    mine = types.ModuleType("my_method_with_a_solver")
    mine.FINGERPRINT_PACKAGES = ("pytest",)
    with_solver = fingerprint_details([mine])
    assert "pytest" in with_solver["versions"]
    plain = types.ModuleType("my_method_with_a_solver")
    assert fingerprint_details([plain])["fingerprint"] != with_solver["fingerprint"]
