"""Independent references shared by several test modules (not a test module itself)."""

from __future__ import annotations

import numpy as np
import torch

from baselines.sparse_delayed import delayed_closed_loop
from codesign.training import _penalized, _Problem, grnn_loss_and_grad, loss_autograd


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
    reference = loss_autograd(prob, *leaves, x0, penalty=penalty, beta=beta, horizon=horizon, activation=activation)
    reference.sum().backward()
    references = [leaf.grad for leaf in leaves]
    if engine == "torch":
        loss, grads = grnn_loss_and_grad(prob, *tensors, x0, penalty=penalty, beta=beta, horizon=horizon,
                                         activation=activation)
    else:
        from codesign.fused import FusedStack

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
