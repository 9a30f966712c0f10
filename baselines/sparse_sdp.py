"""Sparse static gains by an ℓ1-regularized SDP with a diagonal (or node-block-diagonal) Lyapunov matrix.

With ``u = -K x`` (docs/methods.md; the designs returned here store the evaluator's
``u = K x``, i.e. the negated gain) and ``K = Y X⁻¹``:

    minimize    [tr(QX) + tr(R Y X⁻¹ Y')] / trace(P) + γ Σ_{i≠j} |Y_ij|
    subject to  [[X − I, AX − BY], [(AX − BY)', X]] ⪰ 0,   X = diag(x).

The LMI is A_cl X A_cl' + I ⪯ X (I is the initial-state covariance Σ₀ where the
instance sets ``x0_cov``, which must then be positive definite), so X bounds the closed-loop covariance sum and
the bracket bounds trace(P_K) from above; every solution stabilizes. γ is in
units of the normalized cost, as in :mod:`baselines.sparse_admm` (the lqrsp γ
is this one times trace(P), the LQR cost). X is
diagonal so that the pattern of Y is the pattern of K (with X full a sparse Y
gives a dense K); the price is that the bound is loose, so J(K) is always
re-evaluated exactly. With X diagonal, tr(R Y X⁻¹ Y') = Σ_j ‖R^{½} Y e_j‖² / x_j
is a sum of quadratic-over-linear terms: second-order cones instead of the
second 2n × 2n LMI of the textbook form, the same problem at half the cost.

Node blocks. Where nodes hold several states or inputs
(:attr:`codesign.Instance.scalar_nodes` False), links are node blocks Y_ij
(node i's inputs by node j's states) and the problem becomes

    minimize    [tr(QX) + Σ_j tr(R Y_{:,j} X_j⁻¹ Y_{:,j}')] / trace(P) + γ Σ_{i≠j} ‖Y_ij‖_F
    subject to  the same LMI,   X = blkdiag(X_1, ..., X_N),

with one dense symmetric p_j × p_j block X_j on node j's p_j states. K = Y X⁻¹
then has blocks K_ij = Y_ij X_j⁻¹, so Y's node-block pattern is K's, as with
the diagonal X; a block-diagonal X costs no sparsity (links are counted between
nodes, and a node's own block is free), while a diagonal X is needlessly
conservative, even infeasible: on the mass-spring chain
(:mod:`compare.run.families.mass_spring`) a node's position and velocity need a
cross-covariance, and the diagonal-X SDP has no solution. The smooth term
splits by node and by row of R^{½}Y into matrix-fractional terms
(R^{½}Y)_{k,j} X_j⁻¹ (R^{½}Y)_{k,j}', each a (p_j + 1) × (p_j + 1) Schur cone
(a quadratic-over-linear term where p_j = 1); the group penalty (block
Frobenius norms) zeroes whole node blocks, as in :mod:`baselines.sparse_admm`.
The 2n × 2n LMI dominates the cost: with 20 masses (n = 40 states) a solve
takes about 20 s on one core.

γ is a :class:`cvxpy.Parameter`, so a path compiles once. Two solvers, and
``solver="auto"`` (the default) picks SCS on one-state nodes and Clarabel on node
blocks:

- ``"scs"``: SCS, a first-order (operator-splitting) conic solver. One
  iteration costs a factorization solve it caches and one eigendecomposition of
  the 2n × 2n LMI block, so a solve is 24-34x faster than Clarabel's at
  N = 50 (1.4-2.5 s per γ against 39-63 s in one benchmark run) and still runs at
  N = 100 (10-130 s per γ; a 10-γ path 569 s with screening, below).
  Tolerance ``eps`` (absolute and relative), SCS's ``scale`` = 10 (measured:
  about half the iterations of its default 0.1 on the paper family), and each γ
  started from the previous γ's solution (the path runs in increasing γ): from a
  cold start the diagonal end of the path at N = 100 needs over 20,000 iterations
  per γ (3 of 10 points stopped at the limit, 1002 s for the path); warm, one
  (994-1097 s). Screening (the ``screen`` hyperparameter) then skips the γ beyond
  the first diagonal solution, which convexity answers: 569 s. A design can then differ from a lone solve at its γ only in entries
  within SCS's tolerance of the threshold. On node blocks it is no faster and lands elsewhere: on the
  20-mass chain (γ = 1e-3, 1e-2, 3e-2) 114 s against Clarabel's 56, with 114, 74
  and 72 links where Clarabel finds 134, 94 and 86 (one solve at its iteration
  limit), so ``auto`` keeps Clarabel there.
- ``"clarabel"``: the interior-point reference. Each iteration factors the KKT
  system, whose PSD block is dense ((2n)(2n + 1)/2 = 5050 rows at n = 50), so its
  cost grows like n⁶: 40-45 s per γ at N = 50, over 20 minutes at 100 states.

Neither returns exact zeros: Y is thresholded relative to max |Y| (on node
blocks: block norms relative to the largest block norm) before the pattern is
polished on the exact benchmark cost, so both solvers give the same design when
they give the same pattern (``benchmarks/bench_sparse.py`` and the tests compare
them).
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Annotated, Literal

import numpy as np

from codesign.design import Design, Timer
from codesign.methods import Above, AtLeast, Below, NotEmpty, method
from codesign.status import FAILED, INACCURATE, OPTIMAL, USABLE, solver_status

from ._sparse import DecentralizedCache, check_gammas, design_on_pattern, with_diagonal_end

__all__ = ["sparse_sdp", "SparseSDP", "SDP_GAMMAS", "SDP_MAX_STATES", "SDP_SOLVERS", "default_solver"]

#: Packages whose version enters this method's code fingerprint besides the common ones
#: (:mod:`compare.run.fingerprint`): a new SCS can move a pattern, so it reruns the paths.
FINGERPRINT_PACKAGES = ("scs",)

#: The solvers a path can use (the ``solver`` hyperparameter, whose default ``"auto"`` is
#: :func:`default_solver`).
SDP_SOLVERS = ("scs", "clarabel")

#: Largest plant (states) the path solves by default, per solver. Clarabel, measured on
#: 2 cores: ~40 s per γ at 50 states (paper family, N = 50) and ~30 s at 40 (mass-spring
#: chain, N = 20), but more than 22 minutes for one γ at 100 (chain, N = 50): a 10-γ path
#: there would run for hours. SCS: 10-130 s per γ at 100 states (paper family, N = 100; the
#: 10-γ path 569 s with screening), and each iteration's eigendecomposition grows like n³, with more
#: iterations as n grows.
SDP_MAX_STATES = {"scs": 128, "clarabel": 64}

#: Iteration limits when ``max_iter`` is not given: Clarabel's own default, and for SCS
#: a cap above the paper family's hardest γ at N = 100 (about 13,500 iterations, ~170 s).
_DEFAULT_MAX_ITER = {"scs": 20000, "clarabel": 200}

#: What the size guard's message says per solver (from the measurements above).
_SIZE_GUARD_REASON = {
    "scs": "a 10-gamma path takes about 10 minutes at 100 states with SCS, and far longer beyond 128",
    "clarabel": "its 2n x 2n LMI takes over 20 minutes per gamma at 100 states with Clarabel",
}

#: SCS's settings besides the tolerance and the iteration limit (see the module docstring).
_SCS_OPTIONS = {"scale": 10.0, "warm_start": True}

#: SCS's default tolerance (absolute and relative): 1e-6 gave the same patterns on the paper
#: family at N = 20 and 50 and took 1.2-2x the iterations.
SCS_EPS = 1e-5

#: Default weights (normalized units): from an (almost) dense gain to a few links on
#: the paper's family; the path is closed by the diagonal gain at γ = inf.
#: np.geomspace(1e-4, 1.0, 10) written out, for the reason given at ADMM_GAMMAS.
SDP_GAMMAS = (
    0.0001, 0.0002782559402207126, 0.000774263682681127, 0.002154434690031882,
    0.005994842503189409, 0.016681005372000592, 0.046415888336127774,
    0.12915496650148828, 0.3593813663804626, 1.0,
)

#: Clarabel's supernodal factorization (faer) handles the dense 2n x 2n LMI block
#: about 3x faster than its default QDLDL; one thread, so sweeps can run in parallel.
_CLARABEL_OPTIONS = {"direct_solve_method": "faer", "max_threads": 1}


def default_solver(instance) -> str:
    """The solver ``solver="auto"`` takes: SCS on one-state nodes, Clarabel on node blocks."""
    return "scs" if instance.scalar_nodes else "clarabel"


def resolve_solver(solver: str, instance) -> str:
    """``solver`` checked, with ``"auto"`` replaced by :func:`default_solver`."""
    if solver == "auto":
        return default_solver(instance)
    if solver not in SDP_SOLVERS:
        raise ValueError(f"unknown SDP solver {solver!r}; choose one of auto, {', '.join(SDP_SOLVERS)}")
    return solver


def _cvxpy():
    # Imported on first use: cvxpy takes about a second to import, and most users
    # of `baselines` never build an SDP.
    import cvxpy

    return cvxpy


class SparseSDP:
    """The ℓ1-regularized SDP of one instance, compiled once for any γ.

    Parameters
    ----------
    instance : Instance
    solver : {"auto", "scs", "clarabel"}
        See the module docstring; ``auto`` is :func:`default_solver`.
    max_iter : int, optional
        The solver's iteration limit; default 20000 for SCS, 200 (its own default)
        for Clarabel.
    eps : float
        SCS's absolute and relative tolerance (Clarabel keeps its own, tighter ones).
    """

    def __init__(self, instance, *, solver: str = "auto", max_iter: int | None = None, eps: float = SCS_EPS):
        if instance.x0_factor is not None and instance.x0_factor.shape[1] < instance.n:
            raise ValueError(f"sparse_sdp needs a positive definite x0_cov: its LMI X ⪰ A_cl X A_cl' + x0_cov "
                             f"certifies a stabilizing K = Y X⁻¹ only then (x0_cov has rank "
                             f"{instance.x0_factor.shape[1]} of {instance.n}); use sparse_newton or sparse_admm")
        cp = self._cp = _cvxpy()
        solver = self.solver = resolve_solver(solver, instance)
        self.max_iter = _DEFAULT_MAX_ITER[solver] if max_iter is None else max_iter
        self.eps = eps
        self.instance = instance
        self.blocks = not instance.scalar_nodes
        self.gamma = cp.Parameter(nonneg=True, name="gamma")
        if self.blocks:
            self._build_blocks()
            return
        n = instance.n
        self.x = cp.Variable(n, name="x")
        self.Y = cp.Variable((n, n), name="Y")
        R_half = np.linalg.cholesky(instance.R).T  # R = R_half' R_half
        RY = R_half @ self.Y
        X = cp.diag(self.x)
        AXBY = instance.A @ X - instance.B @ self.Y
        self.lmi = cp.bmat([[X - instance.x0_covariance, AXBY], [AXBY.T, X]]) >> 0
        off = 1.0 - np.eye(n)
        objective = (
            cp.trace(instance.Q @ X)
            + sum(cp.quad_over_lin(RY[:, j], self.x[j]) for j in range(n))
            + self.gamma * cp.sum(cp.abs(cp.multiply(off, self.Y)))
        )
        self.problem = cp.Problem(cp.Minimize(objective), [self.lmi])

    def _build_blocks(self):
        """The node-block form: X block-diagonal by node, a group penalty on Y's off-diagonal node blocks."""
        cp, instance = self._cp, self.instance
        n, m, N = instance.n, instance.m, instance.nodes
        self.Y = cp.Variable((m, n), name="Y")
        # The states of each node; X_i is the dense block of X on them.
        self.node_states = [np.flatnonzero(instance.state_nodes == i) for i in range(N)]
        self.X_blocks = [cp.Variable((s.size, s.size), symmetric=True, name=f"X{i}")
                         for i, s in enumerate(self.node_states)]
        X = 0
        for s, Xi in zip(self.node_states, self.X_blocks):
            E = np.zeros((n, s.size))
            E[s, np.arange(s.size)] = 1.0
            X = X + E @ Xi @ E.T
        R_half = np.linalg.cholesky(instance.R).T  # R = R_half' R_half
        RY = R_half @ self.Y
        AXBY = instance.A @ X - instance.B @ self.Y
        self.lmi = cp.bmat([[X - instance.x0_covariance, AXBY], [AXBY.T, X]]) >> 0
        # tr(R Y X^-1 Y') = sum over nodes i and rows k of (R^1/2 Y)[k, S_i] X_i^-1 (R^1/2 Y)[k, S_i]':
        # m small (p_i + 1) x (p_i + 1) Schur cones per node rather than one (p_i + m) cone.
        smooth = []
        for s, Xi in zip(self.node_states, self.X_blocks):
            if s.size == 1:
                smooth.append(cp.quad_over_lin(RY[:, s[0]], Xi[0, 0]))
            else:
                smooth.extend(cp.matrix_frac(RY[k, s], Xi) for k in range(m))
        # Group penalty: the off-diagonal node blocks of Y (inputs of i by states of j), each
        # vectorized into one column (zero-padded to the largest block) of a selection of vec(Y).
        inputs = [np.flatnonzero(instance.input_nodes == i) for i in range(N)]
        pairs = [(i, j) for i in range(N) for j in range(N) if i != j and inputs[i].size]
        size = max(inputs[i].size * self.node_states[j].size for i, j in pairs) if pairs else 0
        rows, cols = [], []
        for col, (i, j) in enumerate(pairs):
            entries = (inputs[i][:, None] + m * self.node_states[j][None, :]).ravel()  # vec(Y), column-major
            rows.extend(col * size + np.arange(entries.size))
            cols.extend(entries)
        objective = cp.trace(instance.Q @ X) + sum(smooth)
        if pairs:
            import scipy.sparse  # imported on use, like every heavy package (fast CLI)

            select = scipy.sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(size * len(pairs), m * n))
            groups = cp.reshape(select @ cp.vec(self.Y, order="F"), (size, len(pairs)), order="F")
            objective = objective + self.gamma * cp.sum(cp.norm(groups, 2, axis=0))
        self.problem = cp.Problem(cp.Minimize(objective), [self.lmi])

    def solve(self, gamma: float) -> dict:
        """Solve at weight ``gamma``.

        Returns a dict with ``status`` (a :class:`Design` status), ``cvxpy_status``,
        ``K`` (``u = K x``, None without a solution), ``Y``, ``x``, ``bound``
        (tr(QX) + tr(RYX⁻¹Y'), an upper bound on trace(P_K)), ``solve_time``,
        ``iterations`` and ``message``; on node blocks also ``X`` (block-diagonal,
        ``x`` its diagonal).
        """
        cp = self._cp
        # The smooth part is left unnormalized; scaling γ instead keeps the data as is.
        self.gamma.value = float(gamma) * self.instance.trace_P
        out = {"K": None, "Y": None, "x": None, "bound": float("nan"), "solve_time": float("nan"),
               "iterations": -1, "message": ""}
        try:
            with warnings.catch_warnings():
                # cvxpy warns on inaccurate solutions; the status is recorded instead.
                warnings.simplefilter("ignore", UserWarning)
                if self.solver == "scs":
                    self.problem.solve(solver=cp.SCS, eps_abs=self.eps, eps_rel=self.eps,
                                       max_iters=int(self.max_iter), **_SCS_OPTIONS)
                else:
                    self._solve_clarabel()
        except cp.error.SolverError as exc:
            return {**out, "status": FAILED, "cvxpy_status": cp.SOLVER_ERROR,
                    "message": f"{self.solver_name} failed: {exc}"}
        raw = str(self.problem.status)
        stats = self.problem.solver_stats
        out.update(cvxpy_status=raw, status=solver_status(raw),
                   solve_time=float(stats.solve_time or float("nan")), iterations=int(stats.num_iters or -1))
        if raw != cp.OPTIMAL:
            out["message"] = f"SDP solver status {raw}"
        if self.solver == "scs" and out["iterations"] >= self.max_iter and raw != cp.OPTIMAL_INACCURATE:
            # SCS labels its last iterate at the limit (even "infeasible_inaccurate" after two
            # iterations): that certifies nothing, so it is a failure, like Clarabel's user_limit.
            out.update(status=FAILED, message=f"SCS stopped at its iteration limit ({self.max_iter}) "
                                                f"with status {raw}; pass a larger max_iter")
        if out["status"] in USABLE and self.blocks and self.Y.value is not None:
            try:
                out.update(self._block_solution())
            except (np.linalg.LinAlgError, FloatingPointError, ValueError, TypeError) as exc:
                out.update(status=FAILED, message=f"SDP solver status {raw}: no usable gain ({exc})")
        elif out["status"] in USABLE and self.Y.value is not None:
            x, Y = np.array(self.x.value), np.array(self.Y.value)
            RY = np.linalg.cholesky(self.instance.R).T @ Y
            bound = float(np.diag(self.instance.Q) @ x + np.sum(RY**2 / x[None, :]))
            out.update(x=x, Y=Y, K=-Y / x[None, :], bound=bound)
        elif out["status"] in USABLE:
            out.update(status=FAILED, message=f"SDP solver status {raw} without a solution")
        return out

    @property
    def solver_name(self) -> str:
        """The solver's name as cvxpy spells it (``SCS``, ``CLARABEL``), as designs record it."""
        return self.solver.upper()

    def _solve_clarabel(self):
        cp = self._cp
        try:
            self.problem.solve(solver=cp.CLARABEL, **_CLARABEL_OPTIONS, max_iter=int(self.max_iter))
        except (cp.error.SolverError, ValueError, TypeError):
            # A Clarabel build without faer: its defaults still solve the problem.
            self.problem.solve(solver=cp.CLARABEL, max_iter=int(self.max_iter))

    def _block_solution(self) -> dict:
        """Y, the blocks X_i, K = -Y X^-1 (node by node) and the bound, from a node-block solve."""
        instance = self.instance
        Y = np.array(self.Y.value)
        K = np.zeros_like(Y)
        X = np.zeros((instance.n, instance.n))
        RY = np.linalg.cholesky(instance.R).T @ Y
        smooth = 0.0
        for s, Xi in zip(self.node_states, self.X_blocks):
            Xi = np.array(Xi.value, dtype=float).reshape(s.size, s.size)
            Xi = (Xi + Xi.T) / 2
            X[np.ix_(s, s)] = Xi
            K[:, s] = -np.linalg.solve(Xi, Y[:, s].T).T
            smooth += float(np.sum(RY[:, s] * np.linalg.solve(Xi, RY[:, s].T).T))
        if not (np.all(np.isfinite(K)) and np.isfinite(smooth)):
            raise ValueError("the gain Y X^-1 is not finite")
        bound = float(np.sum(instance.Q * X)) + smooth
        return {"Y": Y, "X": X, "x": np.diag(X).copy(), "K": K, "bound": bound}

    def small_entries(self, Y, threshold: float) -> np.ndarray:
        """Mask of Y's off-diagonal entries at or below ``threshold`` times the largest: those zeroed.

        On scalar nodes, |Y_ij| relative to max |Y|; on node blocks, whole blocks whose
        Frobenius norm is at most ``threshold`` times the largest block norm (own
        blocks included in that maximum, never zeroed).
        """
        if not self.blocks:
            small = np.abs(Y) <= threshold * np.abs(Y).max()
            np.fill_diagonal(small, False)
            return small
        norms = self.instance.block_norms(Y)
        small = norms <= threshold * norms.max()
        np.fill_diagonal(small, False)
        return self.instance.expand_blocks(small)

    def diagonal_certificate(self, result: dict) -> float:
        """The γ from which a diagonal solve's point stays optimal, read off the last solve's dual.

        At a point whose off-diagonal Y (node blocks: off-diagonal blocks) is zero, the
        KKT conditions of the convex problem hold for every γ at least the largest
        off-diagonal entry (block Frobenius norm) of the smooth Lagrangian's gradient in
        Y, 2 R Y X⁻¹ (objective) plus 2 B' Z₁₂ (LMI dual Z), over trace(P). So once a
        path point is diagonal, this value certifies every larger γ diagonal as well.
        ``result`` is what :meth:`solve` returned for that solve; exact only as far as
        the solve is (the dual of SCS carries its tolerance).
        """
        n = self.instance.n
        Z = np.asarray(self.lmi.dual_value)
        if self.blocks:
            grad = -2.0 * self.instance.R @ result["K"] + 2.0 * self.instance.B.T @ Z[:n, n:]
            norms = self.instance.block_norms(grad)
            np.fill_diagonal(norms, 0.0)
            return float(np.max(norms)) / self.instance.trace_P
        grad = 2.0 * self.instance.R @ result["Y"] / result["x"][None, :] + 2.0 * self.instance.B.T @ Z[:n, n:]
        np.fill_diagonal(grad, 0.0)
        return float(np.max(np.abs(grad))) / self.instance.trace_P

    def gamma_max(self, *, scale: float | None = None) -> float:
        """Smallest γ (normalized units) at which the solution is diagonal; exact, the problem is convex.

        Solves once with a weight ``scale`` large enough to force Y diagonal and reads
        :meth:`diagonal_certificate` there: the diagonal point stays optimal while γ
        bounds the off-diagonal gradient. On node blocks "diagonal" means no
        off-diagonal node block. ``scale`` defaults
        to 1e6 on scalar nodes and 1e3 on node blocks (where 1e5 and more can break
        Clarabel's factorization, e.g. on the 6-mass chain). Exact only as far as the
        solve is: build the problem with ``solver="clarabel"`` (SCS stops near 1e-5 and
        may call the heavily weighted problem ``optimal_inaccurate``, which raises here).
        """
        if scale is None:
            scale = 1e3 if self.blocks else 1e6
        result = self.solve(scale)
        if result["status"] != OPTIMAL:
            raise RuntimeError(f"could not solve the diagonal SDP: {result['message']}")
        top = self.diagonal_certificate(result)
        if self.blocks and not top < scale:
            raise RuntimeError(f"the weight {scale:g} does not make the SDP's gain block-diagonal "
                               f"(gamma_max {top:.3g}): pass a larger scale")
        return top


#: Relative margin on a diagonal certificate before larger γ are screened: SCS's dual carries
#: its tolerance (1e-5), so a γ within 1 % of the certificate is still solved.
_CERTIFICATE_MARGIN = 0.01


def _screened(params: dict, certified: tuple) -> Design:
    """The design at a γ certified diagonal by an earlier solve: that solve's diagonal design, no new solve."""
    from_gamma, bound, design = certified
    extras = {**design.extras, "solver_status": "screened", "screened": True, "solve_time": 0.0, "iterations": 0,
              "screened_by_gamma": from_gamma}
    return replace(design, params=dict(params), extras=extras, seconds=0.0)


@method("sparse_sdp", label="Sparse K (l1 SDP)", node_blocks=True)
def sparse_sdp(
    instance,
    *,
    gammas: Annotated[list[Annotated[float, AtLeast(0)]], NotEmpty()] | None = None,
    polish: bool = True,
    threshold: Annotated[float, AtLeast(0), Below(1)] = 1e-4,
    solver: Literal["auto", "scs", "clarabel"] = "auto",
    eps: Annotated[float, Above(0), Below(1)] = SCS_EPS,
    max_iter: Annotated[int, AtLeast(1)] | None = None,
    max_states: Annotated[int, AtLeast(1)] | None = None,
    diagonal_end: bool = True,
    screen: bool = True,
):
    """Sparse static gains along a γ path by the ℓ1-regularized SDP, polished on their patterns.

    Parameters
    ----------
    instance : Instance
    gammas : list of float, optional
        Sparsity weights in units of the normalized cost; sorted increasing.
        Default: :data:`SDP_GAMMAS` (10 values, 1e-4 to 1).
    polish : bool
        Re-optimize the free entries of each pattern on the exact benchmark cost.
    threshold : float
        Off-diagonal entries with |Y_ij| <= threshold * max|Y| are zero; on node
        blocks, off-diagonal blocks with ‖Y_ij‖_F <= threshold * max ‖Y_kl‖_F.
    solver : {"auto", "scs", "clarabel"}
        SCS (first-order; 23-34x faster than Clarabel on the paper family at
        N = 50) or Clarabel (interior point, the exact reference). ``auto`` takes SCS
        on one-state nodes and Clarabel on node blocks, where SCS is slower and less
        accurate. See the module docstring.
    eps : float
        SCS's absolute and relative tolerance; unused by Clarabel.
    max_iter : int, optional
        The solver's iteration limit (default 20000 for SCS, 200 for Clarabel); a
        solve that stops there is a ``failed`` design (Clarabel: cvxpy status
        ``user_limit``) or, where SCS's residuals are nearly small enough, an
        ``inaccurate`` one.
    max_states : int, optional
        Size guard: on a plant with more states than this, no SDP is compiled and
        every γ is a ``failed`` design that says so, at once. Default
        :data:`SDP_MAX_STATES` of the solver (128 for SCS, 64 for Clarabel; the
        measured times behind them are there); raise it to run larger plants anyway.
    diagonal_end : bool
        Close the path with the decentralized gain as its γ → ∞ point
        (``params["gamma"] = inf``).
    screen : bool
        Skip the solves that convexity already answers: once a γ's solution is
        diagonal, its dual gives the γ from which that point stays optimal
        (:meth:`SparseSDP.diagonal_certificate`); every larger γ beyond it (with a
        1 % margin) is the same diagonal design, returned without a solve
        (``extras["screened"]``). At N = 100 these are the path's slowest solves.

    Returns
    -------
    list of Design
        One per γ (``params = {"gamma": γ, "threshold": ...}``), then the γ = inf
        end, information model ``instantaneous``; extras record the solver, its
        status, solve time, iterations and the SDP's bound on the normalized
        infinite-horizon cost. A γ whose SDP is infeasible or fails is a design
        with that status, never an exception. Diagonal patterns are the
        decentralized gain.
    """
    if not (np.isfinite(threshold) and 0 <= threshold < 1):
        raise ValueError(f"threshold must be in [0, 1), got {threshold!r}")
    solver = resolve_solver(solver, instance)
    if not (isinstance(eps, (int, float)) and not isinstance(eps, bool) and 0 < eps < 1):
        raise ValueError(f"eps must be in (0, 1), got {eps!r}")
    max_states = SDP_MAX_STATES[solver] if max_states is None else max_states
    if max_iter is not None and (isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer))
                                 or max_iter < 1):
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    if isinstance(max_states, bool) or not isinstance(max_states, (int, np.integer)) or max_states < 1:
        raise ValueError(f"max_states must be a positive integer, got {max_states!r}")
    gammas = check_gammas(SDP_GAMMAS if gammas is None else gammas)
    decentral = DecentralizedCache(instance)
    base = {"threshold": float(threshold)}
    if instance.n > max_states:
        why = (f"the l1 SDP is not run on {instance.n} states (max_states = {max_states}): "
               f"{_SIZE_GUARD_REASON[solver]}; pass max_states to run it anyway")
        designs = [Design.failure("sparse_sdp", {"gamma": float(g), **base}, FAILED, why,
                                  info_model="instantaneous", extras={"solver": solver.upper(), "size_guard": True})
                   for g in gammas]
        return with_diagonal_end(designs, "sparse_sdp", base, decentral) if diagonal_end else designs
    with Timer() as compile_timer:
        sdp = SparseSDP(instance, solver=solver, max_iter=max_iter, eps=float(eps))
    designs = []
    certified = None  # (γ, certificate, design) of the first diagonal solve
    for gamma in gammas:
        params = {"gamma": float(gamma), "threshold": float(threshold)}
        if certified is not None and certified[1] * (1.0 + _CERTIFICATE_MARGIN) <= gamma:
            designs.append(_screened(params, certified))
            continue
        with Timer() as timer:
            result = sdp.solve(gamma)
            extras = {"solver": sdp.solver_name, "solver_status": result["cvxpy_status"],
                      "solve_time": result["solve_time"], "iterations": result["iterations"],
                      "sdp_bound": result["bound"] / instance.trace_P}
            if result["K"] is None:
                design = Design.failure("sparse_sdp", params, result["status"], result["message"],
                                        info_model="instantaneous", extras=extras)
            else:
                K = np.where(sdp.small_entries(result["Y"], threshold), 0.0, result["K"])
                design = design_on_pattern(instance, "sparse_sdp", params, K, extras=extras,
                                           polish=polish, decentral=decentral)
                # No codesign.vet_solver_cost here: the SDP's objective only bounds the cost
                # (X is diagonal, or block-diagonal by node) and the inaccurate solve only seeds
                # a pattern whose gain is polished and scored exactly; a gain that does not
                # stabilize is "diverged".
                if result["status"] == INACCURATE and design.status == OPTIMAL:
                    design = replace(design, status=INACCURATE, message=result["message"])
                if screen and result["status"] == OPTIMAL and design.links == 0:
                    bound = sdp.diagonal_certificate(result)
                    design = replace(design, extras={**design.extras, "diagonal_certificate": bound})
                    if np.isfinite(bound):
                        certified = (float(gamma), bound, design)
        designs.append(replace(design, seconds=float(timer.seconds)))
    if designs:
        designs[0] = replace(designs[0], extras={**designs[0].extras, "compile_seconds": compile_timer.seconds})
    return with_diagonal_end(designs, "sparse_sdp", base, decentral) if diagonal_end else designs
