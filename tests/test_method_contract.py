"""The contract every registered method keeps (python-control's kwargs_test.py in spirit).

On a small instance each method, built-in or plug-in, returns valid Designs, rejects an
unknown and a mistyped hyperparameter by name, and gives identical numbers for the
same seed. A new method is covered the moment it is registered.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from codesign import INFO_MODELS, STATUSES, Design, paper_instance
from codesign.methods import Hyperparameter, registered_methods
from compare.run.plugins import load_plugins, parse_plugin

# The plug-in a user would write, loaded from a file as `compare run --plugin` does.
load_plugins([parse_plugin(str(Path(__file__).with_name("plugin_methods.py")))])
import compare.run.registry  # noqa: E402,F401  (the built-ins)

#: Settings that keep each slow method to a second or so; every other method runs its defaults.
FAST = {
    "grnn": {"steps": 3, "ensemble": 1, "stability_steps": 0, "curve_size": 10},
    "grnn_dense": {"steps": 3, "ensemble": 1, "stability_steps": 0, "curve_size": 10},
    "grnn_fixed": {"steps": 3, "ensemble": 1, "stability_steps": 0, "curve_size": 10},
    "grnn_sparse": {"steps": 3, "ensemble": 1, "stability_steps": 0, "curve_size": 10, "beta": 0.5},
    "gcnn": {"steps": 3, "ensemble": 1, "stability_steps": 0, "curve_size": 10},
    "sparse_sdp": {"gammas": [0.01]},
    "sparse_admm": {"gammas": [1e-3, 1e-2]},
    "sparse_newton": {"gammas": [1e-3, 1e-2]},
    "truncated_lqr": {"links": [10, 0]},
    "sparse_budget": {"links": [10, 0]},
    "best_pattern": {"links": [0, 1, 56], "starts": 2},
    "sls_topologies": {"graphs": ["plant", "complete"]},
}
METHODS = sorted(registered_methods())


@pytest.fixture(scope="module")
def instance():
    return paper_instance(1, n=8, degree=4, a_norm=1.05, horizon=12)


def _wrong_value(h: Hyperparameter):
    """A value no annotation of the form int / float / str / bool / list accepts alongside it."""
    for value in ({"not": "valid"}, object()):
        try:
            h.check(value, "x")
        except ValueError:
            return value
    return None


def test_every_method_is_covered():
    assert {"lqr", "sparse_admm", "sls", "grnn_sparse", "gcnn", "plugin_scaled_lqr"} <= set(METHODS)


@pytest.mark.parametrize("name", [m for m in METHODS if not m.startswith("plugin_")])
def test_every_hyperparameter_says_what_it_means(name):
    """`compare methods` prints one meaning per hyperparameter: present, and not shared with another one."""
    hyper = registered_methods()[name].hyperparameters
    missing = [h.name for h in hyper.values() if not h.doc]
    assert not missing, f"{name}: no description for {missing} (numpydoc Parameters entry)"
    docs = [h.doc for h in hyper.values()]
    shared = sorted({d for d in docs if docs.count(d) > 1})
    assert not shared, f"{name}: one description for several hyperparameters: {shared}"


@pytest.mark.parametrize("name", METHODS)
def test_designs_are_valid_and_reproducible(instance, name):
    method = registered_methods()[name]
    params = FAST.get(name, {})
    first = method(instance, **params)
    assert first and all(isinstance(d, Design) for d in first)
    for d in first:
        assert d.method == name
        assert d.status in STATUSES and d.info_model in INFO_MODELS
        if d.status == "optimal":
            assert math.isfinite(d.cost) and d.cost >= 1 - 1e-9, d
        assert 0 <= d.links <= instance.n * (instance.n - 1) and 0 <= d.self_loops <= instance.n
        assert (d.links == 0) or d.info_model != "none"
    again = method(instance, **params)
    assert [d.cost for d in again] == pytest.approx([d.cost for d in first], rel=0, abs=0, nan_ok=True)
    assert [d.links for d in again] == [d.links for d in first]


@pytest.mark.parametrize("name", METHODS)
def test_unknown_and_mistyped_hyperparameters_are_named(instance, name):
    method = registered_methods()[name]
    with pytest.raises(ValueError, match=rf"params\.no_such_setting: unknown hyperparameter for method '{name}'"):
        method(instance, no_such_setting=1)
    checked = [(h, _wrong_value(h)) for h in method.hyperparameters.values()]
    checked = [(h, v) for h, v in checked if v is not None]
    if not method.hyperparameters:
        return
    assert checked, f"{name}: no hyperparameter is type-checked"
    h, value = checked[0]
    with pytest.raises(ValueError, match=rf"params\.{h.name}: expected"):
        method(instance, **{h.name: value})


def test_a_seed_changes_a_learned_design(instance):
    method = registered_methods()["grnn"]
    a = method(instance, **FAST["grnn"], seed=0)[0]
    b = method(instance, **FAST["grnn"], seed=1)[0]
    assert not np.allclose(a.controller.F, b.controller.F)


def test_a_method_refuses_at_once_past_its_size(instance):
    """Through the registry (spec, CLI), a method past its max_states records a failed design giving its reason.

    At once: the method's function is never called (counted, not timed, so that a loaded machine cannot fail it).
    """
    import dataclasses

    from compare.run.registry import get_method

    admm = get_method("sparse_admm")
    assert admm.max_states == 300 and "19 minutes at 500" in admm.max_states_reason
    assert get_method("sparse_delayed").max_states == 200 and get_method("sparse_budget").max_states == 300
    assert get_method("gcnn").max_states == 1000
    assert [get_method(f"grnn{v}").max_states for v in ("", "_dense", "_fixed", "_sparse")] == [1000, 500, 1000, 1000]
    assert get_method("grnn_sparse").size_limit(instance, {})[0] == 500  # its l1 stage on all N^2 pairs
    assert get_method("lqr").max_states is None and get_method("sls_local").max_states is None
    calls = []

    def counted(inst, **params):
        calls.append(params)
        return admm.design(inst, **params)

    small = dataclasses.replace(admm, design=counted, max_states=instance.n - 1)
    designs = small(instance, gammas=[0.01])
    assert calls == []  # refused before the ADMM path starts
    assert [d.status for d in designs] == ["failed"] and designs[0].extras["size_guard"]
    assert designs[0].message.startswith(f"method 'sparse_admm' is not run on {instance.n} states (at most "
                                         f"{instance.n - 1}): the ADMM path's iterations are dense")
    within = dataclasses.replace(small, max_states=instance.n)
    assert all(d.status == "optimal" for d in within(instance, gammas=[0.01]))  # within its size it runs
    assert calls == [{"gammas": [0.01]}]
