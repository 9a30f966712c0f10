"""The verdicts that keep a finding from saying what a reader cannot see: equal within the margin, and mixed."""

import pytest

from compare.report.findings import PRACTICAL_MARGIN, select_comparisons
from compare.run.records import Records

A, B = "Sparse K, delayed (l1)", "GRNN-Sparse"


def _rec(seed, method, label, cost, links=10):
    return {"instance": {"family": "paper", "n": 8, "a_norm": 1.05, "seed": seed}, "method": method, "label": label,
            "params": {}, "links": links, "self_loops": 8, "cost": cost, "cost_stderr": 0.0, "cost_kind": "exact",
            "status": "optimal", "info_model": "delayed", "run_key": f"{label}|{seed}|{cost}", "idx": 0}


def _cell(costs_a, costs_b):
    rows = [_rec(s, "sparse_delayed", A, a) for s, a in enumerate(costs_a)]
    rows += [_rec(s, "grnn_sparse", B, b) for s, b in enumerate(costs_b)]
    (cell,) = [c for c in select_comparisons(Records.from_rows(rows)) if c.budget is None]
    assert (cell.a, cell.b) == (B, A)  # the learned design first: differences are B − A
    return cell


def test_a_difference_below_the_margin_on_every_instance_is_equal_not_a_win():
    # GraSP against ADMM in benchmark-systems: one exactly 1, the other 1 + 2e-6 to 9e-6, on 10 of 10 instances.
    base = [1.0 + 0.01 * s for s in range(10)]
    cell = _cell(base, [c + 2e-6 + 7e-7 * s for s, c in enumerate(base)])
    assert cell.paired.a_wins == 0 and cell.paired.b_wins == 10 and cell.tested
    assert cell.verdict == "equal" and not cell.significant
    # The same ordering by more than the margin is a claim.
    cell = _cell(base, [c + 5 * PRACTICAL_MARGIN for c in base])
    assert cell.verdict == "worse" and cell.significant


def test_a_small_median_with_a_wide_interval_is_no_clear_difference_not_equal():
    base = [1.0 + 0.01 * s for s in range(12)]
    cell = _cell(base, [c + (0.05 if s % 2 else -0.05) for s, c in enumerate(base)])
    assert abs(cell.paired.median) < PRACTICAL_MARGIN and cell.paired.inconclusive
    assert cell.verdict == "no significant difference" and not cell.equal


def test_a_paired_win_the_medians_order_the_other_way_is_mixed():
    # A wins by 0.004 on 16 of 20 instances, but where B wins it wins by much, and B's median cost is lower.
    costs_a = [1.10 + 0.01 * s for s in range(20)]
    costs_b = [c + 0.004 for c in costs_a[:16]] + [1.0] * 4
    cell = _cell(costs_a, costs_b)
    assert cell.paired.median == pytest.approx(0.004) and cell.tested  # B − A: A is better on the typical instance
    assert cell.drawn_a < cell.drawn_b  # ... while the budget fronts as drawn put B (cell.a) below A
    assert cell.verdict == "mixed" and cell.mixed and not cell.significant
