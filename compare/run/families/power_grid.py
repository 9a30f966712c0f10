"""Published power systems from ANDES, reduced to their machines: the swing equations of real grids.

The anchor is Dörfler, Jovanović, Chertkov & Bullo, "Sparsity-promoting optimal
wide-area control of power networks", IEEE Trans. Power Systems 29(5), 2014
(arXiv:1307.4342): on the IEEE 39-bus New England system the ℓ1/ADMM design comes
close to the centralized one with a single wide-area link. Three ANDES cases are
shipped (``compare/run/families/power_cases/<case>.json``, written by
:mod:`compare.run.families.power_cases.generate` with ANDES 2.0.0; this module reads
them without ANDES):

========  ===========================  ========  =========================================
case      ANDES file                   machines  shipped damping D (machine base)
========  ===========================  ========  =========================================
ieee39    ieee39/ieee39_full.xlsx      10        0 (every GENROU)
wecc      wecc/wecc_gencls.xlsx        29        4 (every GENCLS)
npcc      npcc/npcc.xlsx               48        0 (27 GENROU), M/2 (21 GENCLS)
========  ===========================  ========  =========================================

The model. Every synchronous machine becomes a classical machine (constant EMF E_i
behind its transient reactance x'd_i, ANDES's GENCLS, with the case's own inertia and
reactances), loads become constant impedances at their power-flow voltage, and the
network is eliminated (Kron reduction). Linearized at the power flow, machine i has
its rotor angle θ_i (rad) and speed ω_i (rad/s, deviation from synchronous speed):

    θ_i' = ω_i
    M_i ω_i' = −D_i ω_i − Σ_j K_ij θ_j + u_i

with M_i = 2 H_i S_n,i / (S_b ω_s) (p.u. s²/rad; ANDES's M = 2H on the machine base,
ω_s = 2π f), D_i = d S_n,i / (S_b ω_s) for a damping d in p.u. torque per p.u. speed on
the machine's base (ANDES's convention), K_ij = ∂P_e,i/∂δ_j the synchronizing
coefficients of the Kron-reduced network (p.u. on S_b = 100 MVA per rad; ANDES's
small-signal analysis, checked against the Kron reduction when generated), and the
input u_i the machine's mechanical power (p.u. on S_b): ``input = "power"``, B_i = 1/M_i
in the speed row, one input per machine.

Damping: the cases ship none for most machines (ieee39 has D = 0), so ``damping``
sets d for every machine, 2 p.u. by default: a moderate value for the damper-winding,
governor and load damping that the classical model lumps into D (ANDES's own classical
WECC case ships 4), with which the electromechanical modes are damped by a few per cent
(ieee39: 1.7–2.8 %), as lightly damped inter-area modes are. ``damping = "case"`` keeps
the case's own values. npcc's four external equivalents carry M = 2000 s on a 100 MVA
base, so d on that base damps them little (its least damped mode: 0.08 %).

The rotational mode: K's rows sum to zero (only angle differences carry power), so
the angles turning together (θ = c 1, ω = 0) is an equilibrium, a zero eigenvalue that
no cost on angle differences sees. It is removed by grounding: angles are measured
from the reference machine r (the one on the power-flow slack bus: ieee39 G10 at bus
39, the New York equivalent), θ̃_i = θ_i − θ_r, and r keeps only its speed:

    θ̃_i' = ω_i − ω_r,   M_i ω_i' = −D_i ω_i − Σ_{j≠r} K_ij θ̃_j + u_i.

This is exact (Σ_j K_ij θ_j = Σ_{j≠r} K_ij θ̃_j), so the 2N − 1 eigenvalues are those of
the full model less the zero. States machine by machine (θ̃_0, ω_0, θ̃_1, ω_1, ...),
the reference with ω_r only (``state_nodes``); machines ordered by bus number. A
machine's angle state is thus relative to the reference: a gain that reads it at node
i uses node i's state (no link), as relative-angle designs do.

Discretization: zero-order hold with step ``dt`` (0.1 s: below the Nyquist period of
every case's fastest mode, 4.5 Hz in npcc), entries below 1e-9 of the largest dropped
(:func:`compare.run.families._sampled.zoh`).

Costs after Dörfler et al. (2014), their slow-coherency objective: ``cost =
"coherency"`` penalizes the angles' deviation from their average,
Σ_i (θ_i − θ̄)² = θᵀ(I − 11ᵀ/N)θ, which in grounded angles is θ̃ᵀ(I − 11ᵀ/N)θ̃ on the
N − 1 of them, and the kinetic energy through ωᵀ diag(M) ω; R = r I with r = 1.
``cost = "identity"``: Q = I.

Graphs: K is dense (the Kron reduction couples every pair of machines through the
load buses), so the plant graph is complete. The given communication graph links
each machine to the ``neighbours`` machines it is most strongly coupled to (largest
|K_ij|, the electrically nearest), made symmetric, like ``random_network``'s nearest
neighbours; while it has several components the strongest coupling between two of
them is added (npcc at 4 neighbours: 9 and 39 machines, joined by one link).

No randomness: a case is one instance, ``seeds`` is not a key.

Spec::

    [instances]
    family = "power_grid"
    case = ["ieee39"]     # ieee39, wecc, npcc
    damping = 2.0         # d (p.u., machine base) for every machine, or "case"
    input = "power"       # mechanical power at each machine
    dt = 0.1              # zero-order-hold step, s
    cost = "coherency"    # or "identity"
    r = 1.0               # R = r I
    neighbours = 4        # given graph: the strongest couplings
    horizon = 50
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..parsing import SpecError, check_keys, list_of, typed
from . import Family, register_family
from ._sampled import zoh

__all__ = ["CASES", "case_data", "grounded_swing", "power_grid_instance", "strongest_couplings"]

CASES = ("ieee39", "wecc", "npcc")
INPUTS = ("power",)
COSTS = ("coherency", "identity")
KEYS = {"family", "case", "damping", "input", "dt", "cost", "r", "neighbours", "horizon"}
DATA = Path(__file__).resolve().parent / "power_cases"


@functools.cache
def _read(case: str) -> tuple[bytes, str]:
    path = DATA / f"{case}.json"
    data = path.read_bytes()
    return data, hashlib.sha256(data).hexdigest()[:16]


def case_data(case: str) -> dict:
    """The shipped data of ``case`` (a fresh dict: machines, K, reference, provenance)."""
    if case not in CASES:
        raise ValueError(f"unknown power_grid case {case!r} (known: {', '.join(CASES)})")
    return json.loads(_read(case)[0])


def _layout(N: int, reference: int) -> tuple[np.ndarray, dict, dict]:
    """The node of each state, and each machine's angle and speed state (the reference has no angle)."""
    nodes, angle, speed = [], {}, {}
    for i in range(N):
        if i != reference:
            angle[i] = len(nodes)
            nodes.append(i)
        speed[i] = len(nodes)
        nodes.append(i)
    return np.array(nodes), angle, speed


def grounded_swing(K, M, D, reference: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time (Ac, Bc, state_nodes) of the swing equations with angles grounded at ``reference``.

    ``K`` (N, N) synchronizing coefficients (zero row sums), ``M`` and ``D`` per machine in
    the units of the equations (θ in rad, ω in rad/s). States machine by machine,
    (θ_i − θ_r, ω_i), the reference machine with its speed only; one power input per machine.
    """
    K, M, D = np.asarray(K, dtype=float), np.asarray(M, dtype=float), np.asarray(D, dtype=float)
    N = K.shape[0]
    nodes, angle, speed = _layout(N, reference)
    others = [j for j in range(N) if j != reference]
    Ac, Bc = np.zeros((nodes.size, nodes.size)), np.zeros((nodes.size, N))
    for i in range(N):
        if i != reference:
            Ac[angle[i], speed[i]] = 1.0
            Ac[angle[i], speed[reference]] = -1.0
        Ac[speed[i], [angle[j] for j in others]] = -K[i, others] / M[i]
        Ac[speed[i], speed[i]] = -D[i] / M[i]
        Bc[speed[i], i] = 1.0 / M[i]
    return Ac, Bc, nodes


def _machines(data: dict, damping) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """K (p.u./rad), M (p.u. s²/rad) and D (p.u. s/rad) on the system base, speeds in rad/s."""
    omega_s = 2 * math.pi * data["frequency"]
    machines = data["machines"]
    M = np.array([m["M_system"] for m in machines]) / omega_s
    if damping == "case":
        D = np.array([m["D_system"] for m in machines]) / omega_s
    else:
        D = float(damping) * np.array([m["Sn"] for m in machines]) / data["base_mva"] / omega_s
    return np.array(data["K"], dtype=float), M, D


def strongest_couplings(K, neighbours: int) -> np.ndarray:
    """Symmetric 0/1 graph: each machine and the ``neighbours`` others it is most strongly coupled to, connected.

    Coupling strength is max(|K_ij|, |K_ji|) (K is nearly but not exactly symmetric). While the graph has several components, the strongest coupling between two of them
    is added (ties: the first pair in row-major order).
    """
    K = np.abs(np.asarray(K, dtype=float))
    K = np.maximum(K, K.T)
    N = K.shape[0]
    np.fill_diagonal(K, -np.inf)
    order = np.argsort(-K, axis=1, kind="stable")[:, :neighbours]
    adj = np.zeros((N, N))
    adj[np.repeat(np.arange(N), neighbours), order.ravel()] = 1.0
    adj = np.maximum(adj, adj.T)
    while True:
        component = _components(adj)
        if component.max() == 0:
            return adj
        across = np.where(component[:, None] != component[None, :], K, -np.inf)
        i, j = np.unravel_index(int(np.argmax(across)), across.shape)
        adj[i, j] = adj[j, i] = 1.0


def _components(adj) -> np.ndarray:
    """The connected component of each node (0 for node 0's)."""
    N = adj.shape[0]
    label = np.full(N, -1)
    count = 0
    for start in range(N):
        if label[start] >= 0:
            continue
        stack = [start]
        label[start] = count
        while stack:
            i = stack.pop()
            for j in np.flatnonzero(adj[i]):
                if label[j] < 0:
                    label[j] = count
                    stack.append(j)
        count += 1
    return label


def power_grid_instance(case: str = "ieee39", *, damping=2.0, input: str = "power", dt: float = 0.1,
                        cost: str = "coherency", r: float = 1.0, neighbours: int = 4, horizon: int = 50):
    """The machines of an ANDES case as an :class:`codesign.Instance` (module docstring: the model)."""
    from codesign import Instance

    if input not in INPUTS:
        raise ValueError(f"input must be one of {', '.join(INPUTS)}, got {input!r}")
    if cost not in COSTS:
        raise ValueError(f"cost must be one of {', '.join(COSTS)}, got {cost!r}")
    data = case_data(case)
    K, M, D = _machines(data, damping)
    N, reference = K.shape[0], data["reference"]
    Ac, Bc, nodes = grounded_swing(K, M, D, reference)
    A, B = zoh(Ac, Bc, dt)
    _, angle, speed = _layout(N, reference)
    angles, speeds = list(angle.values()), list(speed.values())
    if cost == "coherency":
        Q = np.zeros((nodes.size, nodes.size))
        Q[np.ix_(angles, angles)] = np.eye(N - 1) - 1.0 / N
        Q[speeds, speeds] = M
    else:
        Q = np.eye(nodes.size)
    inst = Instance.from_matrices(A, B, Q=Q, R=r * np.eye(N), comm_adj=strongest_couplings(K, neighbours),
                                  horizon=horizon, state_nodes=nodes, input_nodes=np.arange(N))
    spec = {"family": "power_grid", "case": case, "n": int(N), "damping": damping if damping == "case"
            else float(damping), "input": input, "dt": float(dt), "cost": cost, "r": float(r),
            "neighbours": int(neighbours), "horizon": int(horizon), "sha256": _read(case)[1]}
    return replace(inst, spec=spec)


def _damping(value):
    if value == "case":
        return "case"
    if isinstance(value, str):
        raise SpecError(f"instances.damping: a number (p.u., machine base) or \"case\", got {value!r}")
    value = typed("instances.damping", value, float)
    if value < 0:
        raise SpecError(f"instances.damping: must be >= 0, got {value}")
    return value


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    cases = list_of("instances.case", table.get("case", ["ieee39"]), str, positive=False)
    for case in cases:
        if case not in CASES:
            raise SpecError(f"instances.case: unknown case {case!r} (known: {', '.join(CASES)})")
    damping = _damping(table.get("damping", 2.0))
    choice = {}
    for key, allowed, default in (("input", INPUTS, "power"), ("cost", COSTS, "coherency")):
        choice[key] = typed(f"instances.{key}", table.get(key, default), str)
        if choice[key] not in allowed:
            raise SpecError(f"instances.{key}: must be one of {', '.join(allowed)}, got {choice[key]!r}")
    dt = typed("instances.dt", table.get("dt", 0.1), float)
    r = typed("instances.r", table.get("r", 1.0), float)
    neighbours = typed("instances.neighbours", table.get("neighbours", 4), int)
    horizon = typed("instances.horizon", table.get("horizon", 50), int)
    if not dt > 0:
        raise SpecError(f"instances.dt: must be positive, got {dt}")
    if not r > 0:
        raise SpecError(f"instances.r: must be positive, got {r}")
    if horizon < 1:
        raise SpecError(f"instances.horizon: must be >= 1, got {horizon}")
    specs = []
    for case in cases:
        n = len(case_data(case)["machines"])
        if not 1 <= neighbours < n:
            raise SpecError(f"instances.neighbours: must be between 1 and {n - 1} (case {case}), got {neighbours}")
        specs.append({"family": "power_grid", "case": case, "n": n, "damping": damping, "input": choice["input"],
                      "dt": dt, "cost": choice["cost"], "r": r, "neighbours": neighbours, "horizon": horizon,
                      "sha256": _read(case)[1]})
    return tuple(specs)


def states(spec: dict) -> int:
    """An angle and a speed per machine, less the reference machine's angle."""
    return 2 * spec["n"] - 1


def build(spec: dict):
    if _read(spec["case"])[1] != spec["sha256"]:
        raise ValueError(f"power_grid case {spec['case']!r}: its data file changed after the spec was read "
                         f"(sha256 {_read(spec['case'])[1]}, spec {spec['sha256']}); run the experiment again")
    return power_grid_instance(spec["case"], damping=spec["damping"], input=spec["input"], dt=spec["dt"],
                               cost=spec["cost"], r=spec["r"], neighbours=spec["neighbours"],
                               horizon=spec["horizon"])


POWER_GRID = register_family(Family(
    name="power_grid",
    summary="published grids from ANDES (ieee39, wecc, npcc) reduced to their classical machines (angle and speed "
            "per machine, mechanical-power input), Dörfler et al. 2014",
    parse=parse,
    build=build,
    states=states,
    fields=frozenset({"case", "n", "damping", "input", "dt", "cost", "r", "neighbours", "horizon"}),
))
