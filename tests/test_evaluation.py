import control
import numpy as np
import pytest

from codesign.evaluation import VALIDATION_SIZE
from codesign import (
    StaticGain,
    ZeroInput,
    compare_exact_and_simulated,
    paper_instance,
    response_cost,
    simulate,
    spectral_radius,
    static_gain_cost,
    static_gain_cost_and_grad,
    validation_set,
)


@pytest.fixture(scope="module", params=[0.995, 1.05])
def inst(request):
    return paper_instance(11, a_norm=request.param)


def test_lqr_cost_is_one_and_matches_python_control(inst):
    assert static_gain_cost(inst, inst.K_lqr) == pytest.approx(1.0, abs=1e-9)
    K, S, _ = control.dlqr(inst.A, inst.B, inst.Q, inst.R)
    assert np.allclose(-np.asarray(K), inst.K_lqr, atol=1e-8)  # control uses u = -Kx
    assert np.allclose(S, inst.P, atol=1e-8 * np.abs(inst.P).max())


def test_lqr_is_a_lower_bound(inst):
    rng = np.random.default_rng(0)
    for _ in range(5):
        K = inst.K_lqr + 0.05 * rng.standard_normal((inst.n, inst.n))
        assert static_gain_cost(inst, K) > 1.0


def _random_stabilizing_gain(inst, rng):
    while True:
        K = inst.K_lqr * rng.uniform(0.3, 1.0) + 0.1 * rng.standard_normal((inst.n, inst.n))
        if spectral_radius(inst.A + inst.B @ K) < 0.99:
            return K


def test_exact_and_simulated_agree_for_random_stabilizing_gains(inst):
    rng = np.random.default_rng(1)
    for _ in range(4):
        check = compare_exact_and_simulated(inst, StaticGain(_random_stabilizing_gain(inst, rng)))
        assert abs(check["z"]) < 3, check
        # J(x0) of a linear controller is a quadratic form, which the control
        # variates span: the estimate is the exact cost up to rounding. A wrong
        # feature mean would show here as an O(1) error.
        assert check["control_variate"] == pytest.approx(check["exact"], rel=1e-9)


def test_exact_and_simulated_agree_under_process_noise(inst):
    K = inst.K_lqr
    exact = static_gain_cost(inst, K, noise_std=0.3)
    assert exact > 1.0
    rollout = simulate(inst, StaticGain(K), noise_std=0.3, seed=4)
    assert abs(rollout.cost - exact) < 3 * rollout.stderr


def test_gradient_matches_finite_differences(inst):
    rng = np.random.default_rng(2)
    K = 0.5 * inst.K_lqr
    _, grad = static_gain_cost_and_grad(inst, K)
    for _ in range(5):
        i, j = rng.integers(0, inst.n, size=2)
        E = np.zeros_like(K)
        E[i, j] = 1e-6
        fd = (static_gain_cost(inst, K + E) - static_gain_cost(inst, K - E)) / 2e-6
        assert fd == pytest.approx(grad[i, j], rel=1e-5, abs=1e-9)


def test_response_cost_matches_static_gain_cost(inst):
    K = 0.7 * inst.K_lqr
    Acl = inst.A + inst.B @ K
    phi_x = [np.eye(inst.n)]
    for _ in range(inst.horizon):
        phi_x.append(Acl @ phi_x[-1])
    phi_x = np.array(phi_x)
    phi_u = np.einsum("ij,tjk->tik", K, phi_x[:-1])
    assert response_cost(inst, phi_x, phi_u) == pytest.approx(static_gain_cost(inst, K), rel=1e-12)
    with pytest.raises(ValueError, match="shapes"):
        response_cost(inst, phi_x[:-1], phi_u)


def test_validation_set_is_fixed_and_seeded(inst):
    a, b = validation_set(inst), validation_set(inst)
    assert a.shape == (VALIDATION_SIZE, inst.n) and np.array_equal(a, b)
    assert not np.array_equal(a, validation_set(paper_instance(12)))
    assert not np.array_equal(validation_set(inst, 10), validation_set(inst, 10, seed=99))


def test_autonomous_simulation_and_unbounded_detection():
    inst = paper_instance(0, a_norm=1.2)
    rollout = simulate(inst, ZeroInput(inst.n), steps=500)
    assert not rollout.bounded and rollout.cost == float("inf")
    ok = simulate(inst, StaticGain(inst.K_lqr), steps=500)
    assert ok.bounded and ok.max_state < 20


def test_simulate_rejects_wrong_shapes(inst):
    with pytest.raises(ValueError, match="x0 must have shape"):
        simulate(inst, StaticGain(inst.K_lqr), np.zeros((5, inst.n + 1)))


class _ThreadCountingController:
    """A static gain that records torch's intra-op pool size at every step."""

    def __init__(self, K):
        self.K, self.seen = K, []

    def reset(self, batch):
        return None

    def step(self, state, x):
        import torch

        self.seen.append(torch.get_num_threads())
        return x @ self.K.T, state


def test_rollouts_run_torch_single_threaded_and_restore_its_pool(inst):
    """simulate and local_cost_form hold torch at one thread (numpy and torch pools spin against
    each other otherwise) and give the caller's pool size back, also after an error."""
    import torch

    from codesign.evaluation import local_cost_form, simulate

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        controller = _ThreadCountingController(np.zeros((inst.m, inst.n)))
        simulate(inst, controller, np.ones((3, inst.n)))
        local_cost_form(inst, controller)
        assert set(controller.seen) == {1} and len(controller.seen) == 2 * inst.horizon
        assert torch.get_num_threads() == 2

        class Failing(_ThreadCountingController):
            def step(self, state, x):
                raise RuntimeError("boom")

        with pytest.raises(RuntimeError, match="boom"):
            simulate(inst, Failing(controller.K), np.ones((3, inst.n)))
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
