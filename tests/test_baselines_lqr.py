import numpy as np
import pytest

from baselines import autonomous, decentralized, lqr, polish_gain
from codesign import Design, paper_instance, static_gain_cost


@pytest.fixture(scope="module", params=[0.995, 1.05])
def inst(request):
    return paper_instance(4, a_norm=request.param)


def test_lqr_design(inst):
    d = lqr(inst)
    assert isinstance(d, Design)
    assert d.cost == pytest.approx(1.0, abs=1e-9)
    assert (d.links, d.self_loops, d.info_model, d.status) == (380, 20, "instantaneous", "optimal")
    assert d.extras["spectral_radius"] < 1


def test_autonomous_design(inst):
    d = autonomous(inst)
    assert (d.links, d.self_loops, d.info_model) == (0, 0, "none")
    assert d.cost == pytest.approx(static_gain_cost(inst, np.zeros((20, 20))))
    assert d.cost > 1


def test_decentralized_is_diagonal_stationary_and_between_lqr_and_autonomous(inst):
    d = decentralized(inst)
    K = d.controller.K
    assert np.count_nonzero(K - np.diag(np.diag(K))) == 0
    assert (d.links, d.self_loops, d.info_model, d.status) == (0, 20, "none", "optimal")
    assert 1.0 < d.cost < autonomous(inst).cost
    assert d.extras["grad_norm"] < 1e-6 * d.cost
    # starting elsewhere reaches the same optimum (the problem is smooth and this one is well posed)
    assert decentralized(inst, start="zero").cost == pytest.approx(d.cost, rel=1e-6)


def test_polish_respects_mask(inst):
    mask = np.abs(inst.K_lqr) >= np.quantile(np.abs(inst.K_lqr), 0.8)
    result = polish_gain(inst, np.where(mask, inst.K_lqr, 0), mask)
    assert np.all(result.K[~mask] == 0)
    assert result.cost <= static_gain_cost(inst, np.where(mask, inst.K_lqr, 0)) + 1e-12


def test_decentralized_rejects_unknown_start(inst):
    with pytest.raises(ValueError, match="start"):
        decentralized(inst, start="random")


def test_design_invariants():
    with pytest.raises(ValueError, match="status"):
        Design("x", {}, None, 1.0, 0, 0, "none", status="great")
    with pytest.raises(ValueError, match="info_model"):
        Design("x", {}, None, 1.0, 0, 0, "telepathy")
    with pytest.raises(ValueError, match="finite cost"):
        Design("x", {}, None, float("nan"), 0, 0, "none")
    failed = Design("x", {}, None, 3.0, 0, 0, "none", status="failed")
    assert np.isnan(failed.cost)  # a failure never carries a number
    record = Design.failure("x", {"a": np.float64(1.5)}, "infeasible", "why").to_record()
    assert record["status"] == "infeasible" and record["params"] == '{"a": 1.5}'


def test_decentralized_status_follows_the_gradient_not_the_line_search(monkeypatch):
    """L-BFGS can end 'abnormally' at gradient 1e-8 depending on BLAS threads: that is still optimal."""
    import importlib

    lqr_module = importlib.import_module("baselines.lqr")  # the package re-exports a function of that name
    from baselines import stabilizing
    from baselines.polish import GRAD_RTOL, PolishResult

    inst = paper_instance(1, n=8, degree=4, a_norm=1.05, horizon=12)
    true = polish_gain(inst, np.diag(np.diag(inst.K_lqr)), np.eye(8, dtype=bool))

    def abnormal(grad_norm):
        return lambda *a, **k: PolishResult(true.K, true.cost, grad_norm, False, "ABNORMAL: ", 54)

    # Every start of the search ends at this minimum; the first is kept.
    monkeypatch.setattr(stabilizing, "polish_gain", abnormal(1e-3 * GRAD_RTOL * true.cost))
    assert lqr_module.decentralized(inst).status == "optimal"
    monkeypatch.setattr(stabilizing, "polish_gain", abnormal(10 * GRAD_RTOL * true.cost))
    flagged = lqr_module.decentralized(inst)
    assert flagged.status == "inaccurate" and "gradient norm" in flagged.message


def test_autonomous_with_an_exploding_open_loop_is_diverged():
    """a_norm = 1e6: the open-loop cost overflows; the design is diverged, with the radius, not a crash."""
    inst = paper_instance(0, n=4, degree=2, a_norm=1e6)
    d = autonomous(inst)
    assert d.status == "diverged" and d.controller is None and np.isnan(d.cost)
    assert "open-loop spectral radius 1e+06" in d.message and d.extras["spectral_radius"] >= 1
    assert decentralized(inst).status == "diverged"  # no stabilizing diagonal gain either
    assert lqr(inst).status == "optimal"


def test_autonomous_keeps_a_finite_unstable_open_loop_cost():
    """The reference "no control" cost is reported wherever it is finite, an unstable plant included."""
    inst = paper_instance(1, n=4, degree=2, a_norm=1.2)
    d = autonomous(inst)
    assert d.status == "optimal" and np.isfinite(d.cost) and d.extras["spectral_radius"] > 1
