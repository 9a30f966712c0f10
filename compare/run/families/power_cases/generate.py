"""Write the ``power_grid`` family's case files from ANDES (the only module of the project that imports it).

Run ``python -m compare.run.families.power_cases.generate [--out DIR] [CASE ...]`` in an
environment with ANDES (``pip install -e .[power]``; the shipped files were written
with ANDES 2.0.0). For each case it

1. loads the ANDES case file and keeps its network only: buses, lines and
   transformers, shunts, areas, loads (PQ) and the power-flow generators (PV, Slack);
   governors, exciters, stabilizers, frequency measurements and faults are dropped;
2. puts one classical machine (ANDES ``GENCLS``: constant EMF behind the transient
   reactance x'd) on every synchronous machine of the case (``GENCLS`` kept as it
   is, each ``GENROU`` replaced by a ``GENCLS`` with its own Sn, Vn, fn, M = 2H, D, ra,
   xl and x'd);
3. solves the power flow (Newton, tolerance 1e-10) and runs ANDES's small-signal
   analysis (``EIG``), which linearizes the machines and the network, loads turned
   into constant impedances at their power-flow voltage (ANDES's defaults
   ``pq2z = 1``, ``p2z = q2z = 1``), and eliminates the network;
4. reads from the state matrix the synchronizing coefficients
   K_ij = dP_e,i / dδ_j (p.u. on the system base per rad): ANDES's rows are
   δ_i' = ω_b (ω_i − 1) and M_i ω_i' = P_m,i − P_e,i − D_i (ω_i − 1), so
   K = −M · A[ω, δ]; it checks that A is exactly that (δ rows ω_b, ω rows −K/M and
   −D/M), that K's rows sum to zero (the rotational symmetry), and that K equals the
   derivative of the classical model's Kron-reduced network
   P_e,i = Σ_j E_i E_j (G_ij cos δ_ij + B_ij sin δ_ij) computed here from ANDES's
   admittance matrix (to 1e-5 relative: the power flow's tolerance);
5. writes ``<case>.json`` next to this file: the source (ANDES version, case file,
   models kept and dropped, settings), every machine's parameters on its own base
   and on the system base, its power-flow operating point, K, the reference machine
   (the one on the slack bus) and ANDES's electromechanical mode frequencies at
   the case's own damping. No timestamps: in the same environment a rerun writes
   the same bytes (``tests/test_power_grid.py`` checks it where ANDES is installed).

To add a case, add an entry to :data:`CASES` (any ANDES case whose synchronous
machines are ``GENCLS`` or ``GENROU``), run this script and add the name to
``compare.run.families.power_grid.CASES``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

#: name -> ANDES case file (relative to ANDES's ``cases`` folder) and a title.
CASES = {
    "ieee39": ("ieee39/ieee39_full.xlsx", "IEEE 39-bus New England system (10 machines)"),
    "wecc": ("wecc/wecc_gencls.xlsx", "WECC 179-bus system (29 classical machines)"),
    "npcc": ("npcc/npcc.xlsx", "NPCC 140-bus system (48 machines)"),
}
#: ANDES models that make up the network and the power flow; kept as they are.
NETWORK = ("Bus", "PQ", "PV", "Slack", "Shunt", "Line", "Area")
#: Synchronous-machine models turned into classical machines.
MACHINES = ("GENCLS", "GENROU")
#: The GENCLS parameters copied from each machine (ANDES input values, on the machine's base).
PARAMS = ("idx", "u", "name", "bus", "gen", "Sn", "Vn", "fn", "D", "M", "ra", "xl", "xd1")
#: Newton power-flow tolerance (ANDES's default is 1e-6).
PF_TOL = 1e-10
FORMAT = 1
HERE = Path(__file__).resolve().parent


def _plain(value):
    """Numpy scalars to Python ones (ints stay ints), for JSON."""
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _system(case_file: str):
    """The case's network with one GENCLS per synchronous machine, set up; and what was kept and dropped."""
    import andes

    source = andes.load(andes.get_case(case_file), setup=False, no_output=True, default_config=True)
    present = {name: model.n for name, model in source.models.items() if model.n > 0}
    unknown = [name for name in present if source.models[name].group == "SynGen" and name not in MACHINES]
    if unknown:
        raise SystemExit(f"{case_file}: synchronous machines of models {unknown} (only {MACHINES} are converted)")
    system = andes.System(default_config=True, no_output=True)
    system.PFlow.config.tol = PF_TOL
    for name in NETWORK:
        if present.get(name):
            for _, row in source.models[name].as_df(vin=True).iterrows():
                system.add(name, {k: _plain(v) for k, v in row.items() if k != "uid"})
    rows = []
    for name in MACHINES:
        if present.get(name):
            for _, row in source.models[name].as_df(vin=True).iterrows():
                if row["u"] != 1:
                    raise SystemExit(f"{case_file}: machine {row['idx']} is out of service (u = {row['u']})")
                rows.append((name, {k: _plain(row[k]) for k in PARAMS}))
    rows.sort(key=lambda item: (int(item[1]["bus"]), str(item[1]["idx"])))  # machines ordered by bus
    for _, params in rows:
        system.add("GENCLS", params)
    system.setup()
    kept = {name: present[name] for name in NETWORK if present.get(name)}
    dropped = {name: count for name, count in present.items() if name not in NETWORK and name not in MACHINES}
    return system, [name for name, _ in rows], kept, dropped


def _kron_coupling(system) -> np.ndarray:
    """dP_e/dδ of the classical machines from the network: internal nodes behind ra + j x'd, loads as impedances."""
    gens = system.GENCLS
    nb, n = system.Bus.n, gens.n
    ybus = system.Line.build_ybus() if hasattr(system.Line, "build_ybus") else system.Line.build_y()
    Y = np.zeros((nb, nb), dtype=complex)
    for i, j, y in zip(ybus.I, ybus.J, ybus.V):
        Y[i, j] += y
    where = {bus: k for k, bus in enumerate(system.Bus.idx.v)}
    v = system.Bus.v.v * np.exp(1j * system.Bus.a.v)
    for k in range(system.Shunt.n):
        b = where[system.Shunt.bus.v[k]]
        Y[b, b] += system.Shunt.u.v[k] * (system.Shunt.g.v[k] + 1j * system.Shunt.b.v[k])
    for k in range(system.PQ.n):
        b = where[system.PQ.bus.v[k]]
        Y[b, b] += system.PQ.u.v[k] * (system.PQ.p0.v[k] - 1j * system.PQ.q0.v[k]) / abs(v[b]) ** 2
    buses = np.array([where[b] for b in gens.bus.v])
    z = gens.ra.v + 1j * gens.xd1.v
    E = v[buses] + z * np.conj((gens.Pe.v + 1j * gens.Qe.v) / v[buses])
    full = np.zeros((n + nb, n + nb), dtype=complex)
    full[n:, n:] = Y
    for k in range(n):
        y, b = 1.0 / z[k], n + buses[k]
        full[k, k] += y
        full[b, b] += y
        full[k, b] -= y
        full[b, k] -= y
    reduced = full[:n, :n] - full[:n, n:] @ np.linalg.solve(full[n:, n:], full[n:, :n])
    G, B = reduced.real, reduced.imag
    magnitude, angle = np.abs(E), np.angle(E)
    diff = angle[:, None] - angle[None, :]
    K = -np.outer(magnitude, magnitude) * (B * np.cos(diff) - G * np.sin(diff))
    np.fill_diagonal(K, 0.0)
    np.fill_diagonal(K, -K.sum(axis=1))
    return K, magnitude


def case_data(name: str) -> dict:
    """Everything a case file holds, computed with ANDES."""
    import andes
    import kvxopt

    case_file, title = CASES[name]
    system, models, kept, dropped = _system(case_file)
    if not system.PFlow.run() or not system.PFlow.converged:
        raise SystemExit(f"{case_file}: the power flow did not converge")
    system.EIG.run()
    A = np.array(system.EIG.As, dtype=float)
    gens = system.GENCLS
    n = gens.n
    delta, omega = np.asarray(gens.delta.a), np.asarray(gens.omega.a)
    if sorted(np.concatenate([delta, omega]).tolist()) != list(range(A.shape[0])):
        raise SystemExit(f"{case_file}: the state matrix has states other than the machines' angles and speeds")
    M, D = np.asarray(gens.M.v, dtype=float), np.asarray(gens.D.v, dtype=float)  # on the system base
    omega_b = 2 * math.pi * np.asarray(gens.fn.v, dtype=float)
    K = -M[:, None] * A[np.ix_(omega, delta)]
    scale = np.abs(K).max()
    checks = {
        "delta rows": np.abs(A[np.ix_(delta, omega)] - np.diag(omega_b)).max() / omega_b.max(),
        "delta-delta block": np.abs(A[np.ix_(delta, delta)]).max() / scale,
        "omega-omega block": np.abs(A[np.ix_(omega, omega)] + np.diag(D / M)).max() / max(1.0, np.abs(D / M).max()),
        "row sums of K": np.abs(K.sum(axis=1)).max() / scale,
    }
    kron, emf = _kron_coupling(system)
    checks["K against the Kron-reduced network"] = np.abs(K - kron).max() / scale
    for label, value in checks.items():
        limit = 1e-5 if label.startswith("K against") else 1e-9
        if not value < limit:
            raise SystemExit(f"{case_file}: {label}: relative deviation {value:.3g} (limit {limit:g})")
    slack_buses = set(system.Slack.bus.v)
    reference = [k for k in range(n) if gens.bus.v[k] in slack_buses]
    if len(reference) != 1:
        raise SystemExit(f"{case_file}: {len(reference)} machines on the slack bus, need exactly one")
    mu = np.asarray(system.EIG.mu)
    modes = np.sort(mu.imag[mu.imag > 1e-6] / (2 * math.pi))
    bus_name = dict(zip(system.Bus.idx.v, system.Bus.name.v))
    where = {bus: k for k, bus in enumerate(system.Bus.idx.v)}
    machines = []
    for k in range(n):
        b = where[gens.bus.v[k]]
        machines.append({
            "idx": _plain(gens.idx.v[k]), "name": _plain(gens.name.v[k]), "source_model": models[k],
            "bus": _plain(gens.bus.v[k]), "bus_name": _plain(bus_name[gens.bus.v[k]]), "gen": _plain(gens.gen.v[k]),
            "Sn": float(gens.Sn.v[k]), "Vn": float(gens.Vn.v[k]), "fn": float(gens.fn.v[k]),
            "M": float(gens.M.vin[k]), "D": float(gens.D.vin[k]), "ra": float(gens.ra.vin[k]),
            "xl": float(gens.xl.vin[k]), "xd1": float(gens.xd1.vin[k]),
            "M_system": float(M[k]), "D_system": float(D[k]), "ra_system": float(gens.ra.v[k]),
            "xd1_system": float(gens.xd1.v[k]),
            "P": float(gens.Pe.v[k]), "Q": float(gens.Qe.v[k]), "V": float(system.Bus.v.v[b]),
            "angle": float(system.Bus.a.v[b]), "E": float(emf[k]), "delta0": float(gens.delta.v[k]),
        })
    return {
        "format": FORMAT,
        "case": name,
        "title": title,
        "source": {
            "andes": andes.__version__, "kvxopt": kvxopt.__version__, "numpy": np.__version__,
            "case_file": case_file, "kept": kept, "dropped": dropped,
            "machines": "one ANDES GENCLS per synchronous machine (GENCLS kept, GENROU replaced by a GENCLS with "
                        "its own Sn, Vn, fn, M, D, ra, xl, xd1), machines ordered by bus",
            "power_flow": {"method": "Newton (ANDES PFlow)", "tol": PF_TOL},
            "loads": {k: _plain(v) for k, v in system.PQ.config.as_dict().items()},
            "linearization": "ANDES EIG state matrix (network eliminated); K = -M_system * A[omega, delta]",
            # As the shipped files record it (their sha256 enters every power_grid run key, so they stay as written);
            # the module is compare.run.families.power_cases.generate, and the old name still runs (compare/_moved.py).
            "generator": "python -m compare.families.power_cases.generate",
        },
        "base_mva": float(system.config.mva),
        "frequency": float(system.config.freq),
        "units": {"M": "s (2H) on the machine's base Sn; M_system on base_mva", "D": "p.u. power per p.u. speed, "
                  "machine base (D_system: base_mva)", "K": "p.u. power on base_mva per rad", "P, Q": "p.u. on "
                  "base_mva", "V": "p.u.", "angle, delta0": "rad", "modes_hz": "Hz, at the case's own D"},
        "reference": reference[0],
        "machines": machines,
        "K": K.tolist(),
        "modes_hz": modes.tolist(),
        "_checks": checks,
    }


def dumps(data: dict) -> str:
    """JSON with one machine and one row of K per line (diffable), floats as Python writes them (round-trip)."""
    def inline(value):
        return json.dumps(value, ensure_ascii=False, allow_nan=False)

    lines = ["{"]
    items = list(data.items())
    for i, (key, value) in enumerate(items):
        comma = "," if i < len(items) - 1 else ""
        if key in ("machines", "K"):
            rows = [f"  {inline(row)}" for row in value]
            lines.append(f" {inline(key)}: [\n" + ",\n".join(rows) + f"\n ]{comma}")
        elif key == "source":
            lines.append(f" {inline(key)}: " + json.dumps(value, indent=1, ensure_ascii=False).replace("\n", "\n ")
                         + comma)
        else:
            lines.append(f" {inline(key)}: {inline(value)}{comma}")
    lines.append("}")
    return "\n".join(lines) + "\n"


def write(name: str, out: Path) -> tuple[Path, dict]:
    """Write ``<out>/<name>.json``; the path and the self-checks' relative deviations."""
    data = case_data(name)
    checks = data.pop("_checks")
    path = Path(out) / f"{name}.json"
    path.write_text(dumps(data), encoding="utf-8")
    return path, checks


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m compare.run.families.power_cases.generate",
                                     description="Write the power_grid family's case files from ANDES.")
    parser.add_argument("cases", nargs="*", default=list(CASES), help=f"cases (default: all of {', '.join(CASES)})")
    parser.add_argument("--out", type=Path, default=HERE,
                        help="folder to write <case>.json into (default: the package)")
    args = parser.parse_args(argv)
    import andes

    andes.config_logger(stream_level=40)
    for name in args.cases:
        if name not in CASES:
            parser.error(f"unknown case {name!r} (known: {', '.join(CASES)})")
        path, checks = write(name, args.out)
        print(f"{path}: " + ", ".join(f"{label} {value:.1e}" for label, value in checks.items()))


if __name__ == "__main__":
    main()
