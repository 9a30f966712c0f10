"""simulate's step loop in cache-sized blocks of draws, against one step loop over the whole batch."""

from __future__ import annotations

import numpy as np
import pytest

from codesign import evaluation, paper_instance, simulate, validation_set
from codesign.evaluation import ROLLOUT_BOUND, step_loop
from codesign.learned import GCNNController


class Recording:
    """A controller that records the batch size of every ``reset`` it sees."""

    def __init__(self, controller):
        self.controller, self.batches = controller, []

    def reset(self, batch):
        self.batches.append(batch)
        return self.controller.reset(batch)

    def step(self, state, x):
        return self.controller.step(state, x)


@pytest.fixture(scope="module")
def inst():
    return paper_instance(3, a_norm=1.05)


def _gcnn(inst, seed=0):
    rng = np.random.default_rng(seed)
    return GCNNController(inst.gso, rng.standard_normal((5, 32)) / 3, rng.standard_normal(32) / 6)


def _whole(inst, controller, x):
    """The step loop over the whole batch at once: costs divided by trace P, bounded, max_state."""
    costs, bounded, max_state = step_loop(inst, controller, x, inst.horizon, 0.0, None, ROLLOUT_BOUND,
                                          float(np.max(np.abs(x))))
    return costs / inst.trace_P, bounded, max_state


@pytest.mark.parametrize("draws", [2, 199, 200, 457])
def test_blocks_give_the_whole_batch_costs(inst, draws):
    c = _gcnn(inst)
    x = validation_set(inst, draws)
    rollout = simulate(inst, c, x, control_variates=False)
    costs, bounded, max_state = _whole(inst, c, x)
    assert rollout.bounded and bounded
    np.testing.assert_allclose(rollout.costs, costs, rtol=1e-13, atol=0)
    assert rollout.max_state == pytest.approx(max_state, rel=1e-13)


def test_blocks_hold_four_thousand_states(inst):
    c = Recording(_gcnn(inst))
    simulate(inst, c, validation_set(inst, 457), control_variates=False)
    assert c.batches == [200, 200, 57]  # 4000 states at 20 nodes


def test_block_size_follows_the_states(inst, monkeypatch):
    monkeypatch.setattr(evaluation, "BLOCK_STATES", 3 * inst.n)
    c = Recording(_gcnn(inst, seed=1))
    x = validation_set(inst, 10)
    rollout = simulate(inst, c, x, control_variates=False)
    assert c.batches == [3, 3, 3, 1]
    np.testing.assert_allclose(rollout.costs, _whole(inst, c.controller, x)[0], rtol=1e-13, atol=0)


def test_an_unbounded_block_makes_the_rollout_unbounded_and_the_others_are_rolled_out(inst):
    c = _gcnn(inst)
    x = validation_set(inst, 450)
    x[420] *= 1e9  # in the third block only: past the bound from the start
    rollout = simulate(inst, c, x, control_variates=False)
    assert not rollout.bounded and rollout.cost == float("inf")
    assert rollout.max_state > ROLLOUT_BOUND
    # the first two blocks are complete rollouts: the whole-batch loop gives their costs
    np.testing.assert_allclose(rollout.costs[:400], _whole(inst, c, x[:400])[0], rtol=1e-13, atol=0)


def test_noise_steps_the_whole_batch_together(inst):
    c = Recording(_gcnn(inst))
    x = validation_set(inst, 457)
    noisy = simulate(inst, c, x, noise_std=0.1, seed=3, control_variates=False)
    assert c.batches == [457]
    again = simulate(inst, _gcnn(inst), x, noise_std=0.1, seed=3, control_variates=False)
    np.testing.assert_array_equal(noisy.costs, again.costs)
