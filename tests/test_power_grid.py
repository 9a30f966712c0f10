"""The ``power_grid`` family: published grids from ANDES reduced to their classical machines.

The equations on a two-machine case linearized by hand, the shipped data against ANDES
(where ANDES is installed: ``pip install -e .[power]``), the New England system's
electromechanical modes, and every built-in method through ``compare run``.

Imports of the project are inside the tests: the ANDES test also runs in an environment
with ANDES and numpy alone (``python -m pytest tests/test_power_grid.py -k andes``).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

CASES = {"ieee39": 10, "wecc": 29, "npcc": 48}
DATA = Path(__file__).resolve().parents[1] / "compare" / "run" / "families" / "power_cases"


def _load(case: str) -> dict:
    return json.loads((DATA / f"{case}.json").read_text(encoding="utf-8"))


# -- the equations -------------------------------------------------------------------
def test_two_machines_match_the_swing_equations_linearized_by_hand():
    from compare.run.families.power_grid import grounded_swing

    # Two machines, EMFs E behind a lossless reactance X: P_e,0 = E0 E1 / X sin(δ0 - δ1) = -P_e,1.
    # At δ0 - δ1 = 0.3: dP_e,0/dδ0 = -dP_e,0/dδ1 = c, with c = E0 E1 / X cos 0.3, and the same for machine 1.
    E0, E1, X, angle = 1.05, 0.98, 0.4, 0.3
    c = E0 * E1 / X * math.cos(angle)
    K = np.array([[c, -c], [-c, c]])
    M, D = np.array([0.2, 0.5]), np.array([0.02, 0.05])  # equal D/M = 0.1
    Ac, Bc, nodes = grounded_swing(K, M, D, reference=1)
    # States (θ0 - θ1, ω0, ω1): θ̃' = ω0 - ω1, M0 ω0' = -c θ̃ - D0 ω0 + u0, M1 ω1' = c θ̃ - D1 ω1 + u1.
    expected = [[0, 1, -1], [-c / 0.2, -0.1, 0], [c / 0.5, 0, -0.1]]
    np.testing.assert_allclose(Ac, expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(Bc, [[0, 0], [5, 0], [0, 2]], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(nodes, [0, 0, 1])
    # With D/M = β for both: the swing mode λ = -β/2 ± j sqrt(c (1/M0 + 1/M1) - β²/4) and the mean speed λ = -β.
    beta = 0.1
    w = math.sqrt(c * (1 / 0.2 + 1 / 0.5) - beta ** 2 / 4)
    eig = np.sort_complex(np.linalg.eigvals(Ac))
    np.testing.assert_allclose(eig, np.sort_complex([-beta / 2 - 1j * w, -beta / 2 + 1j * w, -beta]), atol=1e-12)
    # Grounding at machine 0 instead gives the same spectrum.
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(grounded_swing(K, M, D, reference=0)[0])), eig,
                               atol=1e-12)


def test_grounding_removes_exactly_the_rotational_zero():
    from compare.run.families.power_grid import _machines, case_data, grounded_swing

    data = case_data("ieee39")
    K, M, D = _machines(data, 2.0)
    N = K.shape[0]
    full = np.block([[np.zeros((N, N)), np.eye(N)], [-K / M[:, None], -np.diag(D / M)]])
    lost = np.linalg.eigvals(full)
    assert np.min(np.abs(lost)) < 1e-8  # the angles turning together
    kept = np.linalg.eigvals(grounded_swing(K, M, D, data["reference"])[0])
    lost = np.delete(lost, np.argmin(np.abs(lost)))
    np.testing.assert_allclose(np.sort_complex(kept), np.sort_complex(lost), atol=1e-9)
    assert np.min(np.abs(kept)) > 0.1


def test_the_instance_is_the_zero_order_hold_of_the_shipped_case():
    from scipy.linalg import expm

    from compare.run.families.power_grid import power_grid_instance

    data = _load("ieee39")
    inst = power_grid_instance("ieee39", damping=1.5, dt=0.05)
    N, ref = 10, data["reference"]
    assert ref == 9 and data["machines"][ref]["bus"] == 39  # G10, the New York equivalent, on the slack bus
    omega_s = 2 * math.pi * 60.0
    M = np.array([m["M"] * m["Sn"] / 100.0 for m in data["machines"]]) / omega_s
    D = 1.5 * np.array([m["Sn"] / 100.0 for m in data["machines"]]) / omega_s
    K = np.array(data["K"])
    # Build the grounded model by hand: states (θ_i - θ_9, ω_i) for i < 9, then ω_9.
    ang, spd = {i: 2 * i for i in range(9)}, {i: 2 * i + 1 for i in range(9)}
    spd[9] = 18
    Ac, Bc = np.zeros((19, 19)), np.zeros((19, N))
    for i in range(N):
        if i < 9:
            Ac[ang[i], spd[i]], Ac[ang[i], spd[9]] = 1.0, -1.0
        for j in range(9):
            Ac[spd[i], ang[j]] = -K[i, j] / M[i]
        Ac[spd[i], spd[i]] = -D[i] / M[i]
        Bc[spd[i], i] = 1.0 / M[i]
    big = np.zeros((19 + N, 19 + N))
    big[:19, :19], big[:19, 19:] = Ac * 0.05, Bc * 0.05
    Phi = expm(big)
    np.testing.assert_allclose(inst.A, Phi[:19, :19], atol=1e-12)
    np.testing.assert_allclose(inst.B, Phi[:19, 19:], atol=1e-12)
    np.testing.assert_array_equal(inst.state_nodes, [i for i in range(N) for _ in range(1 if i == ref else 2)])
    np.testing.assert_array_equal(inst.input_nodes, np.arange(N))
    np.testing.assert_array_equal(inst.R, np.eye(N))
    # Q: the angles' spread about their mean (any absolute angles: only differences count) plus ω' diag(M) ω.
    rng = np.random.default_rng(1)
    theta, omega = rng.standard_normal(N), rng.standard_normal(N)
    x = np.zeros(19)
    for i in range(N):
        if i < 9:
            x[ang[i]] = theta[i] - theta[9]
        x[spd[i]] = omega[i]
    assert abs(x @ inst.Q @ x - (np.sum((theta - theta.mean()) ** 2) + omega @ (M * omega))) < 1e-12
    assert np.array_equal(power_grid_instance("ieee39", cost="identity").Q, np.eye(19))


def test_graphs_plant_complete_given_the_strongest_couplings_connected():
    from codesign import count_links
    from compare.run.families.power_grid import _components, power_grid_instance

    for case, N in CASES.items():
        inst = power_grid_instance(case, neighbours=4)
        assert inst.A.shape == (2 * N - 1, 2 * N - 1) and inst.B.shape == (2 * N - 1, N)
        assert count_links(inst.plant_adj) == (N * (N - 1), N)  # the Kron reduction couples every pair
        comm = inst.comm_adj != 0
        np.fill_diagonal(comm, False)
        assert np.array_equal(comm, comm.T) and comm.sum(axis=1).min() >= 4
        assert _components(comm.astype(float)).max() == 0  # connected (npcc needs one added link)
        K = np.abs(np.array(_load(case)["K"]))
        K = np.maximum(K, K.T)
        np.fill_diagonal(K, 0)
        for i in range(N):  # each machine's strongest coupling is a given link
            assert comm[i, int(np.argmax(K[i]))]


# -- the shipped data ------------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_shipped_case_files_are_consistent(case):
    from compare.run.families.power_cases.generate import CASES as GENERATED
    from compare.run.families.power_cases.generate import dumps

    text = (DATA / f"{case}.json").read_text(encoding="utf-8")
    data = json.loads(text)
    assert dumps(data) == text  # written by the generator, byte for byte
    assert data["source"]["andes"] == "2.0.0" and data["source"]["case_file"] == GENERATED[case][0]
    assert len(data["machines"]) == CASES[case] and data["base_mva"] == 100.0 and data["frequency"] == 60.0
    K = np.array(data["K"])
    assert np.abs(K.sum(axis=1)).max() < 1e-12 * np.abs(K).max()  # rotational symmetry
    for m in data["machines"]:
        assert math.isclose(m["M_system"], m["M"] * m["Sn"] / 100.0, rel_tol=1e-12)
        assert math.isclose(m["D_system"], m["D"] * m["Sn"] / 100.0, rel_tol=1e-12, abs_tol=1e-15)
        assert math.isclose(m["xd1_system"], m["xd1"] * 100.0 / m["Sn"], rel_tol=1e-12)
    buses = [m["bus"] for m in data["machines"]]
    assert buses == sorted(buses)


#: Largest difference allowed between a regenerated case file's float and the shipped one, relative to the
#: largest magnitude of the same field (each machine parameter across machines, K as a matrix, the modes as a
#: vector, each scalar on its own). Why a tolerance at all: another BLAS, thread count or processor sums in
#: another order, so the last one or two digits move (1e-16 to 1e-14 relative between two machines, the
#: worst 3e-15 of max|K| on wecc). Why normwise: K and the modes come from backward-stable linear algebra
#: (the power flow's Newton solves, the eigenvalues of the state matrix), whose error bounds are eps times
#: the condition times the size of the whole field, not of each entry (an angle or an off-diagonal K near
#: zero moves by the same absolute amount as its largest neighbour). Why 1e-9: the power flow stops below
#: its mismatch tolerance 1e-10 (PF_TOL) after 5, 2 and 2 Newton steps, reaching 2e-12 or less from a
#: previous step 40 to 1000 times above 1e-10, so every build takes the same steps and differs only by
#: rounding times condition, far below 1e-9; and 1e-9 is far below any physical meaning (the case data have
#: 3-4 digits) and the bound generate.py itself applies to the state matrix's structure. Input parameters
#: copied from the case file and their base changes (one IEEE product) agree exactly on every machine and
#: so pass any tolerance.
REGENERATED_RTOL = 1e-9
#: Entries of ``source`` that name the environment that wrote the file, not its content.
ENVIRONMENT = ("andes", "kvxopt", "numpy")


def _float_fields(shipped, fresh, path: str, out: dict) -> None:
    """Check the structure exactly (keys, lengths, strings, ints, bools) and collect the floats by field.

    ``out[field] = [(shipped, fresh), ...]`` where the field is the path with list positions dropped
    (``machines.P``, ``K``, ``modes_hz``): the unit a tolerance is taken relative to.
    """
    if isinstance(shipped, dict):
        assert isinstance(fresh, dict) and list(fresh) == list(shipped), f"{path}: keys {list(fresh)}"
        for key, value in shipped.items():
            if path == "source" and key in ENVIRONMENT:
                assert isinstance(fresh[key], str), f"source.{key}"
                continue
            _float_fields(value, fresh[key], f"{path}.{key}" if path else key, out)
    elif isinstance(shipped, list):
        assert isinstance(fresh, list) and len(fresh) == len(shipped), f"{path}: length {len(fresh)} != {len(shipped)}"
        for a, b in zip(shipped, fresh):
            _float_fields(a, b, path, out)
    elif isinstance(shipped, float):
        assert type(fresh) is float, f"{path}: {fresh!r} is not a float"
        out.setdefault(path, []).append((shipped, fresh))
    else:  # str, int, bool, None: exact, type included (json gives 1 and 1.0 different types)
        assert type(fresh) is type(shipped) and fresh == shipped, f"{path}: {fresh!r} != {shipped!r}"


def assert_same_case_data(shipped: dict, fresh: dict, *, rtol: float = REGENERATED_RTOL) -> None:
    """A regenerated case file against the shipped one: structure exactly, floats within ``rtol`` normwise."""
    fields: dict = {}
    _float_fields(shipped, fresh, "", fields)
    for field, pairs in fields.items():
        a, b = np.array(pairs).T
        scale = np.abs(a).max()
        worst = np.abs(b - a).max()
        assert np.all(np.isfinite(b)) and worst <= rtol * scale, (
            f"{field}: largest difference {worst:.3g}, more than {rtol:g} x {scale:.3g} (largest |value|)")


def test_regenerated_case_data_are_compared_by_structure_and_tolerance():
    """The comparison passes the last digits another machine moves and fails what would be a different case."""
    data = _load("ieee39")
    same = json.loads(json.dumps(data))
    same["modes_hz"][0] *= 1 + 4e-16  # the "...805751" against "...805749"
    same["K"][0][1] += 2e-15 * abs(same["K"][0][1])
    same["machines"][3]["angle"] += 1e-15
    same["source"]["numpy"] = "9.9.9"  # another environment writes the same data
    assert_same_case_data(data, same)
    wrong = json.loads(json.dumps(data))
    wrong["modes_hz"][2] *= 1 + 1e-6
    with pytest.raises(AssertionError, match="modes_hz"):
        assert_same_case_data(data, wrong)
    for change in (lambda d: d["machines"][0].update(bus=31), lambda d: d["machines"].pop(),
                   lambda d: d.update(reference=float(d["reference"])), lambda d: d["source"].update(case_file="x"),
                   lambda d: d["machines"][0].update(P=int(1))):
        wrong = json.loads(json.dumps(data))
        change(wrong)
        with pytest.raises(AssertionError):
            assert_same_case_data(data, wrong)


def test_shipped_case_files_are_what_andes_generates(tmp_path):
    pytest.importorskip("andes", reason="ANDES regenerates the case files (pip install -e .[power])")
    from compare.run.families.power_cases.generate import CASES as GENERATED
    from compare.run.families.power_cases.generate import main

    main(["--out", str(tmp_path), *GENERATED])
    for case in GENERATED:
        # Not byte for byte: the shipped files were written on another machine, whose BLAS and processor
        # round the last digits differently (tests/test_no_byte_compare.py keeps it that way).
        assert_same_case_data(_load(case), json.loads((tmp_path / f"{case}.json").read_text(encoding="utf-8")))


def test_package_data_ships_the_case_files():
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((DATA.parents[3] / "pyproject.toml").read_text())
    globs = project["tool"]["setuptools"]["package-data"]["compare.run"]
    assert "families/power_cases/*.json" in globs
    assert sorted(p.stem for p in DATA.glob("*.json")) == sorted(CASES)
    assert any(d.startswith("andes") for d in project["project"]["optional-dependencies"]["power"])


# -- modes -----------------------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_the_familys_equations_reproduce_the_shipped_modes(case):
    """At the case's own damping, the grounded model has ANDES's electromechanical frequencies."""
    from compare.run.families.power_grid import _machines, case_data, grounded_swing

    data = case_data(case)
    eig = np.linalg.eigvals(grounded_swing(*_machines(data, "case"), data["reference"])[0])
    freqs = np.sort(eig.imag[eig.imag > 1e-6]) / (2 * math.pi)
    np.testing.assert_allclose(freqs, data["modes_hz"], rtol=1e-9)
    assert freqs.size == CASES[case] - 1


def test_new_england_modes_match_the_published_picture():
    """The 39-bus system's nine modes, classical machines and no damping (ANDES 2.0.0).

    Published small-signal studies of the New England system put its electromechanical
    modes at about 0.2-1.6 Hz, the lowest an inter-area mode near 0.6 Hz in which the New
    England machines swing together against the New York equivalent (G10, bus 39). The
    exact values are those ANDES computes (the shipped ``modes_hz``), pinned here.
    """
    from compare.run.families.power_grid import _machines, case_data

    data = case_data("ieee39")
    K, M, _ = _machines(data, 0.0)
    w2, V = np.linalg.eig(K / M[:, None])
    order = np.argsort(w2.real)
    freqs = np.sqrt(np.abs(w2.real[order[1:]])) / (2 * math.pi)
    np.testing.assert_allclose(freqs, [0.61473, 0.90506, 1.05886, 1.17900, 1.28290, 1.40215, 1.45420, 1.52652,
                                       1.55275], atol=1e-5)
    assert 0.2 < freqs.min() and freqs.max() < 1.6
    assert 0.55 < freqs[0] < 0.70
    shape = V[:, order[1]].real
    bus39 = [m["bus"] for m in data["machines"]].index(39)
    others = np.delete(shape, bus39)
    assert np.all(np.sign(others) == np.sign(others[0])) and np.sign(shape[bus39]) == -np.sign(others[0])


def test_open_loop_spectral_radii_at_the_defaults():
    from compare.run.families.power_grid import power_grid_instance

    radii = {case: np.max(np.abs(np.linalg.eigvals(power_grid_instance(case).A))) for case in CASES}
    np.testing.assert_allclose([radii[c] for c in CASES], [0.98951, 0.99035, 0.99982], atol=1e-5)
    undamped = power_grid_instance("ieee39", damping="case")  # D = 0: the mean speed does not decay
    assert abs(np.max(np.abs(np.linalg.eigvals(undamped.A))) - 1.0) < 1e-12


# -- specs and every method ------------------------------------------------------------
@pytest.mark.parametrize("table, message", [
    ('case = "ieee118"', "instances.case: unknown case 'ieee118' (known: ieee39, wecc, npcc)"),
    ('damping = "none"', 'instances.damping: a number (p.u., machine base) or "case", got \'none\''),
    ("damping = -1.0", "instances.damping: must be >= 0, got -1.0"),
    ('input = "excitation"', "instances.input: must be one of power, got 'excitation'"),
    ('cost = "energy"', "instances.cost: must be one of coherency, identity, got 'energy'"),
    ("neighbours = 10", "instances.neighbours: must be between 1 and 9 (case ieee39), got 10"),
    ("dt = 0.0", "instances.dt: must be positive, got 0.0"),
    ("seeds = 2", ("instances.seeds: unknown key (allowed: case, cost, damping, dt, family, horizon, input, "
                   "neighbours, r)")),
])
def test_bad_power_grid_keys_are_named(table, message):
    from compare import SpecError, parse_spec

    with pytest.raises(SpecError, match=re.escape(message)):
        parse_spec(f'name = "p"\n[instances]\nfamily = "power_grid"\n{table}\n[[methods]]\nmethod = "lqr"\n')


def test_specs_expand_per_case_and_refuse_a_changed_data_file():
    from compare import parse_spec
    from compare.run.families import get_family

    spec = parse_spec('name = "p"\n[instances]\nfamily = "power_grid"\ncase = ["ieee39", "wecc"]\n'
                      'damping = "case"\n[[methods]]\nmethod = "lqr"\nwhere = { case = ["wecc"] }\n')
    expanded = spec.instances.expand()
    assert [(s["case"], s["n"], s["damping"]) for s in expanded] == [("ieee39", 10, "case"), ("wecc", 29, "case")]
    assert [r.instance["case"] for r in spec.runs()] == ["wecc"]
    family = get_family("power_grid")
    assert family.states(expanded[0]) == 19
    with pytest.raises(ValueError, match="data file changed"):
        family.build(dict(expanded[0], sha256="0" * 16))


def test_every_method_runs_on_the_new_england_system(tmp_path):
    from click.testing import CliRunner

    from codesign.status import USABLE
    from compare.cli import main
    from compare.run.store import Store

    (tmp_path / "p.toml").write_text("""name = "p"
[instances]
family = "power_grid"
case = ["ieee39"]
horizon = 15
[[methods]]
method = "lqr"
[[methods]]
method = "decentralized"
[[methods]]
method = "sparse_admm"
grid = { gammas = [[1e-2]] }
[[methods]]
method = "sparse_delayed"
grid = { gammas = [[1e-2]] }
[[methods]]
method = "sls"
[[methods]]
method = "grnn"
params = { steps = 10, ensemble = 1, stability_steps = 0 }
""")
    result = CliRunner().invoke(main, ["run", str(tmp_path / "p.toml"), "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code == 0, result.output
    with Store(tmp_path / "out" / "results.sqlite") as store:
        records = store.records()
    assert {r.method for r in records} == {"lqr", "decentralized", "sparse_admm", "sparse_delayed", "sls", "grnn"}
    assert not [(r.method, r.status, r.message) for r in records if r.status not in USABLE]
    cost = {r.method: r.cost for r in records}
    links = {r.method: r.links for r in records}
    assert abs(cost["lqr"] - 1.0) < 1e-9 and links["lqr"] == 90
    assert links["decentralized"] == 0
    # Dörfler et al.'s observation on this system: local feedback comes close to the centralized optimum.
    assert cost["decentralized"] < 1.1
