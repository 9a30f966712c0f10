"""Independent references shared by several test modules (not a test module itself)."""

from __future__ import annotations

import numpy as np
import torch

from baselines.sparse_delayed import delayed_closed_loop
from codesign.learned.grnn_bptt import _node_sizes, _norm, _penalized, _Problem, grnn_loss_and_grad


def static_gain_response_cost(instance, K):
    """Normalized cost from the responses x(t) = Acl^t x(0), summed forward in dense float64."""
    Acl = instance.A + instance.B @ K
    phi = np.eye(instance.n)
    total = 0.0
    for _ in range(instance.horizon):
        u = K @ phi
        total += np.sum(phi * (instance.Q @ phi)) + np.sum(u * (instance.R @ u))
        phi = Acl @ phi
    total += np.sum(phi * (instance.P @ phi))
    return total / instance.trace_P


def augmented_delayed_reference(instance, K_local, K_delayed):
    """Cost and gradient of the augmented loop z = [x; x_prev] by its Lyapunov recursion (m x n gains).

    M = [[A + B Kl, B Kd], [I, 0]], stage cost z'(Qbar + C'RC)z with C = [Kl, Kd],
    terminal x(T)'P x(T), z(0) = [x0; 0]; the gradient over C is
    sum_t 2 (R C + Bbar' Pi_{t+1} M) Sigma_t with Bbar = [B; 0] (2n x m).
    """
    n, m, T = instance.n, instance.m, instance.horizon
    C = np.hstack([K_local, K_delayed])
    M = delayed_closed_loop(instance, K_local, K_delayed)
    Bbar = np.vstack([instance.B, np.zeros((n, m))])
    S = C.T @ instance.R @ C
    S[:n, :n] += instance.Q
    Pis = [None] * (T + 1)
    Pis[T] = np.zeros((2 * n, 2 * n))
    Pis[T][:n, :n] = instance.P
    for t in range(T - 1, -1, -1):
        Pis[t] = S + M.T @ Pis[t + 1] @ M
    sigma = np.zeros((2 * n, 2 * n))
    sigma[:n, :n] = np.eye(n)
    grad = np.zeros((m, 2 * n))
    for t in range(T):
        grad += 2.0 * (instance.R @ C + Bbar.T @ Pis[t + 1] @ M) @ sigma
        sigma = M @ sigma @ M.T
    scale = instance.trace_P
    return np.trace(Pis[0][:n, :n]) / scale, grad[:, :n] / scale, grad[:, n:] / scale


def assert_bptt_matches_autograd(specs, x0, *, horizon: int, activation: str, engine: str = "torch") -> None:
    """The hand-written BPTT's loss and four gradients equal autograd's on a stack of ``specs``.

    ``engine="fused"``: the compiled engine's, whose S gradient exists on the mask only
    (compared there; off the mask it must be exactly zero).
    """
    prob = _Problem(specs, torch.float64)
    tensors = [torch.tensor(np.stack([getattr(s, name) for s in specs])) for name in ("S0", "F0", "W0", "G0")]
    x0 = torch.as_tensor(x0, dtype=torch.float64)
    penalty = torch.tensor([s.penalty for s in specs])
    beta = torch.tensor([s.beta for s in specs])
    leaves = [t.clone().requires_grad_(True) for t in tensors]
    reference = grnn_loss_autograd(prob, *leaves, x0, penalty=penalty, beta=beta, horizon=horizon, activation=activation)
    reference.sum().backward()
    references = [leaf.grad for leaf in leaves]
    if engine == "torch":
        loss, grads = grnn_loss_and_grad(prob, *tensors, x0, penalty=penalty, beta=beta, horizon=horizon,
                                         activation=activation)
    else:
        from codesign.learned.fused import FusedStack

        mask = np.stack([s.mask for s in specs])
        arrays = [t.numpy() for t in tensors]
        stack = FusedStack(*(prob_array.numpy() for prob_array in (prob.A, prob.B, prob.Q, prob.R, prob.P)),
                           arrays[0], mask, hidden=arrays[2].shape[1], horizon=horizon, batch=x0.shape[1],
                           dtype=np.float64, squash=activation == "tanh")
        J, *raw = stack.loss_and_grad(*arrays, np.ascontiguousarray(x0.numpy().transpose(0, 2, 1)))
        assert np.all(raw[0][~mask] == 0.0)
        loss, grads = _penalized(torch.from_numpy(J) / x0.shape[1], [torch.from_numpy(g) for g in raw],
                                 tensors, penalty, beta)
        on_mask = torch.from_numpy(mask.astype(float))
        grads[0], references[0] = grads[0] * on_mask, references[0] * on_mask
    np.testing.assert_allclose(loss.numpy(), reference.detach().numpy(), rtol=1e-12)
    for leaf, grad, expected in zip(leaves, grads, references):
        assert grad.shape == leaf.shape
        np.testing.assert_allclose(grad.numpy(), expected.numpy(), rtol=0, atol=1e-11 * expected.abs().max().item())


# -- autograd references of the hand-written BPTTs (the same losses, plain torch ops) --

def grnn_loss_autograd(prob, S, F, W, G, x0, *, penalty, beta, horizon, activation="tanh", per_node=False):
    """The GRNN loss of :func:`grnn_loss_and_grad` with torch.tanh, node-major and autograd-friendly.

    ``x0`` has shape (M, B, p N) as in :func:`grnn_loss_and_grad`. ``per_node``: each node reads
    out with its own G_i (``G`` of shape (M, N h q)), u_i = Z_i G_i.
    """
    M, Bsz = x0.shape[:2]
    N, p, q = _node_sizes(prob, S.shape[1])
    h = W.shape[1]
    x = x0.transpose(1, 2)  # (M, p N, B): states slot-major
    F3 = F.reshape(M, p, h)
    G3 = G.reshape(M, N, h, q) if per_node else G.reshape(M, h, q)
    Z = torch.zeros(M, N, Bsz, h, dtype=x0.dtype)
    J = torch.zeros(M, dtype=x0.dtype)
    sigma = torch.tanh if activation == "tanh" else (lambda pre: pre)
    for _ in range(horizon):
        SZ = torch.einsum("mij,mjbk->mibk", S, Z)
        xin = torch.einsum("mcib,mck->mibk", x.reshape(M, p, N, Bsz), F3)
        Z = sigma(torch.einsum("mibk,mkl->mibl", SZ, W) + xin)
        u = torch.einsum("mibk,mikc->mcib" if per_node else "mibk,mkc->mcib", Z, G3).reshape(M, q * N, Bsz)
        J = J + torch.einsum("mib,mij,mjb->m", x, prob.Q, x) + torch.einsum("mib,mij,mjb->m", u, prob.R, u)
        x = torch.einsum("mij,mjb->mib", prob.A, x) + torch.einsum("mij,mjb->mib", prob.B, u)
    J = J + torch.einsum("mib,mij,mjb->m", x, prob.P, x)
    loss = J / Bsz + beta * S.abs().sum((1, 2))
    for k, param in enumerate((S, F, W, G)):
        loss = loss + penalty[:, k] * _norm(param)
    return loss


def gcnn_cost_autograd(S, H, w, A_t, B_t, P, x, horizon):
    """Summed cost J (M,) of the stack from x (M, B, N) with plain autograd ops .

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
        act = torch.tanh(z)
        u = torch.bmm(wr, act).view(M, Bsz, N)
        J = J + (x * x).sum((1, 2)) + (u * u).sum((1, 2))
        x = torch.bmm(x, A_t) + torch.bmm(u, B_t)
    return J + (torch.bmm(x, P) * x).sum((1, 2))


def gcnn_block_cost_autograd(S, H, w, Ex, Eu, A_t, B_t, Q, R, P, x, horizon):
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
