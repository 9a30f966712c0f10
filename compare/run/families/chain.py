"""The doubly stochastic chain of the SLS toolboxes (SLSpy's ``generate_doubly_stochastic_chain``).

N scalar nodes on a line, each mixing its state with its two neighbours':

    x_1(t+1) = ρ [(1 - α) x_1(t) + α x_2(t)] + b_1 u_1(t)
    x_i(t+1) = ρ [α x_{i-1}(t) + (1 - 2α) x_i(t) + α x_{i+1}(t)] + b_i u_i(t)
    x_N(t+1) = ρ [α x_{N-1}(t) + (1 - α) x_N(t)] + b_N u_N(t)

so that every row and column of A sums to ρ (ρ = 1: doubly stochastic, marginally
stable, the toolboxes' default; ρ > 1 unstable). A has spectral radius ρ, attained by
the uniform vector. Actuators sit where the toolboxes put them: with an actuation
density d in (0, 1], ``ceil(d N)`` inputs, input k on node ``floor(k / d) mod N``
with b = 1 (d = 1: every node; d = 1/2: every other node). A node without an
actuator still has a state, links and neighbours; the methods that cannot handle it
say so. Costs Q = I, R = I (the toolboxes' z = [x; u]); the given communication
graph is the chain itself (each node talks to its two neighbours), which is also
the plant graph. No randomness: ``seeds`` is not a key.

Spec::

    [instances]
    family = "chain"
    n = [20]
    rho = 1.0          # row sums (spectral radius)
    alpha = 0.2        # share of a state passed to each neighbour, in [0, 1/2]
    actuation = 1.0    # actuation density d in (0, 1]
    horizon = 50
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..parsing import SpecError, check_keys, list_of, typed
from . import Family, register_family

__all__ = ["chain_instance", "actuated_nodes"]

KEYS = {"family", "n", "rho", "alpha", "actuation", "horizon"}


def actuated_nodes(n: int, density: float) -> np.ndarray:
    """The node of each of the ``ceil(density n)`` actuators, in input order (the SLS toolboxes' placement)."""
    count = math.ceil(n * density - 1e-12)
    return np.array([int(math.floor(k / density + 1e-12)) % n for k in range(count)])


def parse_actuation(table: dict) -> tuple[float, int]:
    """The ``actuation`` density (in (0, 1], default 1) and ``horizon`` (>= 1, default 50) keys of a table."""
    actuation = typed("instances.actuation", table.get("actuation", 1.0), float)
    horizon = typed("instances.horizon", table.get("horizon", 50), int)
    if not 0 < actuation <= 1:
        raise SpecError(f"instances.actuation: an actuation density must be in (0, 1], got {actuation}")
    if horizon < 1:
        raise SpecError(f"instances.horizon: must be >= 1, got {horizon}")
    return actuation, horizon


def chain_matrix(n: int, rho: float, alpha: float) -> np.ndarray:
    """ρ times the doubly stochastic tridiagonal mixing matrix (row and column sums ρ)."""
    A = (1.0 - 2.0 * alpha) * np.eye(n) + alpha * (np.eye(n, k=1) + np.eye(n, k=-1))
    A[0, 0] += alpha
    A[-1, -1] += alpha
    return rho * A


def chain_instance(n: int, *, rho: float = 1.0, alpha: float = 0.2, actuation: float = 1.0, horizon: int = 50):
    """The chain of ``n`` nodes as an :class:`codesign.Instance`."""
    from codesign import Instance

    A = chain_matrix(n, rho, alpha)
    nodes = actuated_nodes(n, actuation)
    B = np.zeros((n, nodes.size))
    B[nodes, np.arange(nodes.size)] = 1.0
    path = np.eye(n, k=1) + np.eye(n, k=-1)
    inst = Instance.from_matrices(A, B, comm_adj=path, horizon=horizon, input_nodes=nodes)
    spec = {"family": "chain", "n": n, "rho": float(rho), "alpha": float(alpha), "actuation": float(actuation),
            "horizon": int(horizon)}
    return replace(inst, spec=spec)


def parse(table: dict, base=None) -> tuple:
    check_keys("instances", table, KEYS)
    sizes = list_of("instances.n", table.get("n", [20]), int)
    if any(n < 2 for n in sizes):
        raise SpecError(f"instances.n: at least 2 nodes, got {list(sizes)}")
    rho = typed("instances.rho", table.get("rho", 1.0), float)
    alpha = typed("instances.alpha", table.get("alpha", 0.2), float)
    actuation, horizon = parse_actuation(table)
    if not (math.isfinite(rho) and rho > 0):
        raise SpecError(f"instances.rho: must be positive, got {rho}")
    if not 0 <= alpha <= 0.5:
        raise SpecError(f"instances.alpha: must be in [0, 0.5], got {alpha}")
    return tuple({"family": "chain", "n": n, "rho": rho, "alpha": alpha, "actuation": actuation,
                  "horizon": horizon} for n in sizes)


def build(spec: dict):
    return chain_instance(spec["n"], rho=spec["rho"], alpha=spec["alpha"], actuation=spec["actuation"],
                          horizon=spec["horizon"])


CHAIN = register_family(Family(
    name="chain",
    summary="the SLS toolboxes' doubly stochastic chain (one state per node, rho, alpha, an actuation density)",
    parse=parse,
    build=build,
    fields=frozenset({"n", "rho", "alpha", "actuation", "horizon"}),
))
