"""`compare export` and `Store.to_pandas()`: one row per current design, settings as columns."""

import json
import shutil
import sqlite3
import subprocess
import sys

import pytest
from click.testing import CliRunner

pd = pytest.importorskip("pandas")

from compare import Store, parse_spec, run_experiment  # noqa: E402
from compare.cli import main  # noqa: E402
from compare.run.export import MissingExtra, designs_frame  # noqa: E402

# Seconds to run: an exact baseline, a gamma path, a GRNN-Sparse beta path of a few steps (at the shapes
# test_folder's GRNNs compile, N = 6, T = 10 and the default curve: numba compiles a kernel per shape).
SPEC = """
name = "tiny"
[instances]
n = [6]
a_norms = [1.05]
seeds = 2
degree = 3
horizon = 10
[evaluation]
validation_size = 20
[[methods]]
method = "lqr"
[[methods]]
method = "sparse_admm"
params = { gammas = [1e-3, 1e-2] }
[[methods]]
method = "grnn_sparse"
params = { steps = 3, ensemble = 1, stability_steps = 0 }
grid = { beta = [0.1, 1.0] }
"""


@pytest.fixture(scope="module")
def store_path(tmp_path_factory):
    """A store whose experiment `tiny` dropped a method after its first run (so some designs are superseded)."""
    path = tmp_path_factory.mktemp("store") / "results.sqlite"
    with Store(path) as store:
        run_experiment(parse_spec(SPEC.replace('[[methods]]\nmethod = "lqr"\n', '')), store, progress=False)
        run_experiment(parse_spec(SPEC), store, progress=False)
        # A second experiment sharing the LQR runs.
        run_experiment(parse_spec(SPEC.split('[[methods]]\nmethod = "sparse_admm"')[0].replace('"tiny"', '"other"')),
                       store, progress=False)
        # `tiny` now drops the beta = 1.0 runs: stored, no longer current.
        run_experiment(parse_spec(SPEC.replace("[0.1, 1.0]", "[0.1]")), store, progress=False)
    return path


def _current_designs(path):
    with Store(path) as store:
        return store.records()


def test_to_pandas_has_a_row_per_current_design_with_settings_as_columns(store_path):
    current = _current_designs(store_path)
    with sqlite3.connect(store_path) as con:
        stored = con.execute("SELECT COUNT(*) FROM designs").fetchone()[0]
    with Store(store_path) as store:
        df = store.to_pandas()
    assert len(df) == len(current) < stored  # the beta = 1.0 designs are superseded
    assert not df.duplicated(["run_key", "idx"]).any()
    for column in ("method", "label", "family", "seed", "n", "a_norm", "degree", "horizon", "cost", "cost_stderr",
                   "links", "self_loops", "info_model", "status", "seconds", "fingerprint", "gamma", "beta", "params"):
        assert column in df.columns, column
    assert df["gamma"].dtype == "float64" and df["beta"].dtype == "float64"
    assert df["a_norm"].dtype == "float64" and df["cost"].dtype == "float64"
    assert pd.api.types.is_integer_dtype(df["n"]) and pd.api.types.is_integer_dtype(df["seed"])
    grnn, admm, lqr = (df[df.method == m] for m in ("grnn_sparse", "sparse_admm", "lqr"))
    assert set(grnn["beta"]) == {0.1} and grnn["gamma"].isna().all()
    assert admm["beta"].isna().all() and {1e-3, 1e-2} <= set(admm["gamma"])
    assert lqr[["gamma", "beta"]].isna().all().all()
    assert set(df["seed"]) == {0, 1} and set(df["family"]) == {"paper"}
    # GRNN's own `seed` hyperparameter does not overwrite the instance seed.
    assert "param_seed" in df.columns and grnn["param_seed"].notna().all() and lqr["param_seed"].isna().all()
    assert (df["params"].map(json.loads).map(lambda p: p.get("beta")).dropna() == 0.1).all()
    assert not {"instance", "extras"} & set(df.columns)
    assert "extra_spectral_radius" in df.columns and "extra_curve" not in df.columns  # curves stay in records()
    # Runs shared by two experiments say so.
    assert set(lqr["experiments"]) == {"other,tiny"} and set(grnn["experiments"]) == {"tiny"}
    # The same numbers as the store's records, in the same order.
    assert list(df["cost"].fillna(-1)) == [r.cost if r.cost == r.cost else -1 for r in current]


def test_designs_frame_types_do_not_depend_on_the_methods_present():
    records = [
        {"run_key": "a", "idx": 0, "experiment": "e", "method": "m", "label": "M", "instance": {"seed": 0, "n": 4},
         "params": {"steps": 3, "start": "lqr", "flag": True}, "cost": 1.0, "links": None, "extras": {"curve": [1, 2]}},
        {"run_key": "b", "idx": 0, "experiment": "e", "method": "k", "label": "K", "instance": {"seed": 1, "n": 4},
         "params": {"start": [[1.0, 0.0]], "gamma": 2}, "cost": float("nan"), "links": 3, "extras": {"x": 1}},
    ]
    df = designs_frame(records)
    assert df["steps"].dtype == "float64" and df["gamma"].dtype == "float64"  # ints in params are numbers
    assert df["flag"].dtype == "boolean"
    assert list(df["start"]) == ['"lqr"', "[[1.0, 0.0]]"]  # mixed kinds: JSON text
    assert str(df["links"].dtype) == "Int64" and df["extra_x"].dtype == "float64"
    assert "extra_curve" not in df.columns
    empty = designs_frame([])
    assert len(empty) == 0 and {"method", "cost", "links"} <= set(empty.columns)


def test_a_hyperparameter_named_like_an_instance_field_is_prefixed_whatever_the_instances_hold():
    """`horizon` of a method is `param_horizon` on a family without a `horizon` field too; bare names stay bare."""
    matrices = {"family": "matrices", "name": "ring", "n": 4, "file": "ring.npz", "sha256": "ab"}
    paper = {"family": "paper", "n": 4, "seed": 0, "a_norm": 1.05, "horizon": 10}

    def row(instance, params):
        return {"run_key": "k", "idx": 0, "method": "m", "label": "M", "instance": instance, "params": params,
                "cost": 1.0}

    alone = designs_frame([row(matrices, {"horizon": 30, "neighbours": 2, "gamma": 0.1})])
    assert {"param_horizon", "param_neighbours", "gamma"} <= set(alone.columns)
    assert "horizon" not in alone.columns and "neighbours" not in alone.columns
    mixed = designs_frame([row(matrices, {"horizon": 30}), row(paper, {"horizon": 20, "links": 3})])
    assert list(mixed["param_horizon"]) == [30.0, 20.0] and list(mixed["param_links"].fillna(-1)) == [-1.0, 3.0]
    assert list(mixed["horizon"].astype("Float64").fillna(-1)) == [-1.0, 10.0]  # the instance's, never a method's


def test_cli_export_csv_reads_back_with_the_same_columns(store_path, tmp_path):
    out = tmp_path / "analysis"
    result = CliRunner().invoke(main, ["export", "--out", str(out), "--store", str(store_path)])
    assert result.exit_code == 0, result.output
    df = pd.read_csv(out / "designs.csv")
    with Store(store_path) as store:
        expected = store.to_pandas()
    assert list(df.columns) == list(expected.columns)
    assert len(df) == len(expected) == len(_current_designs(store_path))
    assert df["gamma"].dtype == "float64" and df["beta"].dtype == "float64"
    assert sorted(df["gamma"].dropna()) == sorted(expected["gamma"].dropna())
    assert f"{len(df)} designs" in result.output


def test_cli_export_from_a_report_folder_as_parquet(store_path, tmp_path):
    pytest.importorskip("pyarrow")
    report = tmp_path / "report"
    report.mkdir()
    shutil.copy(store_path, report / "results.sqlite")
    out = tmp_path / "analysis"
    result = CliRunner().invoke(main, ["export", "--out", str(out), "--from", str(report), "--format", "parquet"])
    assert result.exit_code == 0, result.output
    df = pd.read_parquet(out / "designs.parquet")
    with Store(store_path) as store:
        expected = store.to_pandas()
    assert list(df.columns) == list(expected.columns) and len(df) == len(expected)
    assert df["gamma"].dtype == "float64" and df["beta"].dtype == "float64"
    # Exporting into the report folder itself needs no --from.
    again = CliRunner().invoke(main, ["export", "--out", str(report)])
    assert again.exit_code == 0 and (report / "designs.csv").is_file()


def test_without_pandas_a_one_line_error_names_the_extra(store_path, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    result = CliRunner().invoke(main, ["export", "--out", str(tmp_path / "o"), "--store", str(store_path)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "analysis" in lines[0] and "pandas" in lines[0]
    assert not (tmp_path / "o").exists()
    with Store(store_path) as store, pytest.raises(MissingExtra, match=r"\[analysis\]"):
        store.to_pandas()
    assert issubclass(MissingExtra, ImportError)


def test_parquet_without_pyarrow_names_the_extra(store_path, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    result = CliRunner().invoke(main, ["export", "--out", str(tmp_path / "o"), "--store", str(store_path),
                                       "--format", "parquet"])
    assert result.exit_code == 2 and "pyarrow" in result.output and "analysis" in result.output


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "compare.cli", *args], capture_output=True, text=True, cwd=cwd)


def test_bad_export_input_is_one_line_with_exit_code_2(store_path, tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    missing = tmp_path / "missing.sqlite"
    cases = [
        (["--out", str(tmp_path / "o"), "--store", str(missing)], "no result store"),
        (["--out", str(tmp_path / "o"), "--from", str(tmp_path / "nowhere")], "no result store"),
        (["--out", str(tmp_path / "o")], "no result store"),
        (["--out", str(a_file), "--store", str(store_path)], "is a file"),
        (["--out", str(a_file / "sub"), "--store", str(store_path)], "is a file"),
        (["--out", str(tmp_path / "o"), "--store", str(store_path), "--format", "xlsx"], "unknown format 'xlsx'"),
        (["--out", str(tmp_path / "o"), "--store", str(store_path), "--from", str(tmp_path)], "not both"),
        (["--out", str(tmp_path / "o"), "--store", str(tmp_path)], "is a folder"),
    ]
    for args, message in cases:
        result = _cli("export", *args)
        assert result.returncode == 2, (args, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1 and message in result.stderr, (args, result.stderr)
        assert "Traceback" not in result.stderr
    assert not missing.exists() and not (tmp_path / "o").exists()
    assert a_file.read_text() == "x"


def test_a_corrupt_store_is_reported_and_left_alone(tmp_path):
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"garbage" * 200)
    result = _cli("export", "--out", str(tmp_path / "o"), "--store", str(bad))
    assert result.returncode == 2 and "not a usable result store" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert bad.read_bytes() == b"garbage" * 200
