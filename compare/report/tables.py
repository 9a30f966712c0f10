"""The report's Markdown tables: budget tables, medians by method, paired rows, Pareto fronts, provenance.

Each function returns Markdown lines; none draws. "—" in a table means no value: the
method has no usable design there (or the column does not apply to it).
"""

from __future__ import annotations

import itertools
import platform
import re
from collections import Counter, defaultdict
from collections.abc import Mapping

import numpy as np

from ..run.meta import StoreMeta
from ..run.records import OK_STATUSES, Records
from .cost_links import Point, pareto_front
from .findings import UNCERTAIN_RSE, unresolved
from .statistics import (
    best_tables,
    front_quantiles,
    paired_comparisons,
    panel_budgets,
    panel_title,
)

_PACKAGES = ("grnn-codesign", "numpy", "scipy", "cvxpy", "clarabel", "scs", "control", "torch", "numba", "networkx",
             "matplotlib", "plotly")

#: Said under every table that uses it.
DASH_NOTE = "— : no usable design there."

def _words(label: str) -> Counter:
    """The words of a label, whatever their order, case and punctuation ("ℓ1" read as "l1")."""
    return Counter(re.findall(r"[\w²³]+", label.replace("ℓ", "l").lower()))


def canonical_label(method: str, label: str, registry: Mapping[str, str]) -> str:
    """One name per method across reports: a label that is the method's registered label reworded.

    Labels are stored with the runs, so a method can carry the name a spec once gave it
    ("Sparse K, delayed (l1)") in one report and its registered label ("Sparse delayed K
    (l1)") in another. A label with exactly the words of the method's registered label, in
    any order, case or punctuation, becomes that label; any other label (one that names a
    setting or a variant: "GRNN-Sparse (β path, 150 steps)", "Linear GRNN-Sparse") is kept.
    """
    name = registry.get(method)
    return name if name and label != name and _words(label) == _words(name) else label


def registered_labels() -> dict[str, str]:
    """Method name -> the label it is registered with (built-ins and loaded plug-ins); empty if the registry
    cannot be loaded."""
    try:
        from ..run.registry import methods
    except ImportError:  # pragma: no cover - a report without the method code installed
        return {}
    return {name: m.label for name, m in methods().items() if getattr(m, "label", None)}


def software_versions() -> dict[str, str]:
    from ..run.fingerprint import package_versions

    return {"python": platform.python_version(), **package_versions(_PACKAGES)}


def _fmt(value: float, digits: int = 4, *, links: bool = False) -> str:
    """``digits`` significant digits; a link count (or a median of counts) never in scientific notation."""
    if value is None or not np.isfinite(value):
        return "—"
    if links:
        return f"{value:.1f}".removesuffix(".0")
    return f"{value:.{digits}g}"


def _fmt_iqr(q: tuple, digits: int = 4, *, links: bool = False) -> str:
    if not np.isfinite(q[1]):
        return "—"
    return f"{_fmt(q[1], digits, links=links)} [{_fmt(q[0], digits, links=links)}, {_fmt(q[2], digits, links=links)}]"


def _params_text(params: Mapping) -> str:
    def text(value):
        # Grid values such as 0.0021544346900318843 read better at 4 digits; the
        # store and the CSV keep them exact.
        return _fmt(value) if isinstance(value, float) and np.isfinite(value) else str(value)

    return ", ".join(f"{k}={text(v)}" for k, v in sorted(params.items())) or "—"


def summary_tables(points: list[Point], records: Records | None = None) -> list[str]:
    """Medians by setting; a setting with unresolved simulated costs says how many (they enter no finding)."""
    flagged = Counter((r.instance.panel, r.label, r.params_key) for r in unresolved(records)) if records else {}
    lines = []
    for panel in sorted({p.panel for p in points}):
        pts = [p for p in points if p.panel == panel]
        lines += [
            f"### {panel_title(panel)}",
            "",
            "| method | setting | usable | links | self-loops | cost |",
            "|---|---|---:|---|---:|---|",
        ]
        for p in sorted(pts, key=lambda p: (p.label, p.links[1] if np.isfinite(p.links[1]) else -1,
                                            p.cost[1] if np.isfinite(p.cost[1]) else np.inf, p.params_key)):
            k = flagged.get((p.panel, p.label, p.params_key), 0)
            lines.append(
                f"| {p.label}<br>{p.info_model} | {_params_text(p.params)} | {p.ok} of {p.designs} | "
                f"{_fmt_iqr(p.links, 3, links=True)} | {_fmt(p.self_loops, 3, links=True)} | {_fmt_iqr(p.cost)}"
                + (f" ⚠ {k} unresolved" if k else "") + " |"
            )
        lines += ["", "One row per setting (the method's parameters; its information model under its name): its "
                  "usable designs (optimal or inaccurate, finite cost) of all it returned, and over those the "
                  "median [interquartile range] of links and cost, and the median self-loops. " + DASH_NOTE
                  + (" ⚠ k unresolved: k of the costs are simulated estimates whose relative standard error stays "
                     "above 1 %; see How this report was computed." if flagged else ""), ""]
    return lines


def systems_table(records: Records) -> list[str]:
    """The systems compared, one row per panel, from the facts the runner stored (none for older stores)."""
    def spread(values, fmt) -> str:
        values = sorted(v for v in values if v is not None)
        if not values:
            return "—"
        low, mid, high = (fmt(v) for v in (values[0], values[len(values) // 2], values[-1]))
        return mid if low == high else f"{mid} [{low}, {high}]"

    rows = []
    for panel, rs in sorted(records.by_panel.items()):
        instances = [i for i in rs.instances if i.radius is not None]
        if not instances:
            continue
        states = spread([i.n for i in instances if i.n], str)
        rows.append(f"| {panel_title(panel)} | {len(instances)} | {spread([i.node_count for i in instances], str)} | "
                    f"{states} | {spread([i.actuated for i in instances], str)} | "
                    f"{spread([i.plant_links for i in instances], str)} | {spread([i.comm_links for i in instances], str)} "
                    f"| {spread([i.radius for i in instances], lambda v: f'{v:.4g}')} |")
    if not rows:
        return []
    return ["| system | instances | nodes | states | actuated | plant links | given links | radius |",
            "|---|---:|---:|---:|---:|---:|---:|---:|", *rows, "",
            "Actuated: nodes with an input; plant and given links: directed off-diagonal links between nodes of the "
            "plant graph and of the given communication graph; radius: the open-loop spectral radius. Where "
            "instances differ, the median and the range [lowest, highest]. A node without an actuator keeps its "
            "states and its links.", ""]


def budget_tables(records: Records) -> list[str]:
    """The budget fronts at a few budgets per panel (:func:`panel_budgets`), with the instances where some design fits."""
    lines = []
    for panel, in_panel in sorted(records.by_panel.items()):
        budgets = panel_budgets(in_panel)
        grid = np.array([np.inf if b is None else b for b in budgets], dtype=float)
        rows = []
        for (_, label), best in best_tables(in_panel, grid).items():
            cost, reached, covered = front_quantiles(best)
            ran = int((~np.isnan(best).all(axis=1)).sum())
            text = [_fmt(m) if np.isfinite(m) else (f"{k} of {ran}" if k else "—") for m, k in zip(cost[1], reached)]
            rows.append(f"| {label} | {covered} of {ran} | " + " | ".join(text) + " |")
        heads = [f"≤ {b} links" if b is not None else "any" for b in budgets]
        lines += [f"### {panel_title(panel)}", "", "| method | instances with a design | " + " | ".join(heads) + " |",
                  "|---|---:|" + "---:|" * len(budgets), *rows,
                  "", "Median, over the instances the method ran on, of its best cost within the budget, an instance "
                  "without a design within it counting as worse than any (as the figure draws it); where half "
                  "of them or fewer have one, how many do (\"3 of 10\"). Budgets are 1, 3 and 7 links per node (20, 60 and 140 at the paper's N = 20). "
                  + DASH_NOTE, ""]
    return lines


def _paired_cell(r) -> str:
    """"+0.0127 [+0.0102, +0.0147]<br>10/10": the median difference and its interval (its coverage where too few
    instances allow 95 %), then the instances whose difference has the median's sign, of those compared; ○ where the
    interval holds 0."""
    from .findings_text import agreeing_count, estimate_text

    if not r.instances:
        return ""
    mark = " ○" if r.inconclusive and not r.too_few else ""
    estimate = estimate_text(r, coverage=True).replace(" [", "<br>[", 1)
    return f"{estimate}<br>{agreeing_count(_Wrap(r))}/{r.instances}{mark}"


class _Wrap:
    """A :class:`Paired` where the findings' helpers expect a cell (``.paired``)."""

    def __init__(self, paired):
        self.paired = paired


def _paired_table(comparisons: dict, title: str, info: Mapping) -> list[str]:
    """Per panel: one row per second method, one column per budget (fits 800 px where one row per budget did not)."""
    lines = []
    for panel, rows in comparisons.items():
        rows = [r for r in rows if r.instances]
        if not rows:
            continue
        budgets = list(dict.fromkeys(r.budget for r in rows))
        budgets = sorted(budgets, key=lambda b: np.inf if b is None else b)
        by_second: dict[str, dict] = {}
        for r in rows:
            by_second.setdefault(r.b, {})[r.budget] = r
        lines += [f"### {title}, {panel_title(panel)}", "",
                  "| second | " + " | ".join("any" if b is None else f"≤ {b:g} links" for b in budgets) + " |",
                  "|---|" + "---|" * len(budgets)]
        for second, cells in by_second.items():
            first = next(iter(cells.values())).a
            models = "" if info.get(first) == info.get(second) else f"<br>{info.get(second, '?')} information"
            lines.append(f"| {second}{models} | " + " | ".join(_paired_cell(cells[b]) if b in cells else ""
                                                              for b in budgets) + " |")
        lines.append("")
    return lines


def asked_pairs(records: Records, meta: StoreMeta) -> list[tuple[str, str]]:
    """The (first, second) label pairs the specs ask for (``pairs`` in a spec; a method name stands for each of
    its labels)."""
    by_method: dict[str, list[str]] = {}
    for r in records:
        if r.label not in by_method.setdefault(r.method, []):
            by_method[r.method].append(r.label)
    labels = records.by_label
    asked = []
    for _, pairs in sorted(meta.pairs.items()):
        for first, second in pairs:
            for pair in itertools.product(by_method.get(first, [first]), by_method.get(second, [second])):
                if pair[0] != pair[1] and all(x in labels for x in pair) and pair not in asked:
                    asked.append(pair)
    return asked


def paired_lines(records: Records, meta: StoreMeta) -> list[str]:
    """GRNN-Sparse against every other method, and the pairs the specs ask for, per budget."""
    info = {r.label: r.info_model for r in records}
    lines = []
    # The paper's GRNN-Sparse (tanh), not the linear ablation that shares its method name.
    reference = next((r.label for r in records if r.method == "grnn_sparse"
                      and r.params.get("activation", "tanh") == "tanh"), None)
    if reference:
        lines += _paired_table(paired_comparisons(records, reference), f"{reference} against every method", info)
    asked = [pair for pair in asked_pairs(records, meta) if pair[0] != reference]
    for first, second in asked:
        lines += _paired_table(paired_comparisons(records, first, others={second}), f"{first} against {second}", info)
    if not lines:
        return []
    return ["## Paired comparisons", "",
            "Every method runs on the same instances, so methods are compared instance by instance. Each cell: "
            "within the column's link budget, the median over instances of the first method's best cost minus the "
            "second's (negative: the first costs less) with a distribution-free 95 % interval (its coverage in "
            "parentheses where too few instances allow 95 %), and k/n: the instances, of n, whose difference has "
            "the median's sign; ○: the interval holds 0, so the instances do not say which is better. These are "
            "per-panel statistics without Holm's correction; the Findings are the claims.", ""] + lines


def precision_text(records: Records) -> str:
    """The relative standard errors of the simulated costs, as measured."""
    simulated = records.filter(lambda r: r.cost_kind == "simulated" and r.status in OK_STATUSES)
    rel = [r.cost_stderr / r.cost for r in simulated if r.ok and r.cost > 0]
    if not rel:
        return ""
    plain = [r.extras["plain_cost_stderr"] / r.extras["plain_cost"] for r in simulated
             if "plain_cost_stderr" in r.extras and r.extras["plain_cost"] > 0]
    cv = sum(str(r.extras.get("cost_estimator", "")).startswith(("control variates", "importance sampling"))
             for r in simulated)
    how = "control variates" if cv == len(rel) else f"control variates for {cv} of {len(rel)}, else the sample mean"
    refined = sum(r.extras.get("importance_draws", 0) > 0 for r in simulated)
    if refined:
        most = max(r.extras.get("importance_draws", 0) for r in simulated)
        how += f"; {refined} heavy-tailed cost{'s' if refined != 1 else ''} re-estimated on up to {most:,} importance-sampled draws of their own"
    text = (f" ({how}; relative standard error: median {np.median(rel):.3%}, largest {max(rel):.3%} over "
            f"{len(rel)} simulated design{'' if len(rel) == 1 else 's'}")
    if plain:
        text += (f"; the estimate without control variates, kept in the `extras` column of `runs.csv` as `plain_cost` and `plain_cost_stderr`, has a median of "
                 f"{np.median(plain):.2%}")
    return text + ")"


def uncertain_text(records: Records) -> str:
    """A warning naming the panels whose simulated costs stay imprecise after refinement (empty if none)."""
    uncertain = unresolved(records)
    if not len(uncertain):
        return ""
    where = "; ".join(f"{len(rs)} of {label} on {panel_title(panel)}"
                      for (panel, label), rs in sorted(uncertain.by_panel_label.items()))
    k = len(uncertain)
    return (f" {k} simulated cost{'' if k == 1 else 's'} keep{'s' if k == 1 else ''} a relative standard error above "
            f"{UNCERTAIN_RSE:.0%} even so "
            f"({where}). Such a cost is dominated by rare initial states from which the closed loop diverges "
            "within the horizon (the GRNN's and the GCNN's inputs pass through tanh and are bounded, so on an "
            "unstable plant their region of attraction is bounded too); draws that rare are hardly ever "
            "sampled, so the estimate tends to be low and its standard error understates the uncertainty. "
            "Treat these costs as unresolved, not as measured: they enter no finding (docs/evaluation.md, "
            "\"Costs dominated by rare divergent draws\"); the figures and tables still show them.")


def environment_lines(meta: StoreMeta) -> list[str]:
    """Where each experiment's runs were computed (recorded by the runner when it computed runs)."""
    rows = sorted(meta.environments.items())
    if not rows:
        return []
    lines = ["| experiment | computed | commit | CPU | workers (of cores) | python |", "|---|---|---|---|---|---|"]
    for name, env in rows:
        lines.append(f"| {name} | {env.get('date', '—')} | {env.get('commit') or '—'} | {env.get('cpu', '—')} | "
                     f"{env.get('workers', '—')} ({env.get('executor', 'process')}; {env.get('cores', '—')} cores) | "
                     f"{env.get('python', '—')} |")
    return lines + ["", "Package versions: see Software and Code fingerprints below. Exact costs are reproducible "
                    "to rounding on any machine with the same package versions; learned controllers can differ "
                    "in the last digits across CPUs and BLAS builds (float rounding in training), and wall times "
                    "always differ.", ""]


def pareto_tables(points: list[Point]) -> list[str]:
    """Each method's Pareto front (links, median cost), one table per panel; "—" where it has no usable design."""
    lines = []
    for panel in sorted({p.panel for p in points}):
        lines += [f"### {panel_title(panel)}", "", "| method | front: (links, median cost) |", "|---|---|"]
        for label in sorted({p.label for p in points if p.panel == panel}):
            front = pareto_front([p for p in points if p.panel == panel and p.label == label])
            lines.append(f"| {label} | " + (", ".join(f"({_fmt(p.x, links=True)}, {_fmt(p.cost[1])})" for p in front)
                                           or "—") + " |")
        lines.append("")
    return lines


def fingerprint_lines(records: Records, meta: StoreMeta) -> list[str]:
    """Which code produced the runs: one row per (method, fingerprint)."""
    runs = defaultdict(set)
    for r in records:
        runs[(r.method, r.fingerprint or "—")].add(r.run_key)
    lines = ["## Code fingerprints", "",
             "A run is reused from the store only while its fingerprint matches the code: the source of the "
             "method's module and the project modules it uses, the evaluation code, and the versions of numpy, "
             "scipy, cvxpy, clarabel and torch. `runs.csv` gives each run's fingerprint.", "",
             "| method | fingerprint | runs | numerical packages |", "|---|---|---:|---|"]
    for (method, fp), keys in sorted(runs.items()):
        stored = meta.fingerprints.get(fp)
        versions = stored.versions if stored is not None else {}
        text = ", ".join(f"{k} {v}" for k, v in sorted(versions.items())) or "—"
        lines.append(f"| {method} | `{fp}` | {len(keys)} | {text} |")
    return lines + [""]

