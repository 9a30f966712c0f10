"""Estimators of a controller's expected cost from simulated draws.

Two unbiased estimators, both built on quantities whose expectation under
x0 ~ N(0, Σ₀) is known exactly (Σ₀ = I unless the instance sets
:attr:`~codesign.Instance.x0_cov`; with Σ₀ = F F', a proposal tilts z ~ N(0, I)
in x0 = F z):

- :func:`control_variate_estimate`: the mean of J(x0) over validation draws,
  corrected by cross-fitted quadratic monomials ``x0_i x0_j`` (means delta_ij).
- :func:`importance_estimate`: the same on draws from a :class:`TiltedProposal`,
  weighted by the likelihood ratio p/q, with the weights themselves and powers
  of a fitted cost form as further control variates.

A third, :func:`projected_relative_stderr`, projects from a pilot sample the
precision the first will reach on the validation draws: the decision to refine
is taken on it, so that it does not depend on the estimate it lets through.

A learned controller's cost is heavy-tailed when it saturates on large
initial states along the plant's unstable directions: the variance left after
the quadratic correction comes from the top percent of x0'Mx0, with M the
fitted quadratic cost form (measured on GRNN-Fixed and GCNN designs at
‖A‖ = 1.05; the tail is not a matter of the radius |x0| alone). The proposal
therefore tilts N(0, I) along M: it draws those states more often and
weights them down.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .instances import FAST_DARE_ABOVE

__all__ = ["control_variate_estimate", "importance_estimate", "fitted_cost_form", "projected_relative_stderr",
           "TiltedProposal", "CV_FOLDS", "MIN_CV_DRAWS"]

#: Folds of the cross-fitted control-variate regression.
CV_FOLDS = 10
# Regression rows per coefficient at least this many, so that coefficients
# fitted on (CV_FOLDS - 1) folds do not overfit; beyond, fewer features are used.
_ROWS_PER_FEATURE = 4
_MAX_FEATURES = 1500
#: Above this many states (the structured path's threshold, :data:`codesign.evaluation.STRUCTURED_ABOVE`)
#: a draw count too small for the squares fits x0'Px0 alone, not more features than it can fit;
#: at and below, the features are as they were, so that the shipped reports' costs reproduce.
LARGE_ABOVE = FAST_DARE_ABOVE
#: Below this many draws the regression has too little to fit: the (weighted) sample mean is reported.
MIN_CV_DRAWS = 200
# Largest variance inflation of the tilted proposal (along the top eigenvector of
# the cost form) and the share of draws from N(0, I) itself, which bounds every
# weight by 1 / share. Chosen on the heavy-tailed designs of benchmarks/bench_evaluation.py:
# inflations 2, 4, 8, 16 and 64 gave standard errors 0.35, 0.27, 0.26, 0.27 and 0.35 %
# on the worst one at 30,000 draws (1.26 % untilted).
TILT_INFLATION = 4.0
DEFENSIVE_SHARE = 0.2


@dataclass(frozen=True)
class _Features:
    """Quadratic monomials of x0 chosen for a draw count, with their exact means.

    With an initial-state covariance Σ₀ = F F' the monomials are those of z = F⁺ x0
    (z ~ N(0, I_r)): monomials of x0 itself are collinear when Σ₀ is singular.
    """

    rows: np.ndarray
    cols: np.ndarray
    with_P: bool  # x0'Px0 appended
    name: str

    def values(self, instance, x0):
        z = x0 if instance.x0_cov is None else x0 @ instance.x0_whitener.T
        features = z[:, self.rows] * z[:, self.cols]
        if self.with_P:
            features = np.hstack([features, np.einsum("bi,bi->b", x0 @ instance.P, x0)[:, None]])
        return features

    def means(self, instance):
        means = (self.rows == self.cols).astype(float)
        return np.append(means, instance.trace_P) if self.with_P else means

    def form(self, instance, coef) -> np.ndarray:
        """The symmetric matrix M with x0'Mx0 = coef @ features(x0)."""
        width = instance.n if instance.x0_cov is None else instance.x0_factor.shape[1]
        M = np.zeros((width, width))
        M[self.rows, self.cols] += coef[:self.rows.size] / 2
        M[self.cols, self.rows] += coef[:self.rows.size] / 2
        if instance.x0_cov is not None:  # z'Mz with z = W x0
            M = instance.x0_whitener.T @ M @ instance.x0_whitener
        return M + coef[-1] * instance.P if self.with_P else M


def _choose_features(instance, draws: int) -> _Features:
    """All pairs i <= j when there are enough draws; else the squares, the pairs
    coupled in the plant or communication graph, and x0'Px0 (which carries the
    LQR's cost-to-go, the best single quadratic guess)."""
    n = instance.n
    budget = min(_MAX_FEATURES, (draws * (CV_FOLDS - 1)) // (CV_FOLDS * _ROWS_PER_FEATURE))
    if instance.x0_cov is not None:  # monomials of z, which have no nodes
        r = instance.x0_factor.shape[1]
        rows, cols = np.triu_indices(r)
        if rows.size <= budget:
            return _Features(rows, cols, False, f"all {rows.size} quadratic monomials of z (x0 = F z)")
        if r + 1 <= budget:
            return _Features(np.arange(r), np.arange(r), True, f"{r} squares of z (x0 = F z) + x0'Px0")
        return _Features(np.arange(0), np.arange(0), True, "x0'Px0")
    rows, cols = np.triu_indices(n)
    if rows.size <= budget:
        return _Features(rows, cols, False, f"all {rows.size} quadratic monomials")
    coupled = (instance.plant_adj != 0) | (instance.comm_adj != 0)
    coupled = coupled | coupled.T | np.eye(coupled.shape[0], dtype=bool)
    nodes = instance.state_nodes  # the graphs are between nodes; the monomials between states
    keep = (rows == cols) | coupled[nodes[rows], nodes[cols]]
    rows, cols = rows[keep], cols[keep]
    if rows.size + 1 <= budget:
        return _Features(rows, cols, True, f"{rows.size} squares and graph-coupled monomials + x0'Px0")
    if n > LARGE_ABOVE and n + 1 > budget:
        # Fitting n + 1 coefficients on fewer rows only adds noise (1001 on 1800 at n = 1000).
        return _Features(np.arange(0), np.arange(0), True, "x0'Px0")
    return _Features(np.arange(n), np.arange(n), True, f"{n} squares + x0'Px0")


def _cross_fit(centered_rows, y) -> tuple[np.ndarray, str]:
    """Residuals of y on centered features (first column: ones), each fold fitted on the others.

    ``centered_rows(index)`` builds the feature rows of the draws in ``index``,
    so that only one fold's rows are in memory at a time (up to 64,000 draws of
    1500 features would otherwise take 770 MB). Draw i is in fold i mod CV_FOLDS.
    """
    m = y.shape[0]
    folds = [np.arange(k, m, CV_FOLDS) for k in range(CV_FOLDS)]
    grams, moments = [], []
    for index in folds:
        rows = centered_rows(index)
        grams.append(rows.T @ rows)
        moments.append(rows.T @ y[index])
    gram, moment = sum(grams), sum(moments)
    residuals = np.empty(m)
    for index, gram_k, moment_k in zip(folds, grams, moments):
        coef = _solve_normal_equations(gram - gram_k, moment - moment_k)
        residuals[index] = y[index] - centered_rows(index)[:, 1:] @ coef[1:]
    return residuals, f"{CV_FOLDS}-fold cross-fit"


def _solve_normal_equations(gram, moment):
    """Least-squares coefficients from the normal equations: Cholesky, or lstsq where the Gram is singular.

    The centered monomials of N(0, I) draws are nearly orthogonal, so the Gram is well
    conditioned (at least 4 rows per feature) and Cholesky is 8x faster than lstsq's SVD at
    211 features (0.6 against 5.1 ms; ten per estimate), equal to it within ~1e-17 there.
    """
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    try:
        return cho_solve(cho_factor(gram), moment)
    except LinAlgError:  # not positive definite: collinear features, e.g. a repeated draw
        return np.linalg.lstsq(gram, moment, rcond=None)[0]


def control_variate_estimate(instance, x0, costs, form=None) -> tuple[float, float, str]:
    """Cross-fitted control-variate estimate of the mean of ``costs``.

    Parameters
    ----------
    instance : Instance
    x0 : ndarray, shape (batch, n)
        Initial conditions, drawn i.i.d. N(0, I): the exact means of the
        quadratic features rest on it.
    costs : ndarray, shape (batch,)
        Each trajectory's cost.
    form : ndarray (n, n), optional
        A quadratic form M fixed before the draws (the controller's
        :func:`~codesign.evaluation.local_cost_form`): ``x0'Mx0 - tr M`` joins
        the features. Where the monomials are too many for the draws (hundreds
        of states), it carries what they would.

    Returns
    -------
    cost, stderr, estimator : float, float, str
        The estimate, its standard error, and a description of the features.
        Unbiased for any controller: draw i's residual uses coefficients fitted
        without the fold that holds it.
    """
    costs = np.asarray(costs, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    m = costs.shape[0]
    chosen = _choose_features(instance, m)
    means = chosen.means(instance)
    extra = [] if form is None else [np.asarray(form, dtype=float)]

    def centered_rows(index):
        columns = [np.ones((index.size, 1)), chosen.values(instance, x0[index]) - means]
        columns += [_form_feature(instance, x0[index], M) for M in extra]
        return np.hstack(columns)

    residuals, fit = _cross_fit(centered_rows, costs)
    estimator = f"control variates: {chosen.name}{' + the local cost form' if extra else ''}, {fit}"
    return float(residuals.mean()), float(residuals.std(ddof=1) / np.sqrt(m)), estimator


def _form_feature(instance, x0, M) -> np.ndarray:
    """``x0'Mx0 - tr(M Σ₀)`` per row, as a column (mean 0)."""
    return (np.einsum("bi,bi->b", x0 @ M, x0) - instance.x0_mean(M))[:, None]


def projected_relative_stderr(instance, x0, costs, draws: int, form=None, weights=None, *,
                              form_in_estimate: bool = False) -> float:
    """Relative standard error that the estimate on ``draws`` validation draws is projected to have.

    Projected from a pilot: ``costs`` of draws ``x0`` apart from the validation
    set, i.i.d. N(0, I), or from a proposal whose likelihood ratios p/q are
    ``weights`` (the projection is then for N(0, I) draws, as the validation set
    is). The pilot's features are those :func:`control_variate_estimate` would
    choose for the pilot's draw count, a subset of those it chooses for
    ``draws``, so the projection errs high. When the validation estimate spans
    every quadratic monomial, the few the pilot supports would overstate its
    residual about tenfold for a learned controller; ``form`` (the quadratic
    form of the controller's linearization, e.g. from
    :func:`codesign.evaluation.local_cost_form`) then adds the feature
    ``x0'Mx0`` (mean tr M), which lies in the validation estimate's span and
    carries most of what the missing monomials would. Where the validation
    estimate has fewer features, ``form`` is not used: the projection would
    credit the validation estimate with a feature it lacks, unless
    ``form_in_estimate`` says the validation estimate has ``form`` itself among
    its features (:func:`control_variate_estimate` with ``form``, above 200 states).

    Returns
    -------
    float
        ``s / sqrt(draws) / |mean|``, with ``s`` the standard deviation under
        N(0, I) of the pilot's cross-fitted residuals (weighted least squares,
        weighted moments), or of the costs themselves when ``draws`` is below
        :data:`MIN_CV_DRAWS`, where the validation estimate is the sample mean;
        ``inf`` when the mean is 0 and the spread is not.
    """
    costs = np.asarray(costs, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    w = np.ones(costs.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    residuals = costs
    if draws >= MIN_CV_DRAWS and costs.shape[0] >= MIN_CV_DRAWS:
        chosen = _choose_features(instance, costs.shape[0])
        means = chosen.means(instance)
        spans_every_monomial = not _choose_features(instance, draws).with_P
        uses_form = spans_every_monomial or form_in_estimate
        extra = [np.asarray(form, dtype=float)] if form is not None and uses_form else []
        root = np.sqrt(w)

        def centered_rows(index):
            columns = [np.ones((index.size, 1)), chosen.values(instance, x0[index]) - means]
            columns += [_form_feature(instance, x0[index], M) for M in extra]
            return root[index, None] * np.hstack(columns)  # weighted least squares

        residuals = _cross_fit(centered_rows, root * costs)[0] / root
    share = w / w.sum()
    mean = share @ residuals
    spread = np.sqrt(share @ (residuals - mean) ** 2)
    if spread == 0:
        return 0.0
    return float(spread / np.sqrt(draws) / abs(mean)) if mean else float("inf")


def fitted_cost_form(instance, x0, costs) -> np.ndarray:
    """The quadratic form x0'Mx0 that best fits ``costs`` (least squares on all draws).

    Shapes the :class:`TiltedProposal`; a learned controller's J(x0) is close to
    it near the origin.
    """
    costs = np.asarray(costs, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    chosen = _choose_features(instance, costs.shape[0])
    design = np.hstack([np.ones((costs.shape[0], 1)), chosen.values(instance, x0) - chosen.means(instance)])
    coef = np.linalg.lstsq(design, costs, rcond=None)[0]
    return chosen.form(instance, coef[1:])


@dataclass(frozen=True)
class TiltedProposal:
    """The mixture ``share * N(0, I) + (1 - share) * N(0, S)``, ``S^-1 = I - 2t M+``.

    ``M+`` is the positive part of a cost form ``M`` and ``t`` is set so that the
    variance along ``M``'s top eigenvector grows by ``inflation``: the tilt
    ``p(x) exp(t x'M+x)`` of N(0, I), normalized. Draws come from the instance's
    own stream, nested (a smaller set is the first rows of a larger one).

    With an initial-state covariance Σ₀ = F F' (``factor`` F, n × r) the mixture
    is of z ~ N(0, I_r) and the tilt of z along F'MF; draws are x0 = F z.
    """

    form: np.ndarray
    eigvals: np.ndarray
    eigvecs: np.ndarray
    t: float
    inflation: float = TILT_INFLATION
    share: float = DEFENSIVE_SHARE
    factor: np.ndarray | None = None
    whitener: np.ndarray | None = None  # F's pseudo-inverse, z = W x0: every weights() call needs it

    @classmethod
    def along(cls, form, *, inflation: float = TILT_INFLATION, share: float = DEFENSIVE_SHARE,
              factor=None) -> "TiltedProposal":
        form = (np.asarray(form, dtype=float) + np.asarray(form, dtype=float).T) / 2
        eigvals, eigvecs = np.linalg.eigh(form if factor is None else factor.T @ form @ factor)
        eigvals = np.clip(eigvals, 0.0, None)
        top = eigvals.max()
        t = (1 - 1 / inflation) / (2 * top) if top > 0 else 0.0
        whitener = None if factor is None else np.linalg.pinv(factor)
        return cls(form, eigvals, eigvecs, float(t), float(inflation), float(share), factor, whitener)

    @property
    def scales(self) -> np.ndarray:
        """Standard deviations of the tilted component along the eigenvectors."""
        return 1 / np.sqrt(1 - 2 * self.t * self.eigvals)

    def draw(self, instance, size: int, stream: tuple[int, ...]) -> np.ndarray:
        """The first ``size`` draws of the proposal from the instance's ``stream`` (a tuple of ints)."""
        width = instance.n if self.factor is None else self.factor.shape[1]
        z = np.random.default_rng([instance.seed, *stream, 0]).standard_normal((size, width))
        tilted = np.random.default_rng([instance.seed, *stream, 1]).random(size) >= self.share
        z[tilted] = (z[tilted] @ self.eigvecs * self.scales) @ self.eigvecs.T
        return z if self.factor is None else z @ self.factor.T

    def weights(self, x) -> np.ndarray:
        """Likelihood ratios p(x) / q(x) of N(0, Σ₀) to the proposal, at most 1 / share."""
        if self.whitener is not None:  # back to z: F has full column rank and x = F z
            x = np.asarray(x, dtype=float) @ self.whitener.T
        y = x @ self.eigvecs
        log_ratio = self.t * np.einsum("bi,i,bi->b", y, self.eigvals, y) - np.log(self.scales).sum()
        with np.errstate(over="ignore"):
            return 1 / (self.share + (1 - self.share) * np.exp(log_ratio))

    def describe(self) -> str:
        return (f"tilted along the fitted cost form (variance x{self.inflation:g} on its top eigenvector, "
                f"{self.share:.0%} from N(0, I))")


def importance_estimate(instance, x, costs, proposal: TiltedProposal) -> tuple[float, float, float, float, str]:
    """Unbiased estimate of E[J] under N(0, I) from draws ``x`` of ``proposal``.

    The weighted costs ``w J`` (w = p/q) have mean E[J]; their control variates
    are ``w f`` for the quadratic monomials f of :func:`control_variate_estimate`
    (mean E f), ``w`` (mean 1) and ``w (x'Mx)^k`` for k = 2, 3 with M the
    proposal's cost form (means from the cumulants of a Gaussian quadratic form,
    2^(k-1) (k-1)! tr(M^k)). M is fixed before these draws were made, so no
    feature is fitted on them; coefficients are cross-fitted as before.

    Returns
    -------
    cost, stderr, plain, plain_stderr, estimator
        The control-variate estimate and the weighted mean without control
        variates, each with its standard error.
    """
    x = np.asarray(x, dtype=float)
    costs = np.asarray(costs, dtype=float)
    m = costs.shape[0]
    w = proposal.weights(x)
    y = w * costs
    root = np.sqrt(m)
    plain, plain_stderr = float(y.mean()), float(y.std(ddof=1) / root)
    if m < MIN_CV_DRAWS:
        return plain, plain_stderr, plain, plain_stderr, f"importance sampling {proposal.describe()}"
    chosen = _choose_features(instance, m)
    means = chosen.means(instance)
    M = proposal.form
    Mz = M if proposal.factor is None else proposal.factor.T @ M @ proposal.factor  # x0'Mx0 = z'Mz z
    k1, k2, k3 = np.trace(Mz), 2 * np.trace(Mz @ Mz), 8 * np.trace(Mz @ Mz @ Mz)
    q = np.einsum("bi,bi->b", x @ M, x)
    others = np.column_stack([w - 1, w * q**2 - (k2 + k1**2), w * q**3 - (k3 + 3 * k2 * k1 + k1**3)])

    def centered_rows(index):
        weighted = w[index, None] * chosen.values(instance, x[index]) - means
        return np.hstack([np.ones((index.size, 1)), weighted, others[index]])

    residuals, fit = _cross_fit(centered_rows, y)
    estimator = (f"importance sampling {proposal.describe()} with control variates: {chosen.name}, "
                 f"the weights and (x0'Mx0)^2, (x0'Mx0)^3, {fit}")
    return float(residuals.mean()), float(residuals.std(ddof=1) / root), plain, plain_stderr, estimator
