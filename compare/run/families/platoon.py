"""A string of vehicles: Lin, Fardad & Jovanović, "Optimal control of vehicular formations with
nearest neighbor interactions", IEEE TAC 57(9), 2012.

N vehicles on a line, each a double integrator in its errors from the desired
formation: position error p_i and velocity error v_i, p_i' = v_i, v_i' = u_i (the
paper's model with unit masses). The vehicles are not coupled by their dynamics: the
formation couples them through the cost, which charges the spacing errors between
neighbours,

    J = ∫ Σ_{i=0}^{N} (p_{i+1} - p_i)^2 + Σ_i v_i^2 + r Σ_i u_i^2,   p_0 = p_{N+1} = 0,

the fictitious leader 0 and follower N + 1 keeping their places, as in the paper's
formation with both: Q = [[T, 0], [0, I]] with T the tridiagonal Toeplitz matrix with 2
on the diagonal and -1 beside it, R = r I. (The weights are this family's choice: one
unit on every spacing error and every velocity error.) Discretized exactly by zero-order
hold with sampling time ``dt``: per vehicle A_i = [[1, dt], [0, 1]], B_i = [dt^2 / 2; dt];
the stage cost is charged at the sampling instants. States ordered all positions,
then all velocities (``state_nodes = [0..N-1, 0..N-1]``), as in the paper.

Graphs: the plant graph has no links (each vehicle's dynamics are its own), so every
link a design uses is bought by the cost's coupling; the given communication graph
is the string (each vehicle talks to the one ahead and the one behind, the paper's
nearest-neighbour interactions). No randomness: ``seeds`` is not a key.

Spec::

    [instances]
    family = "platoon"
    n = [20]           # vehicles (nodes)
    dt = 0.2
    r = 1.0            # R = r I
    horizon = 50
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..parsing import SpecError, check_keys, typed
from . import Family, register_family
from ._sampled import parse_sampling

__all__ = ["platoon_instance"]

KEYS = {"family", "n", "dt", "r", "horizon"}


def platoon_instance(n: int, *, dt: float = 0.2, r: float = 1.0, horizon: int = 50):
    """The string of ``n`` vehicles as an :class:`codesign.Instance`."""
    from codesign import Instance

    eye, zero = np.eye(n), np.zeros((n, n))
    A = np.block([[eye, dt * eye], [zero, eye]])
    B = np.vstack([dt * dt / 2 * eye, dt * eye])
    spacing = 2 * eye - np.eye(n, k=1) - np.eye(n, k=-1)
    Q = np.block([[spacing, zero], [zero, eye]])
    string = np.eye(n, k=1) + np.eye(n, k=-1)
    inst = Instance.from_matrices(A, B, Q=Q, R=r * eye, comm_adj=string, horizon=horizon,
                                  state_nodes=np.concatenate([np.arange(n), np.arange(n)]), input_nodes=np.arange(n))
    spec = {"family": "platoon", "n": n, "dt": float(dt), "r": float(r), "horizon": int(horizon)}
    return replace(inst, spec=spec)


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    sizes, dt, horizon = parse_sampling(table, noun="vehicles", dt=0.2)
    r = typed("instances.r", table.get("r", 1.0), float)
    if not (math.isfinite(r) and r > 0):
        raise SpecError(f"instances.r: must be positive, got {r}")
    return tuple({"family": "platoon", "n": n, "dt": dt, "r": r, "horizon": horizon} for n in sizes)


def states(spec: dict) -> int:
    """A position error and a velocity error per vehicle."""
    return 2 * spec["n"]


def build(spec: dict):
    return platoon_instance(spec["n"], dt=spec["dt"], r=spec["r"], horizon=spec["horizon"])


PLATOON = register_family(Family(
    name="platoon",
    summary="a string of vehicles (position and velocity error per vehicle), coupled by the spacing cost, "
            "Lin, Fardad & Jovanovic 2012",
    parse=parse,
    build=build,
    states=states,
    fields=frozenset({"n", "dt", "r", "horizon"}),
))
