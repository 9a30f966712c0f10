"""Localized SLS: d-hop locality on top of the delay constraints, solved column by column.

The SLS problem of :mod:`baselines.sls` separates over the columns of the response
maps: column j of ``X[t]``, ``U[t]`` is the closed loop's answer to ``x(0) = e_j``.
Localized SLS (Wang, Matni & Doyle, "Localized LQR optimal control", 2014) adds
*locality*: every map is zero outside ``locality`` hops of the communication graph,
whatever the delay would allow. Column j then lives on the ``locality``-hop
neighbourhood of its node, so each column is a small equality-constrained least
squares problem whose size does not grow with N,

    min  sum_t ||Q^½ X[t] e_j||² + ||R^½ U[t] e_j||² (+ ||P^½ X[T] e_j||²)
    s.t. X[t+1] e_j = A X[t] e_j + B U[t] e_j,   X[0] e_j = e_j,

with the dynamics imposed on every row they reach (outside the neighbourhood they
say ``A X[t] e_j + B U[t] e_j = 0``: the boundary must be held at zero, which can be
impossible: the column is then infeasible). Its KKT system is solved exactly by a
sparse LU factorization (:func:`scipy.sparse.linalg.splu`; the problem is a QP with
equality constraints only, so an interior-point solver would do the same work in one
step), and the solve time grows linearly in N.

With ``locality`` at least the graph's diameter the constraints are those of
:func:`baselines.sls` and the designs agree (tests: same cost to the solver's
tolerance). The design is scored on its designed maps, after checking that they
satisfy the dynamics to rounding: the SLS realization then reproduces them exactly
(tests compare with the realized closed loop at small N).

An initial-state covariance Σ₀ (``Instance.x0_cov``) weighs the columns by Σ₀'s
diagonal when it is diagonal (each column's minimizer unchanged); a non-diagonal Σ₀
couples the columns and is refused (:func:`baselines.sls` solves that problem).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from codesign.cluster import spread
from codesign.design import Design, Timer, count_links
from codesign.evaluation import response_cost
from codesign.instances import hop_distances
from codesign.methods import Above, AtLeast, method
from codesign.status import FAILED, INFEASIBLE, OPTIMAL

from .sls import GRAPH_NAME, SLSController, checked_length, support_hops, topology

__all__ = ["sls_local", "solve_column"]

#: Static regularization of the KKT system and its iterative refinement (as interior-point
#: QP solvers do): the dynamics of a localized column are often rank-deficient (a boundary
#: row that others already imply), which makes the plain KKT matrix singular. Where they
#: are nearly so (singular values down to 1e-9 in the paper family at N = 1000), refinement
#: stalls and a dense rank-revealing solve takes over. δ = 1e-11 and 60 refinements leave 3 %
#: of the columns to it at 3 hops, N = 500 (δ = 1e-9 and 30: 20 %, twice the time), with the
#: same maps to 1e-12.
_REGULARIZATION = 1e-11
_REFINEMENTS = 60

#: A column's dynamics residual (relative to its right-hand side) above this means the
#: constraints cannot be met: the column is infeasible.
_FEASIBILITY_RTOL = 1e-8

#: Columns per task where a design spreads its columns over the dask cluster it runs in: about
#: 1.5 s of work at N = 1000 (3 hops, FIR 10: 30 ms a column), long beside a task's overhead.
COLUMNS_PER_TASK = 50


def _allowed_hops(T: int, locality: int, *, speed: float, act_delay: int) -> list[int]:
    """Hops allowed in X[t] and U[t] for t = 0..T (the SLS papers' Φ[t+1])."""
    return [min(locality, support_hops(t + 1, speed=speed, act_delay=act_delay)) for t in range(T + 1)]


def _solve_columns(instance, node_dist, hops, fir, columns):
    return [solve_column(instance, j, node_dist, hops, fir=fir) for j in columns]


def _all_columns(instance, node_dist, hops, *, fir: bool) -> tuple[list, int]:
    """Every column's :func:`solve_column`, in order, and the number of tasks that solved them.

    Run as a task of a dask cluster (``compare run --executor dask...``), the design spreads
    its columns over the cluster's workers in tasks of :data:`COLUMNS_PER_TASK` columns
    (:func:`codesign.cluster.spread`); elsewhere it solves them in turn. The columns are
    independent, so both give the same numbers.
    """
    n = instance.n
    chunks = [range(start, min(start + COLUMNS_PER_TASK, n)) for start in range(0, n, COLUMNS_PER_TASK)]
    solved, tasks = spread(_solve_columns, chunks, shared=(instance, node_dist, hops, fir))
    return [column for chunk in solved for column in chunk], tasks


def solve_column(instance, j: int, node_dist: np.ndarray, hops: list[int], *, fir: bool):
    """Column j of the localized maps: ``(x_rows, X_j, u_rows, U_j, residual)``.

    ``x_rows[t]``, ``u_rows[t]`` are the states and inputs allowed in ``X[t] e_j`` and
    ``U[t] e_j`` (``X_j[t]``, ``U_j[t]`` their values). ``residual`` is the largest
    violation of the dynamics relative to ``max(1, |A e_j|)``: above rounding, the
    column is infeasible.
    """
    import scipy.sparse as sp

    T = len(hops) - 1
    A, B = instance.A, instance.B
    d_state = node_dist[instance.state_nodes, instance.state_nodes[j]]
    d_input = node_dist[instance.input_nodes, instance.state_nodes[j]]
    x_rows = [np.array([j])] + [np.flatnonzero(d_state <= hops[t]) for t in range(1, T + 1)]
    if fir:
        x_rows[T] = np.zeros(0, dtype=int)
    u_rows = [np.flatnonzero(d_input <= hops[t]) for t in range(T)]
    # Variables: X[1..T] then U[0..T-1], each block its allowed rows.
    x_off = np.cumsum([0] + [r.size for r in x_rows[1:]])
    u_off = x_off[-1] + np.cumsum([0] + [r.size for r in u_rows])
    size = int(u_off[-1])
    # Dynamics rows of step t: every state that X[t+1], A X[t] or B U[t] can reach.
    blocks, rhs, row_base = [], [], 0
    for t in range(T):
        reached = np.flatnonzero(np.any(A[:, x_rows[t]] != 0, axis=1) | np.any(B[:, u_rows[t]] != 0, axis=1))
        rows = np.union1d(reached, x_rows[t + 1])
        position = {r: k for k, r in enumerate(rows)}
        if x_rows[t + 1].size:
            blocks.append((row_base + np.array([position[r] for r in x_rows[t + 1]]),
                           x_off[t] + np.arange(x_rows[t + 1].size), np.ones(x_rows[t + 1].size)))
        for cols, M, offset in ((u_rows[t], B, u_off[t]),) + (((x_rows[t], A, x_off[t - 1]),) if t else ()):
            sub = M[np.ix_(rows, cols)]
            r, c = np.nonzero(sub)
            blocks.append((row_base + r, offset + c, -sub[r, c]))
        b = np.zeros(rows.size)
        if t == 0:
            b = A[rows, j].copy()
        rhs.append(b)
        row_base += rows.size
    r, c, v = (np.concatenate(part) for part in zip(*blocks))
    G = sp.csr_matrix((v, (r, c)), shape=(row_base, size))
    b = np.concatenate(rhs)
    # A reached row that no variable can move says 0 = b there: kept only if b is not 0 (then
    # infeasible); dropped otherwise, so that the KKT matrix is not singular for nothing.
    active = (np.diff(G.indptr) > 0) | (b != 0)
    G, b = G[active].tocsc(), b[active]
    weights = [instance.Q[np.ix_(rows, rows)] for rows in x_rows[1:T]]
    weights.append(np.zeros((0, 0)) if fir else instance.P[np.ix_(x_rows[T], x_rows[T])])
    weights += [instance.R[np.ix_(rows, rows)] for rows in u_rows]
    H = sp.block_diag(weights, format="csc") if size else sp.csc_matrix((0, 0))
    solution = _solve_kkt(sp.bmat([[2 * H, G.T], [G, None]], format="csc"),
                          np.concatenate([np.zeros(size), b]), size)
    z = solution[:size] if solution is not None else _min_weighted_norm(G, b, H)
    residual = float(np.max(np.abs(G @ z - b), initial=0.0)) / max(1.0, float(np.max(np.abs(b), initial=0.0)))
    X_j = [np.ones(1)] + [z[x_off[t - 1]:x_off[t]] for t in range(1, T + 1)]
    U_j = [z[u_off[t]:u_off[t + 1]] for t in range(T)]
    return x_rows, X_j, u_rows, U_j, residual


def _solve_kkt(kkt, rhs, size: int) -> np.ndarray | None:
    """Solve the KKT system ``kkt @ s = rhs`` by a sparse LU, or None if it does not converge.

    The quasi-definite ``kkt + diag(δ I, -δ I)`` is always factorizable; iterative
    refinement against the unregularized matrix removes the regularization's bias.
    It converges fast unless the dynamics are nearly rank-deficient (singular values
    far below √δ): then None, and the caller takes the dense minimum-norm solve.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg

    delta = _REGULARIZATION * max(1.0, abs(kkt).max())
    shift = sp.diags(np.r_[np.full(size, delta), np.full(kkt.shape[0] - size, -delta)], format="csc")
    lu = scipy.sparse.linalg.splu((kkt + shift).tocsc())
    solution = lu.solve(rhs)
    scale = max(1.0, float(np.max(np.abs(rhs), initial=0.0)))
    for _ in range(_REFINEMENTS):
        residual = rhs - kkt @ solution
        if np.max(np.abs(residual), initial=0.0) <= 1e-14 * scale:
            return solution
        solution += lu.solve(residual)
    return None


def _min_weighted_norm(G, b, H) -> np.ndarray:
    """``argmin z'Hz`` subject to ``Gz = b`` (least squares if inconsistent), dense and rank-revealing.

    With ``H = C'C``, ``w = Cz`` is the minimum-norm least-squares solution of
    ``G C^{-1} w = b`` (LAPACK's SVD-based ``gelsd``, which drops singular values
    below 1e-13 of the largest).
    """
    import scipy.linalg

    G = G.toarray()
    H = H.toarray()
    try:
        C = scipy.linalg.cholesky(H, lower=False)
    except np.linalg.LinAlgError:  # a singular weight (Q only semidefinite): least squares on the KKT system
        kkt = np.block([[2 * H, G.T], [G, np.zeros((G.shape[0], G.shape[0]))]])
        return scipy.linalg.lstsq(kkt, np.r_[np.zeros(H.shape[0]), b], cond=1e-13)[0][:H.shape[0]]
    M = scipy.linalg.solve_triangular(C, G.T, trans="T").T  # G C^{-1}
    w = scipy.linalg.lstsq(M, b, cond=1e-13)[0]
    return scipy.linalg.solve_triangular(C, w)


@method("sls_local", label="SLS (localized)", node_blocks=True)
def sls_local(
    instance,
    *,
    locality: Annotated[int, AtLeast(0)] = 2,
    graph: Annotated[str, GRAPH_NAME] = "plant",
    speed: Annotated[float, Above(0)] = 1.0,
    act_delay: Annotated[int, AtLeast(0)] = 1,
    horizon: Annotated[int, AtLeast(1)] | None = None,
    fir: Annotated[int, AtLeast(1)] | None = None,
) -> Design:
    """Localized SLS: the delay constraints of :func:`baselines.sls` plus ``locality``-hop maps, column by column.

    Parameters
    ----------
    instance : Instance
    locality : int
        Hops of ``graph`` beyond which every response map is zero (d-hop locality).
    graph : str
        Communication graph by name (see :func:`baselines.topology`).
    speed : float
        Hops of the graph travelled per step (> 0), as in :func:`baselines.sls`:
        ``Φ[k]`` may reach ``max(0, floor(speed (k - act_delay)))`` hops, capped at ``locality``.
    act_delay : int
        Delay convention of the supports, as in :func:`baselines.sls`: 1 is the GRNN's model.
    horizon : int, optional
        Horizon of the finite-horizon problem (default: the instance's), with the
        terminal cost P.
    fir : int, optional
        FIR length F instead: ``X[F] = 0`` and no terminal cost. Exclusive with ``horizon``.

    Returns
    -------
    Design
        ``links`` are the edges of ``graph``, which relay the information, as for
        :func:`baselines.sls` (none at ``locality = 0``); information model
        ``"delayed"``. ``"infeasible"`` when some column cannot meet the constraints
        (the message names the first one's node and how many others); the extras give
        the columns, the largest column's variables, the largest dynamics residual, the
        infeasible columns' count and the tasks that solved the columns (1 outside a dask
        cluster; see :func:`_all_columns`).
    """
    if isinstance(locality, bool) or not isinstance(locality, (int, np.integer)) or locality < 0:
        raise ValueError(f"locality must be a non-negative integer, got {locality!r}")
    cov = instance.x0_cov
    if cov is not None and np.count_nonzero(cov - np.diag(np.diag(cov))):
        # tr(Φ Σ₀ Φ'Q) couples the columns unless Σ₀ is diagonal; with a diagonal Σ₀ each column's
        # problem is only scaled, so its minimizer is the one solved here.
        raise ValueError("sls_local solves the columns of the response maps one by one, which is the problem "
                         "only for a diagonal x0_cov; this instance's couples states: use sls")
    speed, T = checked_length(instance, speed, act_delay, horizon, fir)
    params = {"locality": int(locality), "graph": graph, "speed": speed, "act_delay": int(act_delay),
              "horizon": None if fir is not None else T, "fir": None if fir is None else int(fir)}
    n, m = instance.n, instance.m
    with Timer() as timer:
        adj = topology(instance, graph)
        node_dist = hop_distances(adj)
        hops = _allowed_hops(T, int(locality), speed=speed, act_delay=int(act_delay))
        X = np.zeros((T + 1, n, n))
        U = np.zeros((T, m, n))
        worst, largest, infeasible = 0.0, 0, []
        columns, tasks = _all_columns(instance, node_dist, hops, fir=fir is not None)
        for j, (x_rows, X_j, u_rows, U_j, residual) in enumerate(columns):
            for t in range(T + 1):
                X[t, x_rows[t], j] = X_j[t]
            for t in range(T):
                U[t, u_rows[t], j] = U_j[t]
            largest = max(largest, sum(r.size for r in x_rows[1:]) + sum(r.size for r in u_rows))
            worst = max(worst, residual)
            if residual > _FEASIBILITY_RTOL:
                infeasible.append(j)
    extras = {"columns": n, "largest_column": largest, "dynamics_residual": worst, "column_tasks": tasks}
    # As in sls: the links are the graph's edges that relay information (none when no map reaches a hop).
    links, self_loops = count_links(adj if max(hops) >= 1 else np.eye(instance.nodes))
    extras["infeasible_columns"] = len(infeasible)
    if infeasible:
        first, node = infeasible[0], int(instance.state_nodes[infeasible[0]])
        others = f" (and {len(infeasible) - 1} other column(s))" if len(infeasible) > 1 else ""
        return Design.failure(
            "sls_local", params, INFEASIBLE,
            f"column {first} (node {node}){others} cannot meet {locality}-hop locality on graph {graph!r} "
            f"at speed {speed:g} over {T} steps{' with X[F] = 0' if fir is not None else ''} "
            f"(dynamics residual {worst:.2e})",
            info_model="delayed", seconds=timer.seconds, links=links, self_loops=self_loops, extras=extras)
    controller = SLSController(X, U)
    cost = response_cost(instance, *_scored_maps(instance, X, U, T, fir=fir is not None))
    if not np.isfinite(cost):
        return Design.failure("sls_local", params, FAILED, f"the designed maps have non-finite cost {cost}",
                              info_model="delayed", seconds=timer.seconds, links=links, self_loops=self_loops,
                              extras=extras)
    return Design(method="sls_local", params=params, controller=controller, cost=cost, links=links,
                  self_loops=self_loops, info_model="delayed", status=OPTIMAL, seconds=timer.seconds,
                  extras=extras)


def _scored_maps(instance, X, U, T, *, fir: bool):
    """The closed loop the SLS realization of the designed maps gives over the instance's horizon.

    Exact maps are reproduced by the realization: over the maps' own horizon they are
    the closed loop, and an FIR response (``X[F] = 0``) stays at zero after F steps.
    Otherwise (a finite-horizon design over another horizon) the realization is rolled out.
    """
    H = instance.horizon
    if T == H:
        return X, U
    if fir and T < H:
        pad = ((0, H - T), (0, 0), (0, 0))
        return np.pad(X, pad), np.pad(U, pad)
    return SLSController(X, U).closed_loop_responses(instance)
