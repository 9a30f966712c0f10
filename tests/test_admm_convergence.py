"""The ℓ1 ADMM converges or stops at once, saying why (issue 60).

On ``paper_instance(1, n=6, a_norm=1.05)`` the ADMM at a fixed ρ = 100 ran 2,000 iterations per γ
and ended ``diverged`` at γ = 3, 10 and 100, where the proximal Newton path gives one link at
1.363193 (γ = 3) and the diagonal gain, 4.340939, above. Here: γ at or above γ_max is answered by
the diagonal gain without iterating, ρ is balanced and raised on a cycle, and a solve that cannot
converge stops with its reason in the design's message.
"""

from __future__ import annotations

import importlib
import time

import numpy as np
import pytest

from baselines import decentralized, sparse_admm
from baselines._sparse import GainPoint, infinite_horizon_point, l1_path
from baselines.sparse_admm import admm_gamma_max
from codesign.instances import paper_instance
from codesign.status import DIVERGED, FAILED, OPTIMAL, USABLE

admm_module = importlib.import_module("baselines.sparse_admm")

#: sparse_newton's designs on the issue's instance (1 link at γ = 3; the diagonal gain at 10 and 100).
NEWTON_GAMMA_3 = 1.363193


@pytest.fixture(scope="module")
def issue60():
    return paper_instance(1, n=6, a_norm=1.05)


@pytest.fixture(scope="module")
def diagonal(issue60):
    return decentralized(issue60)


def test_gamma_at_or_above_gamma_max_is_the_diagonal_gain_without_iterating(issue60, diagonal):
    top = admm_gamma_max(issue60)
    assert 10 < top < 100  # the issue's γ = 100 is above it, γ = 10 below
    start = time.perf_counter()
    designs = sparse_admm(issue60, gammas=[top, 100.0], diagonal_end=False)
    wall = time.perf_counter() - start
    for design in designs:
        assert design.status == OPTIMAL and design.links == 0
        assert design.cost == pytest.approx(diagonal.cost, rel=1e-8)
        assert design.extras["admm_iterations"] == 0 and design.extras["kstep_iterations"] == 0
        assert design.extras["gamma_max"] == pytest.approx(top, rel=1e-12)
        assert "without iterating" in design.message and "gamma_max" in design.message
    # The diagonal gain's own search is all it costs (before: 2,000 iterations, 163-209 s per γ).
    assert wall < 60


def test_the_issue_gammas_give_usable_designs_like_the_newton_path(issue60, diagonal):
    start = time.perf_counter()
    three, ten, hundred, end = sparse_admm(issue60, gammas=[3, 10, 100])
    wall = time.perf_counter() - start
    assert all(d.status in USABLE for d in (three, ten, hundred, end))
    assert three.links == 1 and three.cost == pytest.approx(NEWTON_GAMMA_3, rel=1e-2)
    assert three.extras["admm_converged"]
    for design in (ten, hundred):
        assert design.links == 0 and design.cost == pytest.approx(diagonal.cost, rel=1e-8)
    # The second reweighting round at γ = 3 cycles at ρ = 100: the cycle was seen and ρ raised.
    assert three.extras["rho_changes"] >= 1 and three.extras["rho_final"] > 100
    assert wall < 180  # 17-32 s on a loaded 2-core machine; before, minutes per γ and no design


def _alternating_kstep(first, second):
    """A K-step that returns two gains in turn whatever it is asked: a period-2 cycle no ρ can break."""
    calls = []

    def kstep(instance, point, U, rho, *, tol, maxiter):
        calls.append(rho)
        return (first if len(calls) % 2 else second), 1, True
    return kstep, calls


def test_a_cycle_raises_rho_and_then_stops_at_once_saying_why(issue60, monkeypatch):
    K = np.array(issue60.K_lqr)
    first, second = infinite_horizon_point(issue60, K), infinite_horizon_point(issue60, 0.9 * K)
    kstep, calls = _alternating_kstep(first, second)
    monkeypatch.setattr(admm_module, "_kstep", kstep)
    W = np.ones((6, 6)) - np.eye(6)
    run = admm_module._admm(issue60, first, K.copy(), np.zeros_like(K), 1e-3 * W, 100.0, rho0=100.0, tol=1e-4,
                            kstep_tol=1e-2, maxiter=1000)
    assert not run.converged and "period-2 cycle" in run.message and "raising rho 3 times" in run.message
    # Each rescue needs a few iterations to see the cycle again: far from the 1,000 allowed.
    assert run.iterations <= 4 * (admm_module._CYCLE_COUNT + 3)
    assert max(calls) >= 100.0 * admm_module._RESCUE_STEP  # ρ was raised before it gave up


def test_a_stall_is_seen_and_stops_the_solve(issue60, monkeypatch):
    """A K-step that cannot move and a G-step stuck at zero: residuals frozen, not converged."""
    K = np.array(issue60.K_lqr)
    point = infinite_horizon_point(issue60, K)
    monkeypatch.setattr(admm_module, "_kstep", lambda instance, p, U, rho, *, tol, maxiter: (p, 0, False))
    monkeypatch.setattr(admm_module, "_shrink", lambda V, threshold: np.zeros_like(V))
    W = np.ones((6, 6)) - np.eye(6)
    run = admm_module._admm(issue60, point, K.copy(), np.zeros_like(K), W, 100.0, rho0=100.0, tol=1e-4,
                            kstep_tol=1e-2, maxiter=1000)
    assert not run.converged and "a stall" in run.message
    assert run.iterations <= (admm_module._MAX_RESCUES + 1) * admm_module._STALL_WINDOW
    assert run.kstep_unsolved == run.iterations  # every K-step reported as stopped above its tolerance


def _path_with(instance, answer):
    """l1_path with one stub weighted solve returning ``answer`` = (G, extras, converged)."""
    G, extras, ok = answer
    start = infinite_horizon_point(instance, np.array(instance.K_lqr))

    def solve(state, gamma, W):
        return state, G, dict(extras), ok

    return l1_path(instance, "sparse_admm", [0.5], solve=solve, start_state=start, base={}, reweight=2,
                   eps_weight=1e-3, polish=False, diagonal_end=False, solver="admm", solver_label="ADMM",
                   converged_key="admm_converged")


def test_a_solver_that_stops_for_a_reason_is_failed_with_it_not_diverged(issue60):
    unstable = 10.0 * np.eye(6)
    (stopped,) = _path_with(issue60, (unstable, {"admm_iterations": 7, "message": "ADMM stopped: a stall"}, False))
    assert stopped.status == FAILED and stopped.message.startswith("ADMM stopped: a stall")
    assert "does not stabilize" in stopped.message and np.isnan(stopped.cost)
    assert stopped.extras["admm_iterations"] == 14  # counts add over the two rounds
    # Without a stated reason a non-stabilizing G is what it was: diverged.
    (plain,) = _path_with(issue60, (unstable, {"admm_iterations": 7}, False))
    assert plain.status == DIVERGED


def test_a_solvers_note_reaches_a_usable_designs_message_and_floats_are_not_added(issue60):
    K = np.array(issue60.K_lqr)
    (design,) = _path_with(issue60, (K, {"admm_iterations": 3, "rho_final": 250.0, "message": "why"}, True))
    assert design.status in USABLE and design.message.startswith("why")
    assert design.extras["admm_iterations"] == 6 and design.extras["rho_final"] == 250.0


def test_the_kstep_reports_a_gain_left_above_its_tolerance(issue60):
    point = infinite_horizon_point(issue60, np.array(issue60.K_lqr))
    U = np.zeros((6, 6))
    done, its, solved = admm_module._kstep(issue60, point, U, 100.0, tol=1e-12, maxiter=2)
    assert its == 2 and not solved and isinstance(done, GainPoint)
    done, its, solved = admm_module._kstep(issue60, done, U, 100.0, tol=1e-4, maxiter=500)
    assert solved and np.linalg.norm(done.grad + 100.0 * (done.K - U)) <= 1e-4
