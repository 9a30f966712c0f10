"""The GCNN as a model of the one trainer: its rollout and two hand-written BPTTs.

On the paper's setting (one state and one input per node, Q = R = I) the
gradient is :func:`_loss_and_grad`; on node blocks, or other Q and R, it is
:func:`_block_loss_and_grad` (any Q, R; the filter's linear part x -> S^k X
folded into one matrix). Both are checked against autograd references in the
tests (tests/references.py) and evaluate
tanh as 2 sigmoid(2 z) - 1 (:func:`~codesign.learned.trainer.tanh_`).
:class:`GCNNStack` is the :class:`~codesign.learned.trainer.StackModel` the
trainer advances; it takes the first path where it applies.
"""

from __future__ import annotations

import math

import numpy as np

from .._lazy import lazy_import
from ..evaluation import STRUCTURED_ABOVE
from ..instances import node_ranks, node_width
from dataclasses import dataclass

from .trainer import Loop, Member, StackModel, no_grad, tanh_, torch_dtype

torch = lazy_import("torch")
#: Imported only when the fused engine runs (it loads numba), yet part of this code's fingerprint.
FINGERPRINT_MODULES = ("codesign.learned.gcnn_fused",)

__all__ = ["GCNNStack", "GCNN_TAPS", "GCNN_FEATURES", "gcnn_init", "tap_map", "scatter", "node_layout"]

GCNN_TAPS = 5
GCNN_FEATURES = 32


def scatter(nodes, N: int, width: int) -> np.ndarray:
    """(len(nodes), N * width) one-hot: entry k to slot (node, rank) of the node-major layout."""
    nodes = np.asarray(nodes, dtype=int)
    E = np.zeros((nodes.size, N * width))
    E[np.arange(nodes.size), nodes * width + node_ranks(nodes)] = 1.0
    return E


def tap_map(S, state_nodes, taps: int, width: int) -> np.ndarray:
    """(n, N K p) matrix L with x L = the shifted node signals (S^k X)_{i,c}, ordered (node i, tap k, channel c)."""
    N = S.shape[0]
    powers = [np.eye(N)]
    for _ in range(taps - 1):
        powers.append(S @ powers[-1])
    E = scatter(state_nodes, N, width).reshape(-1, N, width)  # (n, N, p)
    return np.einsum("kij,sjc->sikc", np.stack(powers), E).reshape(E.shape[0], N * taps * width)


def gcnn_init(rng: np.random.Generator, taps: int, features: int, channels: int = 1, outputs: int = 1):
    # torch defaults of the GS21 code: filter taps U(-1/sqrt(K G), 1/sqrt(K G)) with G input
    # features (channels), readout nn.Linear(features, outputs) U(-1/sqrt(features), 1/sqrt(features)).
    # With one channel and one output these are the draws of the (K, F) and (F,) shapes.
    H = rng.uniform(-1.0, 1.0, (taps, channels, features)) / math.sqrt(taps * channels)
    w = rng.uniform(-1.0, 1.0, (features, outputs)) / math.sqrt(features)
    return H, w


class _DenseProducts:
    """The products of the paper-setting BPTT with the stacked dense S, A', B' (M, N, N): batched matmuls."""

    def __init__(self, S, A_t, B_t):
        self.S, self.St, self.A_t, self.B_t = S, S.transpose(1, 2), A_t, B_t
        self.A, self.Bm = A_t.transpose(1, 2), B_t.transpose(1, 2)

    def shift(self, x, out):
        """out = x S' (each model's S acting on the node axis)."""
        torch.bmm(x, self.St, out=out)

    def advance(self, x, u, out):
        """out = x A' + u B' (the next state)."""
        torch.bmm(x, self.A_t, out=out)
        out.baddbmm_(u, self.B_t)

    def input_adjoint(self, scaled, lam, c2, out):
        """out = c2 scaled + lam B."""
        torch.baddbmm(scaled, lam, self.Bm, beta=c2, out=out)

    def shift_adjoint(self, base, g):
        """base + g S."""
        return torch.baddbmm(base, g, self.S)

    def state_adjoint(self, base, lam):
        """base + lam A."""
        return torch.baddbmm(base, lam, self.A)


class _SparseProducts:
    """The same products with S, A, B as one block-diagonal scipy CSR matrix each over the stack.

    Above 200 states (:data:`codesign.evaluation.STRUCTURED_ABOVE`), where the dense
    (M, N, N) products would be O(N^2) per draw and time step and a graph's S or a
    plant's A and B has a few nonzeros per row: each product is then one sparse
    matrix times the node-major signal (M N, B), a copy of O(M N B) each way.
    """

    def __init__(self, S, A, B, dtype):
        import scipy.sparse as sp

        def blocks(mats):
            return sp.block_diag([sp.csr_array(np.asarray(m, dtype=dtype)) for m in mats], format="csr")

        self.S, self.St = blocks(S), blocks([m.T for m in S])
        self.A, self.At = blocks(A), blocks([m.T for m in A])
        self.B, self.Bt = blocks(B), blocks([m.T for m in B])

    @staticmethod
    def _nodes(x):
        """(M, B, N) rows as the node-major (M N, B) numpy matrix (a copy)."""
        M, Bsz, N = x.shape
        return x.transpose(1, 2).reshape(M * N, Bsz).numpy()

    @staticmethod
    def _rows(y, like):
        """A node-major (M N, B) result as an (M, B, N) view, shaped like ``like``."""
        M, Bsz, N = like.shape
        return torch.from_numpy(np.asarray(y)).view(M, N, Bsz).transpose(1, 2)

    def shift(self, x, out):
        out.copy_(self._rows(self.S @ self._nodes(x), x))

    def advance(self, x, u, out):
        out.copy_(self._rows(self.A @ self._nodes(x) + self.B @ self._nodes(u), x))

    def input_adjoint(self, scaled, lam, c2, out):
        torch.mul(scaled, c2, out=out)
        out.add_(self._rows(self.Bt @ self._nodes(lam), lam))

    def shift_adjoint(self, base, g):
        return base + self._rows(self.St @ self._nodes(g), g)

    def state_adjoint(self, base, lam):
        return base + self._rows(self.At @ self._nodes(lam), lam)


@no_grad
def _rollout_cost(S, H, w, A_t, B_t, P, x0, horizon, trace_P, ws=None, products=None):
    J, _ = _forward(S, H, w, A_t, B_t, P, x0, horizon, keep=False, ws=ws, products=products)
    return J / x0.shape[1] / trace_P


def _buffers(M, Bsz, N, K, Fn, horizon, dtype, keep: bool) -> dict:
    """Buffers reused across steps: freshly allocated megabytes cost a page fault per 4 kB."""
    T = horizon
    depth = T if keep else 1
    return dict(
        X=torch.empty(T + 1 if keep else 2, M, Bsz, N, dtype=dtype),
        U=torch.empty(depth, M, Bsz, N, dtype=dtype),
        XK=torch.empty(depth, M, K, Bsz, N, dtype=dtype),
        Acts=torch.empty(depth, M, Fn, Bsz * N, dtype=dtype),
        dz=torch.empty(M, Fn, Bsz * N, dtype=dtype) if keep else None,
        tmp=torch.empty(M, Fn, Bsz * N, dtype=dtype) if keep else None,
    )


def _forward(S, H, w, A_t, B_t, P, x0, horizon, keep: bool, ws: dict | None = None, products=None):
    """Roll the stack out from x0 (M, B, N) with in-place buffers; J (M,) summed over the batch.

    With ``keep`` the trajectories and activations are kept for the backward pass.
    ``products``: how S, A and B multiply (:class:`_SparseProducts`; by default the
    dense S, A_t, B_t).
    """
    M, Bsz, N = x0.shape
    K, Fn = H.shape[1], H.shape[2]
    BN = Bsz * N
    T = horizon
    ops = _DenseProducts(S, A_t, B_t) if products is None else products
    Ht = H.transpose(1, 2)  # (M, F, K)
    wr = w.unsqueeze(1)  # (M, 1, F)
    if ws is None:
        ws = _buffers(M, Bsz, N, K, Fn, horizon, x0.dtype, keep)
    X, U, XK, Acts = ws["X"], ws["U"], ws["XK"], ws["Acts"]
    J = torch.zeros(M, 1, 1, dtype=x0.dtype)
    X[0].copy_(x0)
    for t in range(T):
        slot = t if keep else 0
        x = X[t] if keep else X[t % 2]
        x_next = X[t + 1] if keep else X[(t + 1) % 2]
        xk = XK[slot]
        xk[:, 0].copy_(x)
        for k in range(1, K):
            ops.shift(xk[:, k - 1], xk[:, k])
        a = Acts[slot]
        torch.bmm(Ht, xk.view(M, K, BN), out=a)
        tanh_(a)
        u = U[slot]
        torch.bmm(wr, a, out=u.view(M, 1, BN))
        ops.advance(x, u, x_next)
        J.baddbmm_(x.view(M, 1, BN), x.view(M, BN, 1))
        J.baddbmm_(u.view(M, 1, BN), u.view(M, BN, 1))
    xT = X[T] if keep else X[T % 2]
    PxT = torch.bmm(xT, P)
    J.baddbmm_(xT.view(M, 1, BN), PxT.view(M, BN, 1))
    return J.view(M), (X, U, XK, Acts, PxT)


def _loss_and_grad(S, H, w, A_t, B_t, P, x0, horizon, ws: dict | None = None, products=None):
    """Per-model mean cost J / B and its gradient w.r.t. (H, w), by hand-written BPTT.

    The backward pass reuses the stored activations and buffers instead of
    allocating fresh (M, 32, B N) tensors at every operation. ``products`` as in
    :func:`_forward`.
    """
    M, Bsz, N = x0.shape
    K, Fn = H.shape[1], H.shape[2]
    BN = Bsz * N
    T = horizon
    if ws is None:
        ws = _buffers(M, Bsz, N, K, Fn, horizon, x0.dtype, keep=True)
    ops = _DenseProducts(S, A_t, B_t) if products is None else products
    J, (X, U, XK, Acts, PxT) = _forward(S, H, w, A_t, B_t, P, x0, horizon, keep=True, ws=ws, products=ops)
    wc = w.unsqueeze(2)  # (M, F, 1)
    c2 = 2.0 / Bsz
    lam = PxT * c2
    dHt = torch.zeros(M, Fn, K, dtype=x0.dtype)
    dw = torch.zeros(M, 1, Fn, dtype=x0.dtype)
    du = torch.empty(M, Bsz, N, dtype=x0.dtype)
    dz, tmp = ws["dz"], ws["tmp"]
    dXK = torch.empty(M, K, Bsz, N, dtype=x0.dtype)
    for t in range(T - 1, -1, -1):
        a = Acts[t]
        ops.input_adjoint(U[t], lam, c2, du)
        dw.baddbmm_(du.view(M, 1, BN), a.transpose(1, 2))
        torch.mul(a, a, out=tmp)
        tmp.sub_(1.0)  # a^2 - 1 = -tanh'
        torch.bmm(wc, du.view(M, 1, BN), out=dz)
        dz.mul_(tmp).neg_()
        dHt.baddbmm_(dz, XK[t].view(M, K, BN).transpose(1, 2))
        if t == 0:
            break
        torch.bmm(H, dz, out=dXK.view(M, K, BN))
        g = dXK[:, K - 1]
        for k in range(K - 2, -1, -1):
            g = ops.shift_adjoint(dXK[:, k], g)
        lam_next = ops.state_adjoint(g, lam)
        lam_next.add_(X[t], alpha=c2)
        lam = lam_next
    return J / Bsz, [dHt.transpose(1, 2).contiguous(), dw.view(M, Fn)]


def _block_forward(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon, keep: bool):
    """Roll the node-block stack out from x0 (M, B, n); J (M,) summed over the batch.

    The node-block model with the linear part folded: x L (L from
    :func:`_tap_map`) holds every shifted node signal. With ``keep`` the states,
    inputs and activations are kept for :func:`_block_loss_and_grad`.
    """
    M, Bsz, n = x0.shape
    K, p, Fn = H.shape[1:]
    N = L.shape[2] // (K * p)
    Hf = H.reshape(M, K * p, Fn)
    X, U, Acts = [x0], [], []
    J = torch.zeros(M, 1, 1, dtype=x0.dtype)
    x = x0
    for _ in range(horizon):
        a = torch.bmm(torch.bmm(x, L).view(M, Bsz * N, K * p), Hf)
        tanh_(a)
        u = torch.bmm(torch.bmm(a, w).view(M, Bsz, -1), Eu)
        J.baddbmm_(x.reshape(M, 1, -1), torch.bmm(x, Q).view(M, -1, 1))
        J.baddbmm_(u.reshape(M, 1, -1), torch.bmm(u, R).view(M, -1, 1))
        x = torch.bmm(x, A_t).baddbmm_(u, B_t)
        if keep:
            X.append(x), U.append(u), Acts.append(a)
    J.baddbmm_(x.reshape(M, 1, -1), torch.bmm(x, P).view(M, -1, 1))
    return J.view(M), (X, U, Acts)


def _block_loss_and_grad(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon):
    """Per-model mean cost J / B and its gradient w.r.t. (H, w), by hand-written BPTT.

    Same model as :func:`_block_forward`.
    """
    M, Bsz, n = x0.shape
    K, p, Fn = H.shape[1:]
    N = L.shape[2] // (K * p)
    J, (X, U, Acts) = _block_forward(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon, keep=True)
    c = 1.0 / Bsz
    Hf = H.reshape(M, K * p, Fn)
    Ht, wt, Lt, Eut = Hf.transpose(1, 2), w.transpose(1, 2), L.transpose(1, 2), Eu.transpose(1, 2)
    A, Bm = A_t.transpose(1, 2), B_t.transpose(1, 2)
    Qs, Rs, Ps = ((Z + Z.transpose(1, 2)) * c for Z in (Q, R, P))
    lam = torch.bmm(X[horizon], Ps)  # dJ/dx(T), divided by B
    dH = torch.zeros(M, K * p, Fn, dtype=x0.dtype)
    dw = torch.zeros_like(w)
    for t in range(horizon - 1, -1, -1):
        a = Acts[t]
        du = torch.bmm(U[t], Rs).baddbmm_(lam, Bm)
        dy = torch.bmm(du, Eut).view(M, Bsz * N, -1)
        dw.baddbmm_(a.transpose(1, 2), dy)
        dz = torch.bmm(dy, wt).mul_(torch.mul(a, a).sub_(1.0)).neg_()  # tanh' = 1 - a^2
        dH.baddbmm_(torch.bmm(X[t], L).view(M, Bsz * N, K * p).transpose(1, 2), dz)
        if t == 0:
            break
        lam = torch.bmm(X[t], Qs).baddbmm_(lam, A).baddbmm_(torch.bmm(dz, Ht).view(M, Bsz, -1), Lt)
    return J * c, [dH.view(M, K, p, Fn), dw]


def _fast(instance) -> bool:
    """The paper's setting, trained by the hand-written BPTT: one state and input per node, Q = R = I."""
    return bool(instance.scalar_nodes and np.array_equal(instance.Q, np.eye(instance.n))
                and np.array_equal(instance.R, np.eye(instance.m)))


def node_layout(instance):
    """None on the hand-written path, else (m, N, p, q) of the node-block model (part of the stack key)."""
    if _fast(instance):
        return None
    N = instance.nodes
    return (instance.m, N, node_width(instance.state_nodes), node_width(instance.input_nodes))


@dataclass
class GCNNProblem:
    """One GCNN of a stack: its instance and initial filter taps H0 and readout w0."""

    instance: object
    H0: np.ndarray
    w0: np.ndarray


class GCNNStack(StackModel):
    """A stack of GCNNs for :func:`~codesign.learned.trainer.train_stack`; members' problems are :class:`GCNNProblem`.

    The hand-written paper-setting path where every instance has one state and
    one input per node and Q = R = I (:func:`_fast`), else the node-block path.
    """

    names = ("H", "w")

    def __init__(self, members, loop: Loop, *, engine: str = "torch"):
        tdt = torch_dtype(loop.dtype)
        problems = [m.problem for m in members]
        insts = [p.instance for p in problems]
        layout = node_layout(insts[0])
        if any(node_layout(i) != layout for i in insts):
            raise ValueError("every GCNN of a stack needs the same node layout")
        M, horizon, n, batch = len(members), loop.horizon, insts[0].n, loop.batch
        curve_size = np.shape(members[0].curve_x0)[0]
        self.dim = n

        def stack(arrays):
            return torch.tensor(np.stack(arrays), dtype=tdt)

        trace_P = torch.tensor([i.trace_P for i in insts], dtype=tdt)
        if layout is None:
            H = stack([p.H0.reshape(GCNN_TAPS, GCNN_FEATURES) for p in problems])
            w = stack([p.w0.reshape(GCNN_FEATURES) for p in problems])
        else:
            H, w = stack([p.H0 for p in problems]), stack([p.w0 for p in problems])
        if layout is None and engine == "fused":
            from .gcnn_fused import FusedGCNN

            compiled = FusedGCNN(*(np.stack([getattr(i, k) for i in insts]) for k in ("gso", "A", "B", "P")),
                                 taps=GCNN_TAPS, features=GCNN_FEATURES, horizon=horizon, dtype=H.numpy().dtype)
            Hn, wn = H.numpy(), w.numpy()  # views: Adam updates them in place

            def nodes_first(x0):
                return np.ascontiguousarray(x0.numpy().transpose(0, 2, 1))

            def fused_loss_and_grad(x0):
                J, dH, dw = compiled.loss_and_grad(Hn, wn, nodes_first(x0))
                return torch.from_numpy(J) / x0.shape[1], [torch.from_numpy(dH), torch.from_numpy(dw)]

            self._loss_and_grad = fused_loss_and_grad
            self._curve_cost = lambda x0: torch.from_numpy(compiled.costs(Hn, wn, nodes_first(x0))) / x0.shape[1] / trace_P
            self.params = [H, w]
            return
        P = stack([i.P for i in insts])
        if layout is None and n > STRUCTURED_ABOVE:
            products = _SparseProducts([i.gso for i in insts], [i.A for i in insts], [i.B for i in insts],
                                       H.numpy().dtype)
            ws_train = _buffers(M, batch, n, GCNN_TAPS, GCNN_FEATURES, horizon, tdt, keep=True)
            ws_curve = _buffers(M, curve_size, n, GCNN_TAPS, GCNN_FEATURES, horizon, tdt, keep=False)
            self._loss_and_grad = lambda x0: _loss_and_grad(None, H, w, None, None, P, x0, horizon, ws_train,
                                                            products)
            self._curve_cost = lambda x0: _rollout_cost(None, H, w, None, None, P, x0, horizon, trace_P, ws_curve,
                                                        products)
            self.params = [H, w]
            return
        A_t, B_t = stack([i.A.T for i in insts]), stack([i.B.T for i in insts])
        if layout is None:
            S = stack([i.gso for i in insts])
            ws_train = _buffers(M, batch, n, GCNN_TAPS, GCNN_FEATURES, horizon, tdt, keep=True)
            ws_curve = _buffers(M, curve_size, n, GCNN_TAPS, GCNN_FEATURES, horizon, tdt, keep=False)
            self._loss_and_grad = lambda x0: _loss_and_grad(S, H, w, A_t, B_t, P, x0, horizon, ws_train)
            self._curve_cost = lambda x0: _rollout_cost(S, H, w, A_t, B_t, P, x0, horizon, trace_P, ws_curve)
        else:
            _, N, p, q = layout
            L = stack([tap_map(i.gso, i.state_nodes, GCNN_TAPS, p) for i in insts])
            Eu = stack([scatter(i.input_nodes, N, q).T for i in insts])
            Q, R = stack([i.Q for i in insts]), stack([i.R for i in insts])
            self._loss_and_grad = lambda x0: _block_loss_and_grad(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon)
            self._curve_cost = lambda x0: (
                _block_forward(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon, keep=False)[0] / x0.shape[1] / trace_P)
        self.params = [H, w]

    @classmethod
    def shape_key(cls, member: Member) -> tuple:
        inst = member.problem.instance
        return member.shape_key() + (inst.n, node_layout(inst))

    def loss_and_grad(self, x0):
        return self._loss_and_grad(x0)

    def curve_cost(self, x0):
        return self._curve_cost(x0)
