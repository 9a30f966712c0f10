"""The one-file learned method of docs/extending.md (examples/node_mlp.py) runs through `compare run`."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from compare import Store

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "node_mlp.py"

SPEC = textwrap.dedent(f'''
    name = "node-mlp"
    plugins = ["{EXAMPLE}"]
    [instances]
    n = [6]
    a_norms = [0.995]
    seeds = 2
    degree = 3
    horizon = 8
    [[methods]]
    method = "node_mlp"
    params = {{ steps = 40, stability_steps = 20, curve_every = 10 }}
''')


def _run(tmp_path):
    return subprocess.run([sys.executable, "-m", "compare.cli", "run", str(tmp_path / "spec.toml"), "--out",
                           str(tmp_path / "out"), "--workers", "1"], capture_output=True, text=True, cwd=tmp_path)


def test_the_example_learned_method_runs_from_a_spec_and_is_reused(tmp_path):
    (tmp_path / "spec.toml").write_text(SPEC)
    first = _run(tmp_path)
    assert first.returncode == 0, first.stderr
    assert "2 computed" in first.stdout + first.stderr
    records = list(Store(tmp_path / "out" / "results.sqlite", create=False).records())
    assert [r.status for r in records] == ["optimal", "optimal"]
    for r in records:
        assert r.info_model == "instantaneous" and r.cost_kind == "simulated"
        assert np.isfinite(r.cost) and r.cost >= 1.0 - 10 * r.cost_stderr  # LQR is the floor
        curve = r.extras["curve"]
        assert curve["step"] == [0, 10, 20, 30, 40] and curve["cost"][-1] < curve["cost"][0]  # it learned
    again = _run(tmp_path)
    assert again.returncode == 0 and "0 computed" in again.stdout + again.stderr


def test_autograd_model_trains_like_separate_runs():
    """Stacked members of an AutogradModel train as they would alone (the trainer's contract)."""
    import runpy

    from codesign import paper_instance
    from codesign.learned import Loop, Member, selection_set, train_stack

    module = runpy.run_path(str(EXAMPLE))
    stack = module["NodeMLPStack"]
    insts = [paper_instance(s, n=6, degree=3, horizon=8) for s in (0, 1)]
    members = [Member(problem=(inst, *np.random.default_rng(k).uniform(-1, 1, (3, 4))), data_seed=k,
                      curve_x0=selection_set(inst, 10), lr=0.02) for k, inst in enumerate(insts)]
    loop = Loop(steps=15, batch=8, horizon=8, curve_every=5)
    together = train_stack(stack, members, loop)
    for member, result in zip(members, together):
        (alone,) = train_stack(stack, [member], loop)
        for name in ("a", "b", "w"):
            np.testing.assert_allclose(result.params[name], alone.params[name], rtol=1e-10, atol=1e-13)
        assert not result.diverged and result.curve_cost[-1] < result.curve_cost[0]


def test_takes_settings_documents_the_fields_of_a_function_without_a_parameters_section():
    from codesign.learned import TrainingSettings, takes_settings
    from codesign.methods import Method

    @takes_settings(TrainingSettings)
    def bare(instance, *, seed: int = 0, **settings):
        """A method whose docstring has no Parameters section."""

    method = Method.from_function(bare, name="bare")
    assert list(method.hyperparameters)[:3] == ["seed", "steps", "batch"]
    assert method.hyperparameters["steps"].doc == "Adam updates"
