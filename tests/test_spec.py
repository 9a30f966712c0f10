import dataclasses

import pytest
from tiny_specs import tiny_spec  # tests/tiny_specs.py

from compare import SpecError, load_spec, parse_spec, preset_names

BASE = tiny_spec("t", family="paper", methods=("lqr", "decentralized"), tail='grid = { start = ["lqr_diagonal", "zero"] }\n')


def test_parse_and_expand():
    spec = parse_spec(BASE)
    runs = spec.runs()
    assert len(runs) == 2 * 2 * (1 + 2)
    assert len({r.key for r in runs}) == len(runs)
    assert {r.params.get("start") for r in runs if r.method == "decentralized"} == {"lqr_diagonal", "zero"}
    assert all(r.instance["n"] == 8 and r.instance["horizon"] == 10 for r in runs)
    # content keys are stable across parses and change with the package version
    assert [r.key for r in parse_spec(BASE).runs()] == [r.key for r in runs]
    assert runs[0].key != dataclasses.replace(runs[0], fingerprint="other").key


def test_where_restricts_a_method_entry_to_matching_instances():
    spec = parse_spec(BASE.replace('method = "lqr"', 'method = "lqr"\nwhere = { a_norm = [1.05] }'))
    lqr_runs = [r for r in spec.runs() if r.method == "lqr"]
    assert len(lqr_runs) == 2 and all(r.instance["a_norm"] == 1.05 for r in lqr_runs)
    with pytest.raises(SpecError, match=r"methods\[0\]\.where\.colour: unknown instance field"):
        parse_spec(BASE.replace('method = "lqr"', 'method = "lqr"\nwhere = { colour = [1] }'))


def test_presets_ship_and_parse():
    assert "quick" in preset_names()
    for name in preset_names():
        assert load_spec(name).runs()


@pytest.mark.parametrize(
    "edit, match",
    [
        (("[instances]", "colour = 3\n[instances]"), r"spec\.colour: unknown key"),
        (("seeds = 2", "seeds = 2\nsize = 3"), r"instances\.size: unknown key"),
        (("seeds = 2", 'seeds = "two"'), r"instances\.seeds: expected list"),
        (("seeds = 2", "seeds = [1, 1]"), r"instances\.seeds: duplicate"),
        (("a_norms = [0.995, 1.05]", 'a_norms = ["big"]'), r"instances\.a_norms\[0\]: expected float"),
        (("a_norms = [0.995, 1.05]", "a_norms = [-1.0]"), r"instances\.a_norms: values must be positive"),
        (("n = [8]", "n = [8.5]"), r"instances\.n\[0\]: expected int"),
        (('family = "paper"', 'family = "grid"'), r"instances\.family: unknown family"),
        (('method = "lqr"', 'method = "lqrr"'), r"methods\[0\]\.method: unknown method 'lqrr'"),
        (('method = "lqr"', 'method = "lqr"\nparams = { gamma = 1.0 }'), r"methods\[0\]\.params\.gamma: unknown hyperparameter"),
        (('method = "lqr"', 'method = "lqr"\ncolor = "red"'), r"methods\[0\]\.color: unknown key"),
        (('grid = { start = ["lqr_diagonal", "zero"] }', 'grid = { start = "zero" }'), r"methods\[1\]\.grid\.start: expected a non-empty list"),
        (('grid = { start = ["lqr_diagonal", "zero"] }', 'grid = { start = [1, 2] }'), r"methods\[1\]\.grid\.start: expected 'lqr_diagonal' or 'zero', got int 1"),
        (("horizon = 10", "horizon = 10\n[evaluation]\nnoise_std = -1.0"), r"evaluation\.noise_std: must be >= 0"),
        (("horizon = 10", "horizon = 10\n[evaluation]\nsamples = 3"), r"evaluation\.samples: unknown key"),
        (("horizon = 10", "horizon = ["), r"not valid TOML"),
    ],
)
def test_bad_specs_name_the_key(edit, match):
    old, new = edit
    assert old in BASE
    with pytest.raises(SpecError, match=match):
        parse_spec(BASE.replace(old, new, 1))


def test_spec_without_methods_or_instances():
    with pytest.raises(SpecError, match="missing \\[instances\\]"):
        parse_spec('name = "x"\n[[methods]]\nmethod = "lqr"\n')
    with pytest.raises(SpecError, match="at least one"):
        parse_spec('[instances]\nseeds = 1\n')


def test_unknown_preset_and_missing_file(tmp_path):
    with pytest.raises(SpecError, match="unknown preset 'nope'"):
        load_spec("nope")
    with pytest.raises(SpecError, match="spec file not found"):
        load_spec(tmp_path / "missing.toml")
    with pytest.raises(SpecError, match="spec file not found"):
        load_spec(tmp_path)  # a folder that is no preset


def test_a_folder_named_like_a_preset_does_not_hide_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "quick").mkdir()
    assert load_spec("quick").name == "quick"


def test_default_validation_size_is_the_evaluators():
    """The harness scores on the draws the GRNN and GCNN already scored themselves on (no second rollout)."""
    from codesign.evaluation import VALIDATION_SIZE
    from compare.run.spec import EvaluationSpec

    assert EvaluationSpec().validation_size == VALIDATION_SIZE


def test_degree_one_is_rejected_at_parse_time():
    text = ('name = "x"\n[instances]\nfamily = "paper"\nn = [6]\ndegree = 1\nseeds = 1\n'
            '[[methods]]\nmethod = "lqr"\n')
    with pytest.raises(SpecError, match="instances.degree: must be >= 2"):
        parse_spec(text)
