"""Delayed static gains as GRNNs with a per-node readout: the exact embedding (docs/methods.md).

A delayed static gain (:class:`baselines.DelayedStaticGain`, the designs of
:func:`baselines.sparse_delayed`)

    u(t) = K_l x(t) + K_d x(t − 1),   x(−1) = 0,

with K_l diagonal (each node's own current state) and K_d zero on the diagonal
(a link delivers a neighbour's state one step late), is a GRNN

    Z(t+1) = σ(S Z(t) W + x(t) F),   u_i(t) = Z_i(t+1) G_i,   Z(0) = 0,

with h = 2 hidden features and a per-node readout: F = (ε, 0), W = [[0, 1], [0, 0]]
(feature 1 moves to feature 2, feature 2 is dropped), S = K_d and G_i = (k_ii, 1) / ε.
Unrolled, Z(t+1) = Σ_k S^k x(t − k) F W^k; since F W = (0, ε) and F W² = 0,

    Z_i(t+1) = ε (x_i(t), Σ_j S_ij x_j(t − 1)),   u_i(t) = k_ii x_i(t) + Σ_j (K_d)_ij x_j(t − 1),

the same closed loop for every ε (with the identity σ), with S's off-diagonal
support, the GRNN's links, exactly K_d's. With σ = tanh the hidden states are
tanh of ε times the linear ones, so the loop tends to the design's as ε → 0.

Nodes with several states (p per node, padded) and inputs (q): h = 2p, F = ε [I_p, 0],
W moves features 1..p to p+1..2p, and G_i = [K_l,ii' ; M_i'] / ε. The coefficient of
x_j(t − 1) in u_i(t) is S_ij (F W G_i)' = S_ij M_i: the GRNN weighs a neighbour's whole
hidden state by the one number S_ij, so it holds a delayed gain on node blocks exactly
when each node's delayed blocks K_d,ij are multiples of one q × p matrix M_i (a node
that reads at most one neighbour, K_d = 0, or p = q = 1). Others are refused.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from ..instances import node_ranks, node_width
from ..methods import Above, Hyperparameter
from .grnn_controller import GRNNController, LinearGRNNController
from .grnn_bptt import ACTIVATIONS

__all__ = ["embed_delayed_gain", "delayed_gain_parts"]

#: The bounds of :func:`embed_delayed_gain`'s keywords, checked with the registry's messages.
_SCALE = Hyperparameter("scale", 1.0, Annotated[float, Above(0)])
_RTOL = Hyperparameter("rtol", 1e-10, Annotated[float, Above(0)])


def delayed_gain_parts(source, *, instance=None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(K_local, K_delayed, state_nodes, input_nodes)`` of a delayed or diagonal static design.

    Parameters
    ----------
    source : Design, DelayedStaticGain or StaticGain
        A design (its controller is used) or controller: ``u(t) = K_local x(t) +
        K_delayed x(t − 1)``, or a static gain ``u = K x`` with no link (diagonal, or
        zero outside each node's own block), which is K_local with K_delayed = 0.
    instance : Instance, optional
        Where nodes hold several states or inputs, the node maps of a static gain
        (a delayed gain carries its own); checked against the controller when given.

    Returns
    -------
    K_local, K_delayed : ndarray (m, n)
    state_nodes, input_nodes : ndarray of int, or None
        None with one state and one input per node.

    Raises
    ------
    ValueError
        A failed design (no controller), a controller of another kind, a static gain
        with links (it reads neighbours' current states, which a GRNN's links deliver
        one step late), or sizes and node maps that differ from ``instance``'s.
    """
    controller = getattr(source, "controller", source)
    if controller is None:
        raise ValueError(f"the design has no controller (status {getattr(source, 'status', '?')!r}): nothing to embed")
    if hasattr(controller, "K_local") and hasattr(controller, "K_delayed"):
        K_local = np.asarray(controller.K_local, dtype=float)
        K_delayed = np.asarray(controller.K_delayed, dtype=float)
        state_nodes, input_nodes = getattr(controller, "state_nodes", None), getattr(controller, "input_nodes", None)
    elif getattr(controller, "K", None) is not None and not hasattr(controller, "S"):
        K_local = np.asarray(controller.K, dtype=float)
        K_delayed = np.zeros_like(K_local)
        state_nodes = input_nodes = None
        if instance is not None and not instance.scalar_nodes:
            state_nodes, input_nodes = instance.state_nodes, instance.input_nodes
    else:
        raise ValueError(f"embed_delayed_gain takes a delayed static gain (K_local, K_delayed) or a static gain K, "
                         f"got {type(controller).__name__}")
    if K_local.ndim != 2 or K_local.shape != K_delayed.shape:
        raise ValueError(f"K_local and K_delayed must be (m, n) matrices of one shape, got {K_local.shape} "
                         f"and {K_delayed.shape}")
    m, n = K_local.shape
    if instance is not None:
        if (instance.m, instance.n) != (m, n):
            raise ValueError(f"the gain is {m} x {n} (inputs x states), the instance has m = {instance.m}, "
                             f"n = {instance.n}")
        if state_nodes is not None and not (np.array_equal(state_nodes, instance.state_nodes)
                                            and np.array_equal(input_nodes, instance.input_nodes)):
            raise ValueError("the gain's state_nodes/input_nodes differ from the instance's")
    if state_nodes is None and m != n:
        raise ValueError(f"a {m} x {n} gain needs node maps: pass the instance (state_nodes, input_nodes)")
    own = (np.eye(n, dtype=bool) if state_nodes is None
           else np.asarray(input_nodes)[:, None] == np.asarray(state_nodes)[None, :])
    if np.count_nonzero(K_local[~own]):
        raise ValueError("the gain reads other nodes' current states (a static gain with links): a GRNN's links "
                         "deliver a neighbour's state one step late, so only diagonal (block-diagonal) static "
                         "gains and delayed gains embed")
    if np.count_nonzero(K_delayed[own]):
        raise ValueError("K_delayed must be zero on each node's own entries: a node's own state enters through K_local")
    return K_local, K_delayed, state_nodes, input_nodes


def embed_delayed_gain(source, *, instance=None, scale: float = 1.0, activation: str = "identity",
                       hidden: int | None = None, rtol: float = 1e-10) -> GRNNController:
    """The GRNN with a per-node readout whose closed loop is a delayed (or diagonal) static design's.

    See the module docstring (and docs/methods.md, "What the GRNN can represent")
    for the construction: h = 2p hidden features (p states per node, 1 with one
    state per node), F = ε [I_p, 0], W moving features 1..p to p+1..2p, S the
    delayed gain's node weights (K_d itself with one state and one input per
    node) and G_i = [K_l,ii' ; M_i'] / ε.

    Parameters
    ----------
    source : Design, DelayedStaticGain or StaticGain
        What :func:`delayed_gain_parts` reads: a delayed gain, or a static gain with
        no link (:func:`baselines.decentralized`'s).
    instance : Instance, optional
        Node maps of a static gain on node blocks; sizes checked when given.
    scale : float
        ε: F is multiplied by it and G divided by it. With the identity activation
        the closed loop is the same for every ε (to rounding); with tanh a small ε
        keeps the hidden states in tanh's linear range, so the cost tends to the
        design's as ε → 0 (the gap shrinks like ε²).
    activation : {"identity", "tanh"}
        The identity gives a :class:`LinearGRNNController` (scored exactly by
        :func:`codesign.exact_cost`), tanh a :class:`GRNNController`.
    hidden : int, optional
        Hidden features h (at least 2p; extra features stay zero). Default 2p.
    rtol : float
        On node blocks, how far (relative to the node's largest delayed block, in
        Frobenius norm) a delayed block may be from a multiple of the node's one
        matrix M_i before the design is refused.

    Returns
    -------
    GRNNController or LinearGRNNController
        S (N, N) with zero diagonal, F (2,) or (p, h), W (h, h), G per node (N, h)
        or (N, h, q) (``readout == "per_node"``), and the node maps on node blocks;
        ``arrays()`` holds the parameters.

    Raises
    ------
    ValueError
        A source :func:`delayed_gain_parts` refuses, a bad keyword, or on node blocks a
        node whose delayed blocks are not multiples of one matrix (no GRNN holds it: the
        coefficient of x_j(t − 1) in u_i(t) is S_ij (F W G_i)', one matrix per node i).
    """
    _SCALE.check(scale, "scale")
    _RTOL.check(rtol, "rtol")
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation must be one of {ACTIVATIONS}, got {activation!r}")
    K_local, K_delayed, state_nodes, input_nodes = delayed_gain_parts(source, instance=instance)
    n = K_local.shape[1]
    scalar = state_nodes is None
    if scalar:
        state_nodes = input_nodes = np.arange(n)
    state_nodes, input_nodes = np.asarray(state_nodes, dtype=int), np.asarray(input_nodes, dtype=int)
    N = int(state_nodes.max()) + 1 if n else 0
    p, q = node_width(state_nodes), max(node_width(input_nodes), 1)
    s_slot, u_slot = node_ranks(state_nodes), node_ranks(input_nodes)
    h = 2 * p if hidden is None else hidden
    if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 2 * p:
        raise ValueError(f"hidden must be an integer of at least 2 p = {2 * p} (p = {p} states per node), "
                         f"got {hidden!r}")
    eps = float(scale)

    # The blocks in the padded node layout: local[i] is node i's q x p K_l,ii, delayed[i, j] the block K_d,ij.
    local = np.zeros((N, q, p))
    delayed = np.zeros((N, N, q, p))
    rows, cols = np.nonzero(K_local)
    local[input_nodes[rows], u_slot[rows], s_slot[cols]] = K_local[rows, cols]
    rows, cols = np.nonzero(K_delayed)
    delayed[input_nodes[rows], state_nodes[cols], u_slot[rows], s_slot[cols]] = K_delayed[rows, cols]

    # K_d,ij = S_ij M_i: M_i is node i's largest delayed block scaled so that its largest entry is +1
    # (M_i = 1 and S = K_d itself with one state and one input per node), S_ij the projection on it.
    S = np.zeros((N, N))
    M = np.ones((N, q, p)) if p == q == 1 else np.zeros((N, q, p))  # a node with no link: any M_i will do
    for i in range(N):
        blocks = delayed[i].reshape(N, q * p)
        norms = np.linalg.norm(blocks, axis=1)
        if not norms.any():
            continue
        ref = blocks[int(np.argmax(norms))]
        Mi = ref / ref[int(np.argmax(np.abs(ref)))]
        S[i] = blocks @ Mi / (Mi @ Mi)
        residual = np.linalg.norm(blocks - np.outer(S[i], Mi), axis=1).max()
        if residual > rtol * norms.max():
            readers = np.flatnonzero(norms).tolist()
            raise ValueError(f"node {i}'s delayed blocks from nodes {readers} are not multiples of one {q} x {p} "
                             f"matrix (off by {residual / norms.max():.2g} of the largest): a GRNN weighs a "
                             f"neighbour's hidden state by one number S_ij, so no GRNN holds this gain")
        M[i] = Mi.reshape(q, p)

    F = np.zeros((p, h))
    F[np.arange(p), np.arange(p)] = eps  # state slot c into feature c
    W = np.zeros((h, h))
    W[np.arange(p), p + np.arange(p)] = 1.0  # feature c to feature p + c, then dropped: F W^2 = 0
    G = np.zeros((N, h, q))
    G[:, :p, :] = local.transpose(0, 2, 1) / eps  # u_i = K_l,ii x_i(t) from features 1..p
    G[:, p:2 * p, :] = M.transpose(0, 2, 1) / eps  # + M_i sum_j S_ij x_j(t - 1) from features p+1..2p
    kind = LinearGRNNController if activation == "identity" else GRNNController
    if scalar:
        return kind(S, F.ravel(), W, G[:, :, 0])
    return kind(S, F, W, G, state_nodes, input_nodes)
