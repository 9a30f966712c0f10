"""Unstable second-order nodes scattered in a square, the "distributed systems" example of lqrsp.

After Motee & Jadbabaie (2008), as in the lqrsp example (Lin, Fardad & Jovanović):
N nodes are placed uniformly at random in a square of side L; node i has a
position-like state p_i and a velocity-like state v_i, unstable on its own and
coupled to every other node with a strength that decays with their Euclidean
distance d_ij:

    d/dt [p_i; v_i] = [[1, 1], [1, 2]] [p_i; v_i] + Σ_{j≠i} e^{-d_ij} [p_j; v_j] + [0; 1] u_i.

Costs Q = I and R = I as in the example; states ordered node by node (p_0, v_0,
p_1, v_1, ...). The example has N = 100 in a square of side 10; here the side
defaults to sqrt(N), which keeps that density at every N (``side`` overrides it).
The continuous-time system is discretized by zero-order hold with sampling time
``dt`` (:func:`scipy.signal.cont2discrete`); each ``seed`` draws one placement.

Graphs: every pair of nodes is coupled, so the plant graph is complete (the
exponential weights are small but not zero; entries below ``CUTOFF = 1e-9`` of the
largest are dropped, which removes none at the default density). The given
communication graph is not in the example; here each node talks to its
``neighbours`` nearest nodes (4 by default), made symmetric, with self-loops.

Spec::

    [instances]
    family = "random_network"
    n = [20]
    seeds = 3        # placements 0, 1, 2
    dt = 0.1
    horizon = 50
    neighbours = 4
    side = 0.0       # 0: sqrt(n)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..parsing import SpecError, check_keys, typed
from . import Family, register_family
from ._sampled import parse_sampling, zoh

__all__ = ["random_network_instance"]

KEYS = {"family", "n", "seeds", "dt", "horizon", "neighbours", "side"}
_SALT = 0x4E37


def random_network_instance(n: int, *, seed: int = 0, dt: float = 0.1, horizon: int = 50, neighbours: int = 4,
                            side: float = 0.0):
    """One placement of ``n`` unstable second-order nodes as an :class:`codesign.Instance`."""
    from scipy.spatial.distance import cdist

    from codesign import Instance

    side = float(side) if side else float(np.sqrt(n))
    positions = np.random.default_rng([int(seed), _SALT]).uniform(0.0, side, (n, 2))
    distance = cdist(positions, positions)
    coupling = np.exp(-distance)
    np.fill_diagonal(coupling, 0.0)
    own = np.array([[1.0, 1.0], [1.0, 2.0]])
    Ac = np.kron(coupling, np.eye(2)) + np.kron(np.eye(n), own)
    Bc = np.kron(np.eye(n), np.array([[0.0], [1.0]]))
    A, B = zoh(Ac, Bc, dt)
    order = np.argsort(distance, axis=1, kind="stable")[:, 1:neighbours + 1]
    comm = np.zeros((n, n))
    comm[np.repeat(np.arange(n), order.shape[1]), order.ravel()] = 1.0
    comm = np.maximum(comm, comm.T)
    inst = Instance.from_matrices(A, B, comm_adj=comm, horizon=horizon, state_nodes=np.repeat(np.arange(n), 2),
                                  input_nodes=np.arange(n))
    spec = {"family": "random_network", "n": n, "seed": int(seed), "dt": float(dt), "horizon": int(horizon),
            "neighbours": int(neighbours), "side": float(side)}
    return replace(inst, spec=spec)


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    sizes, dt, horizon = parse_sampling(table, noun="nodes", dt=0.1)
    count = typed("instances.seeds", table.get("seeds", 1), int)
    if count < 1:
        raise SpecError(f"instances.seeds: a count must be >= 1, got {count}")
    neighbours = typed("instances.neighbours", table.get("neighbours", 4), int)
    side = typed("instances.side", table.get("side", 0.0), float)
    if any(not 1 <= neighbours < n for n in sizes):
        raise SpecError(f"instances.neighbours: must be between 1 and n - 1, got {neighbours}")
    if side < 0:
        raise SpecError(f"instances.side: must be >= 0 (0: sqrt(n)), got {side}")
    return tuple({"family": "random_network", "n": n, "seed": seed, "dt": dt, "horizon": horizon,
                  "neighbours": neighbours, "side": side if side else float(np.sqrt(n))}
                 for n in sizes for seed in range(count))


def states(spec: dict) -> int:
    """A position and a velocity per node."""
    return 2 * spec["n"]


def build(spec: dict):
    return random_network_instance(spec["n"], seed=spec["seed"], dt=spec["dt"], horizon=spec["horizon"],
                                   neighbours=spec["neighbours"], side=spec["side"])


RANDOM_NETWORK = register_family(Family(
    name="random_network",
    summary="unstable second-order nodes placed at random, coupled by e^(-distance) (lqrsp's distributed system)",
    parse=parse,
    build=build,
    states=states,
    fields=frozenset({"n", "seed", "dt", "horizon", "neighbours", "side"}),
))
