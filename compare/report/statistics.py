"""Budget fronts and paired comparisons: every method runs on the same instances, so compare per instance.

A method's *best cost within a budget* L on an instance is the lowest cost among
its designs there with at most L directed off-diagonal links (infinite when none
fits, or when the method failed there). Its budget front is the median over the
instances it ran on of that best cost as a step function of L, with the 25–75 %
band: an instance without a design within L counts as worse than any design, so
the median is finite exactly where more than half of the instances have one, and
every point of a front is reached (some design with no more links and no more
cost) on at least half of them.

Paired comparisons take the per-instance difference of two methods' best costs
within the same budget, on the instances where both have a design that fits:
wins, the median difference and a distribution-free 95 % interval for it (order
statistics of the differences, ranks from the binomial distribution).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..run.records import OK_STATUSES, as_records, panel_key

__all__ = ["Front", "budget_fronts", "best_within", "best_tables", "Paired", "paired_difference", "median_interval",
           "paired_comparisons", "instances_by_panel", "front_quantiles", "panel_key", "panel_title", "OK_STATUSES",
           "panel_budgets", "panel_nodes", "BUDGETS_PER_NODE"]

# Quantiles of values that may be infinite: replace inf by a huge sentinel, so that a
# median between a finite and an infinite value reads as "not reached" (inf).
_SENTINEL = 1e300


def panel_title(key: tuple) -> str:
    family, n, a_norm = key
    return f"N = {n}, ‖A‖₂ = {a_norm:g}" if a_norm is not None else f"{family}, N = {n}"


def instances_by_panel(records) -> dict[tuple, list[str]]:
    """Panel -> the sorted :attr:`~compare.run.records.InstanceRecord.key` of every instance with a record in it."""
    return {panel: sorted(rs.by_instance) for panel, rs in as_records(records).by_panel.items()}


def _quantiles(values) -> np.ndarray:
    """25th, 50th, 75th percentiles along axis 0 of values that may be inf; rows of NaN (not run) are left out."""
    values = np.asarray(values, dtype=float)
    if values.ndim == 2:
        values = values[~np.isnan(values).all(axis=1)]
        if not len(values):
            return np.full((3, values.shape[1]), np.inf)
    finite = np.where(np.isfinite(values), values, _SENTINEL)
    q = np.percentile(finite, [25, 50, 75], axis=0)
    return np.where(q >= _SENTINEL / 10, np.inf, q)


@dataclass(frozen=True)
class Front:
    """A method's budget front on one panel: step function of the link budget.

    ``cost[:, k]`` holds the (25 %, median, 75 %), over the ``instances`` the method
    ran on, of the best cost within ``budgets[k]`` links, an instance without a design
    within the budget (or without any usable design) counting as ``inf``; it holds
    from ``budgets[k]`` up to the next budget. The median is finite exactly where more
    than half of those instances have a design within the budget, so that a drawn
    point is one that at least half of them reach (:func:`front_quantiles`).
    ``reached[k]`` counts the instances with a design within ``budgets[k]``;
    ``covered`` those with a usable design at all.
    """

    panel: tuple
    label: str
    info_model: str
    budgets: np.ndarray
    cost: np.ndarray
    instances: int
    covered: int = 0
    reached: np.ndarray | None = None

    def at(self, budget: float) -> tuple[float, float, float]:
        """(25 %, median, 75 %) of the best cost within ``budget`` links."""
        k = np.searchsorted(self.budgets, budget, side="right") - 1
        if k < 0:
            return (np.inf,) * 3
        return tuple(float(v) for v in self.cost[:, k])

    @property
    def start(self) -> float | None:
        """The smallest budget at which the median is finite (None if never)."""
        defined = np.isfinite(self.cost[1])
        return float(self.budgets[int(np.argmax(defined))]) if defined.any() else None


def best_within(records, panel_instances: list[str], budgets) -> np.ndarray:
    """Best cost per (instance, budget) of one method's records: shape (instances, budgets).

    ``inf`` where the method ran on the instance but no design fits the budget (or
    none is usable); ``NaN`` on the whole row of an instance it did not run on (a
    spec's ``where`` can restrict a costly method to some instances), so that
    medians are taken over the instances it ran on.
    """
    index = {inst: i for i, inst in enumerate(panel_instances)}
    budgets = np.asarray(budgets, dtype=float)
    best = np.full((len(panel_instances), budgets.size), np.nan)
    records = as_records(records)
    for key in records.by_instance:
        best[index[key]] = np.inf
    for r in records:
        if r.ok:
            i = index[r.instance.key]
            fits = budgets >= r.links
            best[i, fits] = np.minimum(best[i, fits], r.cost)
    return best


def best_tables(records, budgets) -> dict[tuple, np.ndarray]:
    """(panel, label) -> :func:`best_within` of that label's records; rows are the panel's instances, aligned
    across labels (:func:`instances_by_panel` order)."""
    records = as_records(records)
    panels = instances_by_panel(records)
    return {key: best_within(rs, panels[key[0]], budgets) for key, rs in sorted(records.by_panel_label.items())}


def budget_fronts(records) -> list[Front]:
    """One :class:`Front` per (panel, label), evaluated at every link count any design of it has."""
    records = as_records(records)
    panels = instances_by_panel(records)
    fronts = []
    for (panel, label), rs in sorted(records.by_panel_label.items()):
        budgets = np.unique([0.0] + [float(r.links) for r in rs if r.ok])
        cost, reached, covered = front_quantiles(best_within(rs, panels[panel], budgets))
        info = Counter(r.info_model for r in rs).most_common(1)[0][0]
        fronts.append(Front(panel, label, info, budgets, cost, len(rs.by_instance), covered, reached))
    return fronts


def front_quantiles(best) -> tuple[np.ndarray, np.ndarray, int]:
    """Quartiles of best costs (instances x budgets) over the instances run on, no design counting as ``inf``.

    Returns ``(cost, reached, covered)``: ``cost[:, k]`` the (25 %, median, 75 %) of
    column ``k``, ``inf`` where that quantile falls on or between instances without a
    design within the budget (the median is finite only where more than half have
    one); ``reached[k]`` how many instances have a design within budget ``k``;
    ``covered`` how many have a usable design at all. Rows of NaN (instances the
    method did not run on) are left out.
    """
    best = np.asarray(best, dtype=float)
    ran = best[~np.isnan(best).all(axis=1)] if best.ndim == 2 else best
    reached = np.isfinite(ran).sum(axis=0)
    covered = int(np.isfinite(ran).any(axis=1).sum())
    cost = _quantiles(ran) if len(ran) else np.full((3, best.shape[1]), np.inf)
    return cost, reached, covered


def median_interval(differences, confidence: float = 0.95) -> tuple[float, float, float]:
    """Distribution-free interval for the median of i.i.d. differences: (low, high, coverage).

    The interval between the k-th smallest and k-th largest value covers the median
    with probability 1 − 2 P(Binomial(n, ½) ≤ k − 1); k is the largest rank that
    keeps this at least ``confidence``. With too few values for that, the full range
    and its (lower) coverage are returned.
    """
    d = np.sort(np.asarray(differences, dtype=float))
    n = d.size
    if n == 0:
        return float("nan"), float("nan"), 0.0
    k = int(stats.binom.ppf((1 - confidence) / 2, n, 0.5))  # P(B <= k) >= alpha/2 first at k
    while k >= 1 and 1 - 2 * stats.binom.cdf(k - 1, n, 0.5) < confidence:
        k -= 1
    k = max(k, 1)
    coverage = 1 - 2 * stats.binom.cdf(k - 1, n, 0.5)
    return float(d[k - 1]), float(d[n - k]), float(coverage)


@dataclass(frozen=True)
class Paired:
    """Paired comparison of method ``a`` against ``b`` (difference a − b; negative: a is better)."""

    a: str
    b: str
    budget: float | None
    instances: int
    a_wins: int
    b_wins: int
    median: float
    low: float
    high: float
    coverage: float
    confidence: float = 0.95

    @property
    def inconclusive(self) -> bool:
        """The interval contains 0: the data do not say which is better."""
        return not (self.high < 0 or self.low > 0)

    @property
    def too_few(self) -> bool:
        """Too few instances for an interval of the asked confidence (with 5 or fewer, even the full range covers less than 95 %)."""
        return self.coverage < self.confidence

    @property
    def interval_text(self) -> str:
        """``[low, high]``, followed by the achieved coverage where it falls short of the asked confidence."""
        text = f"[{self.low:+.4f}, {self.high:+.4f}]"
        return text + (f" ({self.coverage:.0%})" if self.too_few else "")


def paired_difference(a_label, b_label, a_costs, b_costs, budget=None, confidence: float = 0.95) -> Paired:
    """Compare two methods' per-instance costs (arrays aligned by instance, inf = no design)."""
    a_costs, b_costs = np.asarray(a_costs, dtype=float), np.asarray(b_costs, dtype=float)
    both = np.isfinite(a_costs) & np.isfinite(b_costs)
    d = a_costs[both] - b_costs[both]
    low, high, coverage = median_interval(d, confidence)
    return Paired(a_label, b_label, budget, int(both.sum()), int((d < 0).sum()), int((d > 0).sum()),
                  float(np.median(d)) if d.size else float("nan"), low, high, coverage, confidence)


#: Link budgets of the tables and findings, in links per node: 20, 60 and 140 links at the paper's
#: N = 20, the same share of the possible links at every size (a fixed 140 links would be "no
#: links" at N = 1000 and "all links" at N = 4).
BUDGETS_PER_NODE = (1, 3, 7)


def panel_nodes(records) -> int | None:
    """The (median) node count of a panel's instances; None where no record says."""
    nodes = [i.nodes for i in as_records(records).instances if i.nodes]
    return int(np.median(nodes)) if nodes else None


def panel_budgets(records) -> tuple:
    """One panel's link budgets: :data:`BUDGETS_PER_NODE` times its node count, then None (any number).

    A budget of N(N − 1) links or more allows every link, so it is "any" under another
    name: such tiers are left out (at N = 4, 4 links, then any: 12 and 28 links would
    repeat "any" and count one comparison three times in Holm's correction).
    """
    n = panel_nodes(records)
    if n is None:
        return (20, 60, 140, None)
    return tuple(k * n for k in BUDGETS_PER_NODE if k * n < n * (n - 1)) + (None,)


def paired_comparisons(records, reference: str, budgets=None, others=None) -> dict:
    """Panel -> list of :class:`Paired` of ``reference`` against every other label, per budget.

    ``budgets``: link budgets (None in it: any number of links), the same in every panel;
    by default each panel's own (:func:`panel_budgets`). ``others`` restricts the labels
    compared with the reference.
    """
    records = as_records(records)
    out = {}
    for panel, in_panel in sorted(records.by_panel.items()):
        panel_grid = panel_budgets(in_panel) if budgets is None else tuple(budgets)
        grid = np.array([np.inf if b is None else b for b in panel_grid], dtype=float)
        tables = best_tables(in_panel, grid)
        if (panel, reference) not in tables:
            continue
        ref = tables[(panel, reference)]
        rows = []
        for (_, label), other in tables.items():
            if label == reference or (others is not None and label not in others):
                continue
            rows += [paired_difference(reference, label, ref[:, k], other[:, k], panel_grid[k])
                     for k in range(len(panel_grid))]
        out[panel] = rows
    return out
