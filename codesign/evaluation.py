"""One scoring path for every method.

The benchmark cost is

    J = sum_{t=0}^{T-1} [x(t)'Q x(t) + u(t)'R u(t)] + x(T)'P x(T),   x(0) ~ N(0, I),

normalized by trace(P), which is what centralized LQR achieves exactly. Linear
controllers are scored in closed form (no sampling noise); any controller can be
scored by a batched rollout on a fixed, seeded validation set.

A rollout on the validation set reports a control-variate estimate: the
per-draw cost J(x0) is regressed on quadratic monomials x0_i x0_j, whose means
under x0 ~ N(0, I) are known exactly (delta_ij). A learned controller is close
to linear near the origin, so J(x0) is nearly a quadratic form and the residual
variance is a small fraction of the plain one (about 50x smaller in standard
error on paper instances). Coefficients are cross-fitted (each fold's residuals
use coefficients fitted on the other folds), which keeps the estimator exactly
unbiased; the plain sample mean is reported beside it. A cost too heavy-tailed
for the target precision is refined on importance-sampled draws, a decision
taken on pilot draws apart from the validation set so that it cannot select
the validation estimates that happened to miss a rare costly state
(:func:`simulate_to_precision`; the estimators are in :mod:`codesign.estimators`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .estimators import (MIN_CV_DRAWS, TiltedProposal, control_variate_estimate, fitted_cost_form, importance_estimate,
                         projected_relative_stderr)
from .instances import FAST_DARE_ABOVE
from .threads import one_torch_thread

__all__ = [
    "static_gain_cost",
    "static_gain_cost_and_grad",
    "response_cost",
    "validation_set",
    "simulate",
    "simulate_to_precision",
    "Rollout",
    "PrecisionRecord",
    "local_cost_form",
    "exact_cost",
    "compare_exact_and_simulated",
    "spectral_radius",
    "structured_operator",
    "control_variate_estimate",
    "impulse_responses",
    "MaskedProduct",
    "step_loop",
    "BLOCK_STATES",
]

VALIDATION_SIZE = 2000
#: Relative standard error a simulated cost aims for (:func:`simulate_to_precision`).
PRECISION_TARGET = 1e-3
#: The most draws :func:`simulate_to_precision` rolls out (64 x VALIDATION_SIZE).
MAX_VALIDATION_SIZE = 128000
#: Draws of the pilot that decides whether :func:`simulate_to_precision` refines (1/8 of VALIDATION_SIZE).
PILOT_SIZE = 250
#: A state beyond this magnitude makes a rollout unbounded (:func:`simulate`'s default ``bound``).
ROLLOUT_BOUND = 1e8
# Salt that separates validation draws from the instance generator's stream.
_VALIDATION_SALT = 0x5EED
# Salt of the importance-sampled draws that extend the validation set.
_PROPOSAL_SALT = 0x715E
# Salt of the pilot draws, a stream apart from both.
_PILOT_SALT = 0x9170
# Amplitude of the initial states whose responses give a controller's linearization (local_cost_form).
_LOCAL_SCALE = 1e-4
# The step loop rolls noiseless draws out this many states (draws x nodes) at a time: a block's
# activations (a GCNN's 32 features per state) then stay in a core's cache. Beside another worker,
# a GCNN stepping 2000 draws at once ran at a sixth of its speed alone and slowed that worker 1.9x;
# in blocks of 4000 states neither slows, at 20 nodes or 100 (benchmarks/bench_rollout_blocks.py;
# 8000 states or more fall off the same cliff).
BLOCK_STATES = 4000
# The most recent draws a proposal's cost form is fitted on.
_REFIT_DRAWS = 16000


def spectral_radius(M) -> float:
    """Largest eigenvalue modulus of ``M``: dense, or a scipy sparse matrix by ARPACK.

    A learned controller's linearized closed loop at n = 1000 is 6000 x 6000: numpy's
    eigvals takes 41 s on it, ARPACK's few products with the sparse matrix well under a
    second. Where ARPACK does not converge (eigenvalues of nearly equal modulus), the
    dense eigenvalues decide.
    """
    import scipy.sparse

    if not scipy.sparse.issparse(M):
        return float(np.max(np.abs(np.linalg.eigvals(M))))
    if M.shape[0] <= 2:
        return spectral_radius(M.toarray())
    from scipy.sparse.linalg import ArpackNoConvergence, eigs

    try:
        values = eigs(M.tocsr(), k=1, which="LM", tol=1e-12, maxiter=20 * M.shape[0],
                      return_eigenvectors=False, v0=np.ones(M.shape[0]))
    except ArpackNoConvergence:
        return spectral_radius(M.toarray())
    return float(np.max(np.abs(values)))


#: Above this many states a static gain's exact cost and gradient take the structured path
#: (:class:`_ClosedLoop`): the closed loop ``A + BK`` multiplied as a sparse matrix where it is
#: sparse, five products with it per time step instead of seven dense n x n products, and a
#: masked gradient computed on the mask's entries only (at n = 1000, T = 50: 1.7-2.4 s per
#: cost and gradient instead of 10 s; ``benchmarks/bench_static_cost.py``). At and below it
#: the dense formulas run unchanged, so that every number of the shipped reports (all at
#: n <= 200) reproduces to the last digit: the instances' fast-DARE threshold, for that reason.
STRUCTURED_ABOVE = FAST_DARE_ABOVE
#: Largest fraction of nonzeros at which a matrix of the structured path is multiplied as
#: scipy CSR rather than dense. CSR times dense costs n^2 x nnz-per-row multiply-adds at
#: memory speed, BLAS n^3 at arithmetic speed: single-threaded at n = 1000, a banded CSR
#: matrix with 18 / 34 / 70 / 100 nonzeros per row takes 4.8 / 8.0 / 14.8 / 20.2 ms against
#: 29 ms dense, at n = 500 1.2 / 2.0 / 3.7 / 5.1 ms against 4.0 ms. They break even near
#: 14 % at both sizes, and the CSR path pays a transposed copy per two products besides.
SPARSE_DENSITY = 0.1
# Rows of the gain per block of the masked gradient (see MaskedProduct).
_MASK_BLOCK = 16
# A masked gradient whose blocks would do more than this fraction of the full product's
# multiply-adds takes the full product (one large BLAS call) and picks the entries.
_MASK_DENSE_FRACTION = 0.25


def _x0_trace(instance, P, order=None) -> float:
    """E[x(0)' P x(0)] = trace(P Σ₀); ``order``: the states' order P is in (a :class:`_ClosedLoop`'s)."""
    if instance.x0_cov is None or order is None:
        return instance.x0_mean(P)
    return float(np.sum(P * instance.x0_cov[np.ix_(order, order)]))


def _cost_to_go(instance, K):
    """Backward recursion P_t = Q + K'RK + Acl' P_{t+1} Acl, P_T = P; returns [P_0..P_T]."""
    Acl = instance.A + instance.B @ K
    stage = instance.Q + K.T @ instance.R @ K
    Ps = [None] * (instance.horizon + 1)
    Ps[-1] = instance.P
    for t in range(instance.horizon - 1, -1, -1):
        Ps[t] = stage + Acl.T @ Ps[t + 1] @ Acl
    return Ps, Acl


def _operator(M):
    """``M`` as a scipy CSR array where it is sparse enough to beat BLAS (:data:`SPARSE_DENSITY`), else dense."""
    import scipy.sparse

    if np.count_nonzero(M) <= SPARSE_DENSITY * M.size:
        return scipy.sparse.csr_array(M)
    return np.asarray(M)


def structured_operator(M):
    """``M`` as scipy CSR where the structured path would take it sparse (:data:`SPARSE_DENSITY`), else None.

    For code outside this module that multiplies by ``M`` many times, above
    :data:`STRUCTURED_ABOVE` states (a learned controller's ``S``).
    """
    op = _operator(M)
    return None if _is_dense(op) else op


class _RolloutPlant:
    """A rollout's plant step and stage costs: dense as ever, or on sparse operators above :data:`STRUCTURED_ABOVE`.

    Rollouts hold the state as rows, ``x`` of shape (batch, n). At and below
    :data:`STRUCTURED_ABOVE` states the products are the dense ``x @ A'`` etc.,
    unchanged, so that every simulated cost of the shipped reports reproduces.
    Above, each matrix that is sparse enough is a CSR operator applied to the
    node-major ``x'`` (a contiguous copy made once per step), the identity is
    skipped, and the next state is returned as the transpose of a node-major
    array: at n = 1000 with 18 nonzeros per row of A and B, a 2000-draw step's
    plant products take 30 ms instead of 160.
    """

    def __init__(self, instance):
        self.n = instance.n
        self.dense = instance.n <= STRUCTURED_ABOVE
        if self.dense:
            self.A_T, self.B_T, self.Q, self.R = instance.A.T, instance.B.T, instance.Q, instance.R
            return
        self.A, self.B = (_operator(M) for M in (instance.A, instance.B))
        self.Q, self.R = (None if _is_identity(M) else _operator(M) for M in (instance.Q, instance.R))

    def advance(self, x, u) -> tuple[np.ndarray, np.ndarray]:
        """Stage costs ``x'Qx + u'Ru`` (batch,) and the next state ``A x + B u`` (batch, n)."""
        if self.dense:
            # Row-wise quadratic forms through a matrix product: a three-operand
            # einsum is several times slower at these sizes.
            stage = np.einsum("bi,bi->b", x @ self.Q, x) + np.einsum("bi,bi->b", u @ self.R, u)
            return stage, x @ self.A_T + u @ self.B_T
        xt, ut = np.ascontiguousarray(x.T), np.ascontiguousarray(u.T)
        stage = (np.einsum("ib,ib->b", xt if self.Q is None else self.Q @ xt, xt)
                 + np.einsum("ib,ib->b", ut if self.R is None else self.R @ ut, ut))
        return stage, (self.A @ xt + self.B @ ut).T

    def stage_form(self, dx, du) -> np.ndarray:
        """``dx Q dx' + du R du'`` for rows of responses (the local cost form's stage term)."""
        if self.dense:
            return dx @ self.Q @ dx.T + du @ self.R @ du.T
        qx = dx if self.Q is None else _product(dx, self.Q)
        ru = du if self.R is None else _product(du, self.R)
        return qx @ dx.T + ru @ du.T

    def step(self, x, u) -> np.ndarray:
        """The next state ``A x + B u`` (batch, n) alone."""
        if self.dense:
            return x @ self.A_T + u @ self.B_T
        return (self.A @ np.ascontiguousarray(x.T) + self.B @ np.ascontiguousarray(u.T)).T


def _is_identity(M) -> bool:
    return M.shape[0] == M.shape[1] and np.count_nonzero(M - np.eye(M.shape[0])) == 0


def _is_dense(op) -> bool:
    return isinstance(op, np.ndarray)


def _transpose(op):
    # CSR of the transpose rather than scipy's CSC view: the CSR kernel is the faster of the two.
    return op.T if _is_dense(op) else op.T.tocsr()


def _product(left, right) -> np.ndarray:
    """``left @ right`` as a dense array, whichever of the two is sparse."""
    if _is_dense(left) and not _is_dense(right):
        return np.asarray((right.T @ left.T).T)  # scipy multiplies a sparse matrix from the left only
    out = left @ right
    return out if _is_dense(out) else out.toarray()


class _ClosedLoop:
    """The structured path's operators for ``u = K x``: closed loop, stage cost, ``RK``, ``B'``.

    Where the closed loop ``Acl = A + BK`` is sparse, states are renumbered in reverse
    Cuthill-McKee order of its pattern, which makes it banded (bandwidth 13 on the paper
    instance at n = 1000): the rows of a dense matrix that one CSR row reads are then
    neighbours in memory, and a product takes 4.4 ms instead of 6.7 ms. Inputs follow the
    states on one-state-one-input nodes and keep their order otherwise. Every matrix here,
    ``terminal`` (P) included, is in that order; :meth:`gain_order` and
    :meth:`original_order` move a gain-shaped array between the two.

    The stage cost ``Q + K'RK`` is symmetrized: its symmetric part gives the same cost and
    keeps every ``P_t`` symmetric, which :meth:`_times_symmetric` relies on.
    """

    def __init__(self, instance, K: np.ndarray):
        gain = _operator(K)
        acl = instance.A + _product(_operator(instance.B), gain)
        n, m = instance.n, instance.m
        self.states, self.inputs = np.arange(n), np.arange(m)
        if not _is_dense(_operator(acl)):
            import scipy.sparse
            from scipy.sparse.csgraph import reverse_cuthill_mckee

            pattern = scipy.sparse.csr_array((acl != 0) | (acl.T != 0))
            self.states = reverse_cuthill_mckee(pattern, symmetric_mode=True)
            if instance.scalar_nodes:
                self.inputs = self.states
        s, i = self.states, self.inputs
        self.acl = _operator(acl[np.ix_(s, s)])
        self.acl_t = _transpose(self.acl)
        self.b_t = _operator(instance.B[np.ix_(s, i)].T)
        gain = _operator(K[np.ix_(i, s)])
        self.rk = np.ascontiguousarray(_product(instance.R[np.ix_(i, i)], gain))
        stage = instance.Q[np.ix_(s, s)] + _product(_transpose(gain), self.rk)
        self.stage = (stage + stage.T) / 2
        self.terminal = instance.P[np.ix_(s, s)]
        # Target of the transposed copies: a fresh 8 MB array each step costs its page faults too.
        self._work = np.empty((n, n))

    def gain_order(self, G: np.ndarray) -> np.ndarray:
        """A gain-shaped array in this loop's order."""
        return G[np.ix_(self.inputs, self.states)]

    def original_order(self, G: np.ndarray) -> np.ndarray:
        """A gain-shaped array in this loop's order, back in the instance's."""
        out = np.empty_like(G)
        out[np.ix_(self.inputs, self.states)] = G
        return out

    def _times_symmetric(self, S, op, op_t) -> np.ndarray:
        """``S @ op`` for a symmetric ``S``, C-contiguous; in the work array where ``op`` is sparse.

        scipy multiplies a sparse matrix from the left only: ``S op = (op' S)'``, and the
        copy to C order is what the next CSR product needs anyway.
        """
        if _is_dense(op):
            return S @ op
        self._work[...] = (op_t @ S).T
        return self._work

    def cost_to_go_step(self, P_next):
        """``(P_t, P_{t+1} Acl)`` from ``P_{t+1}``; the second is overwritten by the next step."""
        X = self._times_symmetric(P_next, self.acl, self.acl_t)
        P = self.acl_t @ X
        P += self.stage
        return P, X

    def covariance_step(self, sigma):
        """``Sigma_{t+1} = Acl Sigma_t Acl'``."""
        return self.acl @ self._times_symmetric(sigma, self.acl_t, self.acl)


class MaskedProduct:
    """The entries of ``sum_t M_t S_t`` on a mask, for symmetric ``S_t``, without the full products.

    Entry (i, j) of ``M S`` is row i of M dotted with row j of S (S symmetric). Rows of the
    mask are taken in blocks of :data:`_MASK_BLOCK` that share columns (reverse Cuthill-McKee
    order of the rows' column-sharing graph: on a local pattern, neighbours), and each block is
    one BLAS product of its rows of M with the rows of S its columns name: O(nnz(mask) x n)
    multiply-adds for a local pattern instead of O(n^3). A pattern without such locality falls
    back to the full product (:data:`_MASK_DENSE_FRACTION`).
    """

    def __init__(self, mask: np.ndarray):
        import scipy.sparse
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        self.shape = mask.shape
        self.rows, self.cols = np.nonzero(mask)
        pattern = scipy.sparse.csr_array(mask.astype(float))
        order = reverse_cuthill_mckee((pattern @ pattern.T).tocsr(), symmetric_mode=True)
        order = order[mask[order].any(axis=1)]
        self.blocks = []
        work = 0
        for start in range(0, len(order), _MASK_BLOCK):
            rows = np.sort(order[start:start + _MASK_BLOCK])
            cols = np.flatnonzero(mask[rows].any(axis=0))
            local_rows, local_cols = np.nonzero(mask[np.ix_(rows, cols)])
            self.blocks.append((rows, cols, local_rows, local_cols))
            work += len(rows) * len(cols)
        self.full = work > _MASK_DENSE_FRACTION * mask.size
        self.sums = np.zeros(mask.shape) if self.full else [np.zeros((len(r), len(c))) for r, c, _, _ in self.blocks]

    def add(self, M: np.ndarray, S: np.ndarray) -> None:
        """Add the masked entries of ``M @ S``."""
        if self.full:
            self.sums += M @ S
            return
        for (rows, cols, _, _), total in zip(self.blocks, self.sums, strict=True):
            total += M[rows] @ S[cols].T

    def result(self) -> np.ndarray:
        """The sums as a gain-shaped array, zero off the mask."""
        out = np.zeros(self.shape)
        if self.full:
            out[self.rows, self.cols] = self.sums[self.rows, self.cols]
            return out
        for (rows, cols, local_rows, local_cols), total in zip(self.blocks, self.sums, strict=True):
            out[rows[local_rows], cols[local_cols]] = total[local_rows, local_cols]
        return out


def _check_mask(mask, K: np.ndarray) -> np.ndarray:
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != K.shape:
        raise ValueError(f"mask shape {mask.shape} does not match the gain's shape {K.shape}")
    return mask


def static_gain_cost(instance, K, *, noise_std: float = 0.0) -> float:
    """Exact normalized expected cost of ``u = K x`` over the instance's horizon.

    Parameters
    ----------
    instance : Instance
    K : array_like, shape (m, n)
        Gain with the sign included (``u = K x``).
    noise_std : float
        Standard deviation of i.i.d. process noise ``w(t) ~ N(0, noise_std^2 I)``
        added to ``x(t+1)`` for t = 0..T-1.

    Notes
    -----
    The cost is ``trace(P_0 Σ₀) + noise_std^2 * sum_{t=1..T} trace(P_t)`` with the
    cost-to-go ``P_t = Q + K'RK + Acl' P_{t+1} Acl``, ``P_T = P``. Above
    :data:`STRUCTURED_ABOVE` states the recursion runs on a sparse closed loop
    (:class:`_ClosedLoop`), one ``P_t`` at a time.
    """
    K = np.asarray(K, dtype=float)
    if instance.n <= STRUCTURED_ABOVE:
        Ps, _ = _cost_to_go(instance, K)
        total = _x0_trace(instance, Ps[0]) + noise_std**2 * sum(np.trace(Pt) for Pt in Ps[1:])
        return float(total / instance.trace_P)
    loop = _ClosedLoop(instance, K)
    P = loop.terminal
    later = 0.0  # sum of trace(P_t), t = 1..T
    for _ in range(instance.horizon):
        later += np.trace(P)
        P, _ = loop.cost_to_go_step(P)
    return float((_x0_trace(instance, P, loop.states) + noise_std**2 * later) / instance.trace_P)


def static_gain_cost_and_grad(instance, K, *, mask=None) -> tuple[float, np.ndarray]:
    """Exact normalized cost of ``u = K x`` and its gradient with respect to K.

    With Sigma_t = E[x(t) x(t)'] = Acl^t Σ₀ Acl^t', the gradient is
    ``sum_t 2 (R K + B' P_{t+1} Acl) Sigma_t`` (divided by trace(P)).

    Parameters
    ----------
    instance : Instance
    K : array_like, shape (m, n)
        Gain with the sign included.
    mask : array_like of bool, shape (m, n), optional
        Entries of the gradient wanted; the others are returned as 0. Above
        :data:`STRUCTURED_ABOVE` states only these entries are computed
        (:class:`MaskedProduct`); at and below, the full gradient is computed
        and restricted, so its masked entries are those of the unmasked call.

    Returns
    -------
    cost : float
    grad : ndarray, shape (m, n)
    """
    K = np.asarray(K, dtype=float)
    if mask is not None:
        mask = _check_mask(mask, K)
    if instance.n <= STRUCTURED_ABOVE:
        Ps, Acl = _cost_to_go(instance, K)
        grad = np.zeros_like(K)
        sigma = np.array(instance.x0_covariance)
        RK = instance.R @ K
        for t in range(instance.horizon):
            grad += (RK + instance.B.T @ Ps[t + 1] @ Acl) @ sigma
            sigma = Acl @ sigma @ Acl.T
        scale = instance.trace_P
        if mask is not None:
            grad = np.where(mask, grad, 0.0)
        return float(_x0_trace(instance, Ps[0]) / scale), 2.0 * grad / scale
    return _structured_cost_and_grad(instance, K, mask)


def _structured_cost_and_grad(instance, K, mask):
    """:func:`static_gain_cost_and_grad` above :data:`STRUCTURED_ABOVE` states.

    The covariances Sigma_0..Sigma_{T-1} are kept from a forward sweep (T dense n x n
    matrices: 400 MB at n = 1000, T = 50); the backward sweep then needs one P_t at a time.
    """
    loop = _ClosedLoop(instance, K)
    s = loop.states
    sigmas = [np.eye(instance.n) if instance.x0_cov is None else instance.x0_cov[np.ix_(s, s)]]
    for _ in range(instance.horizon - 1):
        sigmas.append(loop.covariance_step(sigmas[-1]))
    product = None if mask is None else MaskedProduct(loop.gain_order(mask))
    grad = np.zeros_like(K)
    P = loop.terminal
    for t in range(instance.horizon - 1, -1, -1):
        P, X = loop.cost_to_go_step(P)  # X = P_{t+1} Acl
        M = loop.b_t @ X
        M += loop.rk
        if product is None:
            grad += M @ sigmas[t]
        else:
            product.add(M, sigmas[t])
        sigmas[t] = None  # one covariance fewer held from here on
    grad = loop.original_order(grad if product is None else product.result())
    scale = instance.trace_P
    return float(_x0_trace(instance, P, loop.states) / scale), 2.0 * grad / scale


def _einsum_traces(maps, W) -> np.ndarray:
    """``trace(M_t' W M_t)`` for each map, by one einsum (the digits of every shipped report)."""
    return np.einsum("tij,ik,tkj->t", maps, W, maps)


def _quadratic_traces(maps, W) -> np.ndarray:
    """``trace(M_t' W M_t)`` for each map, through BLAS products: einsum's three-operand loop is
    not BLAS, about 2 s per map at n = 1000 against 0.05 s."""
    return np.array([np.vdot(M, W @ M) for M in maps])


def response_cost(instance, phi_x, phi_u, *, noise_std: float = 0.0) -> float:
    """Exact normalized cost from closed-loop response maps.

    Parameters
    ----------
    phi_x : array_like, shape (T + 1, n, n)
        ``x(t) = phi_x[t] x(0)`` for t = 0..T (so ``phi_x[0] = I``).
    phi_u : array_like, shape (T, m, n)
        ``u(t) = phi_u[t] x(0)`` for t = 0..T-1.
    noise_std : float
        Process noise ``w(t) ~ N(0, noise_std^2 I)`` added to ``x(t+1)`` for
        t = 0..T-1, for a time-invariant closed loop: the noise entering at time s
        is answered by the same maps with T - s steps left, so with c(m) the cost
        of the maps over horizon m (terminal P at m),
        ``E[J] = c(T) + noise_std^2 * sum_{m<T} c(m)``. With an initial-state
        covariance Σ₀ = F F' (:attr:`~codesign.Instance.x0_cov`) the first term
        is that of the maps times F; the noise stays N(0, noise_std^2 I).
    """
    phi_x = np.asarray(phi_x, dtype=float)
    phi_u = np.asarray(phi_u, dtype=float)
    T, n, m = instance.horizon, instance.n, instance.m
    if phi_x.shape != (T + 1, n, n) or phi_u.shape != (T, m, n):
        raise ValueError(
            f"response maps must have shapes {(T + 1, n, n)} and {(T, m, n)}, "
            f"got {phi_x.shape} and {phi_u.shape}"
        )
    if not (np.isfinite(noise_std) and noise_std >= 0):
        raise ValueError(f"noise_std must be a non-negative number, got {noise_std!r}")
    quadratic = _quadratic_traces if n > STRUCTURED_ABOVE else _einsum_traces
    F = instance.x0_factor
    if F is not None:
        start = (quadratic(phi_x[:T] @ F, instance.Q).sum() + quadratic(phi_u @ F, instance.R).sum()
                 + quadratic(phi_x[T:] @ F, instance.P)[0])
        if not noise_std:
            return float(start / instance.trace_P)
    stage = quadratic(phi_x[:T], instance.Q) + quadratic(phi_u, instance.R)
    if not noise_std:
        total = stage.sum() + quadratic(phi_x[T:], instance.P)[0]
        return float(total / instance.trace_P)
    terminal = quadratic(phi_x, instance.P)
    horizon_cost = np.concatenate([[0.0], np.cumsum(stage)]) + terminal  # c(m), m = 0..T
    total = (horizon_cost[T] if F is None else start) + noise_std**2 * horizon_cost[:T].sum()
    return float(total / instance.trace_P)


def validation_set(instance, size: int = VALIDATION_SIZE, *, seed: int | None = None) -> np.ndarray:
    """The fixed set of initial conditions x(0) ~ N(0, Σ₀) used to score controllers (Σ₀ = I by default).

    The same instance (and seed) always gives the same set, so every method on
    an instance is scored on the same draws. ``seed`` defaults to the instance's
    generator seed, kept apart from the generator's own stream.
    """
    if size < 2:
        raise ValueError(f"validation size must be at least 2, got {size}")
    seed = instance.seed if seed is None else int(seed)
    rng = np.random.default_rng([seed, _VALIDATION_SALT])
    return instance.initial_states(rng, size)


@dataclass(frozen=True)
class PrecisionRecord:
    """How :func:`simulate_to_precision` made an estimate: what a design's extras must show to skip a rescore.

    ``shared_draws`` validation draws (the first rows of the instance's
    validation set, shared by every method) at relative standard error
    ``target``, with at most ``max_draws`` draws in all; ``pilot_draws`` pilot
    draws projected a relative standard error of ``pilot_rse`` on the shared
    draws (no pilot, and NaN, when no refinement was possible).
    """

    shared_draws: int
    target: float
    max_draws: int
    pilot_draws: int = 0
    pilot_rse: float = float("nan")

    def extras(self) -> dict:
        record = {"shared_validation_draws": self.shared_draws, "precision_target": self.target,
                  "max_draws": self.max_draws, "pilot_draws": self.pilot_draws}
        if self.pilot_draws:
            record["pilot_rse"] = self.pilot_rse
        return record


@dataclass(frozen=True)
class Rollout:
    """Costs of a batched simulation.

    ``cost`` and ``stderr`` are normalized by trace(P): the control-variate
    estimate when ``estimator`` names one, else the sample mean. ``plain_cost``
    and ``plain_stderr`` are the estimate without control variates and its
    standard error (the sample mean; after an importance-sampled refinement, the
    batches' weighted means, pooled). ``costs`` holds each trajectory's
    normalized cost and ``weights`` its likelihood ratio when the last
    ``importance_draws`` of them were importance-sampled (None: all 1; see
    :func:`simulate_to_precision`). ``bounded`` is False when
    a state or input became non-finite or exceeded ``bound`` on any draw the
    estimate rests on (pilot and importance-sampled draws included), and then
    ``cost`` is infinite and ``divergence`` says which draw; ``max_state`` is
    the largest ``|x_i(t)|`` seen. ``precision`` records how
    :func:`simulate_to_precision` made the estimate (None for :func:`simulate`).
    """

    cost: float
    stderr: float
    costs: np.ndarray
    bounded: bool
    max_state: float
    steps: int
    plain_cost: float = float("nan")
    plain_stderr: float = float("nan")
    estimator: str = "sample mean"
    weights: np.ndarray | None = None
    importance_draws: int = 0
    divergence: str = ""
    precision: PrecisionRecord | None = None

    def summary(self) -> dict:
        """What a design stores about this rollout (its extras).

        ``validation_size`` counts every draw of the estimate; with a
        :class:`PrecisionRecord`, its fields too (``shared_validation_draws``,
        ``precision_target``, ``max_draws``, ``pilot_draws``, ``pilot_rse``),
        which tell :func:`codesign.scoring.evaluate` not to roll the design out
        again; ``divergence`` when a draw left the bound.
        """
        summary = {"validation_size": int(self.costs.shape[0]), "importance_draws": self.importance_draws,
                   "cost_estimator": self.estimator, "plain_cost": self.plain_cost,
                   "plain_cost_stderr": self.plain_stderr}
        if self.precision is not None:
            summary.update(self.precision.extras())
        if self.divergence:
            summary["divergence"] = self.divergence
        return summary


def simulate(
    instance,
    controller,
    x0=None,
    *,
    steps: int | None = None,
    noise_std: float = 0.0,
    seed: int = 0,
    bound: float = ROLLOUT_BOUND,
    control_variates: bool | None = None,
    cost_form=None,
) -> Rollout:
    """Roll ``controller`` out from each row of ``x0`` and score the trajectories.

    Parameters
    ----------
    instance : Instance
    controller : object
        See :mod:`codesign.controllers` for the interface.
    x0 : array_like, shape (batch, n), optional
        Initial conditions; the instance's validation set by default.
    steps : int, optional
        Number of steps, the instance's horizon by default. The terminal cost
        ``x(steps)' P x(steps)`` is always added.
    noise_std : float
        Process noise ``w(t) ~ N(0, noise_std^2 I)`` added to ``x(t+1)``, drawn
        from ``seed``.
    bound : float
        A state beyond this magnitude marks the rollout as unbounded.
    control_variates : bool, optional
        Report the control-variate estimate (:func:`control_variate_estimate`)
        as ``cost``. Only valid when the rows of ``x0`` are i.i.d. N(0, I), so
        the default is True when ``x0`` is the validation set (None) and False
        for a given ``x0``; the sample mean is in ``plain_cost`` either way.
    cost_form : ndarray (n, n), optional
        A quadratic form fixed before the draws (:func:`local_cost_form`) that
        joins the control variates' features.

    Notes
    -----
    A controller with ``rollout(instance, x0, steps)`` may roll a noiseless batch
    out in one pass (:mod:`codesign.controllers`). Otherwise noiseless draws are
    stepped a block at a time (4000 states per block: 200 draws at 20 nodes,
    40 at 100), so a controller's activations stay in cache, and a block that leaves
    ``bound`` stops on its own; with noise, the whole batch steps together.
    """
    if control_variates is None:
        control_variates = x0 is None
    x = validation_set(instance) if x0 is None else np.array(x0, dtype=float)
    if x.ndim != 2 or x.shape[1] != instance.n:
        raise ValueError(f"x0 must have shape (batch, {instance.n}), got {x.shape}")
    steps = instance.horizon if steps is None else int(steps)
    rng = np.random.default_rng(seed) if noise_std else None
    batch = x.shape[0]
    x_start = x
    max_state = float(np.max(np.abs(x)))
    compiled = getattr(controller, "rollout", None)
    # A controller may roll a noiseless batch out in one compiled pass (the GRNN's): taken only
    # while every state stays within the bound, where it computes what the step loop would.
    result = compiled(instance, x, steps) if compiled is not None and rng is None else None
    if result is not None and np.all(result[1] <= bound) and np.all(np.isfinite(result[0])):
        costs, bounded = result[0], True
        max_state = float(max([max_state, *result[1]]))
    elif rng is not None:  # one noise draw per step for the whole batch, so not in blocks
        costs, bounded, max_state = step_loop(instance, controller, x, steps, noise_std, rng, bound, max_state)
    else:
        costs, bounded, max_state = _step_loop_in_blocks(instance, controller, x, steps, bound, max_state)
    costs = costs / instance.trace_P
    if not bounded or not np.all(np.isfinite(costs)):
        inf = float("inf")
        return Rollout(inf, inf, costs, False, max_state, steps, inf, inf)
    plain, plain_stderr = float(costs.mean()), float(costs.std(ddof=1) / np.sqrt(batch))
    cost, stderr, estimator = plain, plain_stderr, "sample mean"
    if control_variates and batch >= MIN_CV_DRAWS:
        cost, stderr, estimator = control_variate_estimate(instance, x_start, costs, cost_form)
    return Rollout(cost, stderr, costs, True, max_state, steps, plain, plain_stderr, estimator)


def step_loop(instance, controller, x, steps, noise_std, rng, bound, max_state):
    """:func:`simulate`'s rollout one step at a time: costs (not divided by trace P), bounded, max_state.

    An unbounded rollout stops at the first step whose largest state leaves ``bound``.
    """
    plant = _RolloutPlant(instance)
    costs = np.zeros(x.shape[0])
    state = controller.reset(x.shape[0])
    bounded = True
    with np.errstate(over="ignore", invalid="ignore"), one_torch_thread():
        for _ in range(steps):
            u, state = controller.step(state, x)
            stage, x = plant.advance(x, u)
            costs += stage
            if rng is not None:
                x = x + noise_std * rng.standard_normal(x.shape)
            peak = float(np.max(np.abs(x)))
            max_state = max(max_state, peak) if np.isfinite(peak) else float("inf")
            if not np.isfinite(peak) or peak > bound:
                bounded = False
                break
        costs += np.einsum("bi,bi->b", x @ instance.P, x)
    return costs, bounded, max_state


def _step_loop_in_blocks(instance, controller, x, steps, bound, max_state):
    """:func:`step_loop` (noiseless) over blocks of draws sized to stay in cache; each block stops
    on its own when it leaves ``bound``."""
    size = max(1, BLOCK_STATES // instance.n)
    costs, bounded = np.empty(x.shape[0]), True
    for start in range(0, x.shape[0], size):
        block = slice(start, start + size)
        costs[block], block_bounded, max_state = step_loop(instance, controller, x[block], steps, 0.0, None,
                                                           bound, max_state)
        bounded = bounded and block_bounded
    return costs, bounded, max_state


def _pooled(batches: list[tuple[int, float, float]]) -> tuple[float, float]:
    """Draw-count-weighted mean of independent batch estimates ``(draws, estimate, stderr)``.

    Fixed weights keep the pooled estimate unbiased; weights from the estimated
    variances would not: a batch that happens to miss a rare costly state
    reports both a lower cost and a smaller error, and would get more weight.
    """
    draws = np.array([b[0] for b in batches], dtype=float)
    share = draws / draws.sum()
    return (float(share @ np.array([b[1] for b in batches])),
            float(np.sqrt(np.sum((share * np.array([b[2] for b in batches]))**2))))


def local_cost_form(instance, controller, scale: float = _LOCAL_SCALE) -> np.ndarray | None:
    """The quadratic form ``M`` of the controller's linearization: ``J(x0) / trace(P) ~ x0'M x0`` near 0.

    The controller is rolled out from ``+scale e_j`` and ``-scale e_j`` and the
    responses are differenced (so a constant offset in its input cancels), which
    gives the closed-loop maps of :func:`impulse_responses` for any controller
    that is smooth at the origin; exact for a linear one. None when a response
    is not finite. Costs ``2 n`` rollout rows.
    """
    n = instance.n
    plant = _RolloutPlant(instance)
    x = np.vstack([scale * np.eye(n), -scale * np.eye(n)])
    state = controller.reset(2 * n)
    form = np.zeros((n, n))
    with np.errstate(over="ignore", invalid="ignore"), one_torch_thread():
        for _ in range(instance.horizon):
            u, state = controller.step(state, x)
            dx, du = (x[:n] - x[n:]) / (2 * scale), (u[:n] - u[n:]) / (2 * scale)
            form += plant.stage_form(dx, du)
            x = plant.step(x, u)
        dx = (x[:n] - x[n:]) / (2 * scale)
        form += dx @ instance.P @ dx.T
    if not np.all(np.isfinite(form)):
        return None
    return (form + form.T) / (2 * instance.trace_P)


def _pilot(instance, controller, size: int, form, form_in_estimate: bool) -> tuple[Rollout, float]:
    """The pilot rollout and the relative standard error it projects for the estimate on ``size`` validation draws.

    The pilot draws from a :class:`~codesign.estimators.TiltedProposal` along the
    controller's :func:`local_cost_form` (N(0, I) when it has none), which is
    known before any cost is drawn: it reaches a rare costly set along the
    costly directions far more often than N(0, I) draws do (80 times as often
    in the rare-set toy of ``tests/test_estimator_faults.py``), and the
    likelihood ratios keep the projection one for N(0, I) draws. ``form`` is the
    controller's :func:`local_cost_form`, ``form_in_estimate`` whether the
    validation estimate has it among its features.
    """
    if form is None:
        x = instance.initial_states(np.random.default_rng([instance.seed, _PILOT_SALT]), PILOT_SIZE)
        weights = None
    else:
        proposal = TiltedProposal.along(form, factor=instance.x0_factor)
        x = proposal.draw(instance, PILOT_SIZE, (_PILOT_SALT,))
        weights = proposal.weights(x)
    pilot = simulate(instance, controller, x, control_variates=False)
    if not pilot.bounded:
        return pilot, float("inf")
    return pilot, projected_relative_stderr(instance, x, pilot.costs, size, form, weights,
                                            form_in_estimate=form_in_estimate)


def _unbounded(rollout: Rollout, divergence: str, precision: PrecisionRecord, **fields) -> Rollout:
    """``rollout`` marked unbounded, its cost infinite, because of the draw ``divergence`` describes."""
    inf = float("inf")
    return replace(rollout, cost=inf, stderr=inf, plain_cost=inf, plain_stderr=inf, bounded=False,
                   divergence=divergence, precision=precision, **fields)


def simulate_to_precision(instance, controller, size: int = VALIDATION_SIZE, *,
                          target: float = PRECISION_TARGET, max_size: int = MAX_VALIDATION_SIZE) -> Rollout:
    """The control-variate estimate on the first ``size`` validation draws, or a refinement where a pilot says so.

    **The decision.** :data:`PILOT_SIZE` pilot draws, from a stream of their
    own and tilted along the controller's :func:`local_cost_form` (see
    :func:`_pilot`), project the relative standard error that the estimate on
    the ``size`` validation draws will have
    (:func:`~codesign.estimators.projected_relative_stderr`). Within ``target``, the
    validation estimate is reported as it is, even when it turns out less
    precise: it is then unbiased, because whether it is reported does not
    depend on its own draws. (Refining whenever the validation estimate missed
    the target reported exactly the validation estimates that had missed a rare
    costly state, and biased the result low.) The pilot's draws are in no
    estimate.

    **The refinement.** Otherwise the cost is re-estimated on batches of
    importance-sampled draws (each as large as all draws so far, up to
    ``max_size`` draws in all) until the pooled relative standard error is
    within ``target``. Each batch comes from a
    :class:`~codesign.estimators.TiltedProposal` along the quadratic form fitted
    to the costs of the draws before it (at most the latest ``_REFIT_DRAWS``)
    and is scored by :func:`~codesign.estimators.importance_estimate`; its
    estimate is unbiased, since its proposal is fixed before its draws are
    made. The reported cost pools the batches by draw count (:func:`_pooled`);
    the validation draws only shape the first proposal. Stopping once the
    pooled error meets the target can still favour batches that missed a rare
    set; the proposal reaches such a set far more often than N(0, I) does (see
    docs/evaluation.md for the measured size). A heavy-tailed cost may stop at
    ``max_size`` above the target; its standard error says so.

    **Divergence.** A pilot or importance-sampled draw that leaves the
    rollout's bound (:data:`ROLLOUT_BOUND`) makes the result unbounded, like a
    validation draw: ``bounded`` False, ``cost`` infinite, ``divergence`` naming
    the draw. It is never dropped.

    **Hundreds of states.** Above :data:`STRUCTURED_ABOVE` states the
    validation estimate's control variates are ``x0'Px0`` (and the squares,
    while the draws can fit them) and the controller's local cost form, which
    is fixed before any draw: at n = 1000 the n(n+1)/2 monomials are far too
    many for the draws, and the form carries what they would (a GRNN at
    n = 1000: relative standard error 3e-6 on the 2000 draws).

    ``Rollout.costs`` holds every draw's cost and ``Rollout.weights`` its
    likelihood ratio (1 for validation draws); ``Rollout.precision`` records
    ``size``, ``target``, ``max_size`` and the pilot.
    """
    if max_size < size:
        raise ValueError(f"max_size must be at least size ({size}), got {max_size}")
    x0 = validation_set(instance, size)
    # Above STRUCTURED_ABOVE states the quadratic monomials are too many for the draws, and the
    # controller's local cost form (computed for the pilot anyway) joins the control variates.
    large = instance.n > STRUCTURED_ABOVE
    form = local_cost_form(instance, controller) if large else None
    first = simulate(instance, controller, x0, control_variates=True, cost_form=form)
    record = PrecisionRecord(int(size), float(target), int(max_size))
    if not first.bounded or max_size == size:
        return replace(first, precision=record)
    pilot, projected = _pilot(instance, controller, size, form if large else local_cost_form(instance, controller),
                              form_in_estimate=large and form is not None)
    record = replace(record, pilot_draws=PILOT_SIZE, pilot_rse=projected)
    if not pilot.bounded:
        return _unbounded(first, f"a pilot draw (one of {PILOT_SIZE} drawn apart from the validation set) left the "
                                 f"rollout's bound {ROLLOUT_BOUND:g}: the cost is treated as infinite", record,
                          max_state=max(first.max_state, pilot.max_state))
    if projected <= target:
        return replace(first, precision=record)
    return _refine(instance, controller, first, x0, record)


def _refine(instance, controller, first: Rollout, x0, record: PrecisionRecord) -> Rollout:
    """Importance-sampled batches after ``first``'s validation draws ``x0``, pooled (:func:`simulate_to_precision`)."""
    size, target, max_size = record.shared_draws, record.target, record.max_draws
    draws, costs, weights = [x0], [first.costs], [np.ones(size)]
    estimates, plains = [], []
    rollout, total, batch = first, size, 0
    why = (f"refined because a {record.pilot_draws}-draw pilot projected a relative standard error of "
           f"{record.pilot_rse:.2%} there")
    while total < max_size and (batch == 0 or rollout.stderr > target * abs(rollout.cost)):
        count = min(total, max_size - total)
        recent_x, recent_costs = np.vstack(draws)[-_REFIT_DRAWS:], np.concatenate(costs)[-_REFIT_DRAWS:]
        proposal = TiltedProposal.along(fitted_cost_form(instance, recent_x, recent_costs), factor=instance.x0_factor)
        x = proposal.draw(instance, count, (_PROPOSAL_SALT, batch))
        more = simulate(instance, controller, x, control_variates=False)
        if not more.bounded:
            return _unbounded(
                rollout, f"an importance-sampled draw of refinement batch {batch + 1} (draws {total + 1}-"
                         f"{total + count}, {proposal.describe()}) left the rollout's bound {ROLLOUT_BOUND:g}: "
                         f"the cost is treated as infinite", record,
                costs=np.concatenate(costs + [more.costs]), weights=np.concatenate(weights + [proposal.weights(x)]),
                importance_draws=total + count - size, max_state=max(rollout.max_state, more.max_state))
        cost, stderr, mean, mean_stderr, described = importance_estimate(instance, x, more.costs, proposal)
        estimates.append((count, cost, stderr))
        plains.append((count, mean, mean_stderr))
        draws.append(x)
        costs.append(more.costs)
        weights.append(proposal.weights(x))
        total, batch = total + count, batch + 1
        rollout = Rollout(*_pooled(estimates), np.concatenate(costs), True,
                          max(rollout.max_state, more.max_state), first.steps, *_pooled(plains),
                          f"{described}, on {total - size} draws in {batch} batch{'es' if batch > 1 else ''} "
                          f"(each proposal fitted to the draws before it, pooled by draw count), after "
                          f"{first.estimator} on the {size} validation draws ({why})",
                          np.concatenate(weights), total - size, precision=record)
    return rollout


def impulse_responses(instance, controller, steps: int | None = None):
    """Closed-loop maps ``(phi_x, phi_u)`` of a linear controller, by rollout from ``x(0) = e_j``.

    For a controller that is linear in its state and x (any linear dynamic
    controller with the ``reset``/``step`` protocol), ``x(t) = phi_x[t] x(0)`` and
    ``u(t) = phi_u[t] x(0)``: the actual closed loop, which
    :func:`response_cost` scores exactly. Shapes ``(steps + 1, n, n)`` and
    ``(steps, n, n)``; ``steps`` defaults to the horizon.
    """
    n, m = instance.n, instance.m
    steps = instance.horizon if steps is None else int(steps)
    phi_x = np.empty((steps + 1, n, n))
    phi_u = np.empty((steps, m, n))
    x = np.eye(n)  # row j: the trajectory from x(0) = e_j
    state = controller.reset(n)
    phi_x[0] = x.T
    for t in range(steps):
        u, state = controller.step(state, x)
        x = x @ instance.A.T + u @ instance.B.T
        phi_u[t] = u.T
        phi_x[t + 1] = x.T
    return phi_x, phi_u


def exact_cost(instance, controller, *, noise_std: float = 0.0) -> float | None:
    """Closed-form normalized cost of a linear controller, or None if it has none.

    Static gains (``controller.K``) are scored by a Lyapunov recursion; dynamic
    time-invariant linear controllers by their closed-loop responses
    (``controller.closed_loop_responses(instance) -> (phi_x, phi_u)``).
    """
    if hasattr(controller, "closed_loop_responses"):
        phi_x, phi_u = controller.closed_loop_responses(instance)
        return response_cost(instance, phi_x, phi_u, noise_std=noise_std)
    K = getattr(controller, "K", None)
    if K is None:
        return None
    return static_gain_cost(instance, K, noise_std=noise_std)


def compare_exact_and_simulated(instance, controller, x0=None) -> dict:
    """Exact versus simulated cost of a linear controller, with the z-score.

    Returns a dict with ``exact``, ``simulated`` (the sample mean), ``stderr`` and
    ``z`` (``(simulated - exact) / stderr``; ``|z| <= 3`` is the expected
    agreement), and ``control_variate`` (the control-variate estimate on the
    validation set, which for a linear controller recovers the exact cost up to
    rounding, because its J(x0) is a quadratic form; NaN for a given ``x0``).
    """
    exact = exact_cost(instance, controller)
    if exact is None:
        raise TypeError(f"{type(controller).__name__} has no closed-form cost")
    rollout = simulate(instance, controller, x0)
    cost, stderr = rollout.plain_cost, rollout.plain_stderr
    z = (cost - exact) / stderr if stderr > 0 else float("inf")
    cv = rollout.cost if rollout.estimator != "sample mean" else float("nan")
    return {"exact": exact, "simulated": cost, "stderr": stderr, "z": float(z), "control_variate": cv}
