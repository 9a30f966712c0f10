"""The field's benchmark systems: the chain, the swing-equation grid and the vehicle string.

Each family against its defining equations on a small hand-computed case, against a
property of the system, and through ``compare run`` with every built-in method.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

from codesign import count_links
from codesign.status import USABLE
from compare import SpecError, parse_spec
from compare.cli import main
from compare.run.families.chain import actuated_nodes, chain_instance
from compare.run.families.platoon import platoon_instance
from compare.run.families.swing_grid import mesh_edges, swing_grid_instance, swing_matrix


# -- the chain -----------------------------------------------------------------------
def test_chain_matches_its_equations_on_four_nodes():
    inst = chain_instance(4, rho=1.1, alpha=0.25, actuation=0.5)
    expected = 1.1 * np.array([[0.75, 0.25, 0, 0], [0.25, 0.5, 0.25, 0], [0, 0.25, 0.5, 0.25], [0, 0, 0.25, 0.75]])
    np.testing.assert_allclose(inst.A, expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(inst.B, np.eye(4)[:, [0, 2]])
    np.testing.assert_array_equal(inst.input_nodes, [0, 2])
    np.testing.assert_array_equal(inst.Q, np.eye(4))
    np.testing.assert_array_equal(inst.R, np.eye(2))
    assert count_links(inst.comm_adj) == (6, 4) and count_links(inst.plant_adj) == (6, 4)


def test_chain_rows_and_columns_sum_to_rho_its_spectral_radius():
    for n, rho, alpha in ((7, 1.0, 0.2), (12, 1.05, 0.4), (5, 0.9, 0.0)):
        A = chain_instance(n, rho=rho, alpha=alpha).A
        np.testing.assert_allclose(A.sum(axis=1), rho, atol=1e-14)
        np.testing.assert_allclose(A.sum(axis=0), rho, atol=1e-14)
        assert abs(np.max(np.abs(np.linalg.eigvals(A))) - rho) < 1e-12


@pytest.mark.parametrize("n, density, nodes", [(4, 1.0, [0, 1, 2, 3]), (6, 1 / 3, [0, 3]), (5, 0.5, [0, 2, 4]),
                                               (10, 0.25, [0, 4, 8])])
def test_actuators_sit_where_the_sls_toolboxes_put_them(n, density, nodes):
    np.testing.assert_array_equal(actuated_nodes(n, density), nodes)


# -- the swing-equation grid -----------------------------------------------------------
def test_swing_matrix_matches_the_euler_blocks_on_two_buses():
    k = np.array([[0.0, 0.8], [0.8, 0.0]])
    A = swing_matrix(k, inv_inertia=np.array([1.0, 2.0]), damping=np.array([1.0, 1.5]), dt=0.2)
    expected = [[1, 0.2, 0, 0], [-0.16, 0.8, 0.16, 0], [0, 0, 1, 0.2], [0.32, 0, -0.32, 0.4]]
    np.testing.assert_allclose(A, expected, rtol=0, atol=1e-15)


def test_swing_grid_rigid_mode_and_undamped_oscillations():
    inst = swing_grid_instance(4, seed=3)
    N = 16
    rigid = np.tile([1.0, 0.0], N)  # all phases moving together: an equilibrium
    np.testing.assert_allclose(inst.A @ rigid, rigid, atol=1e-14)
    # Without damping the continuous-time modes oscillate: Ac = (A - I) / dt has eigenvalues on the
    # imaginary axis (the weighted Laplacian M^-1 L is similar to a PSD matrix).
    theta, omega = np.arange(0, 2 * N, 2), np.arange(1, 2 * N, 2)
    k = np.zeros((N, N))
    for i, j in mesh_edges(4):
        k[i, j] = k[j, i] = 0.7 + 0.01 * (i + j)
    Ac = (swing_matrix(k, inv_inertia=np.linspace(0.1, 2.0, N), damping=np.zeros(N), dt=0.2) - np.eye(2 * N)) / 0.2
    assert np.max(np.abs(np.linalg.eigvals(Ac).real)) < 1e-6  # the rigid mode is a 2x2 Jordan block
    # Drawn parameters lie in the example's ranges: 1 - A_ww = dt m^-1 d in [0, 0.6]; couplings on kept mesh edges.
    assert np.all((1 - inst.A[omega, omega] >= 0) & (1 - inst.A[omega, omega] <= 0.2 * 2 * 1.5 + 1e-12))
    coupled = inst.A[np.ix_(omega, theta)] != 0
    np.fill_diagonal(coupled, False)
    mesh = np.zeros((N, N), dtype=bool)
    for i, j in mesh_edges(4):
        mesh[i, j] = mesh[j, i] = True
    assert not np.any(coupled & ~mesh)
    assert np.array_equal(inst.comm_adj != 0, (inst.comm_adj != 0).T)


def test_swing_grid_reconnects_isolated_buses_and_draws_per_seed():
    sparse = swing_grid_instance(5, seed=0, keep=0.05)
    adj = sparse.comm_adj != 0
    np.fill_diagonal(adj, False)
    assert adj.any(axis=1).all()  # no bus left alone
    assert swing_grid_instance(3, seed=1).A.tolist() != swing_grid_instance(3, seed=2).A.tolist()
    np.testing.assert_array_equal(swing_grid_instance(3, seed=1).A, swing_grid_instance(3, seed=1).A)
    half = swing_grid_instance(3, seed=1, actuation=0.5)
    np.testing.assert_array_equal(half.input_nodes, [0, 2, 4, 6, 8])
    assert half.B.shape == (18, 5) and np.all(half.B[2 * half.input_nodes + 1, np.arange(5)] == 1)


# -- the vehicle string --------------------------------------------------------------
def test_platoon_matches_the_double_integrator_and_spacing_cost_on_two_vehicles():
    inst = platoon_instance(2, dt=0.5, r=2.0)
    np.testing.assert_allclose(inst.A, [[1, 0, 0.5, 0], [0, 1, 0, 0.5], [0, 0, 1, 0], [0, 0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(inst.B, [[0.125, 0], [0, 0.125], [0.5, 0], [0, 0.5]], atol=1e-15)
    np.testing.assert_allclose(inst.Q, [[2, -1, 0, 0], [-1, 2, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    np.testing.assert_allclose(inst.R, 2 * np.eye(2))


def test_platoon_is_the_exact_zero_order_hold_and_charges_spacing_errors():
    from scipy.signal import cont2discrete

    n, dt = 5, 0.3
    inst = platoon_instance(n, dt=dt)
    Ac = np.block([[np.zeros((n, n)), np.eye(n)], [np.zeros((n, n)), np.zeros((n, n))]])
    Bc = np.vstack([np.zeros((n, n)), np.eye(n)])
    A, B, *_ = cont2discrete((Ac, Bc, np.eye(2 * n), np.zeros((2 * n, n))), dt, method="zoh")
    np.testing.assert_allclose(inst.A, A, atol=1e-14)
    np.testing.assert_allclose(inst.B, B, atol=1e-14)
    p, v = np.random.default_rng(0).standard_normal((2, n))
    gaps = np.diff(np.concatenate([[0.0], p, [0.0]]))  # fictitious leader and follower at their places
    x = np.concatenate([p, v])
    assert abs(x @ inst.Q @ x - (np.sum(gaps ** 2) + np.sum(v ** 2))) < 1e-12
    assert count_links(inst.plant_adj) == (0, n)  # no coupling in the dynamics
    assert count_links(inst.comm_adj) == (2 * (n - 1), n)


# -- specs and every method ------------------------------------------------------------
@pytest.mark.parametrize("table, message", [
    ('family = "chain"\nactuation = 0.0', "instances.actuation: an actuation density must be in (0, 1], got 0.0"),
    ('family = "chain"\nalpha = 0.7', "instances.alpha: must be in [0, 0.5], got 0.7"),
    ('family = "swing_grid"\ngrid = [1]', "instances.grid: a mesh needs g >= 2, got [1]"),
    ('family = "swing_grid"\nkeep = 1.5', "instances.keep: a probability in (0, 1], got 1.5"),
    ('family = "platoon"\nr = -1.0', "instances.r: must be positive, got -1.0"),
    ('family = "platoon"\nseeds = 2', "instances.seeds: unknown key (allowed: dt, family, horizon, n, r)"),
])
def test_bad_family_keys_are_named(table, message):
    with pytest.raises(SpecError, match=re.escape(message)):
        parse_spec(f'name = "b"\n[instances]\n{table}\n[[methods]]\nmethod = "lqr"\n')


SMALL = {"steps": 10, "ensemble": 1, "stability_steps": 0}
EVERY_METHOD = """
[[methods]]
method = "lqr"
[[methods]]
method = "autonomous"
[[methods]]
method = "decentralized"
[[methods]]
method = "truncated_lqr"
grid = { links = [[2, 6]] }
[[methods]]
method = "sparse_admm"
grid = { gammas = [[1e-3, 1e-1]] }
[[methods]]
method = "sparse_sdp"
grid = { gammas = [[1e-3, 1e-1]] }
[[methods]]
method = "sparse_delayed"
grid = { gammas = [[1e-3, 1e-1]] }
[[methods]]
method = "sls"
[[methods]]
method = "grnn"
params = { steps = 10, ensemble = 1, stability_steps = 0 }
[[methods]]
method = "grnn_dense"
params = { steps = 10, ensemble = 1, stability_steps = 0 }
[[methods]]
method = "grnn_fixed"
params = { steps = 10, ensemble = 1, stability_steps = 0 }
[[methods]]
method = "grnn_sparse"
params = { steps = 10, ensemble = 1, stability_steps = 0, beta = 0.1 }
[[methods]]
method = "gcnn"
params = { steps = 10, ensemble = 1, stability_steps = 0 }
"""


@pytest.mark.parametrize("instances", [
    'family = "chain"\nn = [6]\nactuation = 0.5\nrho = 1.05\nhorizon = 10',
    'family = "swing_grid"\ngrid = [2]\nseeds = 1\nactuation = 0.5\nhorizon = 10',
    'family = "platoon"\nn = [3]\nhorizon = 10',
])
def test_every_method_runs_on_each_benchmark_family(tmp_path, instances):
    (tmp_path / "b.toml").write_text(f'name = "b"\n[instances]\n{instances}\n{EVERY_METHOD}')
    result = CliRunner().invoke(main, ["run", str(tmp_path / "b.toml"), "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code == 0, result.output
    from compare.run.store import Store

    with Store(tmp_path / "out" / "results.sqlite") as store:
        records = store.records()
    assert {r.method for r in records} >= {"lqr", "sls", "grnn_sparse", "gcnn", "sparse_admm"}
    # Every built-in method handles unactuated nodes, two-state nodes and a cost-coupled plant.
    bad = [(r.method, r.status, r.message) for r in records if r.status not in USABLE]
    assert not bad
    (lqr,) = [r for r in records if r.method == "lqr"]
    assert abs(lqr.cost - 1.0) < 1e-9
    actuated = {"chain": 3, "swing_grid": 2, "platoon": 3}[records[0].instance.spec["family"]]
    nodes = {"chain": 6, "swing_grid": 4, "platoon": 3}[records[0].instance.spec["family"]]
    assert lqr.links == actuated * (nodes - 1)  # links are counted between nodes, from actuated ones only


def test_the_cli_lists_every_family_with_its_fields():
    result = CliRunner().invoke(main, ["families"])
    assert result.exit_code == 0, result.output
    for name in ("paper", "matrices", "mass_spring", "random_network", "chain", "swing_grid", "platoon"):
        assert f"\n{name}: " in "\n" + result.output
    assert "fields: actuation, alpha, horizon, n, rho" in result.output
