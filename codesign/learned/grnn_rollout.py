"""A trained GRNN's closed-loop rollout as one compiled pass (numba): what its simulated cost is made of.

:meth:`GRNNController.step <codesign.learned.grnn.GRNNController.step>` advances a
batch with a few wide numpy products and an elementwise tanh per time step, each a
pass over the whole ``(h, batch, N)`` hidden state (1.6 MB at 2000 draws), and
multiplies by S dense however few links it has. Here draws are rolled out
:data:`BLOCK` at a time through the whole horizon with the block's state in cache:
S on its nonzeros and [A B] on its nonzeros (the fused trainer's helpers,
:mod:`codesign.learned.fused`), tanh by its vectorizing polynomial (within one unit
in the last place). ``benchmarks/bench_grnn_rollout.py`` measures both.

The arithmetic is :func:`codesign.evaluation.simulate`'s step loop, reordered: the
costs agree with it to rounding, not bit for bit (``tests/test_grnn_rollout.py``).
"""

from __future__ import annotations

import functools

import numpy as np

from .fused import (add_input, dense_mix, feature_mix, kernel_jit, padded_rows, readout, sparse_rows, tanh64,
                    tanh_constants)

__all__ = ["BLOCK", "rollout_costs"]

#: Enter the code fingerprint of every method whose designs are scored through this module.
FINGERPRINT_PACKAGES = ("numba", "llvmlite")

#: Draws rolled out together: a multiple of the vector width, small enough that a block's
#: hidden state (N h BLOCK values) stays in cache at N = 100.
BLOCK = 64


@functools.lru_cache(maxsize=None)
def _kernel(h: int, squash: bool, q_identity: bool, r_identity: bool):
    """The rollout for ``h`` hidden features (a compile-time constant, as the block size is)."""
    coef, consts = tanh_constants(np.float64)
    zero = 0.0
    width = h * BLOCK

    @kernel_jit
    def kernel(x0, F, W, G, s_ptr, s_cols, s_vals, ab_ptr, ab_cols, ab_vals, Q, R, P, costs, peaks,
               Z, Zp, Y, XU, XN, tmp, acc):
        """costs (blocks BLOCK,): each draw's summed stage costs and terminal cost (not divided by
        trace P); peaks (blocks, T): the largest |x(t + 1)| of each block at each step (inf if not
        finite). x0 (blocks BLOCK, N), the draws; Z, Zp, Y (N, h BLOCK) hidden-state buffers; XU (2N,
        BLOCK) x(t) over u(t); XN, tmp (N, BLOCK); acc (BLOCK,)."""
        N = P.shape[0]
        T = peaks.shape[1]
        for blk in range(peaks.shape[0]):
            for i in range(N):
                for b in range(BLOCK):
                    XU[i, b] = x0[blk * BLOCK + b, i]
            Zp[:] = zero
            acc[:] = zero
            for t in range(T):
                feature_mix(Y, Zp, W, False, N, h, BLOCK, zero)  # Y_j = W' Z_j(t - 1)
                sparse_rows(Z, Y, s_ptr, s_cols, s_vals, zero)  # Z_i = sum_j S_ij Y_j
                add_input(Z, XU, F, N, h, BLOCK)
                if squash:
                    tanh64(Z.reshape(N * width), coef, consts)
                readout(XU[N:], Z, G, N, h, BLOCK, zero)
                x, u = XU[:N], XU[N:]
                if not q_identity:
                    dense_mix(tmp, Q, x, False, N, zero)
                for i in range(N):
                    for b in range(BLOCK):
                        acc[b] += x[i, b] * (x[i, b] if q_identity else tmp[i, b])
                if not r_identity:
                    dense_mix(tmp, R, u, False, N, zero)
                for i in range(N):
                    for b in range(BLOCK):
                        acc[b] += u[i, b] * (u[i, b] if r_identity else tmp[i, b])
                sparse_rows(XN, XU, ab_ptr, ab_cols, ab_vals, zero)  # x(t + 1) = A x(t) + B u(t)
                peak = zero
                for i in range(N):
                    for b in range(BLOCK):
                        v = XN[i, b]
                        XU[i, b] = v
                        a = abs(v)
                        if not a <= peak:  # a larger value, or NaN
                            peak = a if a == a else np.inf
                peaks[blk, t] = peak
                Z, Zp = Zp, Z
            dense_mix(tmp, P, XU[:N], False, N, zero)
            for i in range(N):
                for b in range(BLOCK):
                    acc[b] += XU[i, b] * tmp[i, b]
            for b in range(BLOCK):
                costs[blk * BLOCK + b] = acc[b]

    return kernel


def rollout_costs(instance, S, F, W, G, x0, steps: int, *, squash: bool = True):
    """Each draw's closed-loop cost of a GRNN (one state and one input per node) and each step's peak state.

    Parameters
    ----------
    instance : Instance
        The plant and costs (A, B, Q, R, P).
    S : ndarray (N, N)
    F, G : ndarray (h,)
    W : ndarray (h, h)
    x0 : ndarray (batch, N)
        Initial states.
    steps : int
        Time steps; the terminal cost x(steps)' P x(steps) is added.
    squash : bool
        tanh (True) or the identity activation.

    Returns
    -------
    costs : ndarray (batch,)
        ``sum_t x'Qx + u'Ru + x(steps)' P x(steps)`` per draw, not divided by trace P.
    peaks : ndarray (steps,)
        ``max |x(t + 1)|`` over the batch at each step t; inf where a state is not finite.
    """
    A, B, Q, R, P = (np.ascontiguousarray(getattr(instance, name), dtype=float) for name in "ABQRP")
    N, h = A.shape[0], W.shape[0]
    batch = x0.shape[0]
    blocks = -(-batch // BLOCK)
    x = np.zeros((blocks * BLOCK, N))  # the last block's missing draws start at 0 and cost 0
    x[:batch] = x0
    s_ptr, s_cols, _, s_vals = padded_rows((S != 0)[None], np.asarray(S, dtype=float)[None])
    AB = np.concatenate([A, B], axis=1)
    ab_ptr, ab_cols, _, ab_vals = padded_rows((AB != 0)[None], AB[None])
    eye = np.eye(N)
    kernel = _kernel(h, bool(squash), bool(np.array_equal(Q, eye)), bool(np.array_equal(R, eye)))
    costs = np.empty(blocks * BLOCK)
    peaks = np.empty((blocks, int(steps)))
    hidden = [np.zeros((N, h * BLOCK)) for _ in range(3)]
    kernel(x, *(np.ascontiguousarray(a, dtype=float) for a in (F, W, G)), s_ptr[0], s_cols[0], s_vals[0],
           ab_ptr[0], ab_cols[0], ab_vals[0], Q, R, P, costs, peaks, *hidden, np.zeros((2 * N, BLOCK)),
           np.zeros((N, BLOCK)), np.zeros((N, BLOCK)), np.zeros(BLOCK))
    return costs[:batch], (peaks.max(axis=0) if blocks else np.zeros(int(steps)))
