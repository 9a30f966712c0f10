import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from tiny_specs import tiny_spec  # tests/tiny_specs.py

from compare.cli import main

SPEC = tiny_spec(head='description = "tiny test experiment"\n')


def _write(tmp_path, text=SPEC, name="tiny.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_run_then_rerun_and_report(tmp_path):
    spec = _write(tmp_path)
    out = tmp_path / "out"
    runner = CliRunner()
    first = runner.invoke(main, ["run", str(spec), "--out", str(out), "--workers", "1", "--no-progress"])
    assert first.exit_code == 0, first.output
    assert "12 computed" in first.output
    for name in ("report.md", "report.html", "cost_vs_links.png", "cost_vs_links.svg", "runs.csv", "results.sqlite"):
        assert (out / name).is_file()
    report = (out / "report.md").read_text()
    assert "LQR (centralized)" in report and "Autonomous" in report and "Decentralized" in report
    snapshot = {p.name: p.read_bytes() for p in out.iterdir() if p.suffix != ".sqlite"}
    second = runner.invoke(main, ["run", str(spec), "--out", str(out), "--no-progress"])
    assert second.exit_code == 0 and "0 computed, 12 already stored" in second.output
    assert snapshot == {p.name: p.read_bytes() for p in out.iterdir() if p.suffix != ".sqlite"}
    regen = runner.invoke(main, ["report", "--out", str(out)])
    assert regen.exit_code == 0
    assert snapshot == {p.name: p.read_bytes() for p in out.iterdir() if p.suffix != ".sqlite"}
    assert len((out / "runs.csv").read_text().splitlines()) == 13


def test_default_output_is_the_untracked_results_folder(tmp_path, monkeypatch):
    """Without --out, `compare run` writes results/<name> (git-ignored), never the shipped reports/."""
    spec = _write(tmp_path)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["run", str(spec), "--workers", "1", "--no-progress"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "results" / "tiny" / "report.md").is_file()
    assert not (tmp_path / "reports").exists()
    again = CliRunner().invoke(main, ["report", "--out", "results/tiny"])
    assert again.exit_code == 0, again.output
    root = Path(__file__).resolve().parents[1]
    assert "/results/" in (root / ".gitignore").read_text().split()


def test_parallel_workers_give_the_same_numbers(tmp_path):
    spec = _write(tmp_path)
    runner = CliRunner()
    for workers, out in (("1", "a"), ("2", "b")):
        result = runner.invoke(main, ["run", str(spec), "--out", str(tmp_path / out), "--workers", workers, "--no-progress"])
        assert result.exit_code == 0, result.output
    assert (tmp_path / "a" / "runs.csv").read_text().count("\n") == (tmp_path / "b" / "runs.csv").read_text().count("\n")

    def costs(folder):
        con = sqlite3.connect(tmp_path / folder / "results.sqlite")
        return sorted(con.execute("SELECT run_key, idx, cost, links FROM designs").fetchall())

    assert costs("a") == costs("b")


def test_methods_and_presets_listing():
    runner = CliRunner()
    listing = runner.invoke(main, ["methods"])
    assert listing.exit_code == 0
    for name in ("lqr", "autonomous", "decentralized"):
        assert name in listing.output
    presets = runner.invoke(main, ["presets"])
    assert presets.exit_code == 0 and "quick" in presets.output
    assert 'name = "quick"' in runner.invoke(main, ["presets", "quick"]).output


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "compare.cli", *args], capture_output=True, text=True, cwd=cwd)


@pytest.mark.parametrize(
    "text, message",
    [
        (SPEC.replace('method = "lqr"', 'method = "nope"'), "unknown method 'nope'"),
        (SPEC.replace("seeds = 2", "seeds = 2\nfoo = 1"), "instances.foo: unknown key"),
        (SPEC.replace("seeds = 2", "seeds = 'x'"), "instances.seeds: expected list"),
        (SPEC.replace('method = "lqr"', 'method = "lqr"\nparams = { gamma = 2 }'), "params.gamma: unknown hyperparameter"),
        (SPEC.replace('method = "lqr"', 'method = "grnn"\nparams = { engine = "gpu" }'),
         "params.engine: expected 'torch' or 'fused' or 'auto', got str 'gpu'"),
        ("this is [not toml", "not valid TOML"),
    ],
)
def test_bad_input_exits_2_without_traceback(tmp_path, text, message):
    spec = _write(tmp_path, text)
    result = _cli("run", str(spec), "--out", str(tmp_path / "o"))
    assert result.returncode == 2, result.stderr
    assert message in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "o" / "results.sqlite").exists()


def test_bad_cli_arguments_exit_2(tmp_path):
    for args in (["run", "no-such-preset"], ["run", str(tmp_path / "missing.toml")], ["run", "quick", "--workers", "0"],
                 ["report", "--out", str(tmp_path / "empty")], ["frobnicate"]):
        result = _cli(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert "Traceback" not in result.stderr


def test_corrupt_store_is_reported_and_left_alone(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    store = out / "results.sqlite"
    store.write_bytes(b"garbage" * 200)
    result = _cli("run", str(_write(tmp_path)), "--out", str(out))
    assert result.returncode == 2 and "not a usable result store" in result.stderr
    assert store.read_bytes() == b"garbage" * 200


def test_sigkill_mid_sweep_resumes_to_the_same_store(tmp_path):
    many = SPEC.replace("seeds = 2", "seeds = 20").replace("horizon = 10", "horizon = 40")  # 120 runs
    spec = _write(tmp_path, many)
    out_killed, out_clean = tmp_path / "killed", tmp_path / "clean"
    args = [sys.executable, "-m", "compare.cli", "run", str(spec), "--workers", "1", "--no-progress"]
    proc = subprocess.Popen(args + ["--out", str(out_killed)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    db = out_killed / "results.sqlite"
    deadline = time.time() + 120
    stored = 0
    while time.time() < deadline and proc.poll() is None:
        if db.exists():
            try:
                con = sqlite3.connect(db, timeout=0.1)
                stored = con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
                con.close()
            except sqlite3.OperationalError:
                pass
            if stored >= 10:
                break
        time.sleep(0.02)
    assert proc.poll() is None, "the sweep finished before it could be killed; make it longer"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    con = sqlite3.connect(db)
    partial = con.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
    con.close()
    assert 10 <= partial < 120

    resumed = _cli("run", str(spec), "--workers", "1", "--no-progress", "--out", str(out_killed))
    assert resumed.returncode == 0, resumed.stderr
    assert f"{120 - partial} computed, {partial} already stored" in resumed.stdout
    clean = _cli("run", str(spec), "--workers", "1", "--no-progress", "--out", str(out_clean))
    assert clean.returncode == 0

    def dump(folder):
        con = sqlite3.connect(folder / "results.sqlite")
        runs = con.execute("SELECT run_key, n_designs FROM runs ORDER BY run_key").fetchall()
        designs = con.execute(
            "SELECT run_key, idx, cost, links, self_loops, status FROM designs ORDER BY run_key, idx"
        ).fetchall()
        con.close()
        return runs, designs

    killed_runs, killed_designs = dump(out_killed)
    clean_runs, clean_designs = dump(out_clean)
    assert len(killed_runs) == 120 and len({k for k, _ in killed_runs}) == 120
    assert killed_runs == clean_runs
    assert killed_designs == clean_designs


def test_out_or_store_of_the_wrong_kind_is_one_line_with_exit_code_2(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    spec = str(_write(tmp_path))
    for args, message in (
        (["run", spec, "--out", str(a_file)], "is a file"),
        (["run", spec, "--out", str(a_file / "sub")], "is a file"),
        (["run", spec, "--out", str(tmp_path / "o"), "--store", str(tmp_path)], "is a folder"),
        (["report", "--out", str(a_file)], "is a file"),
        (["report", "--out", str(tmp_path), "--store", str(tmp_path)], "is a folder"),
    ):
        result = _cli(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1 and message in result.stderr, (args, result.stderr)
        assert "Traceback" not in result.stderr
    assert a_file.read_text() == "x" and not (tmp_path / "o").exists()
