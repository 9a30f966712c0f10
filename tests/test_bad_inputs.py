"""Every bad setting is refused before any work, with one line that names it (issue #31, item 4).

Hyperparameters carry their bounds in their annotations (``Annotated[int, AtLeast(1)]``),
instances refuse NaN, infinite, complex and empty matrices, a spec refuses binary files,
non-finite instance parameters, instances too large for the machine, names that leave
``results/`` and ``pairs`` labels no method entry has. The CLI turns each into exit code 2
and one ``Error:`` line, and creates no store.
"""

import dataclasses
import io
import json
import textwrap
import warnings
from typing import Annotated

import numpy as np
import pytest
from click.testing import CliRunner

import compare.run.registry  # noqa: F401  (the built-in methods)
from baselines import lqr
from codesign import Instance, InstanceError, StaticGain, paper_instance, score
from codesign.methods import AtLeast, Method, get_method, registered_methods
from compare.cli import main
from compare.run.families import get_family
from compare.run.spec import DENSE_MATRICES, SpecError, _check_memory, load_spec, preset_names

SPEC = textwrap.dedent("""\
    name = "bad-inputs"
    [instances]
    family = "paper"
    n = [6]
    degree = 4
    a_norms = [0.995]
    seeds = 1
    horizon = 8

    [[methods]]
    method = "lqr"
""")


def _spec(tmp_path, text: str, name: str = "spec.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _with_method(entry: str) -> str:
    return SPEC.replace('method = "lqr"', entry)


# -- hyperparameter bounds -------------------------------------------------------------------
@pytest.mark.parametrize(
    "name, params, message",
    [
        ("grnn", {"steps": -5}, "steps: must be an integer >= 1, got -5"),
        ("grnn", {"steps": 0}, "steps: must be an integer >= 1, got 0"),
        ("grnn", {"ensemble": 0}, "ensemble: must be an integer >= 1, got 0"),
        ("grnn", {"batch": 0}, "batch: must be an integer >= 1, got 0"),
        ("grnn", {"hidden": 0}, "hidden: must be an integer >= 1, got 0"),
        ("grnn", {"lr": 0.0}, "lr: must be a finite number > 0, got 0.0"),
        ("grnn", {"lr": float("inf")}, "lr: must be a finite number > 0, got inf"),
        ("grnn", {"curve_size": 1}, "curve_size: must be an integer >= 2, got 1"),
        ("grnn", {"stability_steps": -1}, "stability_steps: must be an integer >= 0, got -1"),
        ("grnn", {"seed": -1}, "seed: must be an integer >= 0, got -1"),
        ("grnn_sparse", {"beta": -1}, "beta: must be a finite number >= 0, got -1"),
        ("grnn_sparse", {"beta": float("nan")}, "beta: must be a finite number >= 0, got nan"),
        ("gcnn", {"dtype": "float16"}, "dtype: expected 'float64' or 'float32', got str 'float16'"),
        ("gcnn", {"decay": 0.0}, "decay: must be a finite number in (0, 1], got 0.0"),
        ("gcnn", {"curve_size": 0}, "curve_size: must be an integer >= 2, got 0"),
        ("sparse_admm", {"gammas": [-1, 0.1]}, "gammas[0]: must be a finite number >= 0, got -1"),
        ("sparse_admm", {"gammas": []}, "gammas: must be a non-empty list, got []"),
        ("sparse_admm", {"rho": 0}, "rho: must be a finite number > 0, got 0"),
        ("sparse_admm", {"reweight": -1}, "reweight: must be an integer >= 1, got -1"),
        ("sparse_delayed", {"tol": -1e-7}, "tol: must be a finite number > 0, got -1e-07"),
        ("sparse_delayed", {"maxiter": 0}, "maxiter: must be an integer >= 1, got 0"),
        ("sparse_sdp", {"eps": 1.0}, "eps: must be a finite number in (0, 1), got 1.0"),
        ("sparse_sdp", {"solver": "mosek"}, "solver: expected 'auto' or 'scs' or 'clarabel', got str 'mosek'"),
        ("sls", {"graph": "bogus"}, "graph: must be a graph name: 'given', 'plant', 'given^k', 'plant^k' "
                                    "or 'complete', got 'bogus'"),
        ("sls", {"graph": "plant^0"}, "graph: must be a graph name"),
        ("sls", {"horizon": 0}, "horizon: must be an integer >= 1, got 0"),
        ("sls", {"speed": -1.0}, "speed: must be a finite number > 0, got -1.0"),
        ("sls_topologies", {"graphs": ["plant", "bogus"]}, "graphs[1]: must be a graph name"),
        ("sls_topologies", {"graphs": []}, "graphs: must be a non-empty list, got []"),
        ("truncated_lqr", {"links": [10, -1]}, "links[1]: must be an integer >= 0, got -1"),
        ("decentralized", {"start": "random"}, "start: expected 'lqr_diagonal' or 'zero', got str 'random'"),
    ],
)
def test_out_of_bounds_hyperparameters_are_refused_by_name(name, params, message):
    with pytest.raises(ValueError) as caught:
        get_method(name).check_params(params, f"methods.{name}.params")
    assert str(caught.value).startswith(f"methods.{name}.params.{message}")
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("name, params", [
    ("grnn", {"steps": 1, "curve_size": 2, "stability_steps": 0, "curve_every": 0, "clip": 0.0}),
    ("grnn_sparse", {"beta": 0, "threshold": 0.0}),
    ("gcnn", {"decay": 1.0, "dtype": "float32"}),
    ("sls", {"graph": "given^12", "act_delay": 0, "fir": 1}),
    ("sls", {"graph": "complete", "horizon": None}),
    ("sparse_delayed", {"gammas": [0, 1e-3]}),
    ("sparse_sdp", {"threshold": 0.0, "max_states": 1}),
    ("truncated_lqr", {"links": [0]}),
])
def test_values_on_the_bounds_are_accepted(name, params):
    get_method(name).check_params(params)


@pytest.mark.parametrize("name", sorted(registered_methods()))
def test_every_default_is_within_its_declared_bounds(name):
    method = registered_methods()[name]
    method.check_params(method.defaults)


@pytest.mark.parametrize("name, settings_type", [("grnn_sparse", "GRNNSettings"), ("gcnn", "GCNNSettings")])
def test_the_learned_methods_settings_are_their_one_table(name, settings_type):
    """A learned method's hyperparameters are its settings type's fields (one table), and the settings
    type refuses what the registry refuses, with the same message."""
    import dataclasses

    import codesign.learned as learned

    kind = getattr(learned, settings_type)
    method = get_method(name)
    fields = {f.name: f for f in dataclasses.fields(kind)}
    assert set(method.hyperparameters) - set(fields) <= {"seed", "beta"}
    checked = 0
    for key, f in fields.items():
        h = method.hyperparameters[key]
        assert h.default == f.default and h.annotation == kind.hyperparameters()[key].annotation
        low = [c for c in getattr(h.annotation, "__metadata__", ()) if isinstance(c, AtLeast)]
        if not low or not isinstance(h.default, int):
            continue
        edge = int(low[0].bound)
        kind(**{key: edge})
        method.check_params({key: edge})
        with pytest.raises(ValueError) as by_settings:
            kind(**{key: edge - 1})
        with pytest.raises(ValueError) as by_registry:
            method.check_params({key: edge - 1}, where="")
        assert str(by_registry.value) == "." + str(by_settings.value)
        checked += 1
    assert checked >= 5


def test_compare_methods_shows_the_bounds():
    result = CliRunner().invoke(main, ["methods"])
    assert result.exit_code == 0
    assert "    steps: int >= 1 = 750" in result.output
    assert "    beta: float >= 0 or None = None" in result.output
    assert "    decay: float in (0, 1] = 0.9" in result.output


def test_a_plugin_declares_its_own_bounds():
    def scaled(instance, *, links: Annotated[int, AtLeast(3)] = 5):
        return score(instance, StaticGain(np.asarray(instance.K_lqr)))

    method = Method.from_function(scaled, name="bounded_plugin")
    assert method.hyperparameters["links"].type_name == "int >= 3"
    with pytest.raises(ValueError, match=r"^params\.links: must be an integer >= 3, got 2$"):
        method(paper_instance(0, n=6, degree=4, horizon=8), links=2)


# -- a method that returns nothing, or is given no instance ---------------------------------------
def _empty(instance, *, seed: int = 0):
    return []


def test_a_method_returning_no_design_is_an_error_naming_it():
    method = Method.from_function(_empty, name="empty_method")
    inst = paper_instance(0, n=6, degree=4, horizon=8)
    with pytest.raises(RuntimeError, match="method 'empty_method' returned no design"):
        method(inst)
    batched = Method.from_function(_empty, name="empty_batch", batch=lambda pairs: [[] for _ in pairs])
    with pytest.raises(RuntimeError, match="method 'empty_batch' returned no design"):
        batched.run_batch([(inst, {}), (inst, {})])


def test_the_runner_records_a_method_returning_no_design_as_failed(monkeypatch):
    from codesign import methods
    from compare.run.runner import execute_run
    from compare.run.spec import EvaluationSpec, Run

    monkeypatch.setitem(methods._REGISTRY, "empty_method_run", Method.from_function(_empty, name="empty_method_run"))
    spec = {"family": "paper", "seed": 0, "n": 6, "degree": 4, "a_norm": 0.995, "b_norm": 1.0, "hops": 3,
            "horizon": 8}
    designs = execute_run(Run(spec, "empty_method_run", "Empty", {}, EvaluationSpec(), "f")).designs
    assert [d.status for d in designs] == ["failed"]
    assert "method 'empty_method_run' returned no design" in designs[0].message


@pytest.mark.parametrize("call", [
    lambda: lqr(None),
    lambda: get_method("lqr")(None),
    lambda: get_method("sparse_admm")(np.eye(3)),
    lambda: get_method("gcnn").run_batch([(None, {})]),
])
def test_a_method_given_no_instance_says_so(call):
    with pytest.raises(TypeError, match=r"expected a codesign\.Instance .*, got (NoneType None|ndarray)"):
        call()


# -- instances ---------------------------------------------------------------------------------
GOOD = {"A": 0.5 * np.eye(3), "B": np.eye(3), "Q": np.eye(3), "R": np.eye(3)}


@pytest.mark.parametrize("key", ["A", "B", "Q", "R"])
@pytest.mark.parametrize("bad, message", [
    ("nan", "has non-finite entries"),
    ("inf", "has non-finite entries"),
    ("complex", "is complex"),
])
def test_from_matrices_refuses_nan_inf_and_complex_naming_the_matrix(key, bad, message):
    arrays = {k: v.copy() for k, v in GOOD.items()}
    if bad == "complex":
        arrays[key] = arrays[key] + 0.1j * np.eye(3)
    else:
        arrays[key][0, 0] = float(bad)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning: an error, not a silent cast
        with pytest.raises(InstanceError, match=rf"^{key} {message}") as caught:
            Instance.from_matrices(arrays["A"], arrays["B"], Q=arrays["Q"], R=arrays["R"])
    assert "\n" not in str(caught.value)


def test_from_matrices_refuses_an_empty_system():
    with pytest.raises(InstanceError, match=r"^A is empty \(shape \(0, 0\)\)"):
        Instance.from_matrices(np.zeros((0, 0)), np.zeros((0, 0)))
    with pytest.raises(InstanceError, match=r"^B has no columns"):
        Instance.from_matrices(0.5 * np.eye(2), np.zeros((2, 0)), input_nodes=[])


def test_an_instance_built_directly_refuses_complex_and_nan():
    inst = paper_instance(0, n=6, degree=4, horizon=8)
    with pytest.raises(InstanceError, match="^A is complex"):
        dataclasses.replace(inst, A=inst.A + 1j)
    with pytest.raises(InstanceError, match="^P has non-finite entries"):
        dataclasses.replace(inst, P=inst.P * np.nan)


def test_a_complex_npz_is_a_spec_error_naming_file_and_matrix(tmp_path):
    buffer = io.BytesIO()
    np.savez(buffer, A=0.5 * np.eye(3) + 0.1j * np.eye(3), B=np.eye(3))
    (tmp_path / "complex.npz").write_bytes(buffer.getvalue())
    text = SPEC.replace('family = "paper"\nn = [6]\ndegree = 4\na_norms = [0.995]\nseeds = 1\nhorizon = 8\n',
                        'family = "matrices"\nfiles = ["complex.npz"]\n')
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SpecError, match=r"instances\.files: .*complex\.npz: A is complex"):
            load_spec(_spec(tmp_path, text))


# -- specs -------------------------------------------------------------------------------------
def test_a_binary_spec_file_is_not_a_text_toml_file(tmp_path):
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe")
    with pytest.raises(SpecError, match=r"binary\.toml is not a text TOML file"):
        load_spec(path)
    path.write_bytes(b"name = \"x\"\x00\x00")  # valid UTF-8, still binary
    with pytest.raises(SpecError, match=r"binary\.toml is not a text TOML file \(a NUL byte"):
        load_spec(path)


@pytest.mark.parametrize("old, new, message", [
    ("a_norms = [0.995]", "a_norms = [nan]", r"instances\.a_norms\[0\]: expected a finite number, got nan"),
    ("a_norms = [0.995]", "a_norms = [inf]", r"instances\.a_norms\[0\]: expected a finite number, got inf"),
    ("a_norms = [0.995]", "a_norms = [0.0]", r"instances\.a_norms: values must be positive"),
    ("n = [6]", "n = [0]", r"instances\.n: values must be positive"),
    ("n = [6]", "n = [-4]", r"instances\.n: values must be positive"),
    ("horizon = 8", "horizon = 8\nb_norm = -inf", r"instances\.b_norm: expected a finite number, got -inf"),
    ("horizon = 8", "horizon = 0", r"instances\.horizon: must be >= 1"),
])
def test_bad_instance_parameters_are_refused_at_load(tmp_path, old, new, message):
    assert old in SPEC
    with pytest.raises(SpecError, match=message):
        load_spec(_spec(tmp_path, SPEC.replace(old, new)))


def test_sampled_families_refuse_non_finite_parameters(tmp_path):
    text = SPEC.replace('family = "paper"\nn = [6]\ndegree = 4\na_norms = [0.995]\nseeds = 1\n',
                        'family = "mass_spring"\nn = [4]\ndt = inf\n')
    with pytest.raises(SpecError, match=r"instances\.dt: expected a finite number, got inf"):
        load_spec(_spec(tmp_path, text))


def test_an_instance_too_large_for_memory_is_refused_with_the_largest_that_fits(tmp_path):
    with pytest.raises(SpecError) as caught:
        load_spec(_spec(tmp_path, SPEC.replace("n = [6]", "n = [100000]").replace("degree = 4", "degree = 6")))
    message = str(caught.value)
    assert message.startswith("instances.n: n = 100000 needs about 3.49 TiB per run")
    assert f"{DENSE_MATRICES} dense 100000 x 100000 float64 matrices" in message
    assert "the largest n that fits is" in message


def test_the_size_guard_refuses_just_above_the_largest_size_it_names():
    memory = 2 ** 30  # 1 GiB: at most isqrt(2**30 / (48 * 8)) = 1672 states
    paper, chain = get_family("paper"), get_family("mass_spring")
    _check_memory("instances", paper, [{"n": 1672}], memory)
    with pytest.raises(SpecError, match=r"n = 1673 needs about 1 GiB .* the largest n that fits is 1672$"):
        _check_memory("instances", paper, [{"n": 1673}], memory)
    _check_memory("instances", chain, [{"n": 836}], memory)  # two states per mass
    with pytest.raises(SpecError, match=r"n = 837 \(1674 states\) .* the largest n that fits is 836$"):
        _check_memory("instances", chain, [{"n": 837}], memory)


def test_every_shipped_preset_passes_the_checks():
    for name in preset_names():
        assert load_spec(name).runs()


@pytest.mark.parametrize("name", ["../../escape", "/tmp/abs", "a/b", ".hidden", "..", "", "two words", "a\\b"])
def test_names_that_are_not_plain_folder_names_are_refused(tmp_path, name):
    text = SPEC.replace('name = "bad-inputs"', f"name = {json.dumps(name)}")
    with pytest.raises(SpecError, match=r"^name: must be a plain folder name"):
        load_spec(_spec(tmp_path, text))


def test_plain_names_are_accepted_and_a_file_name_is_checked_too(tmp_path):
    assert load_spec(_spec(tmp_path, SPEC.replace("bad-inputs", "table1_v2.3-small"))).name == "table1_v2.3-small"
    nameless = SPEC.replace('name = "bad-inputs"\n', "")
    assert load_spec(_spec(tmp_path, nameless, "my-spec.toml")).name == "my-spec"
    with pytest.raises(SpecError, match=r"^name: the spec file's name 'my spec' is not a plain folder name"):
        load_spec(_spec(tmp_path, nameless, "my spec.toml"))


def test_pairs_must_name_method_entries(tmp_path):
    text = SPEC + '\n[[methods]]\nmethod = "decentralized"\nlabel = "Diagonal"\n'
    ok = text.replace("[instances]", '[report]\npairs = [["lqr", "Diagonal"]]\n\n[instances]')
    assert load_spec(_spec(tmp_path, ok)).pairs == (("lqr", "Diagonal"),)
    bad = text.replace("[instances]", '[report]\npairs = [["lqr", "Diagonal"], ["GRNN", "lqr"]]\n\n[instances]')
    with pytest.raises(SpecError, match=r"^report\.pairs\[1\]: 'GRNN' is no method entry's label or method name "
                                        r"\(known: 'LQR \(centralized\)', 'Diagonal', 'lqr', 'decentralized'\)$"):
        load_spec(_spec(tmp_path, bad))


# -- the CLI: exit 2, one line, no traceback, no store --------------------------------------------
CLI_CASES = {
    "grnn steps": _with_method('method = "grnn"\nparams = { steps = -5 }'),
    "sls graph": _with_method('method = "sls"\ngrid = { graph = ["plant", "bogus"] }'),
    "gcnn dtype": _with_method('method = "gcnn"\nparams = { dtype = "float16" }'),
    "gammas": _with_method('method = "sparse_admm"\nparams = { gammas = [-1, 0.1] }'),
    "nan a_norm": SPEC.replace("a_norms = [0.995]", "a_norms = [nan]"),
    "huge n": SPEC.replace("n = [6]", "n = [100000]"),
    "escaping name": SPEC.replace('name = "bad-inputs"', 'name = "../../escape"'),
    "unknown pair": SPEC.replace("[instances]", '[report]\npairs = [["lqr", "nope"]]\n\n[instances]'),
}


@pytest.mark.parametrize("case", sorted(CLI_CASES) + ["binary"])
def test_the_cli_refuses_bad_specs_with_one_line_and_no_store(tmp_path, case):
    if case == "binary":
        spec = tmp_path / "spec.toml"
        spec.write_bytes(bytes(range(256)))
    else:
        spec = _spec(tmp_path, CLI_CASES[case])
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(spec), "--out", str(out), "--workers", "1", "--no-progress"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    assert "Traceback" not in result.output
    assert not out.exists()


def test_an_escaping_name_writes_nothing_outside_results(tmp_path, monkeypatch):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    spec = _spec(work, CLI_CASES["escaping name"])
    result = CliRunner().invoke(main, ["run", str(spec), "--workers", "1", "--no-progress"])
    assert result.exit_code == 2 and "name: must be a plain folder name" in result.output
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a", "b", "spec.toml"]
