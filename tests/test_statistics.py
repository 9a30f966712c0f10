"""Budget fronts and paired comparisons of the report."""

import numpy as np
import pytest
from scipy import stats

from compare.report.statistics import budget_fronts, median_interval, paired_comparisons, paired_difference

INST = [{"family": "paper", "seed": s, "n": 8, "a_norm": 1.05} for s in range(4)]


def _rec(inst, label, links, cost, status="optimal"):
    return {"instance": inst, "label": label, "method": label, "params": {}, "links": links, "self_loops": 0,
            "cost": cost, "status": status, "info_model": "instantaneous", "run_key": "k", "idx": 0}


def test_front_is_the_median_over_instances_of_the_best_cost_within_each_budget():
    records = []
    for i, inst in enumerate(INST):
        records += [_rec(inst, "m", 10, 2.0 + i), _rec(inst, "m", 30, 1.5 + i)]
    records.append(_rec(INST[0], "m", 5, 9.0, status="failed"))
    (front,) = budget_fronts(records)
    assert list(front.budgets) == [0, 10, 30]
    assert front.at(9)[1] == np.inf  # no instance has a design within 9 links
    assert front.at(10)[1] == pytest.approx(np.median([2, 3, 4, 5]))
    assert front.at(29)[1] == front.at(10)[1]  # a step function
    assert front.at(1000)[1] == pytest.approx(np.median([1.5, 2.5, 3.5, 4.5]))


def test_an_instance_without_a_design_within_the_budget_counts_as_worse_than_any_design():
    records = [_rec(INST[0], "m", 10, 1.0), _rec(INST[1], "m", 50, 1.1), _rec(INST[2], "m", 50, 1.2),
               _rec(INST[3], "m", 0, float("nan"), status="failed"), _rec(INST[3], "other", 0, 2.0)]
    front = next(f for f in budget_fronts(records) if f.label == "m")
    assert front.instances == 4 and front.covered == 3  # it ran on all four, and failed on one
    assert list(front.reached) == [0, 1, 3]
    assert front.at(10)[1] == np.inf  # 1 of the 4 with a design: the median is not defined
    # Within 50 links three of four have one: the median of (1.0, 1.1, 1.2, inf) is 1.15, the upper quartile inf.
    assert front.at(50)[:2] == pytest.approx((1.075, 1.15)) and front.at(50)[2] == np.inf
    assert front.start == 50


def test_every_point_of_a_front_is_reached_on_at_least_half_of_the_instances():
    """The median best cost within L: on at least half of the instances some design has ≤ L links and no more cost."""
    rng = np.random.default_rng(3)
    insts = [dict(INST[0], seed=s) for s in range(9)]
    records = [_rec(inst, "m", int(k), 1 + float(c)) for inst in insts
               for k, c in zip(rng.integers(0, 60, 4), rng.exponential(0.2, 4))]
    (front,) = budget_fronts(records)
    for budget, median in zip(front.budgets, front.cost[1]):
        if not np.isfinite(median):
            continue
        reached = {r["instance"]["seed"] for r in records if r["links"] <= budget and r["cost"] <= median}
        assert len(reached) >= len(insts) / 2
    # Undefined exactly where half of the instances or fewer have a design within the budget.
    assert np.array_equal(np.isfinite(front.cost[1]), front.reached > len(insts) / 2)


def test_a_method_run_on_some_instances_of_a_panel_is_summarized_over_those():
    """A spec's ``where`` can run a costly method on one instance of a panel: its median is that instance's."""
    records = [_rec(inst, "cheap", 0, 2.0 + i) for i, inst in enumerate(INST)]
    records += [_rec(INST[0], "costly", 10, 1.5), _rec(INST[0], "costly", 30, 1.2)]
    front = next(f for f in budget_fronts(records) if f.label == "costly")
    assert front.instances == 1
    assert front.at(10) == (1.5, 1.5, 1.5) and front.at(30) == (1.2, 1.2, 1.2)
    # paired statistics use the common instances only
    (rows,) = paired_comparisons(records, "costly").values()
    (pair,) = [p for p in rows if p.budget is None]
    assert (pair.instances, pair.a_wins) == (1, 1)


def test_median_interval_has_the_binomial_coverage_and_contains_the_median():
    rng = np.random.default_rng(0)
    d = rng.standard_normal(20)
    low, high, coverage = median_interval(d)
    assert 0.95 <= coverage == pytest.approx(1 - 2 * stats.binom.cdf(5, 20, 0.5))
    s = np.sort(d)
    assert (low, high) == (s[5], s[14]) and low <= np.median(d) <= high
    # Coverage check by simulation: the interval covers the true median 0 about 95.9 % of the time.
    hits = np.mean([(lambda lo, hi: lo <= 0 <= hi)(*median_interval(rng.standard_normal(20))[:2])
                    for _ in range(2000)])
    assert abs(hits - coverage) < 0.015


def test_paired_difference_counts_wins_on_common_instances_only():
    p = paired_difference("a", "b", [1.0, 1.0, 1.0, np.inf], [2.0, 0.5, 3.0, 1.0])
    assert (p.instances, p.a_wins, p.b_wins) == (3, 2, 1)
    assert p.median == pytest.approx(-1.0)


def test_paired_comparisons_flag_an_interval_containing_zero():
    rng = np.random.default_rng(1)
    insts = [dict(INST[0], seed=s) for s in range(30)]
    records = []
    for inst in insts:
        base = 1 + rng.uniform()
        records += [_rec(inst, "ref", 10, base + 0.1), _rec(inst, "worse", 10, base + 0.2),
                    _rec(inst, "same", 10, base + 0.1 + 0.01 * rng.standard_normal())]
    (rows,) = paired_comparisons(records, "ref", budgets=(None,)).values()
    by = {r.b: r for r in rows}
    assert not by["worse"].inconclusive and by["worse"].high < 0 and by["worse"].a_wins == 30
    assert by["same"].inconclusive
