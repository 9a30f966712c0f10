"""Reports: the cost-versus-links figure, the Markdown summary, the CSV of every run.

Everything here is computed from the store's records alone, so ``compare report``
regenerates the same files that ``compare run`` wrote.
"""

from __future__ import annotations

import csv
import json
import platform
from collections import Counter, defaultdict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

__all__ = [
    "Point",
    "pareto_front",
    "budget_costs",
    "plant_links",
    "aggregate",
    "plot_cost_vs_links",
    "write_report",
    "software_versions",
    "quartiles",
    "INFO_STYLE",
]

from .figures import (LINESTYLES, OFF_SCALE, _grid, cost_axis, draw_boundary, finish_legend,  # noqa: E402
                      label_styles, legend_handles, plot_budget_fronts)
from .statistics import _quantiles, best_tables, budget_fronts, paired_comparisons, paired_difference  # noqa: E402
from .statistics import panel_title  # noqa: E402
from .records import OK_STATUSES, Records, as_records  # noqa: E402

#: Line style per information model, so that a zero-delay static gain and a
#: one-step-delay dynamic controller with the same link count never look alike.
INFO_STYLE = {info: {"linestyle": style, "description": text} for info, (style, text) in LINESTYLES.items()}

_PACKAGES = ("grnn-codesign", "numpy", "scipy", "cvxpy", "clarabel", "scs", "control", "torch", "numba", "networkx", "matplotlib")


def quartiles(values) -> tuple[float, float, float]:
    """(25th percentile, median, 75th percentile) of the finite values; NaNs if none."""
    finite = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    if finite.size == 0:
        return (float("nan"),) * 3
    q1, med, q3 = np.percentile(finite, [25, 50, 75])
    return float(q1), float(med), float(q3)


@dataclass(frozen=True)
class Point:
    """One design setting (label + hyperparameters) aggregated over instances.

    ``params`` are the setting's hyperparameters; ``params_key``, their canonical JSON, orders settings.
    """

    panel: tuple
    label: str
    info_model: str
    params: Mapping
    params_key: str
    designs: int
    ok: int
    links: tuple[float, float, float]
    self_loops: float
    cost: tuple[float, float, float]
    cost_mean: float
    statuses: dict


def aggregate(records) -> list[Point]:
    """Group records by (panel, label, info model, params) into quartile summaries.

    ``records``: :class:`~compare.records.Records`, or dicts shaped like the store's rows.
    """
    groups = as_records(records).group(lambda r: (r.instance.panel, r.label, r.info_model, r.params_key))
    points = []
    for (panel, label, info, params_key), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][3])):
        ok = [r for r in rs if r.ok]
        costs = [r.cost for r in ok]
        points.append(
            Point(
                panel=panel,
                label=label,
                info_model=info,
                params=rs[0].params,
                params_key=params_key,
                designs=len(rs),
                ok=len(ok),
                links=quartiles([r.links for r in ok]) if ok else quartiles([r.links for r in rs]),
                self_loops=quartiles([r.self_loops for r in rs])[1],
                cost=quartiles(costs),
                cost_mean=float(np.mean(costs)) if costs else float("nan"),
                statuses=dict(Counter(r.status for r in rs)),
            )
        )
    return points


def pareto_front(points: list[Point]) -> list[Point]:
    """The points no other point beats on both median links and median cost."""
    ok = sorted((p for p in points if p.ok > 0 and np.isfinite(p.cost[1])), key=lambda p: (p.links[1], p.cost[1]))
    front, best = [], float("inf")
    for p in ok:
        if p.cost[1] < best:
            front.append(p)
            best = p.cost[1]
    return front


def budget_costs(records, budgets=(20, 60, 140, None)) -> dict:
    """Per (panel, label): median over instances of the best cost within each link budget.

    For each instance, a method's best cost under budget b is the lowest cost among
    its designs with at most b links (None = any number); instances where no design
    fits count as missing. Returns ``{(panel, label): [(median, instances), ...]}``.
    """
    grid = [np.inf if b is None else b for b in budgets]
    return {key: [(quartiles(column)[1], int(np.isfinite(column).sum())) for column in best.T]
            for key, best in best_tables(records, grid).items() if np.isfinite(best).any()}


def plant_links(records) -> dict:
    """Median off-diagonal plant-graph links per panel: the QI boundary.

    Below this many links no communication graph relaying one hop per step is
    quadratically invariant, so no convex delay-constrained (SLS) design exists
    there. Link counts are the instance facts the store holds
    (:meth:`~compare.records.InstanceRecord.with_facts` for stores without them).
    """
    return {panel: float(np.median([inst.with_facts().plant_links for inst in rs.instances]))
            for panel, rs in as_records(records).by_panel.items()}


def _panel_top(points) -> float | None:
    """Upper y limit of a panel, or None to show everything (no design is off the scale)."""
    shown = [p for p in points if p.cost[1] <= OFF_SCALE]
    if not shown or len(shown) == len(points):
        return None
    return min(OFF_SCALE, max(p.cost[2] for p in shown)) * 1.03


def _dodge(series_by_label: dict, right: float) -> dict:
    """Label -> horizontal offset in points for single-setting methods that share an x position.

    LQR, decentralized and autonomous sit at 0 or N(N-1) links, exactly where path
    methods end: without an offset their markers hide each other.
    """
    at = defaultdict(list)
    for label, series in series_by_label.items():
        if len(series) == 1:
            at[round(series[0].links[1], 6)].append(label)
    crowded = {x for x in at if len(at[x]) > 1 or any(
        len(s) > 1 and any(round(p.links[1], 6) == x for p in s) for s in series_by_label.values())}
    offsets = {}
    for x in crowded:
        group = sorted(at[x])
        for i, label in enumerate(group):
            offsets[label] = 7.0 * (i - (len(group) - 1) / 2) + (6.0 if x == 0 else -6.0 if x >= right else 0.0)
    return offsets


def plot_cost_vs_links(points: list[Point], *, axes=None, colors: dict | None = None,
                       boundaries: dict | None = None):
    """Median cost against median links per design setting, one panel per instance family/size/a_norm.

    Error bars span the 25–75 % quantiles on both axes, and the two medians are
    taken separately (a point need not be any one instance's design). The x-axis is
    symmetric-log so that zero-link designs stay visible; each method has a colour
    and a marker, and the line style gives the information model.

    Parameters
    ----------
    points : list of Point
        From :func:`aggregate`.
    axes : sequence of matplotlib Axes, optional
        One per panel; a new figure is made if omitted.
    colors : dict, optional
        Label -> (colour, marker) as from :func:`compare.figures.label_styles`,
        or label -> colour.
    boundaries : dict, optional
        Panel -> link count of the plant graph, drawn as the QI boundary when a
        delayed method is present.

    Returns
    -------
    fig, axes
    """
    from matplotlib.transforms import offset_copy


    panels = sorted({p.panel for p in points})
    labels = list(dict.fromkeys(p.label for p in sorted(points, key=lambda p: p.label)))
    styles = label_styles(labels)
    for label, value in (colors or {}).items():
        styles[label] = value if isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], str) \
            else (value, styles.get(label, (None, "o"))[1])
    spare = None
    if axes is None:
        fig, axes, spare = _grid(len(panels))
    else:
        fig = axes[0].figure
    for ax, panel in zip(axes, panels):
        usable = [p for p in points if p.panel == panel and p.ok > 0]
        if not usable:
            continue
        top = _panel_top(usable)
        right = max(p.links[1] for p in usable)
        by_label = {label: sorted((p for p in usable if p.label == label), key=lambda p: (p.links[1], p.cost[1]))
                    for label in labels}
        offsets = _dodge({k: v for k, v in by_label.items() if v}, right)
        for label in labels:
            colour, marker = styles[label]
            for info in sorted({p.info_model for p in by_label[label]}):
                series = [p for p in by_label[label] if p.info_model == info]
                x = np.array([p.links[1] for p in series])
                y = np.array([p.cost[1] for p in series])
                xerr = np.array([[p.links[1] - p.links[0] for p in series], [p.links[2] - p.links[1] for p in series]])
                yerr = np.array([[p.cost[1] - p.cost[0] for p in series], [p.cost[2] - p.cost[1] for p in series]])
                transform = ax.transData
                if label in offsets:
                    transform = offset_copy(ax.transData, fig=fig, x=offsets[label], units="points")
                ax.errorbar(
                    x, y, xerr=xerr, yerr=yerr, color=colour, marker=marker,
                    linestyle=INFO_STYLE[info]["linestyle"] if len(series) > 1 else "none",
                    markersize=6, capsize=2, elinewidth=0.8, linewidth=1.2, transform=transform,
                    markeredgecolor="white" if len(series) == 1 else colour, markeredgewidth=0.6, zorder=3,
                )
        low = min(0.98, min(p.cost[0] for p in usable) * 0.99)
        if top is None:
            cost_axis(ax, low, max(p.cost[2] for p in usable) * 1.03)
        else:
            cost_axis(ax, low, top)
        ax.set_xscale("symlog", linthresh=1.0)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        # Explicit: autoscaling ignores the dodged markers (drawn with an offset transform),
        # which left methods sharing a link count outside the axes.
        ax.set_xlim(-0.4, max(p.links[2] for p in usable) * 1.15 + 1)
        label_rows = 0
        if top is not None:
            label_rows = _mark_off_scale(ax, [p for p in usable if p.cost[1] > top], top, styles)
        ax.set_xlabel("directed off-diagonal links (median, IQR bars)")
        ax.set_ylabel("normalized cost E[J] / tr(P) (median, IQR bars)")
        ax.set_title(panel_title(panel))
        ax.axhline(1.0, color="0.6", linewidth=0.8, zorder=0)
        if boundaries and panel in boundaries and any(p.info_model == "delayed" for p in usable):
            draw_boundary(ax, boundaries[panel], below=9.0 * label_rows)
        ax.grid(True, which="major", alpha=0.3)
    used = {p.info_model for p in points if p.ok > 0}
    finish_legend(fig, axes, spare, legend_handles(styles, labels, used))
    return fig, axes


def software_versions() -> dict[str, str]:
    from .fingerprint import package_versions

    return {"python": platform.python_version(), **package_versions(_PACKAGES)}


def _fmt(value: float, digits: int = 4) -> str:
    return "—" if not np.isfinite(value) else f"{value:.{digits}g}"


def _fmt_iqr(q: tuple, digits: int = 4) -> str:
    if not np.isfinite(q[1]):
        return "—"
    return f"{_fmt(q[1], digits)} [{_fmt(q[0], digits)}, {_fmt(q[2], digits)}]"


def _params_text(params: Mapping) -> str:
    def text(value):
        # Grid values such as 0.0021544346900318843 read better at 4 digits; the
        # store and the CSV keep them exact.
        return _fmt(value) if isinstance(value, float) and np.isfinite(value) else str(value)

    return ", ".join(f"{k}={text(v)}" for k, v in sorted(params.items())) or "—"


def _summary_tables(points: list[Point]) -> list[str]:
    lines = []
    for panel in sorted({p.panel for p in points}):
        pts = [p for p in points if p.panel == panel]
        lines += [
            f"### {panel_title(panel)}",
            "",
            "| method | information | params | designs | ok | links: median [IQR] | self-loops | cost: median [IQR] |",
            "|---|---|---|---:|---:|---|---:|---|",
        ]
        for p in sorted(pts, key=lambda p: (p.label, p.links[1] if np.isfinite(p.links[1]) else -1,
                                            p.cost[1] if np.isfinite(p.cost[1]) else np.inf, p.params_key)):
            lines.append(
                f"| {p.label} | {p.info_model} | {_params_text(p.params)} | {p.designs} | {p.ok} | "
                f"{_fmt_iqr(p.links, 3)} | {_fmt(p.self_loops, 3)} | {_fmt_iqr(p.cost)} |"
            )
        lines.append("")
    return lines


def _mark_off_scale(ax, points, top: float, styles: dict) -> int:
    """A triangle on the top edge and the median cost below it for each point above the axis.

    Labels closer than about 30 points to the previous one in a row go one row lower, so
    that values at neighbouring link counts stay readable; a label at either edge of the
    axes extends inwards. Returns the number of label rows.
    """
    labels: dict[tuple, list[str]] = {}  # (links, text) -> colours: methods sharing a value get one label
    for p in sorted(points, key=lambda p: p.links[1]):
        colour = styles[p.label][0]
        ax.plot(p.links[1], top, marker="^", color=colour, markersize=8, clip_on=False, linestyle="none", zorder=5)
        labels.setdefault((p.links[1], f"{p.cost[1]:.3g}"), []).append(colour)
    rows: list[float] = []  # the display x of the last label in each row
    left, right = (v * 72.0 / ax.figure.dpi for v in ax.transAxes.transform([(0, 0), (1, 0)])[:, 0])
    for (links, text), colours in labels.items():
        x = ax.transData.transform((links, top))[0] * 72.0 / ax.figure.dpi
        row = next((i for i, last in enumerate(rows) if x - last >= 30.0), len(rows))
        rows[row:row + 1] = [x]
        ha, dx = ("right", 5) if right - x < 20 else ("left", -5) if x - left < 20 else ("center", 0)
        ax.annotate(text, (links, top), xytext=(dx, -4 - 9 * row), textcoords="offset points", ha=ha,
                    va="top", fontsize=7, color=colours[0] if len(set(colours)) == 1 else "0.25", zorder=6,
                    # A light backing keeps a value legible where a curve runs under it.
                    bbox={"boxstyle": "square,pad=0.1", "facecolor": "white", "edgecolor": "none", "alpha": 0.85})
    return len(rows)


def _budget_tables(records: Records, budgets=(20, 60, 140, None)) -> list[str]:
    """The budget fronts at a few budgets, with the number of instances where some design fits."""
    grid = np.array([np.inf if b is None else b for b in budgets], dtype=float)
    table = {key: list(zip(_quantiles(best)[1], np.isfinite(best).sum(axis=0)))
             for key, best in best_tables(records, grid).items() if np.isfinite(best).any()}
    heads = [f"≤ {b} links" if b is not None else "any" for b in budgets]
    lines = []
    for panel in sorted({key[0] for key in table}):
        lines += [f"### {panel_title(panel)}", "", "Median over the instances a method ran on of the best cost within "
                  "the budget (∞ where fewer than half of them have a design within it), and in parentheses the "
                  "instances with one.", "", "| method | " + " | ".join(heads) + " |",
                  "|---|" + "---:|" * len(budgets)]
        for (pnl, label), cells in table.items():
            if pnl != panel:
                continue
            text = [(f"{_fmt(m)} ({k})" if np.isfinite(m) else f"∞ ({k})") if k else "—" for m, k in cells]
            lines.append(f"| {label} | " + " | ".join(text) + " |")
        lines.append("")
    return lines


def _paired_table(comparisons: dict, title: str) -> list[str]:
    lines = []
    for panel, rows in comparisons.items():
        rows = [r for r in rows if r.instances]
        if not rows:
            continue
        lines += [f"### {title}, {panel_title(panel)}", "",
                  "| first − second | budget | instances | first better | second better | median Δ | 95 % interval |"
                  " note |", "|---|---|---:|---:|---:|---:|---|---|"]
        for r in rows:
            budget = "any" if r.budget is None else f"≤ {r.budget:g}"
            note = "interval contains 0" if r.inconclusive else ""
            lines.append(f"| {r.a} − {r.b} | {budget} | {r.instances} | {r.a_wins} | {r.b_wins} | "
                         f"{r.median:+.4f} | {r.interval_text} | {note} |")
        lines.append("")
    return lines


def _paired_lines(records: Records, meta: dict) -> list[str]:
    """GRNN-Sparse against every other method, and the pairs the specs ask for, per budget."""
    labels = records.by_label
    by_method = {r.method: r.label for r in records}
    lines = []
    # The paper's GRNN-Sparse (tanh), not the linear ablation that shares its method name.
    reference = next((r.label for r in records if r.method == "grnn_sparse"
                      and r.params.get("activation", "tanh") == "tanh"), None)
    if reference:
        lines += _paired_table(paired_comparisons(records, reference), f"{reference} against every method")
    asked = []
    for key, pairs in sorted(meta.items()):
        if key.startswith("pairs:"):
            for first, second in pairs:
                pair = tuple(by_method.get(x, x) for x in (first, second))
                if all(x in labels for x in pair) and pair not in asked and pair[0] != reference:
                    asked.append(pair)
    for first, second in asked:
        lines += _paired_table(paired_comparisons(records, first, others={second}), f"{first} against {second}")
    if not lines:
        return []
    return ["## Paired comparisons", "",
            "Every method runs on the same instances, so methods are compared instance by instance: within each "
            "link budget, the difference of the two methods' best costs on every instance where both have a "
            "design that fits (negative: the first is better), how many instances each wins, the median "
            "difference, and a distribution-free 95 % interval for it (order statistics, binomial ranks; the "
            "achieved coverage is given where fewer instances allow no 95 % interval). Where the interval "
            "contains 0, the instances do not say which method is better.", ""] + lines


def _precision_text(records: Records) -> str:
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
        how += f"; {refined} heavy-tailed costs re-estimated on up to {most:,} importance-sampled draws of their own"
    text = (f" ({how}; relative standard error: median {np.median(rel):.3%}, largest {max(rel):.3%} over "
            f"{len(rel)} simulated designs")
    if plain:
        text += (f"; the estimate without control variates, kept in `runs.csv` as `plain_cost`, has a median of "
                 f"{np.median(plain):.2%}")
    return text + ")"


# Above this relative standard error a refined cost is not a number to compare at the
# third digit: in the shipped reports every such cost came from rare divergent draws.
UNCERTAIN_RSE = 0.01


def _uncertain_text(records: Records) -> str:
    """A warning naming the panels whose simulated costs stay imprecise after refinement (empty if none)."""
    uncertain = records.filter(lambda r: r.cost_kind == "simulated" and r.ok and r.cost > 0
                               and r.cost_stderr > UNCERTAIN_RSE * r.cost)
    if not len(uncertain):
        return ""
    where = "; ".join(f"{len(rs)} of {label} on {panel_title(panel)}"
                      for (panel, label), rs in sorted(uncertain.by_panel_label.items()))
    return (f" {len(uncertain)} simulated costs keep a relative standard error above {UNCERTAIN_RSE:.0%} even so "
            f"({where}). Such a cost is dominated by rare initial states from which the closed loop diverges "
            "within the horizon (the GRNN's and the GCNN's inputs pass through tanh and are bounded, so on an "
            "unstable plant their region of attraction is bounded too); draws that rare are hardly ever "
            "sampled, so the estimate tends to be low and its standard error understates the uncertainty. "
            "Treat these costs as unresolved, not as measured (docs/evaluation.md, "
            "\"Costs dominated by rare divergent draws\").")


def _sls_bounds(records: Records) -> dict:
    """Panel -> (median, instances) of SLS on the complete graph at one hop per step, act_delay 1.

    No controller with the delayed information model beats it on its instance
    (partially nested information: the optimum is linear, and SLS finds it).
    """
    per_panel = defaultdict(list)
    for r in records:
        p = r.params
        if (r.method in ("sls", "sls_topologies") and p.get("graph") == "complete" and p.get("act_delay") == 1
                and p.get("speed") == 1.0 and p.get("fir") is None and r.status in OK_STATUSES):
            per_panel[r.instance.panel].append(r.cost)
    return {panel: (float(np.median(v)), len(v)) for panel, v in per_panel.items()}


def _delayed_section(records, out: Path, files: dict, styles: dict, boundaries: dict) -> list[str]:
    """Budget fronts of the methods with the delayed information model, the SLS bound, and which wins."""
    records = as_records(records)
    delayed = records.filter(lambda r: r.info_model == "delayed")
    if len(delayed.by_label) < 2:
        return []
    bounds = _sls_bounds(records)
    fronts = budget_fronts(delayed)
    fig, _ = plot_budget_fronts(fronts, styles=styles, boundaries=boundaries,
                                bounds={k: (v, "SLS, complete graph (bound)") for k, (v, _) in bounds.items()})
    _save_figure(fig, out, "delayed_fronts", files)
    lines = ["## Delayed information only", "", "![delayed fronts](delayed_fronts.png)", "",
             "The budget fronts of the designs whose links carry information one step per hop, the GRNN's "
             "information model."
             + (" The dash-dotted line is the median over instances of SLS on the complete graph at one hop per "
                "step: with communication as fast as the plant the information is partially nested, so that SLS "
                "optimum is the best cost any controller, linear or not, reaches with this information on its "
                "instance (`tests/test_lower_bound.py` checks that none of the delayed designs beats it)."
                if bounds else " Add SLS on the complete graph (`method = \"sls\"`, `graph = \"complete\"`) to "
                "draw the bound no delayed controller can beat."), ""]
    sentences = []
    budgets = (20, 60, 140)
    tables = best_tables(delayed, budgets)
    for panel in sorted({f.panel for f in fronts}):
        mine = {f.label: f for f in fronts if f.panel == panel}
        parts = []
        for k, budget in enumerate(budgets):
            ranked = sorted((f.at(budget)[1], label) for label, f in mine.items() if np.isfinite(f.at(budget)[1]))
            if not ranked:
                parts.append(f"no delayed design reaches ≤ {budget} links on half the instances")
                continue
            best_cost, best = ranked[0]
            if len(ranked) == 1:
                parts.append(f"at ≤ {budget} links only {best} has designs ({_fmt(best_cost)})")
                continue
            runner_cost, runner = ranked[1]
            pair = paired_difference(best, runner, tables[(panel, best)][:, k], tables[(panel, runner)][:, k])
            if pair.inconclusive:
                verdict = "interval contains 0: not distinguishable"
            elif pair.too_few:
                # With 5 instances or fewer no interval reaches 95 %: report the wins, claim nothing more.
                verdict = (f"{best if pair.high < 0 else runner} better on every common instance; too few "
                           "instances for a 95 % interval")
            elif pair.high < 0:
                verdict = f"{best} significantly better"
            else:
                # Medians over instances can rank two methods against their paired difference
                # when they ran on different instances (e.g. table1's 50 seeds, tradeoff's 30).
                verdict = (f"{runner} significantly better on the {pair.instances} common instances; the "
                           "medians rank them otherwise because the two ran on different instances")
            parts.append(f"at ≤ {budget} links {best} ({_fmt(best_cost)}) against {runner} ({_fmt(runner_cost)}): "
                         f"median paired difference {pair.median:+.4f} {pair.interval_text}, "
                         f"better on {pair.a_wins} of {pair.instances} instances ({verdict})")
        bound = f" The SLS bound's median is {_fmt(bounds[panel][0])}." if panel in bounds else ""
        sentences.append(f"- {panel_title(panel)}: " + "; ".join(parts) + "." + bound)
    return lines + ["Best delayed design per budget (median best cost within the budget; paired over instances "
                    "against the next best):", ""] + sentences + [""]


def _environment_lines(meta: dict) -> list[str]:
    """Where each experiment's runs were computed (recorded by the runner when it computed runs)."""
    rows = [(k.split(":", 1)[1], v) for k, v in sorted(meta.items()) if k.startswith("environment:")]
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


def _pareto_tables(points: list[Point]) -> list[str]:
    lines = []
    for panel in sorted({p.panel for p in points}):
        lines += [f"### {panel_title(panel)}", "", "| method | front: (median links, median cost) |", "|---|---|"]
        for label in sorted({p.label for p in points if p.panel == panel}):
            front = pareto_front([p for p in points if p.panel == panel and p.label == label])
            lines.append(f"| {label} | " + ", ".join(f"({_fmt(p.links[1], 3)}, {_fmt(p.cost[1])})" for p in front) + " |")
        lines.append("")
    return lines


def _fingerprint_lines(records: Records, meta: dict) -> list[str]:
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
        versions = meta.get(f"fingerprint:{fp}", {}).get("versions", {})
        text = ", ".join(f"{k} {v}" for k, v in sorted(versions.items())) or "—"
        lines.append(f"| {method} | `{fp}` | {len(keys)} | {text} |")
    return lines + [""]


def _write_csv(records: Records, path: Path) -> None:
    instance_keys = sorted({k for inst in records.instances for k in inst.spec})
    columns = ["label", "method", "params", "status", "cost", "cost_stderr", "cost_kind", "links", "self_loops",
               "info_model", "seconds", "message", "extras", "run_key", "idx", "fingerprint"]
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow([f"instance_{k}" for k in instance_keys] + columns)
        for r in records:
            scalars = {k: v for k, v in r.extras.items() if isinstance(v, (int, float, str, bool))}
            row = [r.instance.spec.get(k, "") for k in instance_keys]
            for col in columns:
                value = getattr(r, col)
                if col == "params":
                    value = r.params_key
                elif col == "extras":
                    value = json.dumps(scalars, sort_keys=True)
                elif isinstance(value, float):
                    value = repr(value)
                row.append(value)
            writer.writerow(row)


def _save_figure(fig, out: Path, stem: str, files: dict) -> None:
    with plt.rc_context({"svg.hashsalt": "compare-report", "svg.fonttype": "path"}):
        files[f"{stem}.png"] = out / f"{stem}.png"
        files[f"{stem}.svg"] = out / f"{stem}.svg"
        fig.savefig(files[f"{stem}.png"], dpi=130, bbox_inches="tight", metadata={"Software": None})
        fig.savefig(files[f"{stem}.svg"], bbox_inches="tight", metadata={"Date": None, "Creator": None})
    plt.close(fig)


def _experiments_with(section: str, records: Records, meta: dict, members: dict) -> tuple[list[str], Records]:
    """The experiments that ask for ``section`` and the records of their runs."""
    names = sorted(k.split(":", 1)[1] for k, v in meta.items() if k.startswith("sections:") and section in v)
    keys = set().union(*(members.get(n, set()) for n in names)) if names else set()
    # A store written before experiments recorded their members: a run belongs to the one that computed it.
    unlisted = {n for n in names if not members.get(n)}
    return names, records.filter(lambda r: r.run_key in keys or r.experiment in unlisted)


def _producing(product: str, meta: dict) -> dict:
    """Method name -> its stored declaration, for methods that declare ``product``."""
    return {k.split(":", 1)[1]: v for k, v in meta.items() if k.startswith("method:") and product in v.get("produces", [])}


def _learning_sections(records: Records, out: Path, files: dict, load_controller, meta: dict,
                       members: dict) -> list[str]:
    """Sections the data asks for: Table 1 and training curves of the experiments that declare them,
    and the designed-topology path of a method that declares one."""
    from .learning_report import table1_markdown, training_curves_figure
    from .runner import build_instance
    from .topologies import plot_topology_path, topology_path_records

    lines = []
    names, table1 = _experiments_with("table1", records, meta, members)
    if table1:
        lines += ["## Table 1 (paper §IV-A)", "", f"From experiment {', '.join(names)}.", "", table1_markdown(table1), ""]
    names, curved = _experiments_with("training_curves", records, meta, members)
    producing = _producing("training_curve", meta)
    curved = curved.filter(lambda r: r.method in producing and "curve" in r.extras)
    if curved:
        fig, _ = training_curves_figure(curved)
        _save_figure(fig, out, "training_curves", files)
        lines += ["### Training curves (paper Fig. 2)", "", f"From experiment {', '.join(names)}: median and "
                  "25–75 % band over instances of the selection-set cost during training.", "",
                  "![training curves](training_curves.png)", ""]
    path = []
    for name, declared in sorted(_producing("topology_path", meta).items()):
        path = path or topology_path_records(records, method=name, weight=declared["path_param"])
    if len(path) >= 2 and load_controller is not None:
        instance = path[0].instance
        spec = {k: v for k, v in instance.spec.items() if k != "family"}
        weight = next(v["path_param"] for k, v in _producing("topology_path", meta).items() if k == path[0].method)
        entries = []
        for r in path:
            controller = load_controller(r.run_key, r.idx)
            support = getattr(controller, "support", None)
            if support is not None:
                entries.append((r.params[weight], r.links, r.cost, support))
        if len(entries) >= 2:
            # The figure draws the instance's matrices, which the store does not keep.
            fig, _ = plot_topology_path(build_instance(dict(instance.spec)), entries)
            _save_figure(fig, out, "topologies", files)
            inst = ", ".join(f"{k} = {v}" for k, v in spec.items())
            symbol = "β" if weight == "beta" else weight
            lines += [f"## Designed topologies along the {symbol} path (paper Fig. 4)", "",
                      f"{path[0].label} on one instance ({inst}); nodes coloured by the magnitude of the leading "
                      f"eigenvector of A. Under each graph: the weight {symbol}, the directed off-diagonal links "
                      "|E| and the normalized cost J.", "", "![designed topologies](topologies.png)", ""]
    return lines


def write_report(records, out, *, specs: dict | None = None, title: str = "Comparison report",
                 commands: list[str] | None = None, load_controller=None, meta: dict | None = None,
                 members: dict | None = None, superseded: int = 0) -> dict[str, Path]:
    """Write ``cost_vs_links.png/.svg``, ``runs.csv`` and ``report.md`` into ``out``.

    Parameters
    ----------
    records : Records or list of dict
        :meth:`compare.store.Store.records` (dicts shaped like the store's rows are
        converted; their instances' facts are then rebuilt, see
        :meth:`compare.records.InstanceRecord.with_facts`).
    out : str or Path
        Output folder (created).
    specs : dict, optional
        Experiment name -> spec TOML text, shown verbatim.
    title : str
    commands : list of str, optional
        Commands that regenerate the report, shown at the top: the ``compare run``
        commands in order, then the one that rebuilds it from the store alone.
    load_controller : callable, optional
        ``(run_key, idx) -> controller`` (e.g. :meth:`Store.controller`), for the
        designed-topology figure.
    meta : dict, optional
        :meth:`Store.meta`: the sections each experiment asks for, what each method
        declares it produces and code fingerprints. Sections come from these
        declarations only.
    members : dict, optional
        :meth:`Store.members`: experiment name -> its run keys.
    superseded : int
        Stored runs of code that has changed since (not in ``records``), said in the report.

    Returns
    -------
    dict
        Name -> path of every file written.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = Records(sorted(as_records(records), key=lambda r: (r.instance.key, r.label, r.run_key, r.idx)))
    meta, members = dict(meta or {}), dict(members or {})
    points = aggregate(records)
    boundaries = plant_links(records)
    files = {}

    styles = label_styles(sorted(records.by_label))
    fronts = budget_fronts(records)
    if fronts:
        fig, _ = plot_budget_fronts(fronts, styles=styles, boundaries=boundaries)
        _save_figure(fig, out, "budget_fronts", files)
    fig, _ = plot_cost_vs_links(points, colors=styles, boundaries=boundaries)
    _save_figure(fig, out, "cost_vs_links", files)
    files["csv"] = out / "runs.csv"
    _write_csv(records, files["csv"])

    runs = {r.run_key for r in records}
    statuses = Counter(r.status for r in records)
    lines = [f"# {title}", ""]
    if commands:
        *run_commands, rebuild = commands
        how = "Regenerate with " + " then ".join(f"`{c}`" for c in run_commands) if run_commands else ""
        how += (" (runs already in the store are skipped), or from the stored results alone with "
                if run_commands else "Regenerate from the stored results with ") + f"`{rebuild}`."
        lines += [how, ""]
    lines += _environment_lines(meta)
    lines += [
        f"{len(runs)} runs on {len(records.instances)} instances, {len(records)} designs. "
        "Costs are E[J] / trace(P) over the horizon (centralized LQR = 1); links are directed off-diagonal "
        "communication links (self-loops are local feedback and listed separately). "
        "Exact closed-form costs for linear controllers; for learned ones an estimate on the validation set, "
        "shared by every method on an instance" + _precision_text(records) + "." + _uncertain_text(records)
        + (f" The store also holds {superseded} runs made by code that has changed since; they are not "
           "shown (see Code fingerprints)." if superseded else ""),
        "",
    ]
    if fronts:
        lines += [
            "## Best cost within a link budget",
            "",
            "![budget fronts](budget_fronts.png)",
            "",
            "For a budget of L links, each method's best cost on an instance is the lowest cost among its "
            "designs there with at most L directed off-diagonal links. The curve is the median of that over "
            "the instances the method ran on and the band its 25–75 % range, as a step function of L: read it "
            "off at any budget. A marker shows where a curve starts (the smallest budget at which at least half "
            "of those instances have a design); line styles give the information model.",
            "",
        ]
        lines += _budget_tables(records)
    lines += _paired_lines(records, meta)
    lines += _delayed_section(records, out, files, styles, boundaries)
    lines += [
        "## Cost against links per setting (paper Fig. 3 style)",
        "",
        "![cost versus links](cost_vs_links.png)",
        "",
        "One point per method setting (e.g. one γ or β): the median links over instances against the median "
        "cost over instances, with 25–75 % bars on both axes. The two medians are taken separately, so a "
        "point need not be any one instance's design; the budget fronts above are per instance. Each method "
        "has a colour and a marker; line styles give the information model ("
        + "; ".join(f"{v['linestyle']} {v['description']}" for v in INFO_STYLE.values())
        + f"). Where some design's median cost is above {OFF_SCALE:g} (twice centralized LQR), that design "
        "is a triangle on the panel's top edge with its median printed under it. Single-setting methods that "
        "share a link count with another method are shifted sideways by a few points so that neither hides.",
        "",
        "## Medians by method",
        "",
    ]
    lines += _summary_tables(points)
    lines += ["## Pareto fronts", "", "Settings no other setting of the same method beats on both median "
              "links and median cost.", ""]
    lines += _pareto_tables(points)
    if boundaries:
        lines += ["The dotted vertical line in the figure is the median number of off-diagonal plant-graph "
                  "links: below it no communication graph relaying one hop per step is quadratically "
                  "invariant on this family, so no convex delay-constrained design with the GRNN's "
                  "information model exists there (docs/information-models.md).", ""]
    lines += _learning_sections(records, out, files, load_controller, meta, members)
    names, timed = _experiments_with("compute", records, meta, members)
    if timed:
        from .compute_report import compute_section

        lines += compute_section(timed, out, files, styles, _save_figure)
    lines += _fingerprint_lines(records, meta)
    lines += ["## Runs by status", "", "| status | designs |", "|---|---:|"]
    lines += [f"| {status} | {count} |" for status, count in sorted(statuses.items())]
    failures = records.filter(lambda r: r.status != "optimal")
    if failures:
        lines += ["", "Non-optimal designs (first 20):", "", "| instance | method | status | message |", "|---|---|---|---|"]
        for r in failures[:20]:
            inst = ", ".join(f"{k}={v}" for k, v in r.instance.spec.items() if k != "family")
            lines.append(f"| {inst} | {r.label} | {r.status} | {r.message[:160]} |")
    lines += ["", "## Files", ""]
    lines += [f"- `{p.name}`" for key, p in sorted(files.items()) if key.endswith(".png") or key.endswith(".svg")]
    lines += ["- `runs.csv`: every design of every run", "- `report.html`: this page, self-contained", ""]
    lines += ["## Software", "", "| package | version |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in software_versions().items()]
    for name, text in sorted((specs or {}).items()):
        lines += ["", f"## Spec `{name}`", "", "```toml", text.strip(), "```"]
    files["md"] = out / "report.md"
    files["md"].write_text("\n".join(lines) + "\n")
    files["html"] = out / "report.html"
    files["html"].write_text(render_html(files["md"].read_text(), out, title))
    return files


_CSS = """
body { font-family: system-ui, sans-serif; max-width: 1200px; margin: 2em auto; padding: 0 1em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f3f3f3; }
img { max-width: 100%; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; }
code { font-size: 0.92em; }
"""


def render_html(markdown_text: str, folder: Path, title: str) -> str:
    """One self-contained HTML page from the Markdown report (figures inlined as base64)."""
    import base64
    import re

    import markdown

    body = markdown.markdown(markdown_text, extensions=["tables", "fenced_code"])

    def inline(match):
        path = folder / match.group(1)
        if not path.is_file() or path.suffix.lower() != ".png":
            return match.group(0)
        data = base64.b64encode(path.read_bytes()).decode()
        return f'src="data:image/png;base64,{data}"'

    body = re.sub(r'src="([^":]+)"', inline, body)
    return (f"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{title}</title>\n"
            f"<style>{_CSS}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")
