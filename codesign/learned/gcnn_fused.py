"""The GCNN's loss and gradient as one compiled pass per model (numba): its ``fused`` engine.

The paper's setting only (one state and one input per node, Q = R = I), the
model of :func:`codesign.learned.gcnn_bptt._loss_and_grad` with the same
hand-written BPTT, reordered: results agree with the torch path to rounding
(``tests/test_gcnn.py``). The torch path spends most of its time in a dozen
elementwise passes over (M, 32, B N) tensors per time step; here a model's
filter bank, tanh (the GRNN kernel's vectorizable one) and their gradients run
over rows of B N values that stay in cache.

Layout (one model at a time): node signals (N, B); the taps' shifted signals
XK (T, K, N B); activations (T, F, N B).
"""

from __future__ import annotations

import functools

import numpy as np

from .fused import dense_mix, kernel_jit, tanh32, tanh64, tanh_constants

__all__ = ["FusedGCNN"]


@functools.lru_cache(maxsize=None)
def _kernel(N: int, B: int, K: int, F: int, T: int, dtype_name: str, backward: bool):
    """The kernel for one shape, sizes as compile-time constants (the loops over taps and features unroll)."""
    dt = np.dtype(dtype_name).type
    NB = N * B
    ZERO, ONE, C2 = dt(0.0), dt(1.0), dt(2.0 / B)
    COEF, CONSTS = tanh_constants(dt)
    WIDE = dt == np.float64

    @kernel_jit
    def kernel(x0, S, H, w, A, Bm, P, J, dH, dw, X, U, XK, Acts, lam, du, dz, dXK, g, tmp):
        """Summed cost J (M,) from x0 (M, N, B) and, with ``backward``, dJ/dH (M, K, F), dJ/dw (M, F).

        S, A, Bm, P (M, N, N); H (M, K, F); w (M, F). Buffers: X, U (T + 1 or 2, N, B); XK
        (T or 1, K, N B); Acts (T or 1, F, N B); lam, du, g, tmp (N, B); dz (F, N B); dXK (K, N B).
        """
        for m in range(x0.shape[0]):
            Sm, Hm, wm, Am, Bmm = S[m], H[m], w[m], A[m], Bm[m]
            X[0] = x0[m]
            Jm = ZERO
            for t in range(T):
                slot = t if backward else 0
                x = X[t] if backward else X[t % 2]
                x_next = X[t + 1] if backward else X[(t + 1) % 2]
                xk, a, u = XK[slot], Acts[slot], U[t] if backward else U[0]
                xk[0] = x.reshape(NB)
                for k in range(1, K):
                    dense_mix(xk[k].reshape(N, B), Sm, xk[k - 1].reshape(N, B), False, N, ZERO)
                for f in range(F):
                    af = a[f]
                    for c in range(NB):
                        acc = ZERO
                        for k in range(K):
                            acc += Hm[k, f] * xk[k, c]
                        af[c] = acc
                if WIDE:
                    tanh64(a.reshape(F * NB), COEF, CONSTS)
                else:
                    tanh32(a.reshape(F * NB), COEF, CONSTS)
                uf = u.reshape(NB)
                for c in range(NB):
                    acc = ZERO
                    for f in range(F):
                        acc += wm[f] * a[f, c]
                    uf[c] = acc
                dense_mix(x_next, Am, x, False, N, ZERO)
                dense_mix(tmp, Bmm, u, False, N, ZERO)
                xf, nf, tf = x.reshape(NB), x_next.reshape(NB), tmp.reshape(NB)
                for c in range(NB):
                    nf[c] += tf[c]
                    Jm += xf[c] * xf[c] + uf[c] * uf[c]
            xT = X[T] if backward else X[T % 2]
            dense_mix(lam, P[m], xT, False, N, ZERO)
            lf, xf = lam.reshape(NB), xT.reshape(NB)
            for c in range(NB):
                Jm += xf[c] * lf[c]
                lf[c] *= C2  # dJ/dx(T) / B
            J[m] = Jm
            if not backward:
                continue
            dHm, dwm = dH[m], dw[m]
            dHm[:] = ZERO
            dwm[:] = ZERO
            for t in range(T - 1, -1, -1):
                a, xk = Acts[t], XK[t]
                dense_mix(du, Bmm, lam, True, N, ZERO)  # du = B' lam + c2 u
                df, uf = du.reshape(NB), U[t].reshape(NB)
                for c in range(NB):
                    df[c] += C2 * uf[c]
                for f in range(F):  # dz = w du (1 - a^2); dw += a . du
                    af, zf, wf = a[f], dz[f], wm[f]
                    acc = ZERO
                    for c in range(NB):
                        d, s = df[c], af[c]
                        acc += s * d
                        zf[c] = wf * d * (ONE - s * s)
                    dwm[f] += acc
                for k in range(K):  # dH += XK dz'
                    xkk = xk[k]
                    for f in range(F):
                        zf = dz[f]
                        acc = ZERO
                        for c in range(NB):
                            acc += xkk[c] * zf[c]
                        dHm[k, f] += acc
                if t == 0:
                    break
                for k in range(K):  # dXK = H dz
                    dk = dXK[k]
                    for c in range(NB):
                        acc = ZERO
                        for f in range(F):
                            acc += Hm[k, f] * dz[f, c]
                        dk[c] = acc
                g[:] = dXK[K - 1].reshape(N, B)  # back through XK[k] = S XK[k - 1]
                for k in range(K - 2, -1, -1):
                    dense_mix(tmp, Sm, g, True, N, ZERO)
                    gf, tf, dk = g.reshape(NB), tmp.reshape(NB), dXK[k]
                    for c in range(NB):
                        gf[c] = dk[c] + tf[c]
                dense_mix(tmp, Am, lam, True, N, ZERO)  # lam = g + A' lam + c2 x(t)
                gf, tf, xf, lf = g.reshape(NB), tmp.reshape(NB), X[t].reshape(NB), lam.reshape(NB)
                for c in range(NB):
                    lf[c] = gf[c] + tf[c] + C2 * xf[c]

    return kernel


class FusedGCNN:
    """The fused GCNN engine's state for one stack: the plants and buffers, made once per run.

    Parameters
    ----------
    S, A, B, P : ndarray (M, N, N)
        Shift operators, plants and terminal costs (Q = R = I, one state and input per node).
    taps, features, horizon : int
    dtype : numpy dtype (float32 or float64)
    """

    def __init__(self, S, A, B, P, *, taps, features, horizon, dtype):
        self.dtype = np.dtype(dtype).type
        self.S, self.A, self.B, self.P = (np.ascontiguousarray(a, dtype=self.dtype) for a in (S, A, B, P))
        self.N, self.K, self.F, self.T = S.shape[1], taps, features, horizon
        self._buffers = {}

    def _work(self, batch: int, keep: bool) -> tuple:
        if (batch, keep) not in self._buffers:
            N, K, F, T, dt = self.N, self.K, self.F, self.T, self.dtype
            NB = N * batch
            depth = T if keep else 1
            shapes = [(T + 1 if keep else 2, N, batch), (T if keep else 1, N, batch), (depth, K, NB),
                      (depth, F, NB), (N, batch), (N, batch), (F, NB), (K, NB), (N, batch), (N, batch)]
            self._buffers[(batch, keep)] = tuple(np.zeros(shape, dt) for shape in shapes)
        return self._buffers[(batch, keep)]

    def _run(self, H, w, x0, backward: bool):
        M, _, batch = x0.shape
        kernel = _kernel(self.N, batch, self.K, self.F, self.T, np.dtype(self.dtype).name, backward)
        J = np.empty(M, self.dtype)
        dH, dw = np.empty_like(H), np.empty_like(w)
        kernel(np.ascontiguousarray(x0, dtype=self.dtype), self.S, H, w, self.A, self.B, self.P, J, dH, dw,
               *self._work(batch, backward))
        return J, dH, dw

    def loss_and_grad(self, H, w, x0):
        """Summed cost J (M,) and its gradients dH (M, K, F), dw (M, F); x0 (M, N, B) in the dtype."""
        return self._run(H, w, x0, True)

    def costs(self, H, w, x0):
        """Summed cost J (M,) of each model from x0 (M, N, B)."""
        return self._run(H, w, x0, False)[0]
