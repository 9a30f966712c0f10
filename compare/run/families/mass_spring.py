"""A chain of masses and springs, the benchmark of Lin, Fardad & Jovanović's lqrsp examples.

N masses on a line, each tied to its neighbours by springs and the two end
masses to walls (fixed–fixed). Node i has two states, its position p_i and
velocity v_i, and one input, a force on mass i:

    m_i dv_i/dt = -k_i (p_i - p_{i-1}) - k_{i+1} (p_i - p_{i+1}) + u_i,   p_0 = p_{N+1} = 0.

With unit masses and stiffnesses (the example's setting, the default) the
continuous-time matrices are ``A = [[0, I], [-T, 0]]`` and ``B = [[0], [I]]``
with T tridiagonal (2 on the diagonal, -1 beside it), states ordered as in the
example, all positions then all velocities (``state_nodes = [0..N-1, 0..N-1]``).
They are discretized by zero-order hold with sampling time ``dt``
(:func:`scipy.signal.cont2discrete`); a ``seed`` draws masses and stiffnesses
uniformly in [0.5, 1.5] instead. Costs as in the example: Q = I (every position and
velocity) and R = r I with r = 10, horizon T steps, terminal cost the DARE solution as for every instance.
The given communication graph is the chain: each node talks to its two
neighbours.

The plant graph is wider than the chain: the matrix exponential couples every
pair of masses, with entries that decay fast along the chain. Entries of the
discretized A and B below ``CUTOFF = 1e-9`` of their largest are set to zero,
which leaves a band: at dt = 0.2 each mass reaches the masses up to 4 places
away within one step (140 directed links at N = 20, 380 at N = 50). The
dropped entries change costs by far less than any reported digit.

Spec::

    [instances]
    family = "mass_spring"
    n = [20]          # masses (nodes)
    seeds = 0         # 0: unit masses and springs; k: seeds 1..k draw them around 1
    dt = 0.2          # sampling time
    horizon = 50
    r = 10.0          # R = r I (the example's weight)
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..parsing import SpecError, check_keys, typed
from . import Family, register_family
from ._sampled import parse_sampling, zoh

__all__ = ["mass_spring_instance"]

KEYS = {"family", "n", "seeds", "dt", "horizon", "r"}


def mass_spring_instance(n: int, *, seed: int = 0, dt: float = 0.2, horizon: int = 50, r: float = 10.0):
    """The chain of ``n`` masses as an :class:`codesign.Instance` (seed 0: unit masses and springs)."""
    from codesign import Instance

    if seed:
        rng = np.random.default_rng([int(seed), 0x5A5A])
        masses, springs = rng.uniform(0.5, 1.5, n), rng.uniform(0.5, 1.5, n + 1)
    else:
        masses, springs = np.ones(n), np.ones(n + 1)
    stiffness = np.diag(springs[:-1] + springs[1:]) - np.diag(springs[1:-1], 1) - np.diag(springs[1:-1], -1)
    inv_mass = np.diag(1.0 / masses)
    zero, eye = np.zeros((n, n)), np.eye(n)
    Ac = np.block([[zero, eye], [-inv_mass @ stiffness, zero]])
    Bc = np.vstack([zero, inv_mass])
    A, B = zoh(Ac, Bc, dt)
    chain = np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1)
    nodes = np.concatenate([np.arange(n), np.arange(n)])
    inst = Instance.from_matrices(A, B, R=r * np.eye(n), comm_adj=chain, horizon=horizon,
                                  state_nodes=nodes, input_nodes=np.arange(n))
    spec = {"family": "mass_spring", "n": n, "seed": int(seed), "dt": float(dt), "horizon": int(horizon),
            "r": float(r)}
    return replace(inst, spec=spec)


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    sizes, dt, horizon = parse_sampling(table, noun="masses", dt=0.2)
    count = typed("instances.seeds", table.get("seeds", 0), int)
    if count < 0:
        raise SpecError(f"instances.seeds: must be >= 0, got {count}")
    r = typed("instances.r", table.get("r", 10.0), float)
    if not r > 0:
        raise SpecError(f"instances.r: must be positive, got {r}")
    seeds = [0] if count == 0 else list(range(1, count + 1))
    return tuple({"family": "mass_spring", "n": n, "seed": seed, "dt": dt, "horizon": horizon, "r": r}
                 for n in sizes for seed in seeds)


def states(spec: dict) -> int:
    """A position and a velocity per node."""
    return 2 * spec["n"]


def build(spec: dict):
    return mass_spring_instance(spec["n"], seed=spec["seed"], dt=spec["dt"], horizon=spec["horizon"], r=spec["r"])


MASS_SPRING = register_family(Family(
    name="mass_spring",
    summary="a chain of N masses and springs (position and velocity per node, one force input), lqrsp's example",
    parse=parse,
    build=build,
    states=states,
    fields=frozenset({"n", "seed", "dt", "horizon", "r"}),
))
