"""The GRNN's loss and gradient as one compiled pass per model (numba): the ``fused`` engine.

:mod:`codesign.learned.grnn_bptt` advances a stack of models with one torch call per
product per time step, which leaves two costs no arrangement of torch calls
removes: the Python overhead of ~40 calls per time step, and dense products with
S even where the mask makes most of S zero. Here one compiled function runs a
model's whole forward and backward pass (the same recurrence, the same
hand-written BPTT) with its tensors in cache, and multiplies by S, A and B on
sparsity patterns fixed for the run: S on its support (the mask when S trains,
the nonzeros of S0 when it is frozen), [A B] on its nonzeros; either is taken
dense where it is more than about half full.

The arithmetic is the torch engine's, reordered: results agree with it to
rounding, not bit for bit (``tests/test_fused.py``). tanh is evaluated here as
``(s - e) / (s + e)`` from a Taylor polynomial of exp after range reduction,
within one unit in the last place of 1, because the C library's tanh, called per
element, does not vectorize.

Layout (one model at a time, all buffers reused): node signals ``(N, B)`` rows,
hidden states ``(N, h B)`` so that a node's ``h B`` values are one contiguous
row for the products with S. One state and one input per node only.
"""

from __future__ import annotations

import functools
import inspect
from typing import NamedTuple

import numba
import numpy as np

from .engines import FUSED_DENSE_NODES, FUSED_DENSE_S, s_supports

__all__ = ["FusedStack", "Plan", "Workspace", "DENSE_S", "DENSE_AB",
           # the compiled helpers the GCNN kernel and the GRNN rollout share
           "tanh_constants", "tanh32", "tanh64", "feature_mix", "add_input", "readout", "sparse_rows", "dense_mix",
           "padded_rows"]

#: Enter the code fingerprint of every method that trains through this module.
FINGERPRINT_PACKAGES = ("numba", "llvmlite")


class _NoAliasCompiler(numba.core.compiler.CompilerBase):
    """numba's nopython pipeline with the kernel's array arguments marked noalias.

    numba's non-public API: benchmarks/bench_fused_noalias.py measures it worth 12-24 %
    of a pass, so it stays and pyproject.toml pins numba to the versions tested with it.

    Without it LLVM must assume any two arrays may overlap and guards every
    vectorized loop with run-time overlap checks: 15 % of the kernel's time at
    these row lengths. The kernel's arguments are distinct allocations
    (:meth:`FusedStack._run`), which is what noalias promises.
    """

    def define_pipelines(self):
        self.state.flags.noalias = True
        return [numba.core.compiler.DefaultPassBuilder.define_nopython_pipeline(self.state)]


#: The pipeline the kernels compile with; None: numba's default (public) one, which
#: benchmarks/bench_fused_noalias.py measures against this.
PIPELINE = _NoAliasCompiler


def kernel_jit(function):
    """Compile a kernel (this module's and :mod:`codesign.learned.gcnn_fused`'s) with :data:`PIPELINE`."""
    if PIPELINE is None:
        return _jit(function)
    return _jit(pipeline_class=PIPELINE)(function)


# Reassociation lets reductions vectorize; no 'nnan'/'ninf': a diverging model must
# still produce inf/NaN for the trainer to flag it. error_model="numpy": no
# zero-division checks, which otherwise keep every loop with a division scalar.
# Helpers are module-level with their sizes as arguments, inlined into the kernels,
# which are compiled per shape with the sizes as constants: LLVM then unrolls the
# short loops over features and nodes. numba caches all of it on disk.
_jit = functools.partial(numba.njit, fastmath={"reassoc", "contract", "nsz", "arcp"},
                         error_model="numpy", cache=True)
_helper = functools.partial(_jit, inline="always")

#: Fractions of nonzeros above which products with S, and with [A B]', are taken dense
#: (S only up to FUSED_DENSE_NODES nodes, where the loops over nodes unroll).
DENSE_S, DENSE_AB = FUSED_DENSE_S, 0.4


def tanh_constants(dtype):
    """Taylor coefficients of exp (highest first), and (clamp, ln 2 high, ln 2 low, log2 e, 2, 1/2).

    The clamp keeps 2^q exact in the integer type (q <= 58 or 29) and is where
    tanh rounds to 1 in the type anyway.
    """
    degree, clamp = (13, 40.0) if dtype == np.float64 else (7, 20.0)
    coef = [1.0]
    for k in range(1, degree + 1):
        coef.append(coef[-1] / k)
    if dtype == np.float64:
        ln2 = (0.6931471803691238, 1.9082149292705877e-10)
    else:  # Cody-Waite split with a short high part, exact in float32
        ln2 = (0.693359375, -2.12194440e-4)
    return np.array(coef[::-1], dtype=dtype), np.array([clamp, *ln2, 1.4426950408889634, 2.0, 0.5], dtype=dtype)


def _make_tanh(int_type, float_type):
    shift_mask = int_type(8 * np.dtype(int_type).itemsize - 1)

    @_helper
    def tanh(z, coef, consts):
        """z = tanh(z) in place (1-d): with y = 2|x| = q ln 2 - r, |r| <= ln 2 / 2 and s = 2^q,
        exp(-y) = exp(r) / s, so tanh|x| = (s - exp(r)) / (s + exp(r))."""
        clamp, ln2_hi, ln2_lo, log2e, two, half = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5]
        for k in range(z.size):
            x = z[k]
            y = two * abs(x)
            y = clamp if y > clamp else y  # NaN stays NaN (min() would return the clamp)
            q = np.floor(y * log2e + half)
            r = (q * ln2_hi - y) + q * ln2_lo
            p = coef[0]
            for c in range(1, coef.size):
                p = p * r + coef[c]
            # 2^q, exact; the mask keeps the shift defined when x is NaN (p is NaN then anyway)
            s = float_type(int_type(1) << (int_type(q) & shift_mask))
            z[k] = np.copysign((s - p) / (s + p), x)
    return tanh


#: ``tanh(z, coef, consts)``: z = tanh(z) in place, in float32 (int32 range reduction) and in float64; ``coef``
#: and ``consts`` from :func:`tanh_constants` of the same dtype.
tanh32 = _make_tanh(np.int32, np.float32)
tanh64 = _make_tanh(np.int64, np.float64)


@_helper
def feature_mix(out, Z, W, transpose, N, h, B, zero):
    """out[j, (l, b)] = sum_k W[k, l] Z[j, (k, b)] (W[l, k] when transposed); rows of h B."""
    for j in range(N):
        zj, oj = Z[j], out[j]
        for l in range(h):
            for b in range(B):
                acc = zero
                for k in range(h):
                    acc += (W[l, k] if transpose else W[k, l]) * zj[k * B + b]
                oj[l * B + b] = acc


@_helper
def add_input(Z, X, F, N, h, B):
    """Z[i, (l, b)] += F[l] X[i, b]: each node's own signal into its h features."""
    for i in range(N):
        zi, xi = Z[i], X[i]
        for l in range(h):
            f = F[l]
            for b in range(B):
                zi[l * B + b] += xi[b] * f


@_helper
def readout(U, Z, G, N, h, B, zero):
    """U[i, b] = sum_l G[l] Z[i, (l, b)]: each node's input from its h features."""
    for i in range(N):
        zi, ui = Z[i], U[i]
        for b in range(B):
            acc = zero
            for l in range(h):
                acc += G[l] * zi[l * B + b]
            ui[b] = acc


@_helper
def sparse_rows(out, inp, ptr, cols, vals, zero):
    """out[i] = sum_e vals[e] inp[cols[e]] over row i's entries, four at a time (padded)."""
    C = out.shape[1]
    for i in range(out.shape[0]):
        o = out[i]
        if ptr[i] == ptr[i + 1]:
            for c in range(C):
                o[c] = zero
        for e in range(ptr[i], ptr[i + 1], 4):
            r0, r1, r2, r3 = inp[cols[e]], inp[cols[e + 1]], inp[cols[e + 2]], inp[cols[e + 3]]
            v0, v1, v2, v3 = vals[e], vals[e + 1], vals[e + 2], vals[e + 3]
            if e == ptr[i]:
                for c in range(C):
                    o[c] = v0 * r0[c] + v1 * r1[c] + v2 * r2[c] + v3 * r3[c]
            else:
                for c in range(C):
                    o[c] += v0 * r0[c] + v1 * r1[c] + v2 * r2[c] + v3 * r3[c]


@_helper
def _sparse_rows_and_dots(out, inp, ptr, cols, rows, vals, Y, dS, zero):
    """sparse_rows for the transposed pattern of S (row j, entries i), adding
    dS[i, j] += inp[i] . Y[j] on the way, while inp[i] is in registers."""
    C = out.shape[1]
    for j in range(out.shape[0]):
        o, y = out[j], Y[j]
        if ptr[j] == ptr[j + 1]:
            for c in range(C):
                o[c] = zero
        for e in range(ptr[j], ptr[j + 1], 4):
            r0, r1, r2, r3 = inp[cols[e]], inp[cols[e + 1]], inp[cols[e + 2]], inp[cols[e + 3]]
            v0, v1, v2, v3 = vals[e], vals[e + 1], vals[e + 2], vals[e + 3]
            a0 = a1 = a2 = a3 = zero
            first = e == ptr[j]
            for c in range(C):
                p0, p1, p2, p3, yc = r0[c], r1[c], r2[c], r3[c], y[c]
                o[c] = (zero if first else o[c]) + v0 * p0 + v1 * p1 + v2 * p2 + v3 * p3
                a0 += p0 * yc
                a1 += p1 * yc
                a2 += p2 * yc
                a3 += p3 * yc
            for k, a in enumerate((a0, a1, a2, a3)):
                if rows[e + k] >= 0:  # not padding
                    dS[cols[e + k], j] += a


@_helper
def dense_mix(out, mat, inp, transpose, N, zero):
    """out (N, C) = mat @ inp (mat' @ inp when transposed); mat (N, N), inp (N, C)."""
    C = out.shape[1]
    for i in range(N):
        o = out[i]
        for c in range(C):
            acc = zero
            for j in range(N):
                acc += (mat[j, i] if transpose else mat[i, j]) * inp[j, c]
            o[c] = acc


@_helper
def _dense_transposed(out, mat, inp, N, B, zero):
    """out (2N, B) = mat' @ inp; mat (N, 2N), inp (N, B)."""
    for r in range(2 * N):
        o = out[r]
        for b in range(B):
            acc = zero
            for i in range(N):
                acc += mat[i, r] * inp[i, b]
            o[b] = acc


@_helper
def _gather(vals, mat, rows, cols, transpose, zero):
    """vals[e] = mat[rows[e], cols[e]] (transposed: mat[cols[e], rows[e]]); 0 where rows[e] < 0."""
    for e in range(vals.size):
        if rows[e] < 0:
            vals[e] = zero
        else:
            vals[e] = mat[cols[e], rows[e]] if transpose else mat[rows[e], cols[e]]


@functools.lru_cache(maxsize=None)
def _kernel(N: int, B: int, h: int, T: int, squash: bool, dtype_name: str, backward: bool):
    """The kernel for one shape, with the sizes as compile-time constants.

    With them LLVM unrolls the loops over hidden features and nodes inside the
    helpers and vectorizes the batch loop, which is worth ~5x on these tiny
    products. ``backward`` False: costs only, keeping two hidden states instead of T.
    """
    dt = np.dtype(dtype_name).type
    HB = h * B
    ZERO, C2 = dt(0.0), dt(2.0 / B)
    COEF, CONSTS = tanh_constants(dt)
    WIDE = dt == np.float64

    # Every array is an argument of its own, so that the noalias pipeline marks each one: arrays
    # passed inside a tuple, or through a wrapper that LLVM inlines, lose most of it (10.8-11.0
    # against 9.45 ms a pass). Callers pass the named structures spread, in the order _ARGUMENTS
    # checks against this signature.
    @kernel_jit
    def kernel(x0, S, F, W, G, J, dS, dF, dW, dG, s_dense, Q, R, P, q_identity, r_identity, s_ptr, s_cols,
               s_rows, st_ptr, st_cols, st_rows, ab_ptr, ab_cols, ab_vals, abt_ptr, abt_cols, abt_vals, AB,
               ab_dense, g_rows, g_cols, g_count, Zs, XU, Y, dZ, dY, dPre, lam, tmp, tmp2, s_vals, st_vals,
               aF, aG, aW):
        """Summed cost J of every model of the stack and, with ``backward``, its unpenalized
        gradients dS (on the mask only), dF, dW, dG.

        x0 (M, N, B); then the fields of a :class:`Plan` (the stack's fixed patterns and costs) and of a
        :class:`Workspace` (buffers): Zs (T or 2, N, h B); XU (T + 1, 2N, B): x(t) in rows
        :N, u(t) in rows N:; Y, dZ, dY, dPre (N, h B); lam, tmp (N, B); tmp2 (2N, B); aF, aG
        (h, B); aW (h h, B). S is multiplied dense where s_dense[m], else on the padded row
        patterns s_* (st_*: of S'); [A B] on ab_*, its transpose dense (AB) when ab_dense,
        else on abt_*. g_*: the mask's entries (dS).
        """
        for m in range(x0.shape[0]):
            Sm, Fm, Wm, Gm = S[m], F[m], W[m], G[m]
            _gather(s_vals, Sm, s_rows[m], s_cols[m], False, ZERO)
            XU[0, :N] = x0[m]
            Jm = ZERO
            for t in range(T):  # forward
                xu = XU[t]
                slot = t if backward else t % 2
                Z = Zs[slot]
                if t > 0:
                    feature_mix(Y, Zs[t - 1] if backward else Zs[1 - slot], Wm, False, N, h, B, ZERO)
                    if s_dense[m]:
                        dense_mix(Z, Sm, Y, False, N, ZERO)
                    else:
                        sparse_rows(Z, Y, s_ptr[m], s_cols[m], s_vals, ZERO)
                else:
                    Z[:] = ZERO
                add_input(Z, xu, Fm, N, h, B)
                if squash and WIDE:
                    tanh64(Z.reshape(N * HB), COEF, CONSTS)
                elif squash:
                    tanh32(Z.reshape(N * HB), COEF, CONSTS)
                readout(xu[N:], Z, Gm, N, h, B, ZERO)
                sparse_rows(XU[t + 1, :N], xu, ab_ptr[m], ab_cols[m], ab_vals[m], ZERO)
                x, u = xu[:N], xu[N:]
                if q_identity and r_identity:  # one flat pass over x(t) and u(t)
                    flat = xu.reshape(2 * N * B)
                    for k in range(2 * N * B):
                        Jm += flat[k] * flat[k]
                else:
                    if not q_identity:
                        dense_mix(tmp, Q[m], x, False, N, ZERO)
                    for i in range(N):
                        for b in range(B):
                            Jm += x[i, b] * (x[i, b] if q_identity else tmp[i, b])
                    if not r_identity:
                        dense_mix(tmp, R[m], u, False, N, ZERO)
                    for i in range(N):
                        for b in range(B):
                            Jm += u[i, b] * (u[i, b] if r_identity else tmp[i, b])
            xT = XU[T, :N]
            dense_mix(lam, P[m], xT, False, N, ZERO)
            lam_flat, xT_flat = lam.reshape(N * B), XU[T].reshape(2 * N * B)
            for k in range(N * B):
                Jm += xT_flat[k] * lam_flat[k]
                lam_flat[k] *= C2  # dJ/dx(T) / B
            J[m] = Jm
            if not backward:
                continue
            _gather(st_vals, Sm, st_rows[m], st_cols[m], True, ZERO)
            dZ[:] = ZERO
            aF[:] = ZERO
            aG[:] = ZERO
            aW[:] = ZERO
            dSm = dS[m]
            dSm[:] = ZERO
            sp, sc, gr, gc = st_ptr[m], st_cols[m], g_rows[m], g_cols[m]
            for t in range(T - 1, -1, -1):
                xu = XU[t]
                Zn = Zs[t]
                if ab_dense:  # tmp2 = [A B]' lam
                    _dense_transposed(tmp2, AB[m], lam, N, B, ZERO)
                else:
                    sparse_rows(tmp2, lam, abt_ptr[m], abt_cols[m], abt_vals[m], ZERO)
                if r_identity:  # du = B' lam + c2 R u (flat: one long loop)
                    du_flat, u_flat = tmp2.reshape(2 * N * B), xu.reshape(2 * N * B)
                    for k in range(N * B, 2 * N * B):
                        du_flat[k] += C2 * u_flat[k]
                else:
                    dense_mix(tmp, R[m], xu[N:], False, N, ZERO)
                    for i in range(N):
                        di, ti = tmp2[N + i], tmp[i]
                        for b in range(B):
                            di[b] += C2 * ti[b]
                for i in range(N):  # dPre = (G du + dZ) * tanh'; dG, dF summed per (l, b)
                    zi, dzi, pi, di, xi = Zn[i], dZ[i], dPre[i], tmp2[N + i], xu[i]
                    for l in range(h):
                        g = Gm[l]
                        ag, af = aG[l], aF[l]
                        for b in range(B):
                            du = di[b]
                            z = zi[l * B + b]
                            d = g * du + dzi[l * B + b]
                            ag[b] += du * z
                            if squash:
                                d = d - d * z * z
                            pi[l * B + b] = d
                            af[b] += xi[b] * d
                if t == 0:
                    break
                Zp = Zs[t - 1]
                feature_mix(Y, Zp, Wm, False, N, h, B, ZERO)  # recomputed: cheaper than kept
                if s_dense[m]:  # dY = S' dPre; dS on the mask
                    dense_mix(dY, Sm, dPre, True, N, ZERO)
                    for e in range(g_count[m]):
                        pi, yj = dPre[gr[e]], Y[gc[e]]
                        acc = ZERO
                        for c in range(HB):
                            acc += pi[c] * yj[c]
                        dSm[gr[e], gc[e]] += acc
                elif g_count[m]:  # S trains: its pattern is the mask
                    _sparse_rows_and_dots(dY, dPre, sp, sc, st_rows[m], st_vals, Y, dSm, ZERO)
                else:
                    sparse_rows(dY, dPre, sp, sc, st_vals, ZERO)
                for k in range(h):
                    for l in range(h):
                        aw = aW[k * h + l]
                        for b in range(B):
                            acc = aw[b]
                            for j in range(N):
                                acc += Zp[j, k * B + b] * dY[j, l * B + b]
                            aw[b] = acc
                feature_mix(dZ, dY, Wm, True, N, h, B, ZERO)
                if not q_identity:
                    dense_mix(tmp, Q[m], xu[:N], False, N, ZERO)
                for i in range(N):  # lam = A' lam + c2 Q x + F dPre
                    li, ai, xi, ti, pi = lam[i], tmp2[i], xu[i], tmp[i], dPre[i]
                    for b in range(B):
                        acc = ai[b] + C2 * (xi[b] if q_identity else ti[b])
                        for l in range(h):
                            acc += Fm[l] * pi[l * B + b]
                        li[b] = acc
            for l in range(h):
                dF[m, l] = aF[l].sum()
                dG[m, l] = aG[l].sum()
                for k in range(h):
                    dW[m, k, l] = aW[k * h + l].sum()

    names = tuple(inspect.signature(kernel.py_func).parameters)
    if names != _ARGUMENTS:  # the structures' order is the kernel's, checked rather than trusted
        raise RuntimeError(f"fused kernel arguments {names} differ from the structures' {_ARGUMENTS}")
    return kernel


class Plan(NamedTuple):
    """What the kernel needs of a stack besides its parameters, fixed for the run (one field per array).

    s_dense (M,) bool: S multiplied dense; Q, R, P (M, N, N) and whether Q, R are the identity;
    s_ptr, s_cols, s_rows and st_*: the padded row patterns of S's support and of its
    transpose; ab_* and abt_*: of [A B] and its transpose, with their values; AB (M, N, 2N) and
    ab_dense: [A B] for the dense transposed product; g_rows, g_cols, g_count: the mask's entries.
    """

    s_dense: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    q_identity: bool
    r_identity: bool
    s_ptr: np.ndarray
    s_cols: np.ndarray
    s_rows: np.ndarray
    st_ptr: np.ndarray
    st_cols: np.ndarray
    st_rows: np.ndarray
    ab_ptr: np.ndarray
    ab_cols: np.ndarray
    ab_vals: np.ndarray
    abt_ptr: np.ndarray
    abt_cols: np.ndarray
    abt_vals: np.ndarray
    AB: np.ndarray
    ab_dense: bool
    g_rows: np.ndarray
    g_cols: np.ndarray
    g_count: np.ndarray


class Workspace(NamedTuple):
    """The kernel's buffers for one batch size (shapes in the kernel's docstring), reused across calls."""

    Zs: np.ndarray
    XU: np.ndarray
    Y: np.ndarray
    dZ: np.ndarray
    dY: np.ndarray
    dPre: np.ndarray
    lam: np.ndarray
    tmp: np.ndarray
    tmp2: np.ndarray
    s_vals: np.ndarray
    st_vals: np.ndarray
    aF: np.ndarray
    aG: np.ndarray
    aW: np.ndarray


#: The kernel's arguments, in order: the stack's parameters and outputs, then the structures' fields.
_ARGUMENTS = ("x0", "S", "F", "W", "G", "J", "dS", "dF", "dW", "dG") + Plan._fields + Workspace._fields


def padded_rows(patterns: np.ndarray, values: np.ndarray | None = None):
    """Row-compressed patterns of a stack (M, R, C) of bool, each row padded to a multiple of 4.

    Returns ptr (M, R + 1), cols (M, L), rows (M, L) (-1 on padding) and, with
    ``values``, vals (M, L) (0 on padding); L is the longest padded pattern.
    """
    M, R, _ = patterns.shape
    per_row = [[np.flatnonzero(patterns[m, i]) for i in range(R)] for m in range(M)]
    lengths = [sum(-(-len(c) // 4) * 4 for c in rows) for rows in per_row]
    L = max(max(lengths), 4)
    ptr = np.zeros((M, R + 1), np.int64)
    cols = np.zeros((M, L), np.int64)
    rows = np.full((M, L), -1, np.int64)
    for m in range(M):
        at = 0
        for i, c in enumerate(per_row[m]):
            cols[m, at:at + len(c)] = c
            rows[m, at:at + len(c)] = i
            at += -(-len(c) // 4) * 4
            ptr[m, i + 1] = at
    if values is None:
        return ptr, cols, rows
    vals = np.where(rows >= 0, values[np.arange(M)[:, None], np.maximum(rows, 0), cols], 0.0)
    return ptr, cols, rows, vals.astype(values.dtype)


class FusedStack:
    """The fused engine's state for one stack: sparsity patterns and buffers, made once per run.

    Parameters
    ----------
    A, B, Q, R, P : ndarray (M, N, N)
        Plants and costs (one state and one input per node).
    S0, mask : ndarray (M, N, N)
        Initial shift operators and trainable supports (an all-False mask freezes S).
    hidden, horizon, batch : int
    dtype : numpy dtype (float32 or float64)
    squash : bool
        tanh (True) or the identity.
    """

    def __init__(self, A, B, Q, R, P, S0, mask, *, hidden, horizon, batch, dtype, squash):
        M, N, _ = A.shape
        dt = np.dtype(dtype).type
        self.dtype, self.N, self.h, self.T, self.squash = dt, N, hidden, horizon, bool(squash)
        trainable = mask.any(axis=(1, 2))
        support = s_supports(S0, mask)
        # Dense products beat the pattern above about half full (and unroll only for small N).
        s_dense = (support.mean(axis=(1, 2)) > DENSE_S) & (N <= FUSED_DENSE_NODES)
        AB = np.ascontiguousarray(np.concatenate([A, B], axis=2).astype(dt))
        ab_ptr, ab_cols, _, ab_vals = padded_rows(AB != 0, AB)
        ABt = np.ascontiguousarray(AB.transpose(0, 2, 1))
        abt_ptr, abt_cols, _, abt_vals = padded_rows(ABt != 0, ABt)
        g_count = np.where(trainable, mask.sum(axis=(1, 2)), 0).astype(np.int64)
        g_rows = np.zeros((M, max(g_count.max(), 1)), np.int64)
        g_cols = np.zeros_like(g_rows)
        for m in range(M):
            if trainable[m]:
                g_rows[m, :g_count[m]], g_cols[m, :g_count[m]] = np.nonzero(mask[m])
        eye = np.eye(N)
        self.plan = Plan(s_dense, *(np.ascontiguousarray(a, dtype=dt) for a in (Q, R, P)),
                         bool(np.all(Q == eye)), bool(np.all(R == eye)), *padded_rows(support),
                         *padded_rows(support.transpose(0, 2, 1)), ab_ptr, ab_cols, ab_vals,
                         abt_ptr, abt_cols, abt_vals, AB,
                         # The transposed product runs faster dense than by pattern unless [A B] is sparse.
                         bool(np.mean(AB != 0) > DENSE_AB), g_rows, g_cols, g_count)
        self._buffers = {}

    def _work(self, batch: int, keep: bool) -> Workspace:
        key = (batch, keep)
        if key not in self._buffers:
            N, h, T, dt = self.N, self.h, self.T, self.dtype
            hB = h * batch
            shapes = dict(Zs=(T if keep else 2, N, hB), XU=(T + 1, 2 * N, batch), Y=(N, hB),
                          dZ=(N, hB), dY=(N, hB), dPre=(N, hB), lam=(N, batch), tmp=(N, batch),
                          tmp2=(2 * N, batch), s_vals=self.plan.s_cols.shape[1],
                          st_vals=self.plan.st_cols.shape[1], aF=(h, batch), aG=(h, batch), aW=(h * h, batch))
            self._buffers[key] = Workspace(**{name: np.zeros(shape, dt) for name, shape in shapes.items()})
        return self._buffers[key]

    def _run(self, x0, S, F, W, G, backward: bool):
        # The kernel's arguments must be distinct C-contiguous arrays of one dtype (noalias).
        for name, a in (("x0", x0), ("S", S), ("F", F), ("W", W), ("G", G)):
            if a.dtype != self.dtype or not a.flags.c_contiguous:
                raise ValueError(f"{name} must be a C-contiguous {np.dtype(self.dtype).name} array, "
                                 f"got {a.dtype} (contiguous: {a.flags.c_contiguous})")
        M, _, batch = x0.shape
        kernel = _kernel(self.N, batch, self.h, self.T, self.squash, np.dtype(self.dtype).name, backward)
        J = np.empty(M, self.dtype)
        grads = [np.empty_like(a) for a in (S, F, W, G)]
        kernel(x0, S, F, W, G, J, *grads, *self.plan, *self._work(batch, backward))
        return J, grads

    def loss_and_grad(self, S, F, W, G, x0):
        """Summed cost J (M,) and unpenalized gradients dS (on the mask only), dF, dW, dG.

        S (M, N, N), F (M, h), W (M, h, h), G (M, h); x0 (M, N, B), contiguous, in the dtype.
        """
        J, grads = self._run(x0, S, F, W, G, True)
        return (J, *grads)

    def costs(self, S, F, W, G, x0):
        """Summed cost J (M,) of each model from x0 (M, N, B)."""
        return self._run(x0, S, F, W, G, False)[0]
