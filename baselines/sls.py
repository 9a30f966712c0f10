"""System level synthesis (SLS) under communication-delay constraints.

Closed-loop maps, 0-indexed as the evaluator uses them: ``x(t) = X[t] x(0)``,
``u(t) = U[t] x(0)`` with ``X[0] = I`` and ``X[t+1] = A X[t] + B U[t]``
(the SLS papers write ``Φx[k] = X[k-1]``, ``Φu[k] = U[k-1]``). The finite-horizon
problem is the convex QP

    min  sum_{t<T} ||Q^½ X[t]||² + ||R^½ U[t]||² + ||P^½ X[T]||²

over maps supported where information can have arrived: ``Φx[k]`` and ``Φu[k]``
are zero outside ``max(0, floor(speed·(k − act_delay)))`` hops of the communication
graph (the convention of the SLS toolboxes; ``act_delay = 1, speed = 1`` is the
GRNN's information model, ``act_delay = 0`` on the complete graph is centralized
control). The FIR variant replaces the terminal cost by ``X[F] = 0`` (an
infinite-horizon H2 objective over a finite impulse response).

The QP separates over the columns of the maps; it is posed as one sparse problem
whose variables are only the allowed entries, with the dynamics as one sparse
equality ``G z = b``, so cvxpy compiles it in a few vectorized steps.

The controller is the SLS realization (a genuine feedback law on measured states)

    δ(t) = x(t) − x̂(t),   u(t) = sum_m U[m] δ(t−m),   x̂(t) = sum_{m≥1} X[m] δ(t−m).
"""

from __future__ import annotations

import math
import re
from dataclasses import replace
from typing import Annotated

import numpy as np

from codesign.controllers import register_controller
from codesign.design import Design, Timer, count_links
from codesign.evaluation import impulse_responses, response_cost
from codesign.instances import hop_distances
from codesign.methods import Above, AtLeast, Matches, NotEmpty, method
from codesign.status import (FAILED, INACCURATE, INACCURATE_RTOL, INFEASIBLE, OPTIMAL, USABLE, solver_status,
                             vet_solver_cost)

from .qi import check_speed, is_quadratically_invariant

__all__ = [
    "SLSController",
    "sls",
    "sls_topologies",
    "topology",
    "support_hops",
    "TOPOLOGY_FAMILY",
]

#: The sweep from the given graph (infeasible at speed 1) and the sparsest QI graph to all-to-all.
TOPOLOGY_FAMILY = ("given", "plant", "plant^2", "plant^3", "complete")

# A solve whose normalized objective is this far from the realized closed loop's
# exact cost did not really solve the QP (residuals in the dynamics).
_REALIZATION_RTOL = 1e-5
#: The most QP variables (allowed entries of the maps) `sls` poses. The compiled problem and
#: Clarabel's factorization take 3-5 kB per variable (paper family at N = 100: 0.95 million
#: variables, 4.9 GB, 25 s; the 10 x 10 swing grid's complete graph, 2.98 million: 8.6 GB,
#: 206 s for its five graphs), so a larger problem would not fit a workstation's memory or
#: finish in minutes: it is refused at once. `sls_local` solves the localized problem by
#: columns at any size.
MAX_QP_VARIABLES = 4_000_000
# Normalized costs are >= 1; the autonomous system on this family is below 1e3.
_ABSURD_OBJECTIVE = 1e8
_GRAPH_NAME = re.compile(r"^(given|plant)(?:\^([1-9][0-9]*))?$")
#: The graph names :func:`topology` knows, as a hyperparameter's bound (refused in a spec, before any run).
GRAPH_NAME = Matches(r"complete|(given|plant)(\^[1-9][0-9]*)?",
                     "a graph name: 'given', 'plant', 'given^k', 'plant^k' or 'complete'")


# -- topologies and supports ---------------------------------------------------
def topology(instance, name: str) -> np.ndarray:
    """Communication graph by name, 0/1 with self-loops.

    ``"given"`` (the instance's graph), ``"plant"`` (support of A or B),
    ``"given^k"`` / ``"plant^k"`` (k-hop closures), ``"complete"``.
    """
    n = instance.nodes
    if name == "complete":
        return np.ones((n, n))
    match = _GRAPH_NAME.match(name) if isinstance(name, str) else None
    if match is None:
        raise ValueError(
            f"unknown graph {name!r}: use 'given', 'plant', 'given^k', 'plant^k' or 'complete'"
        )
    base = instance.comm_adj if match.group(1) == "given" else instance.plant_adj
    adj = (np.asarray(base) != 0) | np.eye(n, dtype=bool)
    power = int(match.group(2) or 1)
    if power > 1:
        adj = hop_distances(adj) <= power
    return adj.astype(float)


def support_hops(k: int, *, speed: float = 1.0, act_delay: int = 1) -> int:
    """Hops of the communication graph allowed in ``Φx[k]``, ``Φu[k]`` (1-indexed k)."""
    return max(0, math.floor(speed * (k - act_delay) + 1e-9))


def checked_length(instance, speed, act_delay, horizon, fir) -> tuple[float, int]:
    """The checked ``speed`` and the problem's length T: the FIR length, else the horizon, else the instance's."""
    speed = check_speed(speed)
    if isinstance(act_delay, bool) or not isinstance(act_delay, (int, np.integer)) or act_delay < 0:
        raise ValueError(f"act_delay must be a non-negative integer, got {act_delay!r}")
    for label, value in (("horizon", horizon), ("fir", fir)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1):
            raise ValueError(f"{label} must be a positive integer, got {value!r}")
    if horizon is not None and fir is not None:
        raise ValueError("give either horizon (finite-horizon problem) or fir (FIR variant), not both")
    return speed, int(fir if fir is not None else (horizon if horizon is not None else instance.horizon))


# -- the realization -------------------------------------------------------------
@register_controller("sls")
class SLSController:
    """SLS realization of response maps ``X`` (K+1, n, n) and ``U`` (K, n, n).

    The state is the history of the last K−1 innovations ``δ``. With exact maps,
    ``δ(t)`` equals the disturbance that entered ``x(t)`` (``x(0)`` at t = 0), so
    the controller reproduces the designed closed loop; ``X[K]`` (zero for the FIR
    variant) only feeds back after K steps.
    """

    def __init__(self, phi_x, phi_u):
        phi_x = np.array(phi_x, dtype=float)
        phi_u = np.array(phi_u, dtype=float)
        if phi_u.ndim != 3 or phi_u.shape[0] < 1:
            raise ValueError(f"phi_u must have shape (K, m, n) with K >= 1, got {phi_u.shape}")
        K, _, n = phi_u.shape
        if phi_x.shape != (K + 1, n, n):
            raise ValueError(f"phi_x must have shape {(K + 1, n, n)} to match phi_u, got {phi_x.shape}")
        for M in (phi_x, phi_u):
            M.setflags(write=False)
        self.phi_x, self.phi_u = phi_x, phi_u
        # One matmul per step: history (batch, (K-1) n) @ [x̂ weights | past-u weights].
        past = [np.hstack([phi_x[m].T, phi_u[m].T]) for m in range(1, K)]
        self._past = np.vstack(past) if past else np.zeros((0, 2 * n))
        self._u_now = phi_u[0].T

    @property
    def n(self) -> int:
        """States."""
        return self.phi_u.shape[2]

    @property
    def length(self) -> int:
        """K: number of input taps."""
        return self.phi_u.shape[0]

    def reset(self, batch: int):
        return np.zeros((batch, (self.length - 1) * self.n))

    def step(self, state, x):
        n = self.n
        mixed = state @ self._past
        delta = x - mixed[:, :n]
        u = delta @ self._u_now + mixed[:, n:]
        state = np.concatenate([delta, state[:, : state.shape[1] - n]], axis=1)
        return u, state

    def arrays(self) -> dict:
        return {"phi_x": self.phi_x, "phi_u": self.phi_u}

    @classmethod
    def from_arrays(cls, arrays: dict) -> "SLSController":
        return cls(arrays["phi_x"], arrays["phi_u"])

    @property
    def support(self) -> np.ndarray:
        """Union of the supports of all taps: who uses whose information.

        Square when each node has one state and one input; otherwise the inputs'
        taps only, (m, n), which :meth:`codesign.Instance.node_support` maps to nodes.
        """
        used = np.any(self.phi_u != 0, axis=0)
        if used.shape[0] != used.shape[1]:
            return used
        return used | np.any(self.phi_x[1:] != 0, axis=0)

    def closed_loop_responses(self, instance, steps: int | None = None):
        """Maps ``(phi_x, phi_u)`` of this controller in closed loop with the instance.

        Obtained by running the realization on the plant from ``x(0) = e_j``, so
        they are the controller's actual behaviour, not the designed maps.
        """
        if instance.n != self.n:
            raise ValueError(f"controller has n = {self.n}, instance has n = {instance.n}")
        return impulse_responses(instance, self, steps)

    def predicted_cost(self, instance, *, noise_std: float = 0.0) -> float:
        """Exact normalized E[J] of the closed loop, with process noise of ``noise_std``."""
        return response_cost(instance, *self.closed_loop_responses(instance), noise_std=noise_std)

    def __repr__(self):
        return f"SLSController(n={self.n}, taps={self.length})"


# -- the QP ------------------------------------------------------------------------
def _psd_sqrt(M: np.ndarray) -> np.ndarray:
    if np.count_nonzero(M - np.diag(np.diag(M))) == 0:
        return np.diag(np.sqrt(np.clip(np.diag(M), 0.0, None)))
    w, V = np.linalg.eigh((M + M.T) / 2)
    return (V * np.sqrt(np.clip(w, 0.0, None))) @ V.T


#: SCS's tolerances and iteration limit where it stands in for Clarabel (a singular x0_cov).
SCS_EPS = 1e-9
SCS_MAX_ITERS = 100_000


def _variable_count(instance, dist, T, *, speed, act_delay, fir) -> int:
    """Allowed entries of the maps X[1..T] (X[T] = 0 with ``fir``) and U[0..T-1]: the QP's variables."""
    pairs = np.sort(dist[np.ix_(instance.state_nodes, instance.state_nodes)].ravel())
    inputs = np.sort(dist[np.ix_(instance.input_nodes, instance.state_nodes)].ravel())
    reach = [support_hops(t + 1, speed=speed, act_delay=act_delay) for t in range(T + 1)]
    last = T if fir else T + 1  # X[T] = 0 in the FIR variant
    return int(sum(np.searchsorted(pairs, reach[t], side="right") for t in range(1, last))
               + sum(np.searchsorted(inputs, reach[t], side="right") for t in range(T)))


def _solve_qp(instance, dist, T, *, speed, act_delay, fir):
    """Build and solve the SLS QP; returns (X, U, info dict) or (None, None, info)."""
    import cvxpy as cp  # imported on use: cvxpy takes about a second to import
    import scipy.sparse as sp

    n, m = instance.n, instance.m
    nn = n * n
    # Column-major vec: entry (i, j) of a map sits at j*rows + i and vec(A M) = (I ⊗ A) vec(M).
    # Supports are by hop distance between the nodes that own a map's row and column.
    x_dist = dist[np.ix_(instance.state_nodes, instance.state_nodes)].ravel(order="F")
    u_dist = dist[np.ix_(instance.input_nodes, instance.state_nodes)].ravel(order="F")
    x_masks = [x_dist <= support_hops(t + 1, speed=speed, act_delay=act_delay) for t in range(1, T + 1)]
    if fir:
        x_masks[-1] = np.zeros(nn, dtype=bool)  # X[F] = 0
    u_masks = [u_dist <= support_hops(t + 1, speed=speed, act_delay=act_delay) for t in range(T)]
    keep = np.concatenate(x_masks + u_masks)

    eye_n = sp.identity(n, format="csr")
    kA = sp.kron(eye_n, sp.csr_matrix(instance.A), format="csr")
    kB = sp.kron(eye_n, sp.csr_matrix(instance.B), format="csr")
    I_nn = sp.identity(nn, format="csr")
    # Block rows t = 0..T-1: X[t+1] - A X[t] - B U[t] = (A if t == 0 else 0).
    x_part = sp.kron(sp.identity(T), I_nn) - sp.kron(sp.eye(T, k=-1), kA)
    u_part = -sp.kron(sp.identity(T), kB)
    G = sp.hstack([x_part, u_part], format="csc")[:, keep]
    b = np.zeros(T * nn)
    b[:nn] = instance.A.ravel(order="F")

    # Objective weights per block, normalized by trace(P) for solver scaling.
    scale = instance.trace_P
    z = cp.Variable(int(keep.sum()))
    if instance.x0_factor is None:
        kQ = sp.kron(eye_n, sp.csr_matrix(instance.Q))
        kR = sp.kron(eye_n, sp.csr_matrix(instance.R))
        last = sp.csr_matrix((nn, nn)) if fir else sp.kron(eye_n, sp.csr_matrix(instance.P))
        H = sp.block_diag([kQ] * (T - 1) + [last] + [kR] * T, format="csc")[:, keep]
        H = (H[keep, :] / scale).tocsc()
        H = (H + H.T) / 2
        objective = cp.Minimize(cp.quad_form(z, cp.psd_wrap(H)))
    else:
        # x(0) = F z: a map M costs ‖W^½ M F‖², vec(W^½ M F) = (F' ⊗ W^½) vec(M).
        Ft = sp.csr_matrix(np.asarray(instance.x0_factor).T)
        roots = {key: sp.kron(Ft, sp.csr_matrix(_psd_sqrt(W))) for key, W in
                 (("Q", instance.Q), ("R", instance.R), ("P", instance.P))}
        last = sp.csr_matrix((roots["P"].shape[0], nn)) if fir else roots["P"]
        L = sp.block_diag([roots["Q"]] * (T - 1) + [last] + [roots["R"]] * T, format="csc")[:, keep]
        objective = cp.Minimize(cp.sum_squares((L / np.sqrt(scale)) @ z))
    problem = cp.Problem(objective, [G @ z == b])
    info = {"variables": int(keep.sum()), "constraints": int(G.shape[0])}
    try:
        # The SciPy canonicalization backend compiles one big sparse product fastest.
        problem.solve(solver=cp.CLARABEL, canon_backend=cp.SCIPY_CANON_BACKEND)
    except cp.error.SolverError as exc:
        if instance.x0_cov is None:
            info.update(solver_status=cp.SOLVER_ERROR, error=str(exc))
            return None, None, info
        # A singular Σ₀ leaves the responses on the directions it does not reach free, and Clarabel
        # stops at its first step with a numerical error there (a rank-2 Σ₀ on the paper family at
        # N = 6); SCS solves the same QP (25 iterations there).
        info["solver"] = f"SCS (Clarabel: {exc})"
        try:
            problem.solve(solver=cp.SCS, canon_backend=cp.SCIPY_CANON_BACKEND, eps_abs=SCS_EPS, eps_rel=SCS_EPS,
                          max_iters=SCS_MAX_ITERS)
        except cp.error.SolverError as exc:
            info.update(solver_status=cp.SOLVER_ERROR, error=str(exc))
            return None, None, info
    info["solver_status"] = problem.status
    stats = problem.solver_stats
    info["solve_seconds"] = float(stats.solve_time) if stats and stats.solve_time is not None else float("nan")
    info["iterations"] = int(stats.num_iters) if stats and stats.num_iters is not None else -1
    if solver_status(problem.status) not in USABLE or z.value is None:
        return None, None, info
    value = np.zeros(keep.size)
    value[keep] = z.value
    info["objective"] = float(problem.value) + instance.x0_mean(instance.Q) / scale
    info["residual"] = float(np.max(np.abs(G @ z.value - b))) if b.size else 0.0
    X = np.empty((T + 1, n, n))
    X[0] = np.eye(n)
    X[1:] = value[: T * nn].reshape(T, n, n).transpose(0, 2, 1)
    U = value[T * nn:].reshape(T, n, m).transpose(0, 2, 1)
    return X, U, info


def _realized_objective(instance, controller, T: int) -> float:
    """The QP's normalized objective on the realized closed loop over the QP's horizon T.

    The terminal weight is P in both variants: the FIR maps have ``X[F] = 0``, so
    there it only charges what an inexact realization leaves at F.
    """
    phi_x, phi_u = controller.closed_loop_responses(instance, steps=T)
    if instance.x0_factor is not None:  # x(0) = F z: the maps from z
        phi_x, phi_u = phi_x @ instance.x0_factor, phi_u @ instance.x0_factor
    total = np.einsum("tij,ik,tkj->", phi_x[:T], instance.Q, phi_x[:T])
    total += np.einsum("tij,ik,tkj->", phi_u, instance.R, phi_u)
    total += np.einsum("ij,ik,kj->", phi_x[T], instance.P, phi_x[T])
    return float(total / instance.trace_P)


# -- the method ------------------------------------------------------------------------
@method("sls", label="SLS (delay constraints)", node_blocks=True)
def sls(
    instance,
    *,
    graph: Annotated[str, GRAPH_NAME] = "plant",
    comm_adj=None,
    speed: Annotated[float, Above(0)] = 1.0,
    act_delay: Annotated[int, AtLeast(0)] = 1,
    horizon: Annotated[int, AtLeast(1)] | None = None,
    fir: Annotated[int, AtLeast(1)] | None = None,
) -> Design:
    """SLS with communication-delay constraints on a graph (docs/methods.md).

    Parameters
    ----------
    instance : Instance
    graph : str
        Communication graph by name (see :func:`topology`); ignored when
        ``comm_adj`` is given. The default, the plant graph, is the sparsest
        graph on which the constraints are QI at speed 1.
    comm_adj : array_like, shape (n, n), optional
        An explicit communication graph (nonzero = i receives from j); recorded
        as ``graph = "custom"``.
    speed : float
        Hops of the graph travelled per step (> 0).
    act_delay : int
        Delay convention of the supports, ``max(0, floor(speed (k − act_delay)))``
        hops for ``Φ[k]``; 1 (default) is the GRNN's model, 0 adds one
        instantaneous hop.
    horizon : int, optional
        Horizon of the finite-horizon QP (default: the instance's). A shorter one
        is allowed for large instances; the design is still scored on the
        instance's horizon.
    fir : int, optional
        FIR length F: solve the infinite-horizon problem with ``Φx[F+1] = 0``
        instead (a stationary controller). Exclusive with ``horizon``.

    Returns
    -------
    Design
        ``links`` are the off-diagonal edges of the graph used, information model
        ``"delayed"``. Statuses follow :func:`codesign.solver_status`: infeasible
        supports give ``"infeasible"`` with the reason; an inaccurate solve is kept
        as ``"inaccurate"`` only when the realized closed loop's cost agrees with
        the solver's objective (:func:`codesign.vet_solver_cost`); anything else is
        ``"failed"``, with the reason. ``extras["qi"]`` says whether the delay
        constraints (``speed``, ``act_delay``) are quadratically invariant.
    """
    speed, T = checked_length(instance, speed, act_delay, horizon, fir)
    if comm_adj is None:
        name = graph
        adj = topology(instance, graph)
    else:
        name = "custom"
        adj = np.asarray(comm_adj, dtype=float)
        N = instance.nodes
        if adj.shape != (N, N):
            raise ValueError(f"comm_adj must have shape {(N, N)} (one row per node), got {adj.shape}")
        adj = ((adj != 0) | np.eye(N, dtype=bool)).astype(float)
    params = {
        "graph": name,
        "speed": speed,
        "act_delay": int(act_delay),
        "horizon": None if fir is not None else T,
        "fir": None if fir is None else int(fir),
    }
    links, self_loops = count_links(adj)
    dist = hop_distances(adj)
    variables = _variable_count(instance, dist, T, speed=speed, act_delay=act_delay, fir=fir is not None)
    if variables > MAX_QP_VARIABLES:
        return Design.failure(
            "sls", params, FAILED,
            f"the joint SLS QP would have {variables:,} variables on {instance.n} states, above "
            f"MAX_QP_VARIABLES = {MAX_QP_VARIABLES:,} (3-5 kB each: {variables * 3e-6:.0f}-{variables * 5e-6:.0f} GB); "
            "sls_local solves the localized problem column by column at any size",
            info_model="delayed", links=links, self_loops=self_loops,
            extras={"variables": variables, "size_guard": True})
    qi = is_quadratically_invariant(instance, adj, speed=speed, act_delay=act_delay)
    extras = {"qi": qi.qi}
    if not qi.qi:
        extras["qi_pair"] = list(qi.pair)

    with Timer() as timer:
        X, U, info = _solve_qp(instance, dist, T, speed=speed, act_delay=act_delay, fir=fir is not None)
    extras.update({k: v for k, v in info.items() if k != "error"})
    raw = info["solver_status"]
    status = solver_status(raw)

    def fail(kind, message):
        return Design.failure("sls", params, kind, message, info_model="delayed", seconds=timer.seconds,
                              links=links, self_loops=self_loops, extras=extras)

    if status == INFEASIBLE:
        why = f"support constraints on graph {name!r} at speed {speed:g} cannot be met ({raw})"
        why += f"; {qi.reason}" if not qi.qi else "; the graph is QI: the FIR length or horizon is too short"
        return fail(INFEASIBLE, why)
    if X is None:
        return fail(FAILED, f"solver status {raw!r}" + (f": {info['error']}" if "error" in info else ""))
    if not np.isfinite(info["objective"]) or info["objective"] > _ABSURD_OBJECTIVE:
        return fail(FAILED, f"solver said {raw} with an absurd normalized objective {info['objective']:.3g}")

    controller = SLSController(X, U)
    cost = response_cost(instance, *controller.closed_loop_responses(instance))
    extras["realized_objective_gap"] = None
    if (fir is None and T == instance.horizon) or (fir is not None and fir <= instance.horizon):
        # Then the QP objective is exactly the benchmark cost of the designed maps.
        realized = cost
    elif status == INACCURATE:
        # The benchmark cost is over another horizon; an inaccurate solve (solvers report
        # them with objectives of 1e29 on infeasible supports) is checked on its own
        # horizon instead. Optimal solves are trusted there, as they always were.
        realized = _realized_objective(instance, controller, T)
    else:
        realized = None
    if realized is not None:
        extras["realized_objective_gap"] = abs(realized - info["objective"]) / max(1.0, abs(realized))
        rtol = _REALIZATION_RTOL if status == OPTIMAL else INACCURATE_RTOL
        status, why = vet_solver_cost(status, info["objective"], realized, rtol=rtol)
        if status == FAILED:
            return fail(FAILED, f"solver said {raw} but, re-evaluated on the realized closed loop, {why} "
                                  f"(dynamics residual {info['residual']:.2e})")
    if not np.isfinite(cost):
        return fail(FAILED, f"realized closed loop has non-finite cost {cost}")
    message = "" if status == OPTIMAL else (
        f"solver status {raw}; the realized closed loop agrees with its objective "
        f"(relative gap {extras['realized_objective_gap']:.1e})")
    return Design(
        method="sls",
        params=params,
        controller=controller,
        cost=cost,
        links=links,
        self_loops=self_loops,
        info_model="delayed",
        status=status,
        message=message,
        seconds=timer.seconds,
        extras=extras,
    )


@method("sls_topologies", label="SLS (topology family)", node_blocks=True)
def sls_topologies(
    instance,
    *,
    graphs: Annotated[list[Annotated[str, GRAPH_NAME]], NotEmpty()] = list(TOPOLOGY_FAMILY),
    speed: Annotated[float, Above(0)] = 1.0,
    act_delay: Annotated[int, AtLeast(0)] = 1,
    horizon: Annotated[int, AtLeast(1)] | None = None,
    fir: Annotated[int, AtLeast(1)] | None = None,
) -> list[Design]:
    """SLS on a family of communication graphs, one design per graph.

    The default family runs from the given graph (infeasible at speed 1: the
    plant spreads faster than information) through the plant graph (the sparsest
    QI graph) and its 2- and 3-hop closures to the complete graph.

    Graphs with the same edges pose the same QP, which is solved once: the later
    names get the first one's design (same maps, cost and status, to the bit) with
    their own name, the seconds of the copy and ``extras["same_graph_as"]``. On the
    paper's family at N = 20 the 2-hop closure of the plant graph is usually
    complete already, so 3 of the 5 default graphs are solved, not 5.

    Parameters
    ----------
    instance : Instance
    graphs : list of str
        Graph names (see :func:`topology`), one design each.
    speed : float
        Hops of the graph travelled per step (> 0), as in :func:`sls`.
    act_delay : int
        Delay convention of the supports, as in :func:`sls`: 1 is the GRNN's model.
    horizon : int, optional
        Horizon of the finite-horizon QP (default: the instance's), as in :func:`sls`.
    fir : int, optional
        FIR length: the infinite-horizon problem with a finite response, as in :func:`sls`.
    """
    if isinstance(graphs, str) or not graphs:
        raise ValueError(f"graphs must be a non-empty list of graph names, got {graphs!r}")
    designs, solved = [], {}
    for name in graphs:
        with Timer() as timer:
            edges = topology(instance, name).tobytes()
            first = solved.get(edges)
        if first is None:
            designs.append(solved.setdefault(edges, sls(instance, graph=name, speed=speed, act_delay=act_delay,
                                                        horizon=horizon, fir=fir)))
        else:
            designs.append(replace(first, params={**first.params, "graph": name}, seconds=timer.seconds,
                                   extras={**first.extras, "same_graph_as": first.params["graph"]}))
    return designs
