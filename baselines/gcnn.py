"""The GCNN baseline of Gama & Sojoudi (2021), as the paper benchmarked it (docs/methods.md).

Memoryless: one graph-filter layer with K = 5 taps and 32 features, tanh, and a
per-node linear readout, no bias:

    z_f(t) = sum_{k=0}^{4} h_{f,k} S^k x(t),   u_i(t) = sum_f w_f tanh(z_{f,i}(t)),

5 * 32 + 32 = 192 parameters, S the given normalized adjacency. ``S^k x(t)`` is
used with no delay: the controller assumes instantaneous multi-hop communication.

Node blocks (nodes with several states or inputs, ``Instance.scalar_nodes``
False): the node signal has p = (most states at a node) channels, X in R^{N x p},
state k in channel "its rank among its node's states" of node ``state_nodes[k]``
(nodes with fewer states are padded with zeros). Each tap maps the p channels to
the F features and the readout maps the features to q = (most inputs at a node)
outputs per node:

    Z = sum_k S^k X H_k   (H_k in R^{p x F}),   Y = tanh(Z) W   (W in R^{F x q}),

and input a is entry (input_nodes[a], its rank among its node's inputs) of Y
(padded outputs are unused): K p F + F q parameters. With p = q = 1 this is the
model above; the controller then keeps the shapes H (K, F), w (F,) and the
general one stores H (K, p, F), w (F, q) and the node maps.

Training (paper code): Adam, learning rate 0.01 multiplied by 0.9 every 10
updates, coupled weight decay 2, no clipping, loss = mean raw J per batch.
Models are trained in stacks with :class:`codesign.training.BatchedAdam`. On the
paper's family (one state and one input per node, Q = R = I) the gradient is the
hand-written BPTT :func:`_loss_and_grad` (checked against the autograd reference
:func:`_cost`), unchanged; on node blocks, or other Q and R, it is a second
hand-written BPTT, :func:`_block_loss_and_grad` (any Q, R; the filter's linear
part x -> S^k X folded into one matrix), checked against the autograd reference
:func:`_block_cost`. Initialization, data and selection draws use the same
streams on both paths.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property
from typing import Annotated, Literal

import numpy as np

from codesign.controllers import register_controller
from codesign.design import Design, count_links
from codesign.instances import node_ranks, node_width
from codesign.evaluation import simulate, simulate_to_precision, spectral_radius, validation_set
from codesign.methods import Above, AtLeast, AtMost, method
from codesign.status import DIVERGED, OPTIMAL
from codesign._lazy import lazy_import
from codesign.training import DTYPES, BatchedAdam, no_grad, torch_dtype

torch = lazy_import("torch")

__all__ = ["gcnn", "gcnn_batch", "GCNNController", "GCNN_TAPS", "GCNN_FEATURES"]

GCNN_TAPS = 5
GCNN_FEATURES = 32
_DATA, _INIT, _SELECT = 21, 22, 0xC0DE


def _scatter(nodes, N: int, width: int) -> np.ndarray:
    """(len(nodes), N * width) one-hot: entry k to slot (node, rank) of the node-major layout."""
    nodes = np.asarray(nodes, dtype=int)
    E = np.zeros((nodes.size, N * width))
    E[np.arange(nodes.size), nodes * width + node_ranks(nodes)] = 1.0
    return E


def _tap_map(S, state_nodes, taps: int, width: int) -> np.ndarray:
    """(n, N K p) matrix L with x L = the shifted node signals (S^k X)_{i,c}, ordered (node i, tap k, channel c)."""
    N = S.shape[0]
    powers = [np.eye(N)]
    for _ in range(taps - 1):
        powers.append(S @ powers[-1])
    E = _scatter(state_nodes, N, width).reshape(-1, N, width)  # (n, N, p)
    return np.einsum("kij,sjc->sikc", np.stack(powers), E).reshape(E.shape[0], N * taps * width)


@register_controller("gcnn")
@dataclass(frozen=True, eq=False)
class GCNNController:
    """u = tanh(sum_k S^k x h_k) w, applied at every node (numpy, batched).

    Attributes
    ----------
    S : ndarray (N, N)
    H : ndarray (K, F), or (K, p, F) on node blocks
        Filter taps h_{f,k} (tap k, feature f); on node blocks tap k maps the p
        channels of a node's signal to the F features.
    w : ndarray (F,), or (F, q) on node blocks
        Readout weights (to the q outputs of a node).
    state_nodes, input_nodes : ndarray of int or None
        On node blocks (3-D H), the node of each state and input (default one per
        node, in order); state k is channel (its rank among its node's states)
        of its node, input a the output (its rank among its node's inputs). None
        for the one-state-one-input model (2-D H).
    """

    S: np.ndarray
    H: np.ndarray
    w: np.ndarray
    state_nodes: np.ndarray | None = None
    input_nodes: np.ndarray | None = None

    def __post_init__(self):
        for name in ("S", "H", "w"):
            value = np.array(getattr(self, name), dtype=float)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        N = self.S.shape[0]
        if self.S.shape != (N, N):
            raise ValueError(f"S must be square, got {self.S.shape}")
        if self.H.ndim == 2:
            if self.w.shape != (self.H.shape[1],):
                raise ValueError(f"H must be (K, F) and w (F,), got {self.H.shape} and {self.w.shape}")
            for name in ("state_nodes", "input_nodes"):
                nodes = getattr(self, name)
                if nodes is not None and not np.array_equal(nodes, np.arange(N)):
                    raise ValueError(f"{name} other than one per node needs the node-block shapes "
                                     "H (K, p, F) and w (F, q)")
                object.__setattr__(self, name, None)
            return
        if self.H.ndim != 3 or self.w.ndim != 2 or self.w.shape[0] != self.H.shape[2]:
            raise ValueError(f"H must be (K, F) and w (F,), or (K, p, F) and (F, q); got {self.H.shape} "
                             f"and {self.w.shape}")
        for name, width in (("state_nodes", self.H.shape[1]), ("input_nodes", self.w.shape[1])):
            nodes = np.arange(N) if getattr(self, name) is None else np.array(getattr(self, name))
            if nodes.ndim != 1 or not (nodes.size == 0 or np.issubdtype(nodes.dtype, np.integer)):
                raise ValueError(f"{name} must be a 1-D array of node numbers, got {nodes!r}")
            nodes = nodes.astype(int)
            if nodes.size and (nodes.min() < 0 or nodes.max() >= N):
                raise ValueError(f"{name} must name nodes 0..{N - 1}, got {nodes.tolist()}")
            if nodes.size and np.bincount(nodes, minlength=N).max() > width:
                raise ValueError(f"{name}: a node has {np.bincount(nodes).max()} entries, more than the "
                                 f"{width} channels of H and w")
            nodes.setflags(write=False)
            object.__setattr__(self, name, nodes)

    @property
    def blocks(self) -> bool:
        """Whether this is the node-block form (3-D H)."""
        return self.H.ndim == 3

    @property
    def n_parameters(self) -> int:
        return self.H.size + self.w.size

    def reset(self, batch: int):
        return None

    def step(self, state, x):
        if self.blocks:
            return self._step_blocks(x), None
        powers = [x]
        for _ in range(self.H.shape[0] - 1):
            powers.append(powers[-1] @ self.S.T)
        z = np.stack(powers, axis=-1) @ self.H  # (batch, N, F)
        # torch's tanh is twice as fast as numpy's here and agrees to the last bits.
        return torch.tanh(torch.from_numpy(z)).numpy() @ self.w, None

    @cached_property
    def _block_maps(self):
        """(G, input nodes, input slots): z = x G (batch, N F) is the filter bank, linear in x."""
        K, p, F = self.H.shape
        N = self.S.shape[0]
        L = _tap_map(self.S, self.state_nodes, K, p)  # (n, N K p)
        G = (L.reshape(-1, N, K * p) @ self.H.reshape(K * p, F)).reshape(-1, N * F)
        return G, self.input_nodes, node_ranks(self.input_nodes)

    def _step_blocks(self, x):
        G, nodes, slots = self._block_maps
        N, F = self.S.shape[0], self.H.shape[2]
        z = (np.asarray(x, dtype=float) @ G).reshape(-1, N, F)
        y = torch.tanh(torch.from_numpy(z)).numpy() @ self.w  # (batch, N, q)
        return y[:, nodes, slots]

    def arrays(self) -> dict:
        arrays = {"S": self.S, "H": self.H, "w": self.w}
        if self.blocks:
            arrays.update(state_nodes=self.state_nodes, input_nodes=self.input_nodes)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: dict) -> "GCNNController":
        return cls(arrays["S"], arrays["H"], arrays["w"], arrays.get("state_nodes"), arrays.get("input_nodes"))

    @property
    def support(self) -> np.ndarray:
        """Node-level support (N, N): the given graph the filter shifts over."""
        return self.S != 0

    def linear_gain(self) -> np.ndarray:
        """Gain (m, n) of the controller linearized at the origin: sum_k (H_k . w) S^k.

        On node blocks, input a and state s see sum_k (S^k)_{node(a), node(s)} (H_k w)_{slot(s), slot(a)}.
        """
        if not self.blocks:
            coeffs = self.H @ self.w
            K = np.zeros_like(self.S)
            power = np.eye(self.S.shape[0])
            for c in coeffs:
                K += c * power
                power = self.S @ power
            return K
        coeffs = self.H @ self.w  # (K, p, q)
        sn, ss = self.state_nodes, node_ranks(self.state_nodes)
        un, us = self.input_nodes, node_ranks(self.input_nodes)
        K = np.zeros((un.size, sn.size))
        power = np.eye(self.S.shape[0])
        for c in coeffs:
            K += power[np.ix_(un, sn)] * c[ss][:, us].T
            power = self.S @ power
        return K


def _init(rng: np.random.Generator, taps: int, features: int, channels: int = 1, outputs: int = 1):
    # torch defaults of the GS21 code: filter taps U(-1/sqrt(K G), 1/sqrt(K G)) with G input
    # features (channels), readout nn.Linear(features, outputs) U(-1/sqrt(features), 1/sqrt(features)).
    # With one channel and one output these are the draws of the (K, F) and (F,) shapes.
    H = rng.uniform(-1.0, 1.0, (taps, channels, features)) / math.sqrt(taps * channels)
    w = rng.uniform(-1.0, 1.0, (features, outputs)) / math.sqrt(features)
    return H, w


@no_grad
def _rollout_cost(S, H, w, A_t, B_t, P, x0, horizon, trace_P, ws=None):
    J, _ = _forward(S, H, w, A_t, B_t, P, x0, horizon, keep=False, ws=ws)
    return J / x0.shape[1] / trace_P


def _cost(S, H, w, A_t, B_t, P, x, horizon):
    """Summed cost J (M,) of the stack from x (M, B, N) with plain autograd ops (test reference).

    Q = R = I (checked by the trainer).
    """
    M, Bsz, N = x.shape
    St = S.transpose(1, 2)
    Ht = H.transpose(1, 2)  # (M, F, K)
    wr = w.unsqueeze(1)  # (M, 1, F)
    J = torch.zeros(M, dtype=x.dtype)
    for _ in range(horizon):
        powers = [x.reshape(M, 1, Bsz * N)]
        xp = x
        for _ in range(H.shape[1] - 1):
            xp = torch.bmm(xp, St)
            powers.append(xp.reshape(M, 1, Bsz * N))
        z = torch.bmm(Ht, torch.cat(powers, dim=1))  # (M, F, B N)
        act = torch.sigmoid(2.0 * z) * 2.0 - 1.0  # tanh, 3x faster than torch.tanh on CPU
        u = torch.bmm(wr, act).view(M, Bsz, N)
        J = J + (x * x).sum((1, 2)) + (u * u).sum((1, 2))
        x = torch.bmm(x, A_t) + torch.bmm(u, B_t)
    return J + (torch.bmm(x, P) * x).sum((1, 2))


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


def _forward(S, H, w, A_t, B_t, P, x0, horizon, keep: bool, ws: dict | None = None):
    """Roll the stack out from x0 (M, B, N) with in-place buffers; J (M,) summed over the batch.

    With ``keep`` the trajectories and activations are kept for the backward pass.
    """
    M, Bsz, N = x0.shape
    K, Fn = H.shape[1], H.shape[2]
    BN = Bsz * N
    T = horizon
    St = S.transpose(1, 2)
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
            torch.bmm(xk[:, k - 1], St, out=xk[:, k])
        a = Acts[slot]
        torch.bmm(Ht, xk.view(M, K, BN), out=a)
        torch.sigmoid(a.mul_(2.0), out=a).mul_(2.0).sub_(1.0)  # tanh, 3x faster than torch.tanh
        u = U[slot]
        torch.bmm(wr, a, out=u.view(M, 1, BN))
        torch.bmm(x, A_t, out=x_next)
        x_next.baddbmm_(u, B_t)
        J.baddbmm_(x.view(M, 1, BN), x.view(M, BN, 1))
        J.baddbmm_(u.view(M, 1, BN), u.view(M, BN, 1))
    xT = X[T] if keep else X[T % 2]
    PxT = torch.bmm(xT, P)
    J.baddbmm_(xT.view(M, 1, BN), PxT.view(M, BN, 1))
    return J.view(M), (X, U, XK, Acts, PxT)


def _loss_and_grad(S, H, w, A_t, B_t, P, x0, horizon, ws: dict | None = None):
    """Per-model mean cost J / B and its gradient w.r.t. (H, w), by hand-written BPTT.

    Same model as :func:`_cost` (the autograd reference in the tests); the
    backward pass reuses the stored activations and buffers instead of
    allocating fresh (M, 32, B N) tensors at every operation.
    """
    M, Bsz, N = x0.shape
    K, Fn = H.shape[1], H.shape[2]
    BN = Bsz * N
    T = horizon
    if ws is None:
        ws = _buffers(M, Bsz, N, K, Fn, horizon, x0.dtype, keep=True)
    J, (X, U, XK, Acts, PxT) = _forward(S, H, w, A_t, B_t, P, x0, horizon, keep=True, ws=ws)
    wc = w.unsqueeze(2)  # (M, F, 1)
    c2 = 2.0 / Bsz
    A = A_t.transpose(1, 2)
    Bm = B_t.transpose(1, 2)
    lam = PxT * c2
    dHt = torch.zeros(M, Fn, K, dtype=x0.dtype)
    dw = torch.zeros(M, 1, Fn, dtype=x0.dtype)
    du = torch.empty(M, Bsz, N, dtype=x0.dtype)
    dz, tmp = ws["dz"], ws["tmp"]
    dXK = torch.empty(M, K, Bsz, N, dtype=x0.dtype)
    for t in range(T - 1, -1, -1):
        a = Acts[t]
        torch.baddbmm(U[t], lam, Bm, beta=c2, out=du)
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
            g = torch.baddbmm(dXK[:, k], g, S)
        lam_next = torch.baddbmm(g, lam, A)
        lam_next.add_(X[t], alpha=c2)
        lam = lam_next
    return J / Bsz, [dHt.transpose(1, 2).contiguous(), dw.view(M, Fn)]


def _block_cost(S, H, w, Ex, Eu, A_t, B_t, Q, R, P, x, horizon):
    """Summed cost J (M,) of the node-block stack from x (M, B, n), plain autograd ops.

    S (M, N, N); H (M, K, p, F); w (M, F, q); Ex (M, n, N p) and Eu (M, N q, m)
    the one-hot maps from states to node channels and from node outputs to inputs
    (node-major); A_t, B_t the transposed dynamics; any Q, R, P.
    """
    M, Bsz, _ = x.shape
    N = S.shape[1]
    K, p, Fn = H.shape[1:]
    q = w.shape[2]
    Hf = H.reshape(M, K * p, Fn)
    Sb = S.unsqueeze(1)  # (M, 1, N, N), broadcast over the batch
    J = torch.zeros(M, dtype=x.dtype)
    for _ in range(horizon):
        X = torch.bmm(x, Ex).view(M, Bsz, N, p)
        powers = [X]
        for _ in range(K - 1):
            powers.append(torch.matmul(Sb, powers[-1]))
        XK = torch.stack(powers, dim=3).reshape(M, Bsz * N, K * p)  # (tap, channel) as H's
        Y = torch.bmm(torch.tanh(torch.bmm(XK, Hf)), w)  # (M, B N, q)
        u = torch.bmm(Y.reshape(M, Bsz, N * q), Eu)
        J = J + (torch.bmm(x, Q) * x).sum((1, 2)) + (torch.bmm(u, R) * u).sum((1, 2))
        x = torch.bmm(x, A_t) + torch.bmm(u, B_t)
    return J + (torch.bmm(x, P) * x).sum((1, 2))


def _block_forward(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon, keep: bool):
    """Roll the node-block stack out from x0 (M, B, n); J (M,) summed over the batch.

    The same model as :func:`_block_cost` with the linear part folded: x L (L from
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
        torch.sigmoid(a.mul_(2.0), out=a).mul_(2.0).sub_(1.0)  # tanh, 3x faster than torch.tanh on CPU
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

    Same model as :func:`_block_cost` (the autograd reference in the tests).
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


def _layout(instance):
    """None on the hand-written path, else (m, N, p, q) of the node-block model (part of the stack key)."""
    if _fast(instance):
        return None
    N = instance.nodes
    return (instance.m, N, node_width(instance.state_nodes), node_width(instance.input_nodes))


@dataclass
class _GJob:
    instance: object
    seed: int
    params: dict
    settings: dict


def gcnn_batch(jobs, *, stack_size: int = 64) -> list[Design]:
    """Train many GCNN designs together; ``jobs`` is an iterable of (Instance, kwargs of :func:`gcnn`)."""
    parsed = []
    for instance, kwargs in jobs:
        kwargs = dict(kwargs)
        seed = kwargs.pop("seed", 0)
        unknown = set(kwargs) - set(_DEFAULTS)
        if unknown:
            raise ValueError(f"unknown GCNN settings: {sorted(unknown)}; known: {sorted(_DEFAULTS)}")
        s = {**_DEFAULTS, **kwargs}
        _check(instance, seed, s)
        params = {"seed": int(seed), **{k: s[k] for k in sorted(kwargs) if s[k] != _DEFAULTS[k]}}
        parsed.append(_GJob(instance, int(seed), params, s))
    specs = [(j, m) for j, job in enumerate(parsed) for m in range(job.settings["ensemble"])]
    groups: dict[tuple, list] = {}
    for j, m in specs:
        s = parsed[j].settings
        key = (s["steps"], s["batch"], s["dtype"], s["curve_every"], s["curve_size"], parsed[j].instance.horizon,
               parsed[j].instance.n, _layout(parsed[j].instance))
        groups.setdefault(key, []).append((j, m))
    trained: dict[tuple, dict] = {}
    seconds = [0.0] * len(parsed)
    for key, members in groups.items():
        for start in range(0, len(members), stack_size):
            chunk = members[start:start + stack_size]
            t0 = time.perf_counter()
            out = _train([(parsed[j], m) for j, m in chunk], *key[:5], layout=key[7])
            share = (time.perf_counter() - t0) / len(chunk)
            for (j, m), result in zip(chunk, out):
                trained[(j, m)] = result
                seconds[j] += share
    return [_finish(job, [trained[(j, m)] for m in range(job.settings["ensemble"])], seconds[j])
            for j, job in enumerate(parsed)]


@no_grad
def _train(members, steps, batch, dtype, curve_every, curve_size, layout=None):
    tdt = torch_dtype(dtype)
    M = len(members)
    insts = [job.instance for job, _ in members]
    if layout is None and not all(_fast(i) for i in insts):
        raise ValueError("the hand-written GCNN gradient supports one state and input per node and Q = R = I only")
    horizon = insts[0].horizon

    def stack(arrays):
        return torch.tensor(np.stack(arrays), dtype=tdt)

    S = stack([i.gso for i in insts])
    A_t = stack([i.A.T for i in insts])
    B_t = stack([i.B.T for i in insts])
    P = stack([i.P for i in insts])
    trace_P = torch.tensor([i.trace_P for i in insts], dtype=tdt)
    n = insts[0].n
    if layout is None:
        inits = [_init(np.random.default_rng([job.seed, m, _INIT]), GCNN_TAPS, GCNN_FEATURES) for job, m in members]
        H = stack([h.reshape(GCNN_TAPS, GCNN_FEATURES) for h, _ in inits])
        w = stack([w.reshape(GCNN_FEATURES) for _, w in inits])
        ws_train = _buffers(M, batch, n, GCNN_TAPS, GCNN_FEATURES, horizon, tdt, keep=True)
        ws_curve = _buffers(M, curve_size, n, GCNN_TAPS, GCNN_FEATURES, horizon, tdt, keep=False)

        def loss_and_grad(x0):
            return _loss_and_grad(S, H, w, A_t, B_t, P, x0, horizon, ws_train)

        def rollout_cost(x0):
            return _rollout_cost(S, H, w, A_t, B_t, P, x0, horizon, trace_P, ws_curve)
    else:
        _, N, p, q = layout
        inits = [_init(np.random.default_rng([job.seed, m, _INIT]), GCNN_TAPS, GCNN_FEATURES, p, q)
                 for job, m in members]
        H = stack([h for h, _ in inits])
        w = stack([w for _, w in inits])
        L = stack([_tap_map(i.gso, i.state_nodes, GCNN_TAPS, p) for i in insts])
        Eu = stack([_scatter(i.input_nodes, N, q).T for i in insts])
        Q = stack([i.Q for i in insts])
        R = stack([i.R for i in insts])

        def loss_and_grad(x0):
            return _block_loss_and_grad(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon)

        def rollout_cost(x0):
            J, _ = _block_forward(L, H, w, Eu, A_t, B_t, Q, R, P, x0, horizon, keep=False)
            return J / x0.shape[1] / trace_P

    lr0 = torch.tensor([job.settings["lr"] for job, _ in members], dtype=tdt)
    decay = torch.tensor([job.settings["decay"] for job, _ in members], dtype=tdt)
    every = members[0][0].settings["decay_every"]
    adam = BatchedAdam([H, w], weight_decay=members[0][0].settings["weight_decay"])
    rngs = [np.random.default_rng([job.seed, m, _DATA]) for job, m in members]
    curve_x0 = stack([np.random.default_rng([job.instance.seed, _SELECT]).standard_normal((curve_size, job.instance.n))
                      for job, _ in members])
    alive = torch.ones(M, dtype=torch.bool)
    diverged_at = [None] * M
    steps_rec, costs_rec = [], []

    def record(k):
        steps_rec.append(k)
        costs_rec.append(rollout_cost(curve_x0))

    for k in range(steps):
        if curve_every and k % curve_every == 0:
            record(k)
        x0 = stack([rng.standard_normal((batch, n)) for rng in rngs]) * alive.view(M, 1, 1).to(tdt)
        loss, grads = loss_and_grad(x0)
        finite = (torch.isfinite(loss) & torch.isfinite(grads[0].flatten(1).sum(1))
                  & torch.isfinite(grads[1].flatten(1).sum(1)))
        bad = alive & ~finite
        if bool(bad.any()):
            for m in torch.nonzero(bad).flatten().tolist():
                diverged_at[m] = k
            alive &= ~bad
            for p in (H, w):
                p.copy_(torch.where(alive.view((-1,) + (1,) * (p.dim() - 1)), p, torch.zeros_like(p)))
            grads = [torch.nan_to_num(g, nan=0.0, posinf=0.0, neginf=0.0) for g in grads]
        # StepLR(gamma=0.9) stepped after updates 0, 10, 20, ... as in the paper code.
        lr = lr0 * decay ** math.ceil(k / every) * alive.to(tdt)
        adam.step(grads, lr)
    record(steps)
    costs = torch.stack(costs_rec).numpy()
    return [
        dict(H=H[m].numpy().astype(float), w=w[m].numpy().astype(float),
             S=S[m].numpy().astype(float), diverged_at=diverged_at[m],
             curve={"step": list(steps_rec), "cost": [float(c) for c in costs[:, m]]})
        for m in range(M)
    ]


def _controller(instance, r) -> GCNNController:
    """The trained model as a controller: the (K, F), (F,) shapes whenever nodes hold one state and input."""
    H, w = r["H"], r["w"]
    if H.ndim == 2:
        return GCNNController(r["S"], H, w)
    if instance.scalar_nodes:  # p = q = 1 (e.g. trained on the autograd path for Q, R other than I)
        return GCNNController(r["S"], H[:, 0, :], w[:, 0])
    return GCNNController(r["S"], H, w, instance.state_nodes, instance.input_nodes)


def _finish(job: _GJob, results, seconds) -> Design:
    finals = [r["curve"]["cost"][-1] if r["diverged_at"] is None else np.inf for r in results]
    finals = [c if np.isfinite(c) else np.inf for c in finals]
    extras = {"ensemble_curve_costs": [float(c) for c in finals],
              "diverged_members": sum(r["diverged_at"] is not None for r in results)}
    links, self_loops = count_links(job.instance.comm_adj)
    best = int(np.argmin(finals))
    if not np.isfinite(finals[best]):
        return Design.failure("gcnn", job.params, DIVERGED, "every ensemble member diverged",
                              info_model="instantaneous", seconds=seconds, links=links,
                              self_loops=self_loops, extras=extras)
    r = results[best]
    controller = _controller(job.instance, r)
    extras["curve"] = r["curve"]
    extras["n_parameters"] = controller.n_parameters
    extras["spectral_radius"] = spectral_radius(job.instance.A + job.instance.B @ controller.linear_gain())
    s = job.settings
    if s["stability_steps"]:
        long = simulate(job.instance, controller, validation_set(job.instance)[:s["stability_size"]],
                        steps=s["stability_steps"])
        extras["bounded"] = bool(long.bounded)
        extras["max_state"] = float(long.max_state)
        extras["stability_steps"] = s["stability_steps"]
    rollout = simulate_to_precision(job.instance, controller)
    extras.update(rollout.summary())
    if not rollout.bounded:
        return Design.failure("gcnn", job.params, DIVERGED, rollout.divergence or "validation rollout unbounded",
                              info_model="instantaneous", seconds=seconds, links=links,
                              self_loops=self_loops, extras=extras)
    return Design(method="gcnn", params=job.params, controller=controller, cost=rollout.cost, links=links,
                  self_loops=self_loops, info_model="instantaneous", status=OPTIMAL,
                  message="" if not extras["diverged_members"] else
                  f"{extras['diverged_members']} of {len(results)} ensemble members diverged",
                  seconds=seconds, cost_stderr=rollout.stderr, cost_kind="simulated", extras=extras)


_DEFAULTS = dict(steps=750, batch=20, lr=0.01, decay=0.9, decay_every=10, weight_decay=2.0, ensemble=2,
                 curve_every=10, curve_size=100, dtype="float64", stability_steps=500, stability_size=100)


def _check(instance, seed, s):
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    for key in ("steps", "batch", "decay_every", "ensemble", "curve_size", "stability_size"):
        if isinstance(s[key], bool) or not isinstance(s[key], (int, np.integer)) or s[key] < 1:
            raise ValueError(f"{key} must be a positive integer, got {s[key]!r}")
    if not s["lr"] > 0 or not 0 < s["decay"] <= 1 or s["weight_decay"] < 0:
        raise ValueError(f"need lr > 0, 0 < decay <= 1, weight_decay >= 0; got {s['lr']}, {s['decay']}, "
                         f"{s['weight_decay']}")
    if s["curve_every"] < 0 or s["stability_steps"] < 0:
        raise ValueError("curve_every and stability_steps must be non-negative")
    if s["dtype"] not in DTYPES:
        raise ValueError(f"dtype must be one of {sorted(DTYPES)}, got {s['dtype']!r}")


# The runner hands gcnn_batch up to 25 runs at once: they train in shared stacks.
@method("gcnn", label="GCNN", batch=gcnn_batch, batch_size=25, produces=("training_curve",),
        node_blocks=True)
def gcnn(instance, *, seed: Annotated[int, AtLeast(0)] = 0, steps: Annotated[int, AtLeast(1)] = 750,
         batch: Annotated[int, AtLeast(1)] = 20, lr: Annotated[float, Above(0)] = 0.01,
         decay: Annotated[float, Above(0), AtMost(1)] = 0.9, decay_every: Annotated[int, AtLeast(1)] = 10,
         weight_decay: Annotated[float, AtLeast(0)] = 2.0, ensemble: Annotated[int, AtLeast(1)] = 2,
         curve_every: Annotated[int, AtLeast(0)] = 10, curve_size: Annotated[int, AtLeast(1)] = 100,
         dtype: Literal["float64", "float32"] = "float64", stability_steps: Annotated[int, AtLeast(0)] = 500,
         stability_size: Annotated[int, AtLeast(1)] = 100) -> Design:
    """Gama-Sojoudi GCNN (192 parameters, instantaneous multi-hop information), trained as the paper did.

    On node blocks the filter has p input channels and q outputs per node
    (module docstring): 5 p 32 + 32 q parameters; any Q and R.

    Parameters
    ----------
    instance : Instance
    seed : int
        Seeds initializations and training draws (member k of the ensemble uses (seed, k)).
    steps : int
        Adam updates.
    batch : int
        Draws x(0) ~ N(0, I) per update.
    lr : float
        Initial learning rate.
    decay : float
        Factor the learning rate is multiplied by every ``decay_every`` updates (from update 0 on).
    decay_every : int
        Updates between learning-rate decays.
    weight_decay : float
        Coupled L2 weight decay (added to the gradient, as torch.optim.Adam does).
    ensemble : int
        Models trained; the one with the lowest cost on a separate selection set is kept.
    curve_every : int
        Record the selection-set cost every this many updates (0: only at the end).
    curve_size : int
        Draws of the selection set (training curve and ensemble selection), apart from the validation set.
    dtype : {"float64", "float32"}
        Training precision; float32 is about twice as fast.
    stability_steps : int
        Length of the boundedness check rollout (0 skips it).
    stability_size : int
        How many draws of the validation set the boundedness check starts from.

    Returns
    -------
    Design
        Simulated cost on the validation set (control-variate estimate; the
        sample mean in ``extras["plain_cost"]``); links are the given graph's
        off-diagonal edges (between nodes), ``info_model="instantaneous"``; ``extras`` holds the
        training curve, ``n_parameters``, the spectral radius of the closed loop
        linearized at the origin, and the boundedness of a long rollout.
    """
    settings = dict(steps=steps, batch=batch, lr=lr, decay=decay, decay_every=decay_every,
                    weight_decay=weight_decay, ensemble=ensemble, curve_every=curve_every, curve_size=curve_size,
                    dtype=dtype, stability_steps=stability_steps, stability_size=stability_size)
    return gcnn_batch([(instance, {"seed": seed, **settings})])[0]

