"""Sparse static gains by an ℓ1-regularized SDP with a diagonal Lyapunov matrix.

With ``u = -K x`` (docs/methods.md; the designs returned here store the evaluator's
``u = K x``, i.e. the negated gain) and ``K = Y X⁻¹``:

    minimize    [tr(QX) + tr(R Y X⁻¹ Y')] / trace(P) + γ Σ_{i≠j} |Y_ij|
    subject to  [[X − I, AX − BY], [(AX − BY)', X]] ⪰ 0,   X = diag(x).

The LMI is A_cl X A_cl' + I ⪯ X, so X bounds the closed-loop covariance sum and
the bracket bounds trace(P_K) from above; every solution stabilizes. γ is in
units of the normalized cost, as in :mod:`baselines.sparse_admm` (the lqrsp γ
is this one times trace(P), the LQR cost). X is
diagonal so that the pattern of Y is the pattern of K (with X full a sparse Y
gives a dense K); the price is that the bound is loose, so J(K) is always
re-evaluated exactly. With X diagonal, tr(R Y X⁻¹ Y') = Σ_j ‖R^{½} Y e_j‖² / x_j
is a sum of quadratic-over-linear terms: second-order cones instead of the
second 2n × 2n LMI of the textbook form, the same problem at half the cost.

γ is a :class:`cvxpy.Parameter`, so a path compiles once; Clarabel solves it.
Interior-point solvers return no exact zeros: Y is thresholded relative to
max |Y| before the pattern is polished on the exact benchmark cost.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from codesign.design import Design, solver_status
from codesign.methods import method

from ._common import Timer
from ._sparse import DecentralizedCache, check_gammas, design_on_pattern, with_diagonal_end

__all__ = ["sparse_sdp", "SparseSDP", "SDP_GAMMAS"]

#: Default weights (normalized units): from an (almost) dense gain to a few links on
#: the paper's family; the path is closed by the diagonal gain at γ = inf.
SDP_GAMMAS = tuple(float(g) for g in np.geomspace(1e-4, 1.0, 10))

#: Clarabel's supernodal factorization (faer) handles the dense 2n x 2n LMI block
#: about 3x faster than its default QDLDL; one thread, so sweeps can run in parallel.
_CLARABEL_OPTIONS = {"direct_solve_method": "faer", "max_threads": 1}


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
    max_iter : int
        Clarabel's iteration limit (its default, 200).
    """

    def __init__(self, instance, *, max_iter: int = 200):
        cp = self._cp = _cvxpy()
        self.max_iter = max_iter
        n = instance.n
        self.instance = instance
        self.gamma = cp.Parameter(nonneg=True, name="gamma")
        self.x = cp.Variable(n, name="x")
        self.Y = cp.Variable((n, n), name="Y")
        R_half = np.linalg.cholesky(instance.R).T  # R = R_half' R_half
        RY = R_half @ self.Y
        X = cp.diag(self.x)
        AXBY = instance.A @ X - instance.B @ self.Y
        self.lmi = cp.bmat([[X - np.eye(n), AXBY], [AXBY.T, X]]) >> 0
        off = 1.0 - np.eye(n)
        objective = (
            cp.trace(instance.Q @ X)
            + sum(cp.quad_over_lin(RY[:, j], self.x[j]) for j in range(n))
            + self.gamma * cp.sum(cp.abs(cp.multiply(off, self.Y)))
        )
        self.problem = cp.Problem(cp.Minimize(objective), [self.lmi])

    def solve(self, gamma: float) -> dict:
        """Solve at weight ``gamma``.

        Returns a dict with ``status`` (a :class:`Design` status), ``cvxpy_status``,
        ``K`` (``u = K x``, None without a solution), ``Y``, ``x``, ``bound``
        (tr(QX) + tr(RYX⁻¹Y'), an upper bound on trace(P_K)), ``solve_time``,
        ``iterations`` and ``message``.
        """
        cp = self._cp
        # The smooth part is left unnormalized; scaling γ instead keeps the data as is.
        self.gamma.value = float(gamma) * self.instance.trace_P
        out = {"K": None, "Y": None, "x": None, "bound": float("nan"), "solve_time": float("nan"),
               "iterations": -1, "message": ""}
        options = {**_CLARABEL_OPTIONS, "max_iter": int(self.max_iter)}
        try:
            try:
                with warnings.catch_warnings():
                    # cvxpy warns on inaccurate solutions; the status is recorded instead.
                    warnings.simplefilter("ignore", UserWarning)
                    self.problem.solve(solver=cp.CLARABEL, **options)
            except (cp.error.SolverError, ValueError, TypeError):
                # A Clarabel build without faer: its defaults still solve the problem.
                self.problem.solve(solver=cp.CLARABEL, max_iter=int(self.max_iter))
        except cp.error.SolverError as exc:
            return {**out, "status": "failed", "cvxpy_status": "solver_error", "message": f"Clarabel failed: {exc}"}
        raw = str(self.problem.status)
        stats = self.problem.solver_stats
        out.update(cvxpy_status=raw, status=solver_status(raw),
                   solve_time=float(stats.solve_time or float("nan")), iterations=int(stats.num_iters or -1))
        if raw != "optimal":
            out["message"] = f"SDP solver status {raw}"
        if out["status"] in ("optimal", "inaccurate") and self.Y.value is not None:
            x, Y = np.array(self.x.value), np.array(self.Y.value)
            RY = np.linalg.cholesky(self.instance.R).T @ Y
            bound = float(np.diag(self.instance.Q) @ x + np.sum(RY**2 / x[None, :]))
            out.update(x=x, Y=Y, K=-Y / x[None, :], bound=bound)
        elif out["status"] in ("optimal", "inaccurate"):
            out.update(status="failed", message=f"SDP solver status {raw} without a solution")
        return out

    def gamma_max(self, *, scale: float = 1e6) -> float:
        """Smallest γ (normalized units) at which the solution is diagonal; exact, the problem is convex.

        Solves once with a weight large enough to force Y diagonal and reads the
        off-diagonal gradient of the Lagrangian there: 2 R Y X⁻¹ (objective) plus
        2 B' Z₁₂ (LMI dual Z); the diagonal point stays optimal while γ bounds it.
        """
        result = self.solve(scale)
        if result["status"] != "optimal":
            raise RuntimeError(f"could not solve the diagonal SDP: {result['message']}")
        n = self.instance.n
        Z = np.asarray(self.lmi.dual_value)
        grad = 2.0 * self.instance.R @ result["Y"] / result["x"][None, :] + 2.0 * self.instance.B.T @ Z[:n, n:]
        np.fill_diagonal(grad, 0.0)
        return float(np.max(np.abs(grad))) / self.instance.trace_P


@method("sparse_sdp", label="Sparse K (l1 SDP)")
def sparse_sdp(
    instance,
    *,
    gammas: list | None = None,
    polish: bool = True,
    threshold: float = 1e-4,
    max_iter: int = 200,
    diagonal_end: bool = True,
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
        Off-diagonal entries with |Y_ij| <= threshold * max|Y| are zero.
    max_iter : int
        Clarabel's iteration limit; a solve that hits it is a ``failed`` design
        (cvxpy status ``user_limit``).
    diagonal_end : bool
        Close the path with the decentralized gain as its γ → ∞ point
        (``params["gamma"] = inf``).

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
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    gammas = check_gammas(SDP_GAMMAS if gammas is None else gammas)
    with Timer() as compile_timer:
        sdp = SparseSDP(instance, max_iter=max_iter)
    decentral = DecentralizedCache(instance)
    designs = []
    for gamma in gammas:
        params = {"gamma": float(gamma), "threshold": float(threshold)}
        with Timer() as timer:
            result = sdp.solve(gamma)
            extras = {"solver": "CLARABEL", "solver_status": result["cvxpy_status"],
                      "solve_time": result["solve_time"], "iterations": result["iterations"],
                      "sdp_bound": result["bound"] / instance.trace_P}
            if result["K"] is None:
                design = Design.failure("sparse_sdp", params, result["status"], result["message"],
                                        info_model="instantaneous", extras=extras)
            else:
                Y = result["Y"]
                small = np.abs(Y) <= threshold * np.abs(Y).max()
                np.fill_diagonal(small, False)
                K = np.where(small, 0.0, result["K"])
                design = design_on_pattern(instance, "sparse_sdp", params, K, extras=extras,
                                           polish=polish, decentral=decentral)
                # No codesign.vet_solver_cost here: the SDP's objective only bounds the cost
                # (X is diagonal) and the inaccurate solve only seeds a pattern whose gain is
                # polished and scored exactly; a gain that does not stabilize is "diverged".
                if result["status"] == "inaccurate" and design.status == "optimal":
                    design = replace(design, status="inaccurate", message=result["message"])
        designs.append(replace(design, seconds=float(timer.seconds)))
    if designs:
        designs[0] = replace(designs[0], extras={**designs[0].extras, "compile_seconds": compile_timer.seconds})
    base = {"threshold": float(threshold)}
    return with_diagonal_end(designs, "sparse_sdp", base, decentral) if diagonal_end else designs
