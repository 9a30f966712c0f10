"""Findings: the claims a report's data support, and the forest plot they come from.

A report opens with a short list of claims, each backed by paired comparisons
drawn in its first figure. The comparisons are the ones a control researcher
asks of the data, per panel and link budget:

- each learned delayed design (GRNN variants; tanh and linear apart) against the
  delayed ℓ1 static gain, and linear against tanh GRNN-Sparse: both designs see
  the same information (one step per hop);
- every delayed design against the SLS bound (SLS on the complete graph at one
  hop per step), the best cost any controller with that information reaches;
- context across information models, marked as such: GRNN-Sparse against the instantaneous ℓ1
  gain and against the decentralized gain (no communication), GCNN against the
  instantaneous ℓ1 gain;
- the pairs a spec asks for.

Each comparison pairs the two designs instance by instance
(:func:`compare.report.statistics.paired_difference`): the median difference a − b of
their best costs within the budget (LQR-normalized; negative: a is better), a
distribution-free 95 % interval for it, and an exact two-sided sign test on the
wins (ties dropped), Holm-adjusted over every comparison of the report. A claim
says one design "beats" the other only where the interval excludes 0 *and* the
adjusted p < 0.05; an interval excluding 0 alone gives the direction, "not
significant after Holm's correction"; with 5 instances or fewer no 95 % interval
exists, and only counts are given.

Two verdicts guard the claims against what a reader cannot see. Differences smaller
than :data:`PRACTICAL_MARGIN` (0.1 % of centralized LQR's cost) are *equal*, never
"beats": the paper reports costs to three decimals, the figures draw everything
within 0.1 % of LQR on their bottom edge, and the margin is above every solver's
tolerance (ℓ1 paths polished to about 1e-5, SLS by Clarabel to about 1e-8) and above
the median standard error of a simulated cost (about 2e-4 in the shipped reports).
And a difference the paired test finds, but which the budget fronts as drawn (the
median over instances of each method's best cost, :mod:`compare.report.statistics`) order
the other way, is *mixed*: the typical instance favours one design while the median
costs favour the other, so no single order is claimed, and no figure contradicts a
finding.

Simulated costs whose standard error stays above :data:`UNCERTAIN_RSE` of the cost
are unresolved (rare divergent draws dominate them) and enter no claim: those
designs are dropped before best costs are taken, and each comparison counts the
instances this changed.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from ..run.records import Records, as_records
from .statistics import (
    Paired,
    best_within,
    front_quantiles,
    instances_by_panel,
    median_interval,
    paired_difference,
    panel_budgets,
    panel_nodes,
)
from .styles import GRNN_KINDS, Style, grnn_kinds, style_for
from .system_kinds import kind_of

__all__ = ["arm_labels", "UNCERTAIN_RSE", "BOUND_LABEL", "ALPHA", "PRACTICAL_MARGIN", "Comparison", "is_unresolved", "unresolved", "is_sls_bound",
           "select_comparisons", "holm", "sign_test", "budgets_per_node", "Pooled", "pooled_rows"]

#: Above this relative standard error a simulated cost is unresolved: not a number to compare
#: at the third digit (in the shipped reports every such cost came from rare divergent draws).
UNCERTAIN_RSE = 0.01
#: The name of SLS on the complete graph at one hop per step, whatever its records' label.
BOUND_LABEL = "SLS bound (complete graph)"
#: Family-wise level of the Holm-adjusted sign tests.
ALPHA = 0.05
#: Differences of best costs below this, in units of centralized LQR's cost, are "equal" (see the module text).
PRACTICAL_MARGIN = 1e-3
#: In a plan, "each panel's own budgets" (:func:`compare.report.statistics.panel_budgets`, or the caller's).
_PANEL_BUDGETS = "budgets"
#: The group of the claims the findings are about: designs that see the same, delayed, information.
_SAME_DELAYED = "same information model: delayed"

# Learned designs with the delayed information model, in the order the findings list them.
_LEARNED = ("grnn_sparse", "grnn", "grnn_dense", "grnn_fixed")
_SLS = ("sls", "sls_topologies")
_TOO_FEW_COLOUR = "#999999"
#: Differences beyond this (in units of centralized LQR's cost) are off the forest plot's scale:
#: drawn at its edge with their median printed.
X_CAP = 10.0


# --------------------------------------------------------------------------- records


def is_unresolved(r) -> bool:
    """A simulated design whose cost keeps a relative standard error above :data:`UNCERTAIN_RSE`."""
    return (r.cost_kind == "simulated" and r.ok and r.cost > 0
            and math.isfinite(r.cost_stderr) and r.cost_stderr > UNCERTAIN_RSE * r.cost)


def unresolved(records) -> Records:
    """The designs of ``records`` whose costs are unresolved (:func:`is_unresolved`)."""
    return as_records(records).filter(is_unresolved)


def is_sls_bound(r) -> bool:
    """SLS on the complete graph at one hop per step, act_delay 1, no FIR truncation: the delayed bound.

    Recognised by its hyperparameters, not its label: a topology family shares one
    label among all its graphs.
    """
    p = r.params
    return (r.method in _SLS and p.get("graph") == "complete" and p.get("act_delay") == 1
            and p.get("speed") == 1 and p.get("fir") is None)


def _linear(r) -> bool:
    return r.params.get("activation") == "identity"


def _kinds(r) -> tuple:
    """A GRNN design's readout and start (:func:`compare.report.styles.grnn_kinds`): () for the paper's."""
    return tuple(grnn_kinds(r.method, r.params))


def _grnn_words(r, activation: bool, kinds: bool) -> str:
    words = (["linear" if _linear(r) else "tanh"] if activation else [])
    if kinds:
        words += [GRNN_KINDS[k][1] if k in GRNN_KINDS else k.replace("_", " ") for k in _kinds(r)] or ["paper"]
    return ", ".join(words)


def arm_labels(records: Records) -> list[str]:
    """The label each design is compared under (one per design, in order).

    Its own label, except: the SLS bound is :data:`BOUND_LABEL`; a label shared by
    GRNN designs of different kinds is split by what differs: the activation (tanh,
    linear), the readout and the start ("per-node", "warm: delayed"; "paper" for the
    paper's shared readout from a random draw); a label shared by SLS designs on
    several graphs is split by graph.
    """
    activations, kinds, graphs = {}, {}, {}
    for r in records:
        if r.method.startswith("grnn"):
            activations.setdefault(r.label, set()).add(_linear(r))
            kinds.setdefault(r.label, set()).add(_kinds(r))
        if r.method in _SLS:
            graphs.setdefault(r.label, set()).add("bound" if is_sls_bound(r) else r.params.get("graph"))
    out = []
    for r in records:
        if is_sls_bound(r):
            out.append(BOUND_LABEL)
        elif r.method.startswith("grnn") and (len(activations[r.label]) > 1 or len(kinds[r.label]) > 1):
            out.append(f"{r.label} ({_grnn_words(r, len(activations[r.label]) > 1, len(kinds[r.label]) > 1)})")
        elif r.method in _SLS and len(graphs[r.label]) > 1:
            out.append(f"{r.label}: {r.params.get('graph', 'plant')} graph")
        else:
            out.append(r.label)
    return out


@dataclass(frozen=True)
class _Arm:
    """One side of a comparison: a label and what its designs are."""

    label: str
    method: str
    linear: bool
    kinds: tuple
    graph: str | None
    info_model: str
    original: str
    style: Style


def _arms(records: Records, labels: list[str]) -> dict[str, _Arm]:
    grouped: dict[str, list] = {}
    for r, label in zip(records, labels):
        grouped.setdefault(label, []).append(r)
    out = {}
    for label, rs in grouped.items():
        first = rs[0]
        info = Counter(r.info_model or "?" for r in rs).most_common(1)[0][0]
        out[label] = _Arm(label, first.method, _linear(first), _kinds(first), first.params.get("graph"), info,
                          first.label, style_for(first.method, first.params, info))
    return out


# --------------------------------------------------------------------------- comparisons


class _Verdict:
    """The verdict of a paired comparison from its ``tested``, ``equal``, ``too_few``, ``mixed`` and ``paired``:
    one definition for a panel's :class:`Comparison` and a pooled row (:class:`Pooled`)."""

    @property
    def significant(self) -> bool:
        """A claim: tested, not equal within the margin, and drawn in the same order (one "beats" the other)."""
        return self.tested and not self.equal and not self.mixed

    @property
    def verdict(self) -> str:
        """"better" or "worse" (a against b), "equal", "mixed", "no significant difference", or "too few"."""
        if self.equal:
            return "equal"
        if self.too_few:
            return "too few"
        if self.mixed:
            return "mixed"
        if not self.significant:
            return "no significant difference"
        return "better" if self.paired.high < 0 else "worse"


@dataclass(frozen=True)
class Comparison(_Verdict):
    """Design ``a`` against design ``b`` on one panel within one link budget.

    Parameters
    ----------
    panel : tuple
        :func:`compare.run.records.panel_key` of the instances.
    a, b : str
        Labels; the difference is a − b (negative: a is better).
    budget : float or None
        Largest number of directed off-diagonal links; None: any.
    paired : Paired
        Median difference, its distribution-free interval, wins, instances.
    relation : {"same", "cross"}
        Whether both designs use the same information model.
    info_a, info_b : str
        Their information models.
    p_value : float
        Exact two-sided sign test on the wins (ties dropped); 1 without any win.
    p_holm : float
        ``p_value`` Holm-adjusted over every comparison of the report.
    excluded : int
        Instances whose pairing changed because unresolved costs were dropped: the
        instance left the comparison, or a side is represented by its best resolved
        design instead.
    group : str
        The heading it is drawn and listed under.
    panel_instances : int
        Instances of the panel.
    method_a, method_b : str
        The methods of a's and b's designs.
    style_a : Style or None
        a's style from what its designs are (:func:`compare.report.styles.style_for`): the
        figure's fallback for labels split here, which a report's label styles lack.
    per_node : float or None
        ``budget`` per node of the panel (None: any, or no node count known): the forest
        plot's row where panels of different sizes have different budgets.
    drawn_a, drawn_b : float
        Each side's median best cost within the budget as the budget fronts draw it (over
        the instances it ran on, every design counted; ``inf`` where it is not drawn).
    label_a, label_b : str or None
        The label each side is drawn under in the figures (None where the findings split
        a label the figures keep whole).
    differences : tuple of float
        The per-instance differences a − b behind ``paired`` (what :func:`pooled_rows` pools
        over panels); empty for a comparison made by hand.
    """

    panel: tuple
    a: str
    b: str
    budget: float | None
    paired: Paired
    relation: str
    info_a: str
    info_b: str
    p_value: float
    p_holm: float
    excluded: int = 0
    group: str = ""
    panel_instances: int = 0
    method_a: str = ""
    method_b: str = ""
    style_a: Style | None = None
    per_node: float | None = None
    drawn_a: float = math.inf
    drawn_b: float = math.inf
    label_a: str | None = None
    label_b: str | None = None
    differences: tuple = field(default=(), compare=False, repr=False)

    def budget_tier(self, per_node: bool):
        """This cell's budget as figures and text name it: links, or links per node (see :func:`budgets_per_node`)."""
        return self.per_node if per_node else self.budget

    @property
    def too_few(self) -> bool:
        """Too few instances for a 95 % interval: only counts may be stated."""
        return self.paired.too_few

    @property
    def equal(self) -> bool:
        """The median difference is within :data:`PRACTICAL_MARGIN`, and the interval excludes 0 or lies within it.

        (A median that small with an interval reaching past the margin on both sides
        is "no clear difference": the data do not say that the two are equal.)
        """
        p, m = self.paired, PRACTICAL_MARGIN
        if not abs(p.median) < m:
            return False
        return (-m < p.low and p.high < m) or not p.inconclusive

    @property
    def tested(self) -> bool:
        """The interval excludes 0 and the Holm-adjusted sign test rejects at :data:`ALPHA` (before the margin)."""
        return not self.too_few and not self.paired.inconclusive and self.p_holm < ALPHA

    @property
    def mixed(self) -> bool:
        """Tested, beyond the margin, yet the budget fronts as drawn order the two the other way."""
        if not self.tested or self.equal or not (math.isfinite(self.drawn_a) and math.isfinite(self.drawn_b)):
            return False
        return (self.drawn_a - self.drawn_b) * self.paired.median < 0



def sign_test(a_wins: int, b_wins: int) -> float:
    """Exact two-sided sign test of equal win probabilities (ties already dropped); 1 without any win."""
    n = a_wins + b_wins
    return float(stats.binomtest(a_wins, n, 0.5).pvalue) if n else 1.0


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of ``p_values`` (same order): controls the family-wise error rate."""
    p = np.asarray(p_values, dtype=float)
    m = p.size
    order = np.argsort(p, kind="stable")
    adjusted = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adjusted[i] = running
    return adjusted.tolist()


def _resolve(name: str, arms: Mapping[str, _Arm]) -> list[str]:
    """Arm labels a spec's pair entry means: a label, a label split here, or a method name."""
    if name in arms:
        return [name]
    split = [a.label for a in arms.values() if a.original == name]
    return split or [a.label for a in arms.values() if a.method == name][:1]


def _plan(arms: Mapping[str, _Arm], pairs: Iterable) -> list[tuple[str, str, object, str]]:
    """(a, b, budgets, group) of every comparison asked, in the order the findings list them.

    ``budgets`` is ``(None,)`` (any number of links) or :data:`_PANEL_BUDGETS`.
    """
    learned = sorted(_labels_of(arms, *_LEARNED),
                     key=lambda x: (_LEARNED.index(arms[x].method), arms[x].linear, arms[x].kinds, x))
    static_delayed = _labels_of(arms, "sparse_delayed")
    plan = _delayed_plan(arms, learned, static_delayed)
    plan += _decomposition_plan(arms)
    if BOUND_LABEL in arms:
        plan += _bound_plan(arms, learned + static_delayed)
    plan += _cross_plan(arms)
    plan += _asked_plan(arms, pairs, {(a, b) for a, b, _, _ in plan})
    return plan


def _labels_of(arms: Mapping[str, _Arm], *methods: str, linear: bool | None = None) -> list[str]:
    """The arms of ``methods`` (tanh or linear alone where ``linear`` says), the SLS bound left out."""
    return [a.label for a in arms.values()
            if a.method in methods and (linear is None or a.linear == linear) and a.label != BOUND_LABEL]


def _delayed_plan(arms: Mapping[str, _Arm], learned: list[str], static_delayed: list[str]) -> list[tuple]:
    """Each learned design against the delayed ℓ1 gain, and linear against tanh GRNN-Sparse of the same kind."""
    plan = [(a, b, _PANEL_BUDGETS, _SAME_DELAYED) for a in learned for b in static_delayed]
    plan += [(a, b, _PANEL_BUDGETS, _SAME_DELAYED) for a in _labels_of(arms, "grnn_sparse", linear=True)
             for b in _labels_of(arms, "grnn_sparse", linear=False) if arms[a].kinds == arms[b].kinds]
    return plan


def _decomposition_plan(arms: Mapping[str, _Arm]) -> list[tuple]:
    """GRNN-Sparse kinds against each other, for why a GRNN-Sparse design loses (compare.report.decomposition).

    The model class (per-node against the shared readout, both from random) and the
    training (a warm start against the random draw), both sides at the same activation.
    """
    sparse = [arms[x] for x in _labels_of(arms, "grnn_sparse")]
    plan = [(a.label, b.label, _PANEL_BUDGETS, _SAME_DELAYED) for a in sparse for b in sparse
            if a.linear == b.linear and a.kinds == ("per_node",) and b.kinds == ()]
    plan += [(a.label, b.label, _PANEL_BUDGETS, _SAME_DELAYED) for a in sparse for b in sparse
             if a.linear == b.linear and len(a.kinds) == 2 and a.kinds[0] == "per_node" and b.kinds == ("per_node",)]
    return plan


def _bound_plan(arms: Mapping[str, _Arm], delayed: list[str]) -> list[tuple]:
    """The ``delayed`` designs and SLS on the plant graph against the SLS bound, at any number of links."""
    plant_sls = [a.label for a in arms.values() if a.method in _SLS and a.graph == "plant"
                 and a.label != BOUND_LABEL]
    return [(a, BOUND_LABEL, (None,), "same information model: delayed, against the SLS bound")
            for a in delayed + plant_sls]


def _cross_plan(arms: Mapping[str, _Arm]) -> list[tuple]:
    """Cross-model context: GRNN-Sparse against the instantaneous ℓ1 and decentralized gains, GCNN against ℓ1."""
    instantaneous = _labels_of(arms, "sparse_admm") or _labels_of(arms, "sparse_sdp")
    tanh_sparse = _labels_of(arms, "grnn_sparse", linear=False)
    # For the paper's GRNN-Sparse only, where other kinds of it stand beside it.
    tanh_sparse = [x for x in tanh_sparse if not arms[x].kinds] or tanh_sparse
    cross = [(a, b, _PANEL_BUDGETS) for a in tanh_sparse for b in instantaneous]
    cross += [(a, b, _PANEL_BUDGETS) for a in tanh_sparse for b in _labels_of(arms, "decentralized")]
    cross += [(a, b, (None,)) for a in _labels_of(arms, "gcnn") for b in instantaneous]
    return [(a, b, bs, _group(arms[a].info_model, arms[b].info_model)) for a, b, bs in cross]


def _asked_plan(arms: Mapping[str, _Arm], pairs: Iterable, asked: set) -> list[tuple]:
    """The spec's ``pairs`` not already ``asked`` (in either order), within each panel's budgets."""
    asked, plan = set(asked), []
    for first, second in pairs:
        for a in _resolve(first, arms):
            for b in _resolve(second, arms):
                if a != b and (a, b) not in asked and (b, a) not in asked:
                    asked.add((a, b))
                    plan.append((a, b, _PANEL_BUDGETS, _group(arms[a].info_model, arms[b].info_model)))
    return plan


def _group(info_a: str, info_b: str) -> str:
    if info_a == info_b:
        return f"same information model: {info_a}"
    return f"different information: {info_a} against {info_b}"


def _group_rank(group: str) -> tuple:
    """Delayed-information claims first (same model, then against the bound), other same-model ones, cross last.

    (Ties keep the plan's order: the sort is stable.)
    """
    if group == _SAME_DELAYED:
        return (0,)
    if "bound" in group:
        return (1,)
    if group.startswith("same information model:"):
        return (2,)
    return (3,)


def _panel_order(panel: tuple) -> tuple:
    """Panels by family, then N and ‖A‖₂ as numbers (instance keys are JSON text: "n": 100 sorts before 20)."""
    family, n, a_norm = panel
    return (family, n, -math.inf if a_norm is None else a_norm)


def _tables(records: Records, labels: list[str], panels: dict, grids: dict) -> dict:
    grouped: dict[tuple, list] = {}
    for r, label in zip(records, labels):
        grouped.setdefault((r.instance.panel, label), []).append(r)
    return {key: best_within(Records(rs), panels[key[0]], grids[key[0]]) for key, rs in grouped.items()}


def select_comparisons(records, *, budgets=None, pairs=()) -> list[Comparison]:
    """The comparisons a researcher asks of these data, per panel and budget, with Holm-adjusted sign tests.

    Parameters
    ----------
    records : Records or iterable of dict
    budgets : tuple of (float or None), optional
        Link budgets, the same in every panel; None in it: any number of links. By
        default each panel's own, 1, 3 and 7 links per node and any
        (:func:`compare.report.statistics.panel_budgets`). Comparisons against the SLS bound
        and of the GCNN use "any" alone.
    pairs : iterable of (str, str)
        Extra (first, second) pairs (labels or method names, as a spec's
        ``report.pairs``), compared within every budget.

    Returns
    -------
    list of Comparison
        Grouped as the findings list them (same-model delayed claims first), then by
        pair, panel and budget. Pairs with no instance where both have a design
        within the budget are left out.
    """
    records = as_records(records)
    labels = arm_labels(records)
    arms = _arms(records, labels)
    panels = instances_by_panel(records)
    by_panel = records.by_panel
    panel_grid = {p: tuple(budgets) if budgets is not None else panel_budgets(by_panel[p]) for p in panels}
    panel_node_count = {p: panel_nodes(by_panel[p]) for p in panels}
    grids = {p: np.array([np.inf if b is None else float(b) for b in g]) for p, g in panel_grid.items()}
    full = _tables(records, labels, panels, grids)
    keep = [not is_unresolved(r) for r in records]
    kept = _tables(Records(r for r, k in zip(records, keep) if k), [x for x, k in zip(labels, keep) if k],
                   panels, grids)
    plan = sorted(_plan(arms, pairs), key=lambda item: _group_rank(item[3]))
    drawn_labels = _drawn_labels(records, labels)
    out = []
    for a, b, pair_budgets, group in plan:
        for panel in sorted(panels, key=_panel_order):
            if (panel, a) not in full or (panel, b) not in full:
                continue
            column = {b: k for k, b in enumerate(panel_grid[panel])}
            for budget in panel_grid[panel] if pair_budgets == _PANEL_BUDGETS else pair_budgets:
                if budget not in column:
                    continue
                k = column[budget]
                out_k = _compare(a, b, budget, [kept.get((panel, x)) for x in (a, b)],
                                 [full[(panel, x)] for x in (a, b)], k)
                if out_k is None:
                    continue
                paired, excluded, differences = out_k
                ia, ib = arms[a].info_model, arms[b].info_model
                nodes = panel_node_count[panel]
                per_node = None if budget is None or not nodes else budget / nodes
                drawn = [_drawn_median(full[(panel, x)][:, k]) for x in (a, b)]
                out.append(Comparison(panel, a, b, budget, paired, "same" if ia == ib else "cross", ia, ib,
                                      sign_test(paired.a_wins, paired.b_wins), 1.0, excluded, group,
                                      len(panels[panel]), arms[a].method, arms[b].method, arms[a].style,
                                      per_node, *drawn, *(drawn_labels.get(x) for x in (a, b)), differences))
    adjusted = holm([c.p_value for c in out])
    return [replace(c, p_holm=p) for c, p in zip(out, adjusted)]


def _drawn_median(best) -> float:
    """The median of one budget's best costs (instances, NaN where not run) as the budget fronts draw it."""
    return float(front_quantiles(np.asarray(best, dtype=float)[:, None])[0][1, 0])


def _drawn_labels(records: Records, labels: list[str]) -> dict[str, str]:
    """Arm label -> the record label its designs are drawn under, where that is one label drawn for this arm alone."""
    originals: dict[str, set] = {}
    arms_of: dict[str, set] = {}
    for r, label in zip(records, labels):
        originals.setdefault(label, set()).add(r.label)
        arms_of.setdefault(r.label, set()).add(label)
    return {arm: next(iter(o)) for arm, o in originals.items() if len(o) == 1 and len(arms_of[next(iter(o))]) == 1}


def budgets_per_node(comparisons: Sequence[Comparison]) -> bool:
    """Whether budgets are best told per node: panels of different sizes put one tier at different link counts."""
    budgets: dict = {}
    for c in comparisons:
        if c.per_node is not None:
            budgets.setdefault(c.per_node, set()).add(c.budget)
    return any(len(values) > 1 for values in budgets.values())


def _compare(a, b, budget, kept, full, k):
    """(Paired, instances changed by dropping unresolved costs, the differences a − b), or None where no instance
    has both."""
    fa, fb = (t[:, k] for t in full)
    ka, kb = (t[:, k] if t is not None else np.full(fa.shape, np.nan) for t in kept)
    with np.errstate(invalid="ignore"):
        paired = paired_difference(a, b, ka, kb, budget)
        both_full = np.isfinite(fa) & np.isfinite(fb)
        same = np.isfinite(ka) & np.isfinite(kb) & (ka == fa) & (kb == fb)
    if not paired.instances:
        return None
    both = np.isfinite(ka) & np.isfinite(kb)
    return paired, int((both_full & ~same).sum()), tuple(float(x) for x in ka[both] - kb[both])


# --------------------------------------------------------------------------- pooled over panels


@dataclass(frozen=True)
class Pooled(_Verdict):
    """One pair within one budget tier, pooled over the panels where it is compared: a row of the findings table.

    The instances of every panel are taken together: the median of all their
    differences a − b with a distribution-free 95 % interval (:func:`median_interval`),
    and a stratified sign test (the wins counted in each panel and summed; under no
    difference each instance is a fair coin whatever its panel, so the total is
    binomial), Holm-adjusted over every pooled row of the report. A pair compared on one
    panel only is that panel's cell, tested the same way.

    Parameters
    ----------
    cells : tuple of Comparison
        The per-panel cells pooled, in panel order.
    paired : Paired
        Median, interval, wins and instances over all of them.
    p_value, p_holm : float
        The stratified sign test, and it Holm-adjusted over the report's pooled rows.
    tier : float or None
        The budget (links, or links per node where the panels differ in size; None: any).
    """

    cells: tuple
    paired: Paired
    p_value: float
    p_holm: float = 1.0
    tier: float | None = None

    a = property(lambda self: self.cells[0].a)
    b = property(lambda self: self.cells[0].b)
    group = property(lambda self: self.cells[0].group)
    relation = property(lambda self: self.cells[0].relation)
    info_a = property(lambda self: self.cells[0].info_a)
    info_b = property(lambda self: self.cells[0].info_b)

    @property
    def panels(self) -> tuple:
        return tuple(c.panel for c in self.cells)

    @property
    def too_few(self) -> bool:
        return self.paired.too_few

    @property
    def equal(self) -> bool:
        """As :attr:`Comparison.equal`: the pooled median within the margin, the interval excluding 0 or inside it."""
        p, m = self.paired, PRACTICAL_MARGIN
        if not abs(p.median) < m:
            return False
        return (-m < p.low and p.high < m) or not p.inconclusive

    @property
    def tested(self) -> bool:
        return not self.too_few and not self.paired.inconclusive and self.p_holm < ALPHA

    @property
    def mixed(self) -> bool:
        """Tested, beyond the margin, yet something shown orders the two the other way: on one panel, the budget
        fronts as drawn (as :attr:`Comparison.mixed`); pooled over several, a panel whose interval excludes 0 on
        the other side."""
        if not self.tested or self.equal:
            return False
        return bool(self.against())

    def against(self) -> list:
        """The cells that order the two against the pooled median (see :attr:`mixed`)."""
        m = self.paired.median
        if len(self.cells) == 1:
            return [c for c in self.cells if math.isfinite(c.drawn_a) and math.isfinite(c.drawn_b)
                    and (c.drawn_a - c.drawn_b) * m < 0]
        return [c for c in self.cells if not c.too_few and not c.paired.inconclusive and c.paired.median * m < 0]



def _pool(cells: Sequence[Comparison], tier) -> Pooled:
    """The pooled row of ``cells`` (one pair, one tier, one cell per panel), before Holm's adjustment."""
    if len(cells) == 1:
        c = cells[0]
        return Pooled((c,), c.paired, c.p_value, c.p_value, tier)
    c0 = cells[0]
    a_wins = sum(c.paired.a_wins for c in cells)
    b_wins = sum(c.paired.b_wins for c in cells)
    n = sum(c.paired.instances for c in cells)
    d = np.concatenate([np.asarray(c.differences, dtype=float) for c in cells])
    if d.size == n:
        low, high, coverage = median_interval(d)
        median = float(np.median(d))
    else:  # comparisons made by hand, without their differences: counts only
        low = high = median = float("nan")
        coverage = 0.0
    paired = Paired(c0.a, c0.b, c0.budget, n, a_wins, b_wins, median, low, high, coverage)
    p = sign_test(a_wins, b_wins)
    return Pooled(tuple(cells), paired, p, p, tier)


def pooled_rows(comparisons: Sequence[Comparison], kinds: Mapping | None = None) -> list[Pooled]:
    """One :class:`Pooled` per pair and budget tier, over the panels where the pair is compared within it.

    With ``kinds`` (panel -> its kind of system, :func:`compare.report.system_kinds.system_kinds`), one per pair, kind
    of system and budget tier instead: no row pools panels that are different systems (docs/reports.md,
    "Pooling"); a panel ``kinds`` does not name is a kind of its own.

    In the order of ``comparisons`` (pairs as the findings list them, then kinds in the order their panels first
    come, then tiers in increasing order, any number of links last); Holm-adjusted over all of them.
    """
    per_node = budgets_per_node(comparisons)
    groups: dict[tuple, dict] = {}
    for c in comparisons:
        kind = kind_of(kinds, c.panel)
        (groups.setdefault((c.group, c.a, c.b), {}).setdefault(kind, {})
         .setdefault(c.budget_tier(per_node), []).append(c))
    rows = []
    for by_kind in groups.values():
        for tiers in by_kind.values():
            for tier in sorted(tiers, key=lambda t: math.inf if t is None else t):
                rows.append(_pool(tiers[tier], tier))
    adjusted = holm([r.p_value for r in rows])
    return [replace(r, p_holm=q) for r, q in zip(rows, adjusted)]
