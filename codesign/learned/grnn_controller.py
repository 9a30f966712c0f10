"""The trained GRNN as a controller: the numpy simulator every design is scored with, and its linear form.

    Z(t+1) = act(S Z(t) W + x(t) F),   u(t) = Z(t+1) G  (or Z_i(t+1) G_i per node),   Z(0) = 0.

Apart from :mod:`codesign.learned.grnn` (the training) so that what builds controllers without
training them (:mod:`codesign.learned.embedding`, the warm starts) does not import the trainer,
and the trainer's use of the warm starts does not make an import cycle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._lazy import lazy_import
from ..controllers import register_controller
from ..evaluation import STRUCTURED_ABOVE, impulse_responses, structured_operator
from ..instances import node_ranks, node_width
from .trainer import tanh_

torch = lazy_import("torch")

#: Imported on use (numba loads with it), and part of the fingerprint of every method that uses this module.
FINGERPRINT_MODULES = ("codesign.learned.grnn_rollout",)

__all__ = ["GRNNController", "LinearGRNNController", "slot_index"]


def slot_index(owners, nodes: int) -> tuple[np.ndarray, int]:
    """Where each state (or input) sits in the padded node signal, slot-major, and the slot count.

    Slot c of node i is entry c N + i: with one entry per node the layout is the plain one.
    """
    owners = np.asarray(owners, dtype=int)
    return node_ranks(owners) * nodes + owners, node_width(owners)


@register_controller("grnn")
@dataclass(frozen=True, eq=False)
class GRNNController:
    """A trained GRNN as the common simulator sees it (numpy, batched).

    Attributes
    ----------
    S : ndarray (N, N)
        Graph shift operator; its off-diagonal support is the set of links.
    F : ndarray (h,), or (p, h) when nodes hold several states
        Input weights: node i's (padded) states x_i in R^p enter its hidden state as x_i' F.
    W : ndarray (h, h)
    G : ndarray (h,), or (h, q) when nodes hold several inputs; per node (N, h), or (N, h, q)
        Readout: node i's (padded) inputs are Z_i G (the paper's readout, shared by
        every node), or Z_i G_i with G_i = G[i] (``readout="per_node"``: one readout
        per node, told apart by the leading node axis). A per-node G fixes the
        number of nodes: it does not transfer to a graph of another size.
    state_nodes, input_nodes : ndarray of int, optional
        The node of each state and input (None: one of each per node, in order).
        State k is slot "its rank among its node's states" of its node's signal.
    """

    S: np.ndarray
    F: np.ndarray
    W: np.ndarray
    G: np.ndarray
    state_nodes: np.ndarray | None = None
    input_nodes: np.ndarray | None = None

    def __post_init__(self):
        for name in ("S", "F", "W", "G"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.S.ndim != 2 or self.S.shape[0] != self.S.shape[1]:
            raise ValueError(f"S must be square, got shape {self.S.shape}")
        if self.W.ndim != 2 or self.W.shape[0] != self.W.shape[1]:
            raise ValueError(f"W must be square (h, h), got shape {self.W.shape}")
        h, nodes = self.W.shape[0], self.S.shape[0]
        blocks = self.state_nodes is not None or self.input_nodes is not None
        if not blocks:
            # A per-node G is told apart by its shape: (N, h) where the shared one has h entries.
            per_node = self.G.size != h and self.G.shape == (nodes, h)
            if self.F.size != h or (self.G.size != h and not per_node):
                raise ValueError(f"F, W, G must have shapes (h,), (h, h), (h,) or per node ({nodes}, h), with "
                                 f"h = {h} and N = {nodes} nodes (S); got {self.F.shape}, {self.W.shape}, "
                                 f"{self.G.shape}")
            object.__setattr__(self, "F", self.F.ravel())
            object.__setattr__(self, "G", self.G if per_node else self.G.ravel())
            object.__setattr__(self, "_per_node", per_node)
            # Above STRUCTURED_ABOVE nodes a sparse S is multiplied on its support, the hidden
            # state kept node-major (N, h, batch) so that S acts on rows: a step then costs
            # O(N degree h batch) instead of O(N^2 h batch) (11x at N = 1000, 7 links per node).
            # At and below, the dense products run unchanged (the shipped reports' costs).
            sparse = structured_operator(self.S) if nodes > STRUCTURED_ABOVE else None
            object.__setattr__(self, "_S_op", sparse)
            return
        object.__setattr__(self, "_S_op", None)
        layout = {}
        for name, default in (("state_nodes", nodes), ("input_nodes", nodes)):
            value = getattr(self, name)
            owners = np.arange(default) if value is None else np.array(value, dtype=int)
            owners.setflags(write=False)
            object.__setattr__(self, name, owners)
            layout[name] = slot_index(owners, nodes)
        (p_index, p), (q_index, q) = layout["state_nodes"], layout["input_nodes"]
        shared_shapes = [(h, q)] + [(h,)] * (q == 1)
        per_node = (self.G.shape not in shared_shapes
                    and self.G.shape in [(nodes, h, q)] + [(nodes, h)] * (q == 1))
        if self.F.shape in ((p, h), (h,) * (p == 1)) and (per_node or self.G.shape in shared_shapes):
            object.__setattr__(self, "F", self.F.reshape(p, h))
            object.__setattr__(self, "G", self.G.reshape((nodes, h, q) if per_node else (h, q)))
        else:
            raise ValueError(f"with {p} states and {q} inputs per node, F and G must have shapes ({p}, {h}) and "
                             f"({h}, {q}) or per node ({nodes}, {h}, {q}); got {self.F.shape} and {self.G.shape}")
        object.__setattr__(self, "_per_node", per_node)
        object.__setattr__(self, "_state_index", p_index)
        object.__setattr__(self, "_input_index", q_index)

    @property
    def hidden(self) -> int:
        return self.W.shape[0]

    @property
    def blocks(self) -> bool:
        """Whether nodes hold several states or inputs (F and G are matrices)."""
        return self.state_nodes is not None

    @property
    def readout(self) -> str:
        """``"shared"`` (one G for every node, the paper's) or ``"per_node"`` (G[i] at node i)."""
        return "per_node" if self._per_node else "shared"

    def reset(self, batch: int):
        # Hidden state kept feature-major, (h, batch, N): W acts on the first axis and S on the
        # last, each as one wide matrix product. The node-major (N, batch, h) layout needs a
        # tall-thin (N batch, h) x (h, h) product that runs several times slower.
        if self._S_op is not None:
            return np.zeros((self.S.shape[0], self.hidden, batch))
        return np.zeros((self.hidden, batch, self.S.shape[0]))

    def _pre_activation(self, state, x):
        if self._S_op is not None:  # node-major (N, h, batch): S by its CSR on rows, W per node
            n, h, batch = state.shape
            pre = (self._S_op @ np.matmul(self.W.T, state).reshape(n, h * batch)).reshape(n, h, batch)
            xt = np.ascontiguousarray(x.T)  # no copy in a rollout, whose states are node-major
            for k in range(h):
                pre[:, k, :] += self.F[k] * xt
            return pre
        h, batch, n = state.shape
        pre = ((self.W.T @ state.reshape(h, batch * n)).reshape(h * batch, n) @ self.S.T).reshape(h, batch, n)
        if not self.blocks:
            pre += self.F[:, None, None] * x[None]
            return pre
        padded = np.zeros((batch, self.F.shape[0] * n))
        padded[:, self._state_index] = x
        pre += np.einsum("ck,bcn->kbn", self.F, padded.reshape(batch, -1, n))
        return pre

    def _output(self, Z):
        if self._per_node:  # G[i] reads node i's features (the shared products below stay as they were)
            if self._S_op is not None:
                return np.ascontiguousarray(np.einsum("nk,nkb->bn", self.G, Z))
            if not self.blocks:
                return np.einsum("nk,kbn->bn", self.G, Z)
            return np.einsum("nkc,kbn->bcn", self.G, Z).reshape(Z.shape[1], -1)[:, self._input_index]
        if self._S_op is not None:
            return np.ascontiguousarray(np.matmul(self.G, Z).T)
        h, batch, n = Z.shape
        if not self.blocks:
            return (self.G @ Z.reshape(h, batch * n)).reshape(batch, n)
        return np.einsum("kc,kbn->bcn", self.G, Z).reshape(batch, -1)[:, self._input_index]

    #: The activation of the compiled rollout (tanh; the identity in LinearGRNNController).
    _squash = True

    def rollout(self, instance, x0, steps: int):
        """Each draw's cost and each step's peak state from one compiled pass (:mod:`.grnn_rollout`).

        None where that pass does not apply: node blocks, S taken sparse above
        STRUCTURED_ABOVE nodes, a per-node readout, or a plant without one input per node.
        """
        if (self.blocks or self._per_node or self._S_op is not None or instance.m != instance.n
                or instance.n != self.S.shape[0]):
            return None
        from .grnn_rollout import rollout_costs  # numba loads on first use

        return rollout_costs(instance, self.S, self.F, self.W, self.G, x0, steps, squash=self._squash)

    def step(self, state, x):
        Z = self._pre_activation(state, x)
        # tanh as 2 sigmoid(2 z) - 1 through torch (shared memory, in place): numpy's float64
        # tanh takes most of a rollout; this is several times faster and within 4e-16 of it.
        tanh_(torch.from_numpy(Z))
        return self._output(Z), Z

    def arrays(self) -> dict:
        arrays = {"S": self.S, "F": self.F, "W": self.W, "G": self.G}
        if self.blocks:
            arrays.update(state_nodes=self.state_nodes, input_nodes=self.input_nodes)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: dict) -> "GRNNController":
        return cls(arrays["S"], arrays["F"], arrays["W"], arrays["G"],
                   arrays.get("state_nodes"), arrays.get("input_nodes"))

    @property
    def support(self) -> np.ndarray:
        return self.S != 0

    @property
    def states(self) -> int:
        return self.S.shape[0] if not self.blocks else self.state_nodes.size

    def linearized_closed_loop(self, instance, *, sparse: bool = False):
        """Closed loop in (x, vec Z) linearized at the origin (tanh'(0) = 1).

        With z = vec(Z) row-major (node i's features at i h, ..., i h + h - 1):
        z' = (S kron W') z + Kzx x, u = Gm z', x' = A x + B u, where Kzx puts
        F' x_i into node i's features and Gm reads Z_i G (I kron F', I kron G'
        with one state and one input per node; Z_i G_i and the block diagonal
        of the rows G_i' with a per-node readout). ``sparse``: as a scipy CSR
        matrix, built from sparse factors (one state and one input per node), for
        :func:`~codesign.evaluation.spectral_radius` at a thousand nodes, where
        the dense matrix is (n + n h)^2 (288 MB at n = 1000, h = 5).
        """
        n, h = self.S.shape[0], self.hidden
        if sparse and not self.blocks:
            import scipy.sparse as sp

            Kzz = sp.kron(sp.csr_array(self.S), self.W.T, format="csr")
            Kzx = sp.kron(sp.eye_array(n), self.F.reshape(h, 1), format="csr")
            if self._per_node:  # row i holds G_i' at node i's features
                Gm = sp.csr_array((self.G.ravel(), np.arange(n * h), np.arange(0, n * h + 1, h)), shape=(n, n * h))
            else:
                Gm = sp.kron(sp.eye_array(n), self.G.reshape(1, h), format="csr")
            B = sp.csr_array(instance.B)
            top = sp.hstack([sp.csr_array(instance.A) + B @ (Gm @ Kzx), B @ (Gm @ Kzz)])
            return sp.vstack([top, sp.hstack([Kzx, Kzz])], format="csr")
        Kzz = np.kron(self.S, self.W.T)
        if not self.blocks:
            Kzx = np.kron(np.eye(n), self.F.reshape(h, 1))
            if self._per_node:
                Gm = np.zeros((n, n * h))
                Gm[np.arange(n)[:, None], np.arange(n * h).reshape(n, h)] = self.G
            else:
                Gm = np.kron(np.eye(n), self.G.reshape(1, h))
        else:
            s_nodes, s_slots = self.state_nodes, node_ranks(self.state_nodes)
            u_nodes, u_slots = self.input_nodes, node_ranks(self.input_nodes)
            Kzx = np.zeros((n * h, s_nodes.size))
            Gm = np.zeros((u_nodes.size, n * h))
            for k in range(h):
                Kzx[s_nodes * h + k, np.arange(s_nodes.size)] = self.F[s_slots, k]
                Gm[np.arange(u_nodes.size), u_nodes * h + k] = (self.G[u_nodes, k, u_slots] if self._per_node
                                                                else self.G[k, u_slots])
        top = np.hstack([instance.A + instance.B @ Gm @ Kzx, instance.B @ Gm @ Kzz])
        bottom = np.hstack([Kzx, Kzz])
        return np.vstack([top, bottom])


@register_controller("grnn_linear")
@dataclass(frozen=True, eq=False)
class LinearGRNNController(GRNNController):
    """A GRNN with the identity activation: Z(t+1) = S Z(t) W + x(t) F, u(t) = Z(t+1) G.

    A linear dynamic controller that relays information one hop per step, so its
    cost has a closed form (:meth:`closed_loop_responses`, scored by
    :func:`codesign.exact_cost`) and :meth:`linearized_closed_loop` is its exact
    closed loop.
    """

    _squash = False

    def step(self, state, x):
        Z = self._pre_activation(state, x)
        return self._output(Z), Z

    def closed_loop_responses(self, instance, steps: int | None = None):
        """Maps ``(phi_x, phi_u)`` of this controller in closed loop with the instance (by :meth:`step`)."""
        if instance.n != self.states:
            raise ValueError(f"controller has n = {self.states}, instance has n = {instance.n}")
        return impulse_responses(instance, self, steps)
