"""The GRNN as a model of the one trainer: its rollout and hand-written BPTT, on two engines.

The gradient is a hand-written backward pass through time (BPTT) of

    Z(t+1) = σ(S Z(t) W + x(t) F),  u(t) = Z(t+1) G,  x(t+1) = A x(t) + B u(t),

with σ = tanh (the paper's GRNN) or the identity (the linear GRNN, see
:data:`ACTIVATIONS`; one activation per stack), checked against autograd in the
tests (tests/references.py). Doing it by hand avoids autograd's graph
bookkeeping and lets tanh be evaluated as ``2 sigmoid(2 x) - 1``
(:func:`~codesign.learned.trainer.tanh_`), three times faster than ``torch.tanh``
on CPU and equal to it within 4e-16.

:class:`GRNNStack` is the :class:`~codesign.learned.trainer.StackModel` the
trainer advances: the ``torch`` engine (one batched torch call per product and
time step, any node layout) or the ``fused`` engine (one compiled numba pass per
model, :mod:`codesign.learned.fused`).

Tensor layout (model axis first, nodes next, so that ``S @`` is one batched
matmul with no transposes): x, u ``(M, N, B)``; Z ``(M, N, B, h)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._lazy import lazy_import
from .engines import ENGINES, fused_unsupported, resolve_engine, s_supports
from .trainer import Loop, Member, StackModel, no_grad, tanh_, torch_dtype, train_stack

torch = lazy_import("torch")
#: Imported only when the fused engine runs (it loads numba), yet part of this code's fingerprint.
FINGERPRINT_MODULES = ("codesign.learned.fused",)

__all__ = ["ModelSpec", "GRNNStack", "train_grnn", "rollout_cost", "grnn_loss_and_grad",
           "init_fwg", "ACTIVATIONS", "READOUTS", "ENGINES"]

#: The GRNN's activation σ: the paper's tanh, or the identity (a linear dynamic controller).
ACTIVATIONS = ("tanh", "identity")

#: The GRNN's readout u_i = Z_i G: one G shared by every node (the paper's), or one G_i per node.
READOUTS = ("shared", "per_node")


def _check_activation(activation: str) -> None:
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation must be one of {ACTIVATIONS}, got {activation!r}")


def _check_readout(readout: str) -> None:
    if readout not in READOUTS:
        raise ValueError(f"readout must be one of {READOUTS}, got {readout!r}")


def init_fwg(rng: np.random.Generator, hidden: int, states: int = 1, inputs: int = 1
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, W (h, h), G: uniform [0, 1) entries scaled to spectral norm 1 (paper code).

    F is (h,) and G (h,) with one state and one input per node (``states`` =
    ``inputs`` = 1), else F is (states, h) and G (h, inputs).
    """
    F = rng.random((states, hidden))
    G = rng.random((hidden, inputs))
    W = rng.random((hidden, hidden))
    F, W, G = F / np.linalg.norm(F, 2), W / np.linalg.norm(W, 2), G / np.linalg.norm(G, 2)
    if states == inputs == 1:
        return F.ravel(), W, G.ravel()
    return F, W, G


@dataclass
class ModelSpec:
    """Everything one model of a stack needs.

    Attributes
    ----------
    A, B, Q, R, P : ndarray (N, N)
        Plant and costs (terminal cost P).
    trace_P : float
        Normalizer of reported costs.
    S0 : ndarray (N, N)
        Initial graph shift operator (zero outside ``mask`` when S trains).
        A, B, Q, R, P are in the padded node layout when nodes hold several
        states or inputs (``state_index``): p N states and q N inputs, slot-major.
    mask : ndarray (N, N) of bool
        Entries of S that train; all False freezes S.
    F0, W0, G0 : ndarray
        Initial F (h,) or (p, h), W (h, h), G (h,) or (h, q): p states and q
        inputs per node (one of each: the vectors). With a per-node readout
        G0 has a leading node axis: (N, h), or (N, h, q).
    data_seed : int or sequence of int
        Seed of this model's training draws x(0) ~ N(0, I).
    curve_x0 : ndarray (batch_v, N)
        Initial conditions of the validation curve.
    lr : float
        Base learning rate (cosine-annealed to 0 over the run).
    beta : float
        Weight of the l1 penalty beta * sum |S_ij|.
    penalty : tuple of 4 floats
        Weights of the plain Frobenius norms of (S, F, W, G) in the loss.
    state_index : ndarray of int, optional
        Where each of the n states sits in the padded state vector: training
        draws x(0) ~ N(0, I_n) are placed there, the padding stays 0. None: the
        states are the plant's rows, in order.
    x0_factor : ndarray (n, r), optional
        F of the instance's initial-state covariance Σ₀ = F F': training draws
        are x(0) = F z with z ~ N(0, I_r). None: Σ₀ = I.
    """

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    trace_P: float
    S0: np.ndarray
    mask: np.ndarray
    F0: np.ndarray
    W0: np.ndarray
    G0: np.ndarray
    data_seed: object
    curve_x0: np.ndarray
    lr: float = 0.02
    beta: float = 0.0
    penalty: tuple = (2.0, 2.0, 0.0, 2.0)
    state_index: np.ndarray | None = None
    x0_factor: np.ndarray | None = None

    def member(self) -> Member:
        """This model as a member of a trainer's stack."""
        return Member(problem=self, data_seed=self.data_seed, curve_x0=self.curve_x0, lr=self.lr,
                      placement=self.state_index, x0_factor=self.x0_factor)


class _Problem:
    """Stacked plant and cost tensors."""

    def __init__(self, specs, dtype):
        def stack(name):
            return torch.tensor(np.stack([getattr(s, name) for s in specs]), dtype=dtype)

        self.A, self.B = stack("A"), stack("B")
        self.At = self.A.transpose(1, 2).contiguous()
        self.Bt = self.B.transpose(1, 2).contiguous()
        self.Q, self.R, self.P = stack("Q"), stack("R"), stack("P")
        self.Qt = self.Q.transpose(1, 2).contiguous()
        self.Rt = self.R.transpose(1, 2).contiguous()
        self.Pt = self.P.transpose(1, 2).contiguous()
        # Q = R = I in the paper's family: skip those products.
        self.Q_identity = bool(torch.all(self.Q == torch.eye(self.Q.shape[1], dtype=dtype)))
        self.R_identity = bool(torch.all(self.R == torch.eye(self.R.shape[1], dtype=dtype)))
        self.trace_P = torch.tensor([s.trace_P for s in specs], dtype=dtype)


class _Workspace:
    """Buffers reused across training steps (fresh 1 MB tensors every op cost page faults).

    ``p`` states and ``q`` inputs per node (padded layout, slot-major: state c of
    node i is entry c N + i).
    """

    def __init__(self, M, N, Bsz, h, horizon, dtype, keep: bool, p: int = 1, q: int = 1):
        T = horizon
        self.shape = (M, N, Bsz, h)
        self.p, self.q = p, q
        self.X = torch.empty(T + 1, M, Bsz, p * N, dtype=dtype)
        self.U = torch.empty(T, M, Bsz, q * N, dtype=dtype)
        depth = T if keep else 2
        self.Zs = torch.empty(depth, M, h, Bsz, N, dtype=dtype)
        self.Ys = torch.empty(depth, M, h, Bsz, N, dtype=dtype)
        self.keep = keep
        self.J = torch.empty(M, 1, 1, dtype=dtype)
        self.PxT = torch.empty(M, Bsz, p * N, dtype=dtype)
        self.RUt = torch.empty(M, Bsz, q * N, dtype=dtype)
        if q > 1:
            self.Uq = torch.empty(M, q, Bsz, N, dtype=dtype)  # u slot-first, as G^T Z gives it
        if keep:
            self.QX = torch.empty(T, M, Bsz, p * N, dtype=dtype)
            self.RU = torch.empty(T, M, Bsz, q * N, dtype=dtype)
            self.du = torch.empty(M, Bsz, q * N, dtype=dtype)
            self.lam = [torch.empty(M, Bsz, p * N, dtype=dtype) for _ in range(2)]
            self.dZ, self.dZn, self.tmp, self.dPre, self.dY = (
                torch.empty(M, h, Bsz, N, dtype=dtype) for _ in range(5)
            )
            if p > 1:
                self.xp = torch.empty(M, p, Bsz, N, dtype=dtype)
                self.lp = torch.empty(M, p, Bsz, N, dtype=dtype)


def _slots(v: torch.Tensor, k: int) -> torch.Tensor:
    """(M, B, k N) node signals as an (M, k, B, N) view: slot first (no copy)."""
    M, Bsz, kN = v.shape
    return v.view(M, Bsz, k, kN // k).transpose(1, 2)


def _forward(prob, S, F, W, G, x0, horizon: int, ws: _Workspace, activation: str = "tanh",
             per_node: bool = False) -> torch.Tensor:
    """Roll the stack out from x0 (M, B, p N) into the workspace; J (M,) summed over the batch.

    Node signals are row vectors here (nodes on the last axis), so ``S Z`` is
    ``Z S'`` and ``Z W`` acts on the feature axis: both are single batched
    matmuls with wide operands, which BLAS runs far faster than the tall-thin
    (N B, h) x (h, h) products of the node-major layout. F is (M, p, h) and G
    (M, h, q) (views of (M, h) when nodes hold one state and one input); with
    ``per_node`` G is (M, N, h, q) in any view, node i reading its features with G[:, i].
    """
    M, N, Bsz, h = ws.shape
    p, q = ws.p, ws.q
    BN, hB = Bsz * N, h * Bsz
    F3 = F.view(M, p, h)
    Fb = [F3[:, c].reshape(M, h, 1, 1) for c in range(p)]
    if per_node:
        Gn = G.view(M, N, h, q)
    else:
        Gq = G.view(M, 1, h) if q == 1 else G.view(M, h, q).transpose(1, 2).contiguous()  # (M, q, h)
    Wt = W.transpose(1, 2)
    St = S.transpose(1, 2)
    X, U, J = ws.X, ws.U, ws.J
    squash = activation == "tanh"
    X[0].copy_(x0)
    J.zero_()
    for t in range(horizon):
        x = X[t]
        xs = _slots(x, p)
        slot = t if ws.keep else t % 2
        Z = ws.Zs[slot]
        if t == 0:
            torch.mul(xs[:, 0].unsqueeze(1), Fb[0], out=Z)
            first = 1
        else:
            Zprev = ws.Zs[slot - 1] if ws.keep else ws.Zs[1 - slot]
            Y = ws.Ys[slot]
            torch.bmm(Wt, Zprev.view(M, h, BN), out=Y.view(M, h, BN))  # (Z W) on features
            torch.bmm(Y.view(M, hB, N), St, out=Z.view(M, hB, N))  # S (.) on nodes
            first = 0
        for c in range(first, p):
            Z.addcmul_(xs[:, c].unsqueeze(1), Fb[c])
        if squash:
            tanh_(Z)
        u = U[t]
        if per_node:  # u_i = Z_i G_i: node i's features by its own readout
            _slots(u, q).copy_(torch.einsum("mkbn,mnkc->mcbn", Z, Gn))
        elif q == 1:
            torch.bmm(Gq, Z.view(M, h, BN), out=u.view(M, 1, BN))
        else:
            torch.bmm(Gq, Z.view(M, h, BN), out=ws.Uq.view(M, q, BN))
            _slots(u, q).copy_(ws.Uq)
        torch.bmm(x, prob.At, out=X[t + 1])
        X[t + 1].baddbmm_(u, prob.Bt)
        xv, uv = x.view(M, 1, -1), u.view(M, 1, -1)
        if prob.Q_identity:
            J.baddbmm_(xv, x.view(M, -1, 1))
        else:
            qx = ws.QX[t] if ws.keep else ws.PxT
            torch.bmm(x, prob.Qt, out=qx)
            J.baddbmm_(xv, qx.view(M, -1, 1))
        if prob.R_identity:
            J.baddbmm_(uv, u.view(M, -1, 1))
        else:
            ru = ws.RU[t] if ws.keep else ws.RUt
            torch.bmm(u, prob.Rt, out=ru)
            J.baddbmm_(uv, ru.view(M, -1, 1))
    xT = X[horizon]
    torch.bmm(xT, prob.Pt, out=ws.PxT)
    J.baddbmm_(xT.view(M, 1, -1), ws.PxT.view(M, -1, 1))
    return J.view(M).clone()


def _norm(p):
    return p.reshape(p.shape[0], -1).norm(dim=1)


def _node_sizes(prob, nodes: int) -> tuple[int, int, int]:
    """Nodes N and padded states p and inputs q per node of a stacked problem."""
    return nodes, prob.A.shape[1] // nodes, prob.B.shape[2] // nodes


def grnn_loss_and_grad(prob, S, F, W, G, x0, *, penalty, beta, horizon, ws=None, activation="tanh",
                       readout="shared"):
    """Per-model loss and its gradient with respect to (S, F, W, G), by hand-written BPTT.

    Parameters
    ----------
    prob : _Problem
    S, F, W, G : Tensor
        Shapes (M, N, N), (M, h) or (M, p, h), (M, h, h), (M, h) or (M, h, q);
        G is (M, N, h) or (M, N, h, q) with ``readout="per_node"``.
    x0 : Tensor (M, B, p N)
        Initial conditions, one row per trajectory (padded slot-major layout).
    penalty : Tensor (M, 4)
        Frobenius-norm weights of (S, F, W, G).
    beta : Tensor (M,)
        l1 weights on S.
    ws : _Workspace, optional
        Reusable buffers (made here if not given).
    activation : {"tanh", "identity"}
    readout : {"shared", "per_node"}

    Returns
    -------
    loss : Tensor (M,)
        mean_batch J + sum_k penalty_k ||param_k||_F + beta sum |S|.
    grads : list of Tensor
        dS, dF, dW, dG (dS unmasked), shaped like S, F, W, G.
    """
    M, Bsz = x0.shape[:2]
    N, p, q = _node_sizes(prob, S.shape[1])
    h = W.shape[1]
    if ws is None:
        ws = _Workspace(M, N, Bsz, h, horizon, S.dtype, keep=True, p=p, q=q)
    BN, hB = Bsz * N, h * Bsz
    _check_activation(activation)
    _check_readout(readout)
    per_node = readout == "per_node"
    squash = activation == "tanh"
    J = _forward(prob, S, F, W, G, x0, horizon, ws, activation, per_node)
    X, U, Zs, Ys = ws.X, ws.U, ws.Zs, ws.Ys
    QX = X if prob.Q_identity else ws.QX
    RU = U if prob.R_identity else ws.RU
    c2 = 2.0 / Bsz
    Fr = F.view(M, p, h)
    dS = torch.zeros_like(S)
    # dF, dG accumulate as row vectors: (1, BN) x (BN, h) runs ~6x faster than (h, BN) x (BN, 1).
    dF = torch.zeros(M, p, h, dtype=S.dtype)
    dWt = torch.zeros_like(W)
    if per_node:
        Gn = G.view(M, N, h, q)
        dG = torch.zeros(M, N, h, q, dtype=S.dtype)
    else:
        Gc = G.view(M, h, q)
        dG = torch.zeros(M, q, h, dtype=S.dtype)
    lam, lam_next = ws.lam
    torch.mul(ws.PxT, c2, out=lam)
    du, dZ, dZn, tmp, dPre, dY = ws.du, ws.dZ, ws.dZn, ws.tmp, ws.dPre, ws.dY
    dPre_h = dPre.view(M, h, BN)
    for t in range(horizon - 1, -1, -1):
        torch.baddbmm(RU[t], lam, prob.B, beta=c2, out=du)  # d/du of x' = x A' + u B'
        Zn = Zs[t]  # Z(t+1)
        if per_node:  # dZ(t+1)_i = G_i du_i (+ what Z(t+2) sent back); dG_i = sum_b Z_i(t+1)' du_i
            du_nodes = _slots(du, q)  # (M, q, B, N)
            from_u = torch.einsum("mnkc,mcbn->mkbn", Gn, du_nodes)
            if t == horizon - 1:
                dZn.copy_(from_u)
            else:
                torch.add(dZ, from_u, out=dZn)
            dG.add_(torch.einsum("mcbn,mkbn->mnkc", du_nodes, Zn))
        else:
            if q == 1:
                duq = du.view(M, 1, BN)
            else:
                ws.Uq.copy_(_slots(du, q))
                duq = ws.Uq.view(M, q, BN)
            if t == horizon - 1:
                torch.bmm(Gc, duq, out=dZn.view(M, h, BN))
            else:
                torch.baddbmm(dZ.view(M, h, BN), Gc, duq, out=dZn.view(M, h, BN))
            dG.baddbmm_(duq, Zn.view(M, h, BN).transpose(1, 2))
        if squash:
            torch.mul(dZn, Zn, out=tmp)
            torch.addcmul(dZn, tmp, Zn, value=-1.0, out=dPre)  # dZn * (1 - Zn^2)
        else:
            dPre.copy_(dZn)
        if p == 1:
            dF.baddbmm_(X[t].view(M, 1, BN), dPre_h.transpose(1, 2))
        else:
            ws.xp.copy_(_slots(X[t], p))
            dF.baddbmm_(ws.xp.view(M, p, BN), dPre_h.transpose(1, 2))
        if t == 0:
            break
        dS.baddbmm_(dPre.view(M, hB, N).transpose(1, 2), Ys[t].view(M, hB, N))
        torch.bmm(dPre.view(M, hB, N), S, out=dY.view(M, hB, N))
        dWt.baddbmm_(dY.view(M, h, BN), Zs[t - 1].view(M, h, BN).transpose(1, 2))
        torch.bmm(W, dY.view(M, h, BN), out=dZ.view(M, h, BN))
        torch.baddbmm(QX[t], lam, prob.A, beta=c2, out=lam_next)
        if p == 1:
            lam_next.view(M, 1, BN).baddbmm_(Fr, dPre_h)
        else:
            torch.bmm(Fr, dPre_h, out=ws.lp.view(M, p, BN))
            _slots(lam_next, p).add_(ws.lp)
        lam, lam_next = lam_next, lam
    dF = dF.view(F.shape)
    if per_node:
        dG = dG.view(G.shape)
    else:
        dG = dG.view(G.shape) if q == 1 else dG.transpose(1, 2).reshape(G.shape)
    dW = dWt.transpose(1, 2)
    return _penalized(J / Bsz, [dS, dF, dW, dG], (S, F, W, G), penalty, beta)


def _penalized(cost, grads, params, penalty, beta):
    """Loss = cost + sum_k penalty_k ||param_k||_F + beta sum |S|, and its gradient from the cost's."""
    S = params[0]
    loss = cost + beta * S.abs().sum((1, 2))
    grads = list(grads)
    for k, param in enumerate(params):
        weight = penalty[:, k]
        norm = _norm(param)
        loss = loss + weight * norm
        scale = torch.where(norm > 0, weight / norm.clamp_min(1e-300), torch.zeros_like(norm))
        grads[k] = grads[k] + scale.view((-1,) + (1,) * (param.dim() - 1)) * param
    grads[0] = grads[0] + beta.view(-1, 1, 1) * torch.sign(S)
    return loss, grads


@no_grad
def rollout_cost(prob, S, F, W, G, x0, horizon, ws=None, activation="tanh", readout="shared") -> torch.Tensor:
    """Mean normalized cost per model on the initial conditions x0 (M, B, p N)."""
    _check_readout(readout)
    M, Bsz = x0.shape[:2]
    if ws is None:
        N, p, q = _node_sizes(prob, S.shape[1])
        ws = _Workspace(M, N, Bsz, W.shape[1], horizon, S.dtype, keep=False, p=p, q=q)
    J = _forward(prob, S, F, W, G, x0, horizon, ws, activation, readout == "per_node")
    return J / Bsz / prob.trace_P




class GRNNStack(StackModel):
    """A stack of GRNNs for :func:`~codesign.learned.trainer.train_stack`; members' problems are :class:`ModelSpec`.

    Options: ``activation`` (one of :data:`ACTIVATIONS`), ``engine`` (one of
    :data:`ENGINES`; the engines agree to rounding) and ``readout`` (one of
    :data:`READOUTS`; "per_node" trains on the torch engine only, its members'
    G0 with a leading node axis). S trains on its mask (an all-False mask
    freezes it at S0; the others start on their support).
    """

    names = ("S", "F", "W", "G")

    def __init__(self, members, loop: Loop, *, activation: str = "tanh", engine: str = "torch",
                 readout: str = "shared"):
        _check_activation(activation)
        _check_readout(readout)
        specs = [m.problem for m in members]
        tdt = torch_dtype(loop.dtype)
        M, N = len(specs), specs[0].S0.shape[0]
        prob = _Problem(specs, tdt)
        _, p, q = _node_sizes(prob, N)
        masks = np.stack([np.asarray(s.mask, dtype=bool) for s in specs])
        engine = self.engine_for(members, engine, readout=readout)
        self.dim = p * N
        h = np.shape(specs[0].W0)[0]
        if readout == "per_node" and np.shape(specs[0].G0) not in [(N, h, q)] + [(N, h)] * (q == 1):
            raise ValueError(f"readout 'per_node' needs G0 of shape ({N}, {h}, {q})"
                             f"{f' or ({N}, {h})' if q == 1 else ''}, got {np.shape(specs[0].G0)}")

        def stack(name):
            return torch.tensor(np.stack([np.asarray(getattr(s, name), dtype=float) for s in specs]), dtype=tdt)

        S, F, W, G = stack("S0"), stack("F0"), stack("W0"), stack("G0")
        mask = torch.tensor(masks)
        maskf = mask.to(tdt)
        frozen = ~mask.any(dim=(1, 2))
        S.mul_(torch.where(frozen.view(M, 1, 1), torch.ones_like(maskf), maskf))
        self.params = [S, F, W, G]
        penalty = torch.tensor([s.penalty for s in specs], dtype=tdt)
        beta = torch.tensor([s.beta for s in specs], dtype=tdt)
        h, horizon, batch = W.shape[1], loop.horizon, loop.batch
        curve_size = np.shape(members[0].curve_x0)[0]
        if engine == "fused":
            from . import fused

            compiled = fused.FusedStack(prob.A.numpy(), prob.B.numpy(), prob.Q.numpy(), prob.R.numpy(),
                                        prob.P.numpy(), S.numpy(), masks, hidden=h, horizon=horizon,
                                        batch=batch, dtype=S.numpy().dtype, squash=activation == "tanh")
            arrays = [param.numpy() for param in self.params]  # views: Adam updates them in place

            def loss_and_grad(x0):
                J, *grads = compiled.loss_and_grad(*arrays, np.ascontiguousarray(x0.numpy().transpose(0, 2, 1)))
                return _penalized(torch.from_numpy(J) / batch, [torch.from_numpy(g) for g in grads],
                                  self.params, penalty, beta)

            def curve_cost(x0):
                nodes = np.ascontiguousarray(x0.numpy().transpose(0, 2, 1))
                return torch.from_numpy(compiled.costs(*arrays, nodes)) / x0.shape[1] / prob.trace_P
        else:
            ws_train = _Workspace(M, N, batch, h, horizon, tdt, keep=True, p=p, q=q)
            ws_curve = _Workspace(M, N, curve_size, h, horizon, tdt, keep=False, p=p, q=q)

            def loss_and_grad(x0):
                return grnn_loss_and_grad(prob, S, F, W, G, x0, penalty=penalty, beta=beta, horizon=horizon,
                                          ws=ws_train, activation=activation, readout=readout)

            def curve_cost(x0):
                return rollout_cost(prob, S, F, W, G, x0, horizon, ws_curve, activation, readout)

        self._loss_and_grad, self._curve_cost, self._maskf = loss_and_grad, curve_cost, maskf
        self.engine = engine

    @classmethod
    def shape_key(cls, member: Member) -> tuple:
        s = member.problem
        return member.shape_key() + tuple(np.shape(getattr(s, k)) for k in ("A", "B", "S0", "F0", "W0", "G0"))

    @staticmethod
    def engine_for(members, engine: str, *, readout: str = "shared") -> str:
        """The engine a stack of ``members`` trains with (:func:`~codesign.learned.engines.resolve_engine`)."""
        specs = [m.problem for m in members]
        N = specs[0].S0.shape[0]
        masks = np.stack([np.asarray(s.mask, dtype=bool) for s in specs])
        supports = s_supports(np.stack([s.S0 for s in specs]), masks)
        unsupported = fused_unsupported(states_per_node=specs[0].A.shape[1] // N,
                                        inputs_per_node=specs[0].B.shape[1] // N, readout=readout)
        return resolve_engine(engine, unsupported=unsupported, nodes=N,
                              support_density=supports.mean(axis=(1, 2)).max())

    @classmethod
    def independent(cls, members, loop: Loop, *, activation: str = "tanh", engine: str = "torch",
                    readout: str = "shared") -> bool:
        """On the fused engine: it runs each model on its own, and Adam and the clip act per model."""
        return cls.engine_for(members, engine, readout=readout) == "fused"

    def loss_and_grad(self, x0):
        loss, grads = self._loss_and_grad(x0)
        grads[0].mul_(self._maskf)  # masked gradients keep S exactly zero (or frozen) off the support
        return loss, grads

    def curve_cost(self, x0):
        return self._curve_cost(x0)


def train_grnn(specs: list[ModelSpec], *, steps: int = 750, batch: int = 20, horizon: int = 50,
               clip: float = 10.0, curve_every: int = 10, dtype: str = "float64", activation: str = "tanh",
               engine: str = "auto", readout: str = "shared"):
    """Train the GRNNs of ``specs`` as one stack (cosine schedule); one TrainResult per spec.

    A convenience over :func:`~codesign.learned.trainer.train_stack` with
    :class:`GRNNStack`, for tests and benchmarks that build specs by hand.
    """
    loop = Loop(steps=steps, batch=batch, horizon=horizon, clip=clip, curve_every=curve_every, dtype=dtype)
    return train_stack(GRNNStack, [s.member() for s in specs], loop, activation=activation, engine=engine,
                       readout=readout)
