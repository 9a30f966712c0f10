"""Problem instances: the paper's random family and users' own systems.

An :class:`Instance` is everything a method needs to design a controller and
everything the evaluator needs to score it: the dynamics ``x(t+1) = A x(t) + B u(t)``,
the stage costs ``Q`` and ``R``, the terminal cost ``P`` (the DARE solution, so that
centralized LQR scores exactly 1), the horizon, the given communication graph and
the plant graph.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

__all__ = ["Instance", "InstanceError", "check_instance", "paper_instance", "hop_distances", "node_ranks",
           "node_width", "knn_neighbours", "is_connected", "knn_graph", "gaussian_states"]


class InstanceError(ValueError):
    """Raised for malformed problem data (shapes, NaN, costs, stabilizability)."""


def _frozen(label: str, array: np.ndarray) -> np.ndarray:
    if np.iscomplexobj(array):
        raise InstanceError(f"{label} is complex; an instance holds real matrices")
    array = np.array(array, dtype=float, copy=True)
    if not np.all(np.isfinite(array)):
        raise InstanceError(f"{label} has non-finite entries (NaN or inf)")
    array.setflags(write=False)
    return array


def check_instance(value, where: str = "") -> None:
    """Raise TypeError, prefixed by ``where``, when ``value`` is not an :class:`Instance`.

    Methods read the instance's attributes at once; without this a ``None`` or an
    array gives an AttributeError from deep inside the method.
    """
    if not isinstance(value, Instance):
        prefix = f"{where}: " if where else ""
        shown = repr(value)
        shown = shown if len(shown) <= 60 else shown[:57] + "..."
        raise TypeError(f"{prefix}expected a codesign.Instance (Instance.from_matrices, paper_instance or a "
                        f"family's instance), got {type(value).__name__} {shown}")


def hop_distances(adj: np.ndarray) -> np.ndarray:
    """All-pairs hop distance of the directed graph ``adj[i, j] != 0`` (i -> j).

    Unreachable pairs get ``np.inf``; the diagonal is 0.
    """
    import networkx as nx  # imported on use: `compare --help` and `compare methods` must stay fast

    adj = np.asarray(adj) != 0
    graph = nx.from_numpy_array(adj.astype(int), create_using=nx.DiGraph)
    graph.remove_edges_from(nx.selfloop_edges(graph))
    n = adj.shape[0]
    dist = np.full((n, n), np.inf)
    for source, lengths in nx.all_pairs_shortest_path_length(graph):
        for target, d in lengths.items():
            dist[source, target] = d
    return dist


@dataclass(frozen=True, eq=False)
class Instance:
    """One linear-quadratic distributed control problem.

    ``n`` is the number of states and ``m`` the number of inputs; the N nodes
    (:attr:`nodes`) each hold one or more states, so n = N only when each node
    has one state, as in the paper's family.

    Attributes
    ----------
    A : ndarray, shape (n, n)
    B : ndarray, shape (n, m)
        Dynamics ``x(t+1) = A x(t) + B u(t)`` with n states and m inputs.
    Q : ndarray, shape (n, n)
    R : ndarray, shape (m, m)
        Stage cost ``x'Qx + u'Ru``.
    P : ndarray, shape (n, n)
        Terminal cost, the stabilizing DARE solution.
    horizon : int
        T; the cost sums stages 0..T-1 and adds ``x(T)' P x(T)``.
    comm_adj : ndarray of {0, 1}, shape (N, N)
        The given communication graph between the N nodes, self-loops included;
        ``comm_adj[i, j] = 1`` means node i may receive from node j.
    plant_adj : ndarray of {0, 1}, shape (N, N)
        Who influences whom in one step: node j's states or inputs enter node i's
        states through ``A`` or ``B``.
    spec : dict
        Where the instance came from (family and arguments); JSON-serializable. It
        keys stored results, so two instances with the same spec are the same.
    state_nodes, input_nodes : ndarray of int, shapes (n,) and (m,)
        The node each state and each input belongs to (nodes 0..N-1). By default
        one state and one input per node, in order (the paper's family).
    x0_cov : ndarray, shape (n, n), or None
        Covariance Σ₀ of the initial state, ``x(0) ~ N(0, Σ₀)``; None (the
        default, and the paper's problem) is the identity. Every cost, gradient
        and the normalizer :attr:`trace_P` = trace(P Σ₀) read it, so a problem
        whose source weights disturbances by ``B1 B1'`` (an H2 problem, as in
        lqrsp) is posed with ``x0_cov = B1 @ B1.T``. It may be singular.
    """

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    horizon: int
    comm_adj: np.ndarray
    plant_adj: np.ndarray
    spec: dict[str, Any] = field(default_factory=dict)
    state_nodes: np.ndarray | None = None
    input_nodes: np.ndarray | None = None
    x0_cov: np.ndarray | None = None

    # -- construction -----------------------------------------------------
    @classmethod
    def from_matrices(
        cls,
        A,
        B,
        *,
        Q=None,
        R=None,
        comm_adj=None,
        horizon: int = 50,
        name: str | None = None,
        state_nodes=None,
        input_nodes=None,
        x0_cov=None,
    ) -> "Instance":
        """Build an instance from a user's own matrices, with validation.

        Parameters
        ----------
        A : array_like, shape (n, n)
        B : array_like, shape (n, m)
            Dynamics.
        Q : array_like, shape (n, n), optional
        R : array_like, shape (m, m), optional
            Stage costs, identity by default. ``Q`` must be symmetric positive
            semidefinite and not zero, ``R`` symmetric positive definite.
        comm_adj : array_like, shape (N, N), optional
            Given communication graph between the N nodes (nonzero = link).
            Self-loops are added. Defaults to the plant graph.
        horizon : int
            Finite horizon T >= 1.
        name : str, optional
            A label stored in :attr:`spec`.
        state_nodes : array_like of int, shape (n,), optional
            The node of each state, numbering the nodes 0..N-1; every node has at
            least one state. Default: one state per node (N = n).
        input_nodes : array_like of int, shape (m,), optional
            The node of each input (a node may have none). Default: one input per
            node, which needs m = N.
        x0_cov : array_like, shape (n, n), optional
            Covariance of the initial state, symmetric positive semidefinite;
            the identity by default. For a disturbance input ``B1`` (the H2
            problem ``trace(B1' P_K B1)``) pass ``B1 @ B1.T``.

        Raises
        ------
        InstanceError
            Naming the problem: shapes, non-finite entries, Q not PSD, R not PD,
            x0_cov not PSD or not seen by the cost, (A, B) not stabilizable, bad
            horizon.
        """
        A = _as_matrix("A", A)
        n = A.shape[0]
        if A.shape != (n, n):
            raise InstanceError(f"A must be square, got shape {A.shape}")
        if n == 0:
            raise InstanceError("A is empty (shape (0, 0)): an instance needs at least one state")
        B = _as_matrix("B", B)
        if B.shape[0] != n:
            raise InstanceError(f"B must have {n} rows to match A, got shape {B.shape}")
        m = B.shape[1]
        if m == 0:
            raise InstanceError(f"B has no columns (shape {B.shape}): an instance needs at least one input")
        state_nodes, input_nodes = _node_maps(n, m, state_nodes, input_nodes)
        nodes = int(state_nodes.max()) + 1
        Q = np.eye(n) if Q is None else _as_matrix("Q", Q)
        R = np.eye(m) if R is None else _as_matrix("R", R)
        for label, M, size in (("Q", Q, n), ("R", R, m)):
            if M.shape != (size, size):
                raise InstanceError(f"{label} must have shape {(size, size)}, got {M.shape}")
            if not np.allclose(M, M.T, atol=1e-10 * max(1.0, np.abs(M).max())):
                raise InstanceError(f"{label} must be symmetric")
        q_min = np.linalg.eigvalsh(Q).min()
        if q_min < -1e-10 * max(1.0, np.abs(Q).max()):
            raise InstanceError(f"Q must be positive semidefinite (smallest eigenvalue {q_min:.3g})")
        if not np.any(Q):
            raise InstanceError("Q must not be zero: costs are normalized by trace(P), which would be 0")
        r_min = np.linalg.eigvalsh(R).min()
        if r_min <= 1e-12 * max(1.0, np.abs(R).max()):
            raise InstanceError(f"R must be positive definite (smallest eigenvalue {r_min:.3g})")
        if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
            raise InstanceError(f"horizon must be a positive integer, got {horizon!r}")
        plant_adj = _node_coupling(A != 0, state_nodes, state_nodes, nodes)
        plant_adj = ((plant_adj + _node_coupling(B != 0, state_nodes, input_nodes, nodes)) != 0).astype(float)
        if comm_adj is None:
            comm = plant_adj.copy()
        else:
            comm = _as_matrix("comm_adj", comm_adj)
            if comm.shape != (nodes, nodes):
                raise InstanceError(f"comm_adj must have shape {(nodes, nodes)} (one row per node), got {comm.shape}")
            comm = (comm != 0).astype(float)
        np.fill_diagonal(comm, 1.0)
        cov = None if x0_cov is None else _covariance(x0_cov, n)
        P = solve_dare(A, B, Q, R)
        if cov is not None and not np.sum(P * cov) > 0:
            raise InstanceError("x0_cov: trace(P x0_cov) is 0, so LQR's cost and every normalized cost would be 0/0 "
                                "(the initial states it allows cost nothing)")
        digest = hashlib.sha256()
        scalar = nodes == n == m and np.array_equal(state_nodes, np.arange(n)) and np.array_equal(input_nodes, np.arange(m))
        # x0_cov enters the digest only when given, so that every identity-covariance key stays what it was.
        extra = (() if scalar else (state_nodes, input_nodes)) + (() if cov is None else (cov,))
        for M in (A, B, Q, R, comm) + extra:
            digest.update(np.ascontiguousarray(M, dtype=float).tobytes())
        spec = {"family": "matrices", "n": nodes, "horizon": int(horizon), "sha256": digest.hexdigest()[:16]}
        if not scalar:
            spec.update(states=n, inputs=m)
        if name is not None:
            spec["name"] = str(name)
        return cls(A, B, Q, R, P, int(horizon), comm, plant_adj, spec, state_nodes, input_nodes, cov)

    def __post_init__(self):
        for name in ("A", "B", "Q", "R", "P", "comm_adj", "plant_adj"):
            object.__setattr__(self, name, _frozen(name, getattr(self, name)))
        object.__setattr__(self, "spec", dict(self.spec))
        for name, size in (("state_nodes", self.A.shape[0]), ("input_nodes", self.B.shape[1])):
            value = getattr(self, name)
            nodes = np.arange(size) if value is None else np.array(value, dtype=int, copy=True)
            nodes.setflags(write=False)
            object.__setattr__(self, name, nodes)
        if self.x0_cov is not None:
            object.__setattr__(self, "x0_cov", _frozen("x0_cov", _covariance(self.x0_cov, self.A.shape[0])))

    # -- derived quantities -------------------------------------------------
    @property
    def n(self) -> int:
        """Number of states n, not of nodes (:attr:`nodes`); the two are equal only when each node has one state."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Number of inputs."""
        return self.B.shape[1]

    @property
    def nodes(self) -> int:
        """Number of nodes N: the size of the communication and plant graphs."""
        return self.comm_adj.shape[0]

    @property
    def scalar_nodes(self) -> bool:
        """One state and one input per node, in order (every method supports this)."""
        return (self.n == self.m == self.nodes and np.array_equal(self.state_nodes, np.arange(self.n))
                and np.array_equal(self.input_nodes, np.arange(self.m)))

    def node_support(self, K) -> np.ndarray:
        """Node-level support (N, N) of a gain K (m, n): node i uses node j if any input of i reads a state of j."""
        return _node_coupling(np.asarray(K) != 0, self.input_nodes, self.state_nodes, self.nodes)

    def block_mask(self) -> np.ndarray:
        """(m, n) mask of the gain entries from a node's own states to its own inputs (decentralized)."""
        return self.input_nodes[:, None] == self.state_nodes[None, :]

    def block_norms(self, K) -> np.ndarray:
        """(N, N) Frobenius norms of the node blocks of a gain K (m, n): node i's inputs by node j's states."""
        K = np.asarray(K, dtype=float)
        return np.sqrt(_one_hot(self.input_nodes, self.nodes) @ (K * K) @ _one_hot(self.state_nodes, self.nodes).T)

    def expand_blocks(self, node_values) -> np.ndarray:
        """An (N, N) array repeated over the entries of each node block, as an (m, n) gain-shaped array."""
        return np.asarray(node_values)[np.ix_(self.input_nodes, self.state_nodes)]

    @property
    def seed(self) -> int:
        """The generator seed, or 0 for user-supplied matrices."""
        return int(self.spec.get("seed", 0))

    @property
    def trace_P(self) -> float:
        """Normalizer: centralized LQR's expected cost, trace(P Σ₀) with x(0) ~ N(0, Σ₀) (trace(P) by default)."""
        return self.x0_mean(self.P)

    def x0_mean(self, M) -> float:
        """E[x(0)' M x(0)] = trace(M Σ₀) (trace(M) for Σ₀ = I)."""
        if self.x0_cov is None:
            return float(np.trace(M))
        return float(np.sum(M * self.x0_cov))

    @cached_property
    def x0_covariance(self) -> np.ndarray:
        """Σ₀, the covariance of x(0): :attr:`x0_cov`, or the identity."""
        cov = np.eye(self.n) if self.x0_cov is None else self.x0_cov
        cov.setflags(write=False)
        return cov

    @cached_property
    def x0_factor(self) -> np.ndarray | None:
        """F (n, r) with Σ₀ = F F' and r = rank Σ₀, so that ``x(0) = F z`` with z ~ N(0, I_r); None for Σ₀ = I."""
        if self.x0_cov is None:
            return None
        values, vectors = np.linalg.eigh(self.x0_cov)
        keep = values > 1e-12 * max(values.max(), 0.0)
        F = vectors[:, keep] * np.sqrt(values[keep])
        F.setflags(write=False)
        return F

    @cached_property
    def x0_whitener(self) -> np.ndarray | None:
        """W (r, n), the pseudo-inverse of :attr:`x0_factor`: z = W x(0) for every x(0) = F z; None for Σ₀ = I."""
        if self.x0_factor is None:
            return None
        W = np.linalg.pinv(self.x0_factor)
        W.setflags(write=False)
        return W

    def initial_states(self, rng, size: int) -> np.ndarray:
        """``size`` draws of x(0) ~ N(0, Σ₀) from ``rng`` as rows (size, n).

        With Σ₀ = I these are exactly ``rng.standard_normal((size, n))``, the
        draws every shipped report rests on.
        """
        return gaussian_states(rng, size, self.n, self.x0_factor)

    @cached_property
    def K_lqr(self) -> np.ndarray:
        """Centralized LQR gain for ``u = K x`` (sign included)."""
        BtP = self.B.T @ self.P
        K = -np.linalg.solve(self.R + BtP @ self.B, BtP @ self.A)
        K.setflags(write=False)
        return K

    @cached_property
    def gso(self) -> np.ndarray:
        """Given graph shift operator: ``comm_adj`` divided by its spectral norm."""
        S = self.comm_adj / np.linalg.norm(self.comm_adj, 2)
        S.setflags(write=False)
        return S

    @property
    def open_loop_radius(self) -> float:
        """Spectral radius of A."""
        return float(np.max(np.abs(np.linalg.eigvals(self.A))))

    @property
    def key(self) -> str:
        """Canonical JSON of :attr:`spec`, used to key stored results."""
        return json.dumps(self.spec, sort_keys=True, separators=(",", ":"))

    def __repr__(self) -> str:
        spec = ", ".join(f"{k}={v!r}" for k, v in self.spec.items())
        return f"Instance({spec})"


def _node_maps(n: int, m: int, state_nodes, input_nodes) -> tuple[np.ndarray, np.ndarray]:
    """Validated node of each state and input; one per node by default."""
    def as_nodes(label, value, size):
        nodes = np.asarray(value)
        if nodes.shape != (size,):
            raise InstanceError(f"{label} must have one entry per {label.split('_')[0]} ({size}), got shape {nodes.shape}")
        if not np.issubdtype(nodes.dtype, np.integer) or (nodes.size and nodes.min() < 0):
            raise InstanceError(f"{label} must hold node numbers 0, 1, ..., got {nodes.tolist()}")
        return nodes.astype(int)

    sn = np.arange(n) if state_nodes is None else as_nodes("state_nodes", state_nodes, n)
    nodes = int(sn.max()) + 1 if sn.size else 0
    missing = sorted(set(range(nodes)) - set(sn.tolist()))
    if missing:
        raise InstanceError(f"state_nodes: every node 0..{nodes - 1} needs a state; nodes {missing} have none")
    if input_nodes is None:
        if m != nodes:
            raise InstanceError(f"B has {m} columns but there are {nodes} nodes: pass input_nodes "
                                "(the node of each input) unless each node has one input")
        un = np.arange(m)
    else:
        un = as_nodes("input_nodes", input_nodes, m)
        if un.size and un.max() >= nodes:
            raise InstanceError(f"input_nodes names node {int(un.max())}, but state_nodes has nodes 0..{nodes - 1}")
    return sn, un


def node_ranks(owners) -> np.ndarray:
    """Rank of each entry among the entries of its node: its slot when node signals are padded to a common width."""
    owners = np.asarray(owners, dtype=int)
    ranks = np.zeros(owners.shape, dtype=int)
    for node in np.unique(owners):
        where = np.flatnonzero(owners == node)
        ranks[where] = np.arange(where.size)
    return ranks


def node_width(owners) -> int:
    """Most entries at one node (at least 1): the common width node signals are padded to."""
    owners = np.asarray(owners, dtype=int)
    return int(np.bincount(owners).max()) if owners.size else 1


def _one_hot(owners, nodes: int) -> np.ndarray:
    """(N, len(owners)) matrix with a 1 where entry k belongs to node ``owners[k]``."""
    out = np.zeros((nodes, len(owners)))
    out[owners, np.arange(len(owners))] = 1.0
    return out


def _node_coupling(support: np.ndarray, row_nodes, col_nodes, nodes: int) -> np.ndarray:
    """(N, N) 0/1 matrix: 1 where some row of node i and column of node j are coupled in ``support``."""
    coupled = _one_hot(row_nodes, nodes) @ support.astype(float) @ _one_hot(col_nodes, nodes).T
    return (coupled != 0).astype(float)


def gaussian_states(rng, size: int, n: int, factor=None) -> np.ndarray:
    """``size`` rows of n states ~ N(0, F F') from ``rng``: ``rng.standard_normal((size, n))`` when ``factor`` F
    (n, r) is None, else ``z F'`` with z (size, r) standard normal."""
    if factor is None:
        return rng.standard_normal((size, n))
    return rng.standard_normal((size, factor.shape[1])) @ factor.T


def _covariance(value, n: int) -> np.ndarray:
    """A validated initial-state covariance (n, n): symmetric positive semidefinite, finite, not zero."""
    cov = _as_matrix("x0_cov", value)
    if cov.shape != (n, n):
        raise InstanceError(f"x0_cov must have shape {(n, n)} (one row per state), got {cov.shape}")
    scale = max(1.0, float(np.abs(cov).max()))
    if not np.allclose(cov, cov.T, atol=1e-10 * scale):
        raise InstanceError("x0_cov must be symmetric")
    low = float(np.linalg.eigvalsh(cov).min())
    if low < -1e-10 * scale:
        raise InstanceError(f"x0_cov must be positive semidefinite (smallest eigenvalue {low:.3g})")
    if not np.any(cov):
        raise InstanceError("x0_cov must not be zero: every initial state would be 0 and every cost 0")
    return (cov + cov.T) / 2


def _as_matrix(label: str, value) -> np.ndarray:
    try:
        raw = np.asarray(value)
        # A cast to float would drop an imaginary part with only a warning.
        if np.iscomplexobj(raw):
            raise InstanceError(f"{label} is complex; give a real matrix (its .real if the imaginary parts are zero)")
        M = np.array(raw, dtype=float)
    except InstanceError:
        raise
    except (TypeError, ValueError) as exc:
        raise InstanceError(f"{label} must be a numeric matrix: {exc}") from None
    if M.ndim != 2:
        raise InstanceError(f"{label} must be a 2-D matrix, got {M.ndim} dimension(s)")
    if not np.all(np.isfinite(M)):
        raise InstanceError(f"{label} has non-finite entries (NaN or inf)")
    return M


#: Above this many states the stabilizing DARE solution comes from the doubling
#: solver of :mod:`codesign.riccati` (2.7 s at n = 1000 against scipy's 85-190 s,
#: agreeing to 1e-13); at and below it from scipy's QZ-based solver (0.3 s at n = 200),
#: which every shipped report rests on, so that they reproduce to the last digit.
FAST_DARE_ABOVE = 200


def solve_dare(A, B, Q, R) -> np.ndarray:
    """Stabilizing DARE solution, or :class:`InstanceError` if there is none.

    scipy's :func:`scipy.linalg.solve_discrete_are` up to :data:`FAST_DARE_ABOVE`
    states, :func:`codesign.riccati.solve_discrete_are` above; the stabilizing
    closed loop is checked either way.
    """
    import scipy.linalg

    from .riccati import NoStabilizingSolutionError, solve_discrete_are

    try:
        if A.shape[0] > FAST_DARE_ABOVE:
            P = solve_discrete_are(A, B, Q, R)
        else:
            P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError, NoStabilizingSolutionError) as exc:
        raise InstanceError(
            f"(A, B) is not stabilizable with these costs: the DARE has no stabilizing solution ({exc})"
        ) from None
    P = (P + P.T) / 2
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    radius = np.max(np.abs(np.linalg.eigvals(A - B @ K)))
    if not np.all(np.isfinite(P)) or radius >= 1 - 1e-12:
        raise InstanceError(
            f"(A, B) is not stabilizable with these costs: the DARE solution does not stabilize "
            f"(closed-loop spectral radius {radius:.6g})"
        )
    return P


#: How :func:`paper_instance` reaches a connected graph: the paper's redraw, or bridging the gaps.
CONNECT_RULES = ("redraw", "bridge")


def _bridge_gaps(adj: np.ndarray, positions: np.ndarray) -> None:
    """Link, in place, the two nodes on either side of each gap between the graph's components.

    A node's nearest positions on a line form an interval around it, so every link
    spans consecutive positions of one component: the components are runs in the
    sorted order, and one link per boundary between runs connects them.
    """
    import scipy.sparse.csgraph

    _, label = scipy.sparse.csgraph.connected_components(adj, directed=False)
    order = np.argsort(positions, kind="stable")
    for left, right in zip(order[:-1], order[1:]):
        if label[left] != label[right]:
            adj[left, right] = adj[right, left] = 1.0


def knn_neighbours(positions: np.ndarray, degree: int) -> np.ndarray:
    """Each node's ``degree`` nearest positions (itself included), as ``(n, degree)`` indices.

    The same sets as ``np.argsort(|x_i - x_j|, axis=1, kind="stable")[:, :degree]`` (ties to the
    lower index), in O(n degree log degree) instead of O(n^2 log n): on a line a node's nearest
    positions lie within ``degree - 1`` ranks of its own in the sorted order. That holds exactly
    only where the nearest position just outside that window is strictly farther than the
    ``degree``-th chosen (rounding keeps distances monotone along the line, but may tie them);
    where it is not, the dense sort answers.
    """
    n = positions.size
    order = np.argsort(positions, kind="stable")
    rank = np.empty(n, dtype=np.intp)
    rank[order] = np.arange(n)
    offsets = np.arange(-(degree - 1), degree)
    window = rank[:, None] + offsets[None, :]
    inside = (window >= 0) & (window < n)
    candidates = order[np.clip(window, 0, n - 1)]
    gaps = np.where(inside, np.abs(positions[:, None] - positions[candidates]), np.inf)
    chosen = np.lexsort((candidates, gaps), axis=-1)[:, :degree]
    nearest = np.take_along_axis(candidates, chosen, axis=1)
    kth = np.take_along_axis(gaps, chosen[:, -1:], axis=1)[:, 0]
    for side in (-degree, degree):
        beyond = rank + side
        exists = (beyond >= 0) & (beyond < n)
        outside = np.abs(positions - positions[order[np.clip(beyond, 0, n - 1)]])
        if np.any(exists & (outside <= kth)):
            return np.argsort(np.abs(positions[:, None] - positions[None, :]), axis=1, kind="stable")[:, :degree]
    return nearest


def is_connected(nearest: np.ndarray) -> bool:
    """Whether the kNN graph of ``nearest`` (:func:`knn_neighbours`, links taken both ways) is connected."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components

    n, degree = nearest.shape
    links = scipy.sparse.coo_matrix((np.ones(n * degree), (np.repeat(np.arange(n), degree), nearest.ravel())),
                                    shape=(n, n))
    return connected_components(links, directed=False, return_labels=False) == 1


def knn_graph(positions: np.ndarray, degree: int, nearest: np.ndarray | None = None) -> np.ndarray:
    """The symmetric (n, n) 0/1 adjacency linking each position to its ``degree`` nearest (itself included).

    ``nearest``: the neighbours :func:`knn_neighbours` gives, where the caller has them already.
    """
    n = positions.size
    if nearest is None:
        nearest = knn_neighbours(positions, degree)
    adj = np.zeros((n, n))
    rows = np.repeat(np.arange(n), degree)
    adj[rows, nearest.ravel()] = 1.0
    adj[nearest.ravel(), rows] = 1.0
    return adj


def haar_orthogonal(dim: int, rng: np.random.Generator) -> np.ndarray:
    """A Haar-random orthogonal ``dim x dim`` matrix: the draw of ``scipy.stats.ortho_group.rvs(dim, random_state=rng)``.

    The same algorithm (Mezzadri 2007: Q of the QR factorization of a standard normal
    matrix, its columns signed by R's diagonal) on the same stream, so the same matrix
    to the last bit (``tests/test_instances.py``), without importing scipy.stats, which
    added 0.35 s (up to 1.7 s on a busy machine) to the first instance of every process
    (``benchmarks/bench_instance_start.py``).
    """
    q, r = np.linalg.qr(rng.normal(size=(dim, dim)))
    d = r.diagonal()
    return q * (d / abs(d))[np.newaxis, :]


def canonical_eigh(M: np.ndarray, *, rng: np.random.Generator | None = None,
                   tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and an orthonormal eigenbasis of symmetric ``M`` that do not depend on LAPACK.

    Inside the eigenspace of a repeated eigenvalue any orthonormal basis is an
    eigenbasis, and LAPACK builds for different CPUs return different ones. The kNN
    graphs of the paper's family always have a repeated eigenvalue (nodes with the
    same neighbourhood give a null space of dimension 5-11 at N = 20), so
    ``V diag(a) V'`` would depend on the machine. Within each cluster of eigenvalues
    closer than ``tol`` (relative to the largest), the basis is first made canonical:
    the eigenvectors of the generic diagonal form ``V_k' D V_k`` with
    ``D = diag(sqrt(i + 1/2))``, which the eigenspace alone determines, each signed
    so that its largest entry (lowest index among ties) is positive. With ``rng``,
    that basis is then rotated by a Haar-random orthogonal matrix
    (:func:`haar_orthogonal`), so that the basis of a degenerate eigenspace
    is uniformly distributed, as no choice of basis is privileged.
    """
    w, V = np.linalg.eigh(M)
    scale = max(float(np.abs(w).max()), 1e-300)
    D = np.sqrt(np.arange(M.shape[0]) + 0.5)
    start = 0
    for stop in range(1, w.size + 1):
        if stop < w.size and w[stop] - w[stop - 1] <= tol * scale:
            continue
        if stop - start > 1:
            block = V[:, start:stop]
            _, W = np.linalg.eigh((block.T * D) @ block)
            block = block @ W
            magnitude = np.abs(block)
            lead = np.argmax(magnitude >= magnitude.max(axis=0) - 1e-9, axis=0)
            block = block * np.sign(block[lead, np.arange(block.shape[1])])
            if rng is not None:
                block = block @ haar_orthogonal(stop - start, rng)
            V[:, start:stop] = block
            w[start:stop] = w[start:stop].mean()
        start = stop
    return w, V


#: Salt of the stream that rotates degenerate eigenspaces, apart from the instance's own stream.
_BASIS_SALT = 0xBA515
#: Draws of positions :func:`paper_instance` tries before it gives up on ``connect="redraw"``.
#: At 500 nodes 1 draw in 34 is connected, so 1000 fail together with probability 1e-13;
#: a draw costs about 2 ms at 3000 nodes (benchmarks/bench_redraw.py), so giving up takes seconds;
#: at 1000 nodes none was in thousands.
MAX_REDRAWS = 1000


def paper_instance(
    seed: int,
    *,
    n: int = 20,
    degree: int = 6,
    a_norm: float = 0.995,
    b_norm: float = 1.0,
    hops: int = 3,
    horizon: int = 50,
    connect: str = "redraw",
) -> Instance:
    """One instance of the paper's random family (Yang & Matni 2021, Sec. IV).

    Positions ``~ U[0, 1)``; each node links to its ``degree`` nearest positions
    (itself included), made symmetric; redrawn until connected. ``A`` and ``B``
    share the eigenvectors of the normalized adjacency with i.i.d. N(0, 1)
    eigenvalues, are cut to ``hops`` hops and scaled to spectral norms ``a_norm``
    and ``b_norm``. ``Q = R = I`` and ``P`` solves the DARE. Where the adjacency
    has a repeated eigenvalue (always, at the paper's sizes), the eigenvectors of its
    eigenspace are a seeded uniformly random basis (:func:`canonical_eigh`), so a
    seed gives the same instance on every machine.

    Parameters
    ----------
    seed : int
        Seed of the only random stream used (positions, then eigenvalues of A, then of B).
    n, degree, a_norm, b_norm, hops, horizon
        Family parameters; the defaults are the paper's.
    connect : {"redraw", "bridge"}
        How a connected graph is reached. ``"redraw"`` (the paper's): draw positions
        again until the kNN graph is connected. ``"bridge"``: keep the first draw and
        link the two nodes on either side of each gap between its components (one
        link per gap; on a line the components are runs of consecutive positions).
        Past a few hundred nodes the kNN graph on [0, 1) is almost never connected
        (6 neighbours: 1 draw in 34 at N = 500, none in thousands at N = 1000), so
        redrawing does not end there: after :data:`MAX_REDRAWS` draws an
        :class:`InstanceError` says to bridge. The instance's spec records
        ``connect`` only when it is ``"bridge"``.
    """
    for label, value, low in (("n", n, 2), ("degree", degree, 2), ("hops", hops, 0), ("horizon", horizon, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise InstanceError(f"{label} must be an integer >= {low}, got {value!r}")
    if degree > n:
        raise InstanceError(f"degree ({degree}) cannot exceed n ({n})")
    for label, value in (("a_norm", a_norm), ("b_norm", b_norm)):
        if not (isinstance(value, (int, float, np.floating)) and np.isfinite(value) and value > 0):
            raise InstanceError(f"{label} must be a positive finite number, got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InstanceError(f"seed must be a non-negative integer, got {seed!r}")
    if connect not in CONNECT_RULES:
        raise InstanceError(f"connect must be one of {', '.join(CONNECT_RULES)}, got {connect!r}")
    rng = np.random.default_rng(int(seed))
    for _ in range(MAX_REDRAWS):
        positions = rng.uniform(0.0, 1.0, n)
        # The neighbours on the sorted line and scipy's components on n * degree links, not the
        # dense graph: a draw then costs milliseconds at 3000 nodes instead of 0.6 s, so the
        # MAX_REDRAWS draws that end a hopeless redraw take seconds, not ten minutes.
        nearest = knn_neighbours(positions, degree)
        if connect == "bridge":
            comm = knn_graph(positions, degree, nearest)
            _bridge_gaps(comm, positions)
            break
        if is_connected(nearest):
            comm = knn_graph(positions, degree, nearest)
            break
    else:
        raise InstanceError(f"no connected {degree}-nearest-neighbour graph on {n} nodes in {MAX_REDRAWS} draws "
                            f"(seed {seed}); pass connect='bridge' to link the gaps of the first draw instead")
    gso = comm / np.linalg.norm(comm, 2)
    _, V = canonical_eigh(gso, rng=np.random.default_rng([int(seed), _BASIS_SALT]))
    a = rng.standard_normal(n)
    b = rng.standard_normal(n)
    far = hop_distances(comm) > hops
    A = (V * a) @ V.T
    B = (V * b) @ V.T
    A[far] = 0.0
    B[far] = 0.0
    A = (A + A.T) / 2  # exact symmetry; eigh round-off is O(1e-16)
    B = (B + B.T) / 2
    A *= a_norm / np.linalg.norm(A, 2)
    B *= b_norm / np.linalg.norm(B, 2)
    Q = np.eye(n)
    R = np.eye(n)
    P = solve_dare(A, B, Q, R)
    plant = ((A != 0) | (B != 0)).astype(float)
    spec = {
        "family": "paper",
        "seed": int(seed),
        "n": int(n),
        "degree": int(degree),
        "a_norm": float(a_norm),
        "b_norm": float(b_norm),
        "hops": int(hops),
        "horizon": int(horizon),
    }
    if connect != "redraw":
        spec["connect"] = connect
    return Instance(A, B, Q, R, P, int(horizon), comm, plant, spec)
