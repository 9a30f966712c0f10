"""Importance-sampled refinement of heavy-tailed simulated costs: unbiased, and far tighter."""

import numpy as np
import pytest

from codesign import paper_instance, simulate, validation_set
from codesign.estimators import DEFENSIVE_SHARE, TiltedProposal, fitted_cost_form, importance_estimate
from codesign.evaluation import simulate_to_precision


class SaturatedGain:
    """u = clip(K x, -level, level): linear near the origin, heavy-tailed cost on an unstable plant."""

    kind = "saturated_gain_test"

    def __init__(self, K, level):
        self.gain, self.level = K, level  # not ``K``: a controller with ``K`` is scored as a linear gain

    def reset(self, batch):
        return None

    def step(self, state, x):
        return np.clip(x @ self.gain.T, -self.level, self.level), None


@pytest.fixture(scope="module")
def heavy():
    instance = paper_instance(1, a_norm=1.1)
    return instance, SaturatedGain(instance.K_lqr, 0.4)


def test_proposal_draws_are_nested_and_weights_bounded_with_unit_mean():
    instance = paper_instance(0)
    form = np.diag(np.linspace(0.1, 3.0, instance.n))
    proposal = TiltedProposal.along(form)
    many = proposal.draw(instance, 40_000, stream=(7,))
    np.testing.assert_array_equal(proposal.draw(instance, 1000, stream=(7,)), many[:1000])
    weights = proposal.weights(many)
    assert weights.max() <= 1 / DEFENSIVE_SHARE + 1e-12
    # E_q[p/q] = 1, and the tilted component inflates the top direction's variance by the inflation.
    assert abs(weights.mean() - 1) < 4 * weights.std() / np.sqrt(weights.size)
    top = many[:, -1]
    expected = DEFENSIVE_SHARE + (1 - DEFENSIVE_SHARE) * proposal.inflation
    assert abs(top.var() / expected - 1) < 0.05


def test_importance_estimate_is_unbiased_for_a_heavy_tailed_function_of_known_mean():
    # J(x) = exp(a (v'x)^2) has mean (1 - 2a)^(-1/2) under N(0, I); at a = 0.2 its
    # variance under N(0, I) is finite but its tail is heavy.
    instance = paper_instance(0)
    n = instance.n
    v = np.ones(n) / np.sqrt(n)
    a = 0.2
    truth = 1 / np.sqrt(1 - 2 * a)
    proposal = TiltedProposal.along(np.outer(v, v))
    estimates, stderrs = [], []
    for salt in range(60):
        x = proposal.draw(instance, 2000, stream=(salt,))
        cost, stderr, plain, plain_stderr, _ = importance_estimate(instance, x, np.exp(a * (x @ v) ** 2), proposal)
        estimates.append(cost)
        stderrs.append(stderr)
    estimates = np.asarray(estimates)
    spread = estimates.std(ddof=1)
    assert abs(estimates.mean() - truth) < 3 * spread / np.sqrt(estimates.size), (estimates.mean(), truth)
    # The reported standard error describes the actual spread of the estimates.
    assert 0.7 < np.mean(stderrs) / spread < 1.4


def test_pure_noise_costs_stay_unbiased():
    instance = paper_instance(0)
    proposal = TiltedProposal.along(np.eye(instance.n))
    rng = np.random.default_rng(3)
    estimates = []
    for salt in range(100):
        x = proposal.draw(instance, 400, stream=(salt,))
        estimates.append(importance_estimate(instance, x, 1.0 + rng.standard_normal(400), proposal)[0])
    estimates = np.asarray(estimates)
    assert abs(estimates.mean() - 1.0) < 3 * estimates.std(ddof=1) / np.sqrt(estimates.size)


def test_reported_errors_match_the_spread_over_independent_proposal_streams(heavy, monkeypatch):
    # The saturated gain escapes when the state along A's unstable mode exceeds a
    # threshold (about 1 draw in 6000 under N(0, I), 14 % of the mean cost): a rare
    # costly event that the 2000 validation draws usually miss. Estimates on
    # independent proposal streams must scatter as their reported errors say.
    from codesign import evaluation

    instance, controller = heavy
    estimates, stderrs = [], []
    for salt in range(16):
        monkeypatch.setattr(evaluation, "_PROPOSAL_SALT", 1000 + salt)
        rollout = evaluation.simulate_to_precision(instance, controller, max_size=16_000)
        estimates.append(rollout.cost)
        stderrs.append(rollout.stderr)
    spread = np.std(estimates, ddof=1)
    assert 0.6 < spread / np.mean(stderrs) < 1.6, (spread, np.mean(stderrs))


@pytest.mark.slow
def test_heavy_tailed_estimate_agrees_with_two_million_plain_draws(heavy):
    instance, controller = heavy
    rollout = simulate_to_precision(instance, controller)
    costs = np.concatenate([simulate(instance, controller, validation_set(instance, 100_000, seed=10**6 + k),
                                     control_variates=False).costs for k in range(20)])
    reference, reference_stderr = costs.mean(), costs.std(ddof=1) / np.sqrt(costs.size)
    assert abs(rollout.cost - reference) < 3 * np.hypot(rollout.stderr, reference_stderr)


def test_heavy_tailed_cost_is_refined_on_importance_draws_and_agrees_with_a_plain_mean(heavy):
    instance, controller = heavy
    rollout = simulate_to_precision(instance, controller)
    assert "importance sampling" in rollout.estimator
    assert rollout.weights is not None and rollout.weights.shape == rollout.costs.shape
    np.testing.assert_array_equal(rollout.weights[:2000], 1.0)  # the shared validation draws come first
    first = simulate(instance, controller, validation_set(instance, 2000))
    np.testing.assert_array_equal(rollout.costs[:2000], first.costs)
    # The same number of plain validation draws, with control variates, is far less precise.
    untilted = simulate(instance, controller, validation_set(instance, rollout.costs.size))
    assert rollout.stderr * 5 < untilted.stderr, (rollout.stderr, untilted.stderr)
    # Unbiased: agrees with a plain mean on 200,000 fresh draws (a cheap controller).
    fresh = simulate(instance, controller, validation_set(instance, 200_000, seed=instance.seed + 10_007),
                     control_variates=False)
    combined = np.hypot(rollout.stderr, fresh.plain_stderr)
    assert abs(rollout.cost - fresh.plain_cost) < 3 * combined, (rollout.cost, fresh.plain_cost, combined)
    assert abs(rollout.plain_cost - fresh.plain_cost) < 3 * np.hypot(rollout.plain_stderr, fresh.plain_stderr)


def test_fitted_cost_form_recovers_a_quadratic():
    instance = paper_instance(0)
    x = validation_set(instance, 2000)
    M = np.random.default_rng(0).standard_normal((instance.n, instance.n))
    M = M @ M.T
    np.testing.assert_allclose(fitted_cost_form(instance, x, np.einsum("bi,ij,bj->b", x, M, x)), M, atol=1e-8)


def test_harness_rescores_when_a_spec_asks_for_more_shared_validation_draws(heavy):
    from codesign import score
    from codesign.scoring import evaluate

    instance, controller = heavy
    design = score(instance, controller, links=0, self_loops=instance.n)
    extras = design.extras
    assert extras["importance_draws"] > 0 and extras["validation_size"] == 2000 + extras["importance_draws"]
    assert evaluate(instance, design).cost == design.cost  # scored on these draws already
    # More draws than the validation draws it shares: rolled out again on 4000 validation draws.
    again = evaluate(instance, design, validation_size=4000)
    assert again.extras["validation_size"] - again.extras["importance_draws"] == 4000
    assert abs(again.cost - design.cost) < 4 * np.hypot(again.cost_stderr, design.cost_stderr)
