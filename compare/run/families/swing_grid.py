"""Linearized swing equations on a randomized mesh: the power-grid example of the SLS literature.

After Anderson, Doyle, Low & Matni, "System level synthesis", Annual Reviews in
Control 47 (2019), its power-grid example. A g x g mesh of buses; each mesh edge is
kept with probability ``keep`` and a bus left with no edge is reconnected to one of
its mesh neighbours (drawn at random), so that every bus is coupled. Bus i has two
states, its phase angle θ_i and frequency ω_i:

    θ_i' = ω_i
    ω_i' = m_i^-1 [-d_i ω_i - Σ_j k_ij (θ_i - θ_j) + u_i]

with couplings k_ij ~ U[0.5, 1] per kept edge, inverse inertias m_i^-1 ~ U[0, 2] and
dampings d_i ~ U[1, 1.5] per bus, discretized with step Ts = 0.2 by forward Euler, as
in the example (its blocks A_ii = [[1, Ts], [-k_i m_i^-1 Ts, 1 - d_i m_i^-1 Ts]],
A_ij = [[0, 0], [k_ij m_i^-1 Ts, 0]], k_i = Σ_j k_ij, B_i = [0; 1]). The input enters
the frequency row directly (B_i = [0; 1], as in the example's blocks). Actuators as in
:mod:`compare.run.families.chain`: ``ceil(d N)`` of them at density d, input k on bus
``floor(k / d) mod N``. Costs Q = I, R = I. The plant graph and the given
communication graph are the kept mesh.

Continuous time, the Laplacian coupling has a zero mode: the grid's phases all moving
together (θ = c 1, ω = 0) is an equilibrium of the undamped and the damped system
alike, so A has the eigenvalue 1 on the vector (1, 0) per bus; it is stabilizable as
long as one bus is actuated.

States ordered bus by bus (θ_0, ω_0, θ_1, ω_1, ...); buses numbered row by row.

Spec::

    [instances]
    family = "swing_grid"
    grid = [5]         # g: a g x g mesh, N = g^2 buses
    seeds = 3          # seeds 0, 1, 2: one draw of edges and parameters each
    keep = 0.8         # probability that a mesh edge is kept
    actuation = 1.0    # actuation density d in (0, 1]
    dt = 0.2           # Euler step Ts
    horizon = 50
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..parsing import SpecError, check_keys, list_of, typed
from . import Family, register_family
from .chain import actuated_nodes, parse_actuation

__all__ = ["swing_grid_instance", "swing_matrix", "mesh_edges"]

KEYS = {"family", "grid", "seeds", "keep", "actuation", "dt", "horizon"}
_SALT = 0x5717


def mesh_edges(g: int) -> list[tuple[int, int]]:
    """The edges (i, j), i < j, of the g x g mesh, buses numbered row by row."""
    edges = []
    for r in range(g):
        for c in range(g):
            i = r * g + c
            if c + 1 < g:
                edges.append((i, i + 1))
            if r + 1 < g:
                edges.append((i, i + g))
    return edges


def _kept_mesh(g: int, keep: float, rng) -> np.ndarray:
    """Symmetric 0/1 adjacency of the mesh with each edge kept with probability ``keep``, isolated buses reconnected."""
    N = g * g
    edges = mesh_edges(g)
    adj = np.zeros((N, N))
    for (i, j), kept in zip(edges, rng.random(len(edges)) < keep):
        if kept:
            adj[i, j] = adj[j, i] = 1.0
    for i in np.flatnonzero(adj.sum(axis=1) == 0):
        candidates = [j for a, b in edges for j in ((b,) if a == i else (a,) if b == i else ())]
        j = candidates[int(rng.integers(len(candidates)))]
        adj[i, j] = adj[j, i] = 1.0
    return adj


def swing_matrix(k, *, inv_inertia, damping, dt: float) -> np.ndarray:
    """A of the Euler-discretized swing equations, states bus by bus (θ_0, ω_0, θ_1, ...).

    ``k`` (N, N) symmetric couplings (zero where buses are not connected); ``inv_inertia``
    and ``damping`` per bus.
    """
    k = np.asarray(k, dtype=float)
    inv_inertia, damping = np.asarray(inv_inertia, dtype=float), np.asarray(damping, dtype=float)
    N = k.shape[0]
    laplacian = np.diag(k.sum(axis=1)) - k
    A = np.zeros((2 * N, 2 * N))
    theta, omega = np.arange(0, 2 * N, 2), np.arange(1, 2 * N, 2)
    A[theta, theta] = 1.0
    A[theta, omega] = dt
    A[np.ix_(omega, theta)] = -dt * inv_inertia[:, None] * laplacian
    A[omega, omega] = 1.0 - dt * inv_inertia * damping
    return A


def swing_grid_instance(g: int, *, seed: int = 0, keep: float = 0.8, actuation: float = 1.0, dt: float = 0.2,
                        horizon: int = 50):
    """One draw of the swing-equation grid on a ``g`` x ``g`` mesh as an :class:`codesign.Instance`."""
    from codesign import Instance

    rng = np.random.default_rng([int(seed), _SALT])
    N = g * g
    adj = _kept_mesh(g, keep, rng)
    k = np.triu(adj, 1) * rng.uniform(0.5, 1.0, (N, N))
    k = k + k.T
    A = swing_matrix(k, inv_inertia=rng.uniform(0.0, 2.0, N), damping=rng.uniform(1.0, 1.5, N), dt=dt)
    nodes = actuated_nodes(N, actuation)
    B = np.zeros((2 * N, nodes.size))
    B[2 * nodes + 1, np.arange(nodes.size)] = 1.0
    inst = Instance.from_matrices(A, B, comm_adj=adj, horizon=horizon, state_nodes=np.repeat(np.arange(N), 2),
                                  input_nodes=nodes)
    spec = {"family": "swing_grid", "grid": int(g), "n": int(N), "seed": int(seed), "keep": float(keep),
            "actuation": float(actuation), "dt": float(dt), "horizon": int(horizon)}
    return replace(inst, spec=spec)


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    grids = list_of("instances.grid", table.get("grid", [5]), int)
    if any(g < 2 for g in grids):
        raise SpecError(f"instances.grid: a mesh needs g >= 2, got {list(grids)}")
    count = typed("instances.seeds", table.get("seeds", 1), int)
    if count < 1:
        raise SpecError(f"instances.seeds: a count must be >= 1, got {count}")
    keep = typed("instances.keep", table.get("keep", 0.8), float)
    actuation, horizon = parse_actuation(table)
    dt = typed("instances.dt", table.get("dt", 0.2), float)
    if not 0 < keep <= 1:
        raise SpecError(f"instances.keep: a probability in (0, 1], got {keep}")
    if not (math.isfinite(dt) and dt > 0):
        raise SpecError(f"instances.dt: must be positive, got {dt}")
    # n, the node count g^2, is derived (not a key): reports and `where` read every family's size from it.
    return tuple({"family": "swing_grid", "grid": g, "n": g * g, "seed": seed, "keep": keep, "actuation": actuation,
                  "dt": dt, "horizon": horizon} for g in grids for seed in range(count))


def states(spec: dict) -> int:
    """A phase and a frequency per bus."""
    return 2 * spec["grid"] ** 2


def build(spec: dict):
    return swing_grid_instance(spec["grid"], seed=spec["seed"], keep=spec["keep"], actuation=spec["actuation"],
                               dt=spec["dt"], horizon=spec["horizon"])


SWING_GRID = register_family(Family(
    name="swing_grid",
    summary="linearized swing equations on a randomized g x g mesh (phase and frequency per bus), the SLS grid example",
    parse=parse,
    build=build,
    states=states,
    fields=frozenset({"grid", "n", "seed", "keep", "actuation", "dt", "horizon"}),
))
