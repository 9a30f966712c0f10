"""An initial-state covariance Σ₀ (``Instance.x0_cov``): every cost, gradient and draw reads it.

lqrsp poses its wide-area problem as an H2 norm with disturbances entering through
B1, J(K) = trace(B1' P_K B1); with ``x0_cov = B1 B1'`` the toolkit's cost is that
problem's. The checks compare with closed-form Lyapunov values computed here by
scipy, independent of the code under test.
"""

import numpy as np
import pytest
import scipy.linalg

from codesign import Instance, InstanceError, paper_instance
from codesign.evaluation import (impulse_responses, response_cost, simulate, static_gain_cost,
                                 static_gain_cost_and_grad, validation_set)
from codesign.controllers import StaticGain


def _h2_instance(horizon=60, rank=2, seed=0, n=6):
    base = paper_instance(1, n=n, a_norm=1.05)
    B1 = np.random.default_rng(seed).standard_normal((n, rank))
    inst = Instance.from_matrices(base.A, base.B, comm_adj=base.comm_adj, horizon=horizon, x0_cov=B1 @ B1.T)
    return inst, B1


def _damped_gain(inst):
    """A stabilizing non-LQR gain: the LQR gain's diagonal plus a little of its off-diagonal part."""
    K = inst.K_lqr
    gain = np.diag(np.diag(K)) + 0.5 * (K - np.diag(np.diag(K)))
    assert np.max(np.abs(np.linalg.eigvals(inst.A + inst.B @ gain))) < 0.95
    return gain


def test_lqr_costs_one_and_the_normalizer_is_the_h2_norm():
    inst, B1 = _h2_instance()
    assert inst.trace_P == pytest.approx(np.trace(B1.T @ inst.P @ B1), rel=1e-12)
    assert static_gain_cost(inst, inst.K_lqr) == pytest.approx(1.0, abs=1e-10)


def test_finite_horizon_cost_matches_the_closed_form_lyapunov_value():
    inst, B1 = _h2_instance(horizon=7)
    K = _damped_gain(inst)
    Acl = inst.A + inst.B @ K
    PK = scipy.linalg.solve_discrete_lyapunov(Acl.T, inst.Q + K.T @ inst.R @ K)
    # P_t - P_K = Acl'^(T-t) (P - P_K) Acl^(T-t): the horizon-T cost in closed form.
    AT = np.linalg.matrix_power(Acl, inst.horizon)
    expected = np.trace(B1.T @ (PK + AT.T @ (inst.P - PK) @ AT) @ B1) / np.trace(B1.T @ inst.P @ B1)
    assert static_gain_cost(inst, K) == pytest.approx(expected, rel=1e-10)
    # The identity covariance gives a different number: Σ₀ is really read.
    plain = Instance.from_matrices(inst.A, inst.B, comm_adj=inst.comm_adj, horizon=7)
    assert abs(static_gain_cost(plain, K) - expected) > 1e-3


def test_gradient_matches_finite_differences():
    inst, _ = _h2_instance(horizon=20)
    K = _damped_gain(inst)
    _, grad = static_gain_cost_and_grad(inst, K)
    step = 1e-6
    for i, j in [(0, 0), (1, 3), (4, 2)]:
        E = np.zeros_like(K)
        E[i, j] = step
        fd = (static_gain_cost(inst, K + E) - static_gain_cost(inst, K - E)) / (2 * step)
        assert grad[i, j] == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_infinite_horizon_point_is_the_h2_norm():
    from baselines._sparse import infinite_horizon_point
    from baselines.stabilizing import lyapunov_cost_and_grad

    inst, B1 = _h2_instance()
    K = _damped_gain(inst)
    Acl = inst.A + inst.B @ K
    PK = scipy.linalg.solve_discrete_lyapunov(Acl.T, inst.Q + K.T @ inst.R @ K)
    h2 = np.trace(B1.T @ PK @ B1)
    point = infinite_horizon_point(inst, K)
    assert point.J == pytest.approx(h2, rel=1e-9)
    cost, grad = lyapunov_cost_and_grad(inst, K)
    assert cost == pytest.approx(h2 / inst.trace_P, rel=1e-9)
    assert np.allclose(grad, point.grad / inst.trace_P, rtol=1e-6, atol=1e-10)


def test_response_maps_and_draws_agree_with_the_exact_cost():
    inst, B1 = _h2_instance(horizon=30)
    K = _damped_gain(inst)
    exact = static_gain_cost(inst, K)
    controller = StaticGain(K)
    assert response_cost(inst, *impulse_responses(inst, controller)) == pytest.approx(exact, rel=1e-10)
    x0 = validation_set(inst, 4000)
    # The draws lie in the range of B1 and have covariance B1 B1'.
    residual = x0 - x0 @ B1 @ np.linalg.pinv(B1)
    assert np.abs(residual).max() < 1e-10
    assert np.allclose(x0.T @ x0 / x0.shape[0], B1 @ B1.T, atol=0.15 * np.abs(B1 @ B1.T).max())
    rollout = simulate(inst, controller, x0, control_variates=True)
    assert abs(rollout.plain_cost - exact) < 4 * rollout.plain_stderr
    assert abs(rollout.cost - exact) < 1e-8  # the control variates are exact for a linear controller


def test_default_covariance_keeps_keys_and_draws():
    base = paper_instance(1, n=6, a_norm=1.05)
    plain = Instance.from_matrices(base.A, base.B)
    same = Instance.from_matrices(base.A, base.B, x0_cov=None)
    weighted = Instance.from_matrices(base.A, base.B, x0_cov=2 * np.eye(6))
    assert plain.key == same.key and plain.key != weighted.key
    assert plain.x0_factor is None and plain.trace_P == np.trace(plain.P)
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    assert np.array_equal(plain.initial_states(rng_a, 5), rng_b.standard_normal((5, 6)))
    assert weighted.trace_P == pytest.approx(2 * np.trace(weighted.P), rel=1e-12)


@pytest.mark.parametrize("cov, message", [
    (np.eye(5), "x0_cov must have shape (6, 6)"),
    (np.diag([1, 1, 1, 1, 1, -1.0]), "positive semidefinite"),
    (np.triu(np.ones((6, 6))), "symmetric"),
    (np.zeros((6, 6)), "must not be zero"),
    (np.full((6, 6), np.nan), "non-finite"),
])
def test_bad_covariances_are_refused_with_one_line(cov, message):
    base = paper_instance(1, n=6, a_norm=1.05)
    with pytest.raises(InstanceError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        Instance.from_matrices(base.A, base.B, x0_cov=cov)
    assert "\n" not in str(info.value)


# -- every method reads it ------------------------------------------------------------------


def test_the_l1_path_scores_under_the_covariance_and_ends_at_the_diagonal_gain():
    from baselines import decentralized, sparse_newton

    inst, _ = _h2_instance()
    path = sparse_newton(inst, gammas=[1e-3, 1e-1])
    usable = [d for d in path if np.isfinite(d.cost)]
    assert usable and usable[-1].links == 0
    for d in usable:
        assert d.cost == pytest.approx(static_gain_cost(inst, d.controller.K), rel=1e-10)
        assert np.max(np.abs(np.linalg.eigvals(inst.A + inst.B @ d.controller.K))) < 1
    assert usable[-1].cost == pytest.approx(decentralized(inst).cost, rel=1e-6)


def test_a_low_rank_covariance_gets_stabilizing_searches_that_say_why():
    # A rank-2 x0_cov on 6 states: the finite-horizon cost's diagonal and delayed minima leave a weakly
    # excited mode unstable (spectral radius 1.04), so the searches minimize the infinite-horizon cost.
    from baselines import decentralized, refit

    inst, _ = _h2_instance()
    for design in (decentralized(inst), refit(inst)):
        assert design.status == "inaccurate" and np.isfinite(design.cost)
        assert design.extras["spectral_radius"] < 1
        assert "x0_cov" in design.message and "infinite-horizon" in design.message


def test_sls_solves_the_weighted_qp_even_for_a_singular_covariance():
    from baselines import sls

    inst, B1 = _h2_instance()
    design = sls(inst, graph="complete")
    assert design.status in ("optimal", "inaccurate") and design.cost >= 1 - 1e-6
    # The realized controller's cost under Σ₀, summed here from its responses to x(0) = B1 z.
    phi_x, phi_u = impulse_responses(inst, design.controller)
    T = inst.horizon
    total = sum(np.trace(B1.T @ phi_x[t].T @ inst.Q @ phi_x[t] @ B1) + np.trace(B1.T @ phi_u[t].T @ inst.R @ phi_u[t] @ B1)
                for t in range(T)) + np.trace(B1.T @ phi_x[T].T @ inst.P @ phi_x[T] @ B1)
    assert design.cost == pytest.approx(total / np.trace(B1.T @ inst.P @ B1), rel=1e-9)
    # The bound on delayed information is below the diagonal gain, which reads only its own node.
    from baselines import decentralized
    assert design.cost < decentralized(inst).cost


def test_the_sdp_refuses_a_singular_covariance_in_one_line_and_reads_a_definite_one():
    from baselines import sparse_sdp

    inst, B1 = _h2_instance()
    with pytest.raises(ValueError, match="positive definite x0_cov") as info:
        sparse_sdp(inst, gammas=[0.1])
    assert "\n" not in str(info.value)
    definite = Instance.from_matrices(inst.A, inst.B, comm_adj=inst.comm_adj, horizon=inst.horizon,
                                      x0_cov=B1 @ B1.T + np.eye(inst.n))
    designs = [d for d in sparse_sdp(definite, gammas=[0.1]) if np.isfinite(d.cost)]
    assert designs
    for d in designs:
        assert d.cost == pytest.approx(static_gain_cost(definite, d.controller.K), rel=1e-10)


def test_learned_training_and_selection_draws_come_from_the_covariance():
    from codesign.learned.trainer import selection_set

    inst, B1 = _h2_instance()
    x0 = selection_set(inst, 50)
    assert x0.shape == (50, inst.n)
    assert np.abs(x0 - x0 @ B1 @ np.linalg.pinv(B1)).max() < 1e-10


def test_a_matrices_file_carries_the_covariance(tmp_path):
    from compare.run.families import matrices

    inst, B1 = _h2_instance()
    np.savez(tmp_path / "h2.npz", A=inst.A, B=inst.B, comm_adj=inst.comm_adj, horizon=np.int64(60), x0_cov=B1 @ B1.T)
    np.savez(tmp_path / "plain.npz", A=inst.A, B=inst.B, comm_adj=inst.comm_adj, horizon=np.int64(60))
    specs = matrices.parse({"family": "matrices", "files": ["h2.npz", "plain.npz"]}, base=tmp_path)
    weighted, plain = (matrices.build(spec) for spec in specs)
    assert np.allclose(weighted.x0_cov, B1 @ B1.T) and plain.x0_cov is None
    assert weighted.trace_P == pytest.approx(inst.trace_P, rel=1e-12)
    np.savez(tmp_path / "bad.npz", A=inst.A, B=inst.B, x0_cov=-np.eye(inst.n))
    from compare.run.parsing import SpecError
    with pytest.raises(SpecError, match="x0_cov must be positive semidefinite"):
        matrices.parse({"family": "matrices", "files": ["bad.npz"]}, base=tmp_path)


def test_the_newton_path_reaches_its_diagonal_end_on_a_fine_dt_plant_under_lqrsps_weighting():
    # lqrsp's model at dt = 0.01 under B1 B1' stalled at 23 links with no diagonal end (issue #60); the
    # stand-in (a -5e-6 /s rotational mode, ZOH at dt = 0.01) with disturbances where the inputs enter.
    from baselines import sparse_newton
    from test_stabilizing_search import slow_mode_system

    plant = slow_mode_system(0.01)
    inst = Instance.from_matrices(plant.A, plant.B, x0_cov=plant.B @ plant.B.T, horizon=plant.horizon,
                                  state_nodes=plant.state_nodes, input_nodes=plant.input_nodes)
    path = sparse_newton(inst, gammas=[1e-3, 1e-1])
    usable = [d for d in path if np.isfinite(d.cost)]
    assert [d.links for d in usable][-1] == 0 and usable[0].links > 0
    for d in usable:
        assert np.max(np.abs(np.linalg.eigvals(inst.A + inst.B @ d.controller.K))) < 1
        assert d.cost == pytest.approx(static_gain_cost(inst, d.controller.K), rel=1e-10)


def test_localized_sls_reads_a_diagonal_covariance_and_refuses_a_coupling_one():
    from baselines import sls, sls_local

    inst, _ = _h2_instance()
    with pytest.raises(ValueError, match="diagonal x0_cov") as info:
        sls_local(inst, locality=10)
    assert "\n" not in str(info.value)
    weights = np.diag(np.linspace(0.5, 2.0, inst.n))
    diagonal = Instance.from_matrices(inst.A, inst.B, comm_adj=inst.comm_adj, horizon=20, x0_cov=weights)
    # Beyond the graph's diameter the localized columns are sls's problem: the same design under Σ₀.
    local, full = sls_local(diagonal, locality=10, graph="complete"), sls(diagonal, graph="complete")
    assert local.cost == pytest.approx(full.cost, rel=1e-6)


def test_the_tilted_proposal_tilts_z_and_its_weights_are_likelihood_ratios():
    from codesign.estimators import TiltedProposal

    inst, B1 = _h2_instance()
    proposal = TiltedProposal.along(np.eye(inst.n) + 0.5, factor=inst.x0_factor)
    x = proposal.draw(inst, 200_000, (7,))
    assert np.abs(x - x @ B1 @ np.linalg.pinv(B1)).max() < 1e-9  # in the range of x0_cov
    w = proposal.weights(x)
    assert w.max() <= 1 / proposal.share + 1e-12
    # E_q[w] = 1 and E_q[w x'Px] = E_p[x'Px] = trace(P Σ₀), to sampling error.
    assert abs(w.mean() - 1) < 5 * w.std() / np.sqrt(w.size)
    q = w * np.einsum("bi,ij,bj->b", x, inst.P, x)
    assert abs(q.mean() - inst.trace_P) < 5 * q.std() / np.sqrt(q.size)
