"""The GRNN's compiled rollout (codesign.learned.grnn_rollout) against simulate's step loop."""

from __future__ import annotations

import numpy as np
import pytest

from codesign import GRNNController, Instance, paper_instance, simulate, validation_set
from codesign.evaluation import simulate_to_precision
from codesign.learned import LinearGRNNController
from codesign.learned.grnn_rollout import BLOCK


class StepByStep:
    """The same controller without its ``rollout``: simulate takes the step loop."""

    def __init__(self, controller):
        self.controller = controller

    def reset(self, batch):
        return self.controller.reset(batch)

    def step(self, state, x):
        return self.controller.step(state, x)


def _controller(inst, rng, *, links_per_node=None, cls=GRNNController, h=5, scale=0.4):
    S = inst.gso * (inst.comm_adj != 0) + 0.05 * rng.standard_normal((inst.n, inst.n))
    if links_per_node is not None:  # keep each row's largest entries: a sparse design
        drop = np.argsort(-np.abs(S), axis=1)[:, links_per_node:]
        np.put_along_axis(S, drop, 0.0, axis=1)
    return cls(S, scale * rng.standard_normal(h), scale * rng.standard_normal((h, h)), -scale * rng.random(h))


def _both(inst, controller, x, **kwargs):
    return (simulate(inst, controller, x, control_variates=False, **kwargs),
            simulate(inst, StepByStep(controller), x, control_variates=False, **kwargs))


@pytest.fixture(scope="module")
def inst():
    return paper_instance(3, a_norm=1.05)


@pytest.mark.parametrize("links", [None, 6, 1])
@pytest.mark.parametrize("batch", [2, BLOCK, 2 * BLOCK + 7])
def test_costs_agree_with_the_step_loop_to_rounding(inst, links, batch):
    rng = np.random.default_rng(batch)
    c = _controller(inst, rng, links_per_node=links)
    x = validation_set(inst, batch)
    fast, loop = _both(inst, c, x)
    assert fast.bounded and loop.bounded
    np.testing.assert_allclose(fast.costs, loop.costs, rtol=1e-12, atol=0)
    assert fast.max_state == pytest.approx(loop.max_state, rel=1e-12)
    assert fast.costs.shape == (batch,)


def test_identity_activation_other_weights_and_long_horizons():
    inst = paper_instance(4, a_norm=0.9)  # open-loop stable: 500 steps of a small linear GRNN stay bounded
    rng = np.random.default_rng(7)
    M = rng.standard_normal((inst.n, inst.n))
    custom = Instance.from_matrices(inst.A, inst.B, Q=np.eye(inst.n) + M @ M.T / inst.n, R=2.0 * np.eye(inst.n),
                                    comm_adj=inst.comm_adj)
    x = validation_set(custom, 100)
    for cls in (GRNNController, LinearGRNNController):
        c = _controller(custom, rng, cls=cls, h=3, scale=0.2)
        fast, loop = _both(custom, c, x, steps=500)  # the boundedness check's length
        assert fast.bounded and loop.bounded
        np.testing.assert_allclose(fast.costs, loop.costs, rtol=1e-11, atol=0)
        assert fast.max_state == pytest.approx(loop.max_state, rel=1e-11)


def test_an_unbounded_rollout_is_the_step_loop_s_exactly(inst):
    rng = np.random.default_rng(3)
    c = _controller(inst, rng, scale=3.0)  # large weights: the closed loop leaves the bound
    x = validation_set(inst, 300)
    fast, loop = _both(inst, c, x, bound=50.0)
    assert not fast.bounded and not loop.bounded
    assert fast.steps == loop.steps and fast.max_state == loop.max_state
    np.testing.assert_array_equal(fast.costs, loop.costs)
    bad = GRNNController(np.full((inst.n, inst.n), np.nan), c.F, c.W, c.G)
    fast, loop = _both(inst, bad, x)
    assert not fast.bounded and not loop.bounded and fast.max_state == loop.max_state == float("inf")


def test_the_estimate_to_precision_agrees(inst):
    rng = np.random.default_rng(11)
    c = _controller(inst, rng, links_per_node=3)
    fast, loop = simulate_to_precision(inst, c), simulate_to_precision(inst, StepByStep(c))
    assert fast.estimator == loop.estimator
    assert fast.cost == pytest.approx(loop.cost, rel=1e-11)
    assert fast.stderr == pytest.approx(loop.stderr, rel=1e-8)


def test_it_declines_where_it_does_not_apply(inst):
    rng = np.random.default_rng(5)
    c = _controller(inst, rng)
    x = validation_set(inst, 10)
    assert c.rollout(inst, x, 5) is not None
    blocks = GRNNController(c.S, c.F.reshape(1, -1), c.W, c.G.reshape(-1, 1), state_nodes=np.arange(inst.n))
    assert blocks.rollout(inst, x, 5) is None
    fewer_inputs = Instance.from_matrices(inst.A, inst.B[:, :-1], comm_adj=inst.comm_adj,
                                          input_nodes=np.arange(inst.n - 1))
    assert c.rollout(fewer_inputs, x, 5) is None
