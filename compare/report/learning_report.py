"""Paper Table 1 and the training-curve figure (paper Fig. 2) from stored records.

``records`` are :class:`compare.run.records.Records` (or dicts shaped like the store's
rows); learned controllers keep ``extras["curve"] = {"step": [...], "cost": [...]}``.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np
import scipy.stats

from ..run.records import OK_STATUSES, as_records

__all__ = ["table1_markdown", "training_curves_figure", "bootstrap_interval", "PAPER_TABLE1", "PAPER_SPARSE_EDGES",
           "PAPER_STATISTIC", "GAP_NOTES", "GAP_REASONS", "SPARSE_EDGES_NOTE", "DASH", "PaperValue", "paper_values",
           "gap_z"]

#: Paper Table 1 (docs/reproduction.md): median normalized cost over 50 instances; autonomous is a mean.
PAPER_TABLE1 = {
    "autonomous": {0.995: 2.534, 1.05: 69.294},
    "grnn": {0.995: 1.112, 1.05: 1.153},
    "grnn_dense": {0.995: 1.091, 1.05: 1.110},
    "grnn_sparse": {0.995: 1.093, 1.05: 1.124},
    "grnn_fixed": {0.995: 1.267, 1.05: 2.210},
    "gcnn": {0.995: 1.212, 1.05: 1.715},
}
#: GRNN-Sparse's mean edge count in the paper, self-loops included (its convention).
PAPER_SPARSE_EDGES = {0.995: 53.4, 1.05: 56.1}

#: What a comparison with the paper's published code (unstable-zeros/grnn-comms-codesign,
#: experiments/lossdecrease.py and the modules it calls) found about a Table 1 gap that
#: instance sampling alone does not explain.
GAP_NOTES: dict[str, str] = {
    "grnn_fixed": (
        "The paper's code freezes S at the same normalized adjacency and trains F, W, G with the "
        "same initialization, learning rate, schedule, penalty, clipping and single model; "
        "no difference in model, training or scoring explains this gap."
    ),
    "grnn_dense": (
        "The paper's code trains the dense S from the same row-stochastic start with the same "
        "penalty, schedule and single model; no difference in model, training or scoring "
        "explains this gap, and training in float64 as the paper did gives the same costs as "
        "our float32 to 1e-6 (16 instances)."
    ),
    "gcnn": (
        "We train with weight decay 2, as the paper's code does; the paper's text says its table "
        "shows GCNNs trained without weight decay, which it found to do better."
    ),
}

#: What is known about GRNN-Sparse's edge count differing from the paper's 53.4 / 56.1.
SPARSE_EDGES_NOTE = (
    "The paper's code counts edges the same way (nonzeros of S after zeroing |S_ij| < 4e-3, "
    "diagonal included) after the same l1 stage (2-model ensemble, penalty J + β Σ|S_ij| + "
    "2(‖S‖ + ‖F‖), learning rate 0.03, cosine schedule, clipping at 10); training in float64 as "
    "the paper did gives the same mean count as our float32 to 0.1 edge (16 instances); its "
    "published script sets β = 2 for both norms, which would lower the count at 0.995, not raise "
    "it. No known cause."
)

#: |gap| in standard deviations of a difference of two 50-instance statistics beyond which
#: instance sampling is not taken as the explanation.
_NOISE_Z = 2.0


#: What is known about a Table 1 gap beyond sampling noise, in a few words (the answer at the top of a report
#: gives it; :data:`GAP_NOTES` has the full text), to follow "GCNN's gap is": a documented paper-code
#: difference, or what was ruled out. Methods not listed have no known cause.
GAP_REASONS: dict[str, str] = {
    "gcnn": ("a documented paper-code difference (the paper's table shows GCNNs trained without weight decay; "
             "its code, like ours, uses 2)"),
    "grnn_fixed": "unexplained (the paper's code trains the same model the same way)",
    "grnn_dense": "unexplained (the paper's code trains the same model the same way)",
}


def gap_z(stat: float, paper: float, low: float, high: float) -> float:
    """Our statistic minus the paper's, in standard errors of that difference (from our 95 % interval).

    The paper's statistic is computed on its own random instances (its code seeds
    nothing) and carries the same sampling noise as ours: the difference has sqrt(2)
    times the spread of one statistic, estimated from our bootstrap interval.
    """
    spread = (high - low) / (2 * scipy.stats.norm.ppf(0.975))  # the interval is a 95 % one
    return (stat - paper) / (np.sqrt(2) * spread) if spread > 0 else np.inf


def _gap_note(method, stat, paper, low, high) -> str:
    """Why a paper value lies outside our interval: instance noise, or what else is known."""
    z = gap_z(stat, paper, low, high)
    if abs(z) < _NOISE_Z:
        return (f"Within instance-sampling noise: {z:+.1f} standard deviations of the difference "
                "between two statistics over independent instance draws (the paper's instances cannot be "
                "redrawn: its code seeds nothing).")
    return f"Beyond instance-sampling noise ({z:+.1f} s.d.). " + GAP_NOTES.get(method, "No known cause.")

_ROW_ORDER = ["lqr", "autonomous", "grnn", "grnn_dense", "grnn_sparse", "grnn_fixed", "gcnn"]

#: The statistic over instances of each paper value (Table 1 gives medians; Autonomous a mean).
PAPER_STATISTIC = {"autonomous": "mean"}
#: A mean is shown beside a median where the two differ by more than this fraction of the median.
_MATERIAL = 0.02
#: What "—" stands for in the tables of this module.
DASH = "—"
_STATISTICS = {"median": np.median, "mean": np.mean}


def _a_norm(record) -> float:
    a_norm = record.instance.a_norm
    return float("nan") if a_norm is None else float(a_norm)


def _fmt(value, digits=3) -> str:
    return DASH if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def _signed(value: float, digits: int, unit: str = "") -> str:
    """``value`` with its sign (a minus sign, as the rest of the page writes it), ``digits`` decimals and
    ``unit``; a value that rounds to zero has no sign."""
    text = f"{value:+.{digits}f}"
    if float(text) == 0:
        text = f"{0:.{digits}f}"
    return text.replace("-", "−") + unit


def _links_text(value: float) -> str:
    """A link count in plain decimal notation: whole numbers without decimals, others to one decimal."""
    if not np.isfinite(value):
        return DASH
    return f"{value:.0f}" if float(value).is_integer() else f"{value:.1f}"


def _material(mean: float, median: float) -> bool:
    return bool(np.isfinite(mean) and np.isfinite(median) and abs(mean - median) > _MATERIAL * abs(median))


#: Bootstrap resamples for the confidence interval of a Table 1 statistic.
_BOOTSTRAP = 4000


def bootstrap_interval(values, statistic=np.median, *, level: float = 0.95, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic`` over instances (seeded, so reports are reproducible).

    Another draw of 50 instances moves a median by this much: a gap to the paper
    inside the interval is what a different set of random instances alone can make.
    """
    values = np.asarray(values, dtype=float)
    if values.size < 2:
        return float("nan"), float("nan")
    result = scipy.stats.bootstrap((values,), statistic, n_resamples=_BOOTSTRAP, vectorized=True,
                                   confidence_level=level, method="percentile", rng=np.random.default_rng(seed))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


@dataclass(frozen=True)
class _Cost:
    """One method at one ‖A‖₂: our median and mean cost, and the statistic compared with the paper's value."""

    median: float
    low: float
    high: float
    mean: float
    paper: float | None
    statistic: str  # the paper's statistic, which ours is compared in
    ours: float  # our value of that statistic
    ours_low: float
    ours_high: float

    @classmethod
    def of(cls, costs: np.ndarray, paper: float | None, statistic: str) -> _Cost:
        median = float(np.median(costs)) if costs.size else float("nan")
        mean = float(np.mean(costs)) if costs.size else float("nan")
        low, high = bootstrap_interval(costs, np.median)
        if statistic == "median":
            return cls(median, low, high, mean, paper, statistic, median, low, high)
        ours_low, ours_high = bootstrap_interval(costs, _STATISTICS[statistic])
        return cls(median, low, high, mean, paper, statistic, mean, ours_low, ours_high)

    @property
    def outside(self) -> bool:
        """Whether the paper's value lies outside our interval of the same statistic."""
        return bool(self.paper and np.isfinite(self.ours_low) and not self.ours_low <= self.paper <= self.ours_high)

    def cells(self) -> list[str]:
        """Median, its interval, the mean (where it differs materially or is what the paper reported), paper, Δ."""
        interval = f"[{_fmt(self.low)}, {_fmt(self.high)}]" if np.isfinite(self.low) else DASH
        show_mean = _material(self.mean, self.median) or (self.paper and self.statistic == "mean")
        mean = _fmt(self.mean) if show_mean else DASH
        marked = f" ({self.statistic})" if self.statistic != "median" else ""
        paper = _fmt(self.paper) + marked if self.paper else DASH
        gap = DASH
        if self.paper and np.isfinite(self.ours):
            gap = _signed(100 * (self.ours / self.paper - 1), 1, " %") + marked
        return [_fmt(self.median), interval, mean, paper, gap]


def _link_cell(good, *, paper_edges: float | None = None) -> tuple[str, tuple | None]:
    """Median directed off-diagonal links (with self-loops), the means beside them where they differ materially.

    With ``paper_edges`` (the paper's mean edge count, self-loops included) the mean is
    always shown, with its 95 % bootstrap interval; returns the cell and, where the paper's
    count lies outside that interval, (mean, low, high).
    """
    links = np.array([np.nan if r.links is None else r.links for r in good], dtype=float)
    loops = np.array([np.nan if r.self_loops is None else r.self_loops for r in good], dtype=float)
    if not links.size:
        return DASH, None
    edges = links + loops
    cell = f"{_links_text(np.median(links))} ({_links_text(np.median(edges))})"
    if paper_edges is None:
        if _material(links.mean(), np.median(links)) or _material(edges.mean(), np.median(edges)):
            cell += f"; mean {links.mean():.1f} ({edges.mean():.1f})"
        return cell, None
    low, high = bootstrap_interval(edges, np.mean)
    cell += (f"; mean {links.mean():.1f} ({edges.mean():.1f}) [{_fmt(low, 1)}, {_fmt(high, 1)}]; "
             f"paper mean ({paper_edges:.1f})")
    outside = np.isfinite(low) and not low <= paper_edges <= high
    return cell, (float(edges.mean()), low, high) if outside else None


def _caption() -> str:
    return (
        "\nCosts: E[J]/trace(P), exact for linear controllers and a control-variate estimate on the validation "
        "set for learned ones. The main number is the median over instances, with a 95 % bootstrap interval "
        "of that median; the mean is given beside it where it differs from the median by more than "
        f"{100 * _MATERIAL:g} % (a few instances far above the rest pull a mean up), and always where the "
        "paper's value is a mean. The paper reported medians over its 50 instances, except for Autonomous "
        "(a mean, marked \"(mean)\"); Δ compares the paper's value with ours in the same statistic. "
        "Links: median directed off-diagonal links over instances, in parentheses with self-loops (the "
        "convention of the paper's edge counts), and the means beside them where they differ by more than "
        f"{100 * _MATERIAL:g} %; for GRNN-Sparse the paper gave the mean edge count, self-loops included "
        "(53.4 / 56.1), shown with a 95 % bootstrap interval of our mean. "
        f"{DASH}: no value (the mean is within {100 * _MATERIAL:g} % of the median, the paper has no value, or "
        "no design succeeded).\n"
    )


@dataclass(frozen=True)
class PaperValue:
    """One paper Table 1 value against ours: what :func:`paper_values` gives for each (method, ‖A‖₂)."""

    method: str
    label: str
    a_norm: float
    statistic: str
    ours: float
    low: float
    high: float
    paper: float
    outside: bool

    @property
    def z(self) -> float:
        """Ours minus the paper's, in standard errors of the difference (:func:`gap_z`)."""
        return gap_z(self.ours, self.paper, self.low, self.high)

    @property
    def within_noise(self) -> bool:
        """Within instance-sampling noise: under :data:`_NOISE_Z` standard errors of the difference."""
        return abs(self.z) < _NOISE_Z


def _table1_groups(records):
    records = as_records(records)
    groups = records.group(lambda r: (r.method, r.label or r.method))
    a_norms = sorted({_a_norm(r) for r in records if np.isfinite(_a_norm(r))})

    def order(key):
        method, label = key
        return (_ROW_ORDER.index(method) if method in _ROW_ORDER else len(_ROW_ORDER), label)

    return records, groups, a_norms, sorted(groups, key=order)


def _cost_at(rows, method: str, a: float, linear: bool) -> _Cost:
    good = [r for r in rows if _a_norm(r) == a and r.ok]
    paper = None if linear else PAPER_TABLE1.get(method, {}).get(a)
    return _Cost.of(np.array([r.cost for r in good], dtype=float), paper, PAPER_STATISTIC.get(method, "median"))


def paper_values(records) -> list[PaperValue]:
    """Every paper Table 1 value the records can be compared with, against our statistic and its 95 % interval.

    In Table 1's row order, ‖A‖₂ ascending within a row; the linear ablations (no paper
    value) are left out. ``outside``: the paper's value lies outside our interval.
    """
    records, groups, a_norms, keys = _table1_groups(records)
    out = []
    for method, label in keys:
        rows = groups[(method, label)]
        linear = any(r.params.get("activation") == "identity" for r in rows)
        for a in a_norms:
            cost = _cost_at(rows, method, a, linear)
            if cost.paper and np.isfinite(cost.ours):
                out.append(PaperValue(method, label, a, cost.statistic, cost.ours, cost.ours_low, cost.ours_high,
                                      cost.paper, cost.outside))
    return out


def table1_markdown(records) -> str:
    """Markdown Table 1: our medians (and means where they differ) per (method, ‖A‖₂) beside the paper's value.

    Costs are medians over instances, with a 95 % bootstrap interval; the mean
    is shown beside the median where the two differ materially, and wherever
    the paper's value is a mean (Autonomous, :data:`PAPER_STATISTIC`); the
    relative difference Δ compares the paper's value with ours in the paper's
    statistic. Failed designs are left out of the statistics and counted in the
    ``ok`` column. Links are medians over instances: directed off-diagonal
    links, and in parentheses with self-loops (the paper's edge convention).
    Below the table, every paper value outside our interval is listed with what
    is known to cause the gap (:data:`GAP_NOTES`).
    """
    records, groups, a_norms, keys = _table1_groups(records)
    if not groups or not a_norms:
        return "_No records for Table 1._\n"

    header = ["Method", "median", "95 % CI", "mean", "paper", "Δ", "ok", "links (w/ self-loops)"]
    # One table per ‖A‖₂: side by side, seven columns per norm ran off the page at 800 px (issue 61).
    tables = {a: [f"**‖A‖₂ = {a:g}**", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
              for a in a_norms}
    notes = []
    outside = []
    edge_gaps = []
    for method, label in keys:
        rows = groups[(method, label)]
        linear = any(r.params.get("activation") == "identity" for r in rows)
        for a in a_norms:
            here = [r for r in rows if _a_norm(r) == a]
            good = [r for r in here if r.ok]
            cost = _cost_at(rows, method, a, linear)
            if cost.outside:
                outside.append((method, label, a, cost))
            edges = PAPER_SPARSE_EDGES.get(a) if method == "grnn_sparse" and not linear else None
            link_cell, edge_gap = _link_cell(good, paper_edges=edges)
            if edge_gap:
                edge_gaps.append((label, a, *edge_gap, edges))
            tables[a].append("| " + " | ".join([label] + cost.cells() + [f"{len(good)}/{len(here)}", link_cell]) + " |")
        if any(r.status not in OK_STATUSES for r in rows):
            statuses = defaultdict(int)
            for r in rows:
                statuses[r.status] += 1
            notes.append(f"{label}: " + ", ".join(f"{v} {k}" for k, v in sorted(statuses.items())))
    lines = [line for a in a_norms for line in tables[a] + [""]][:-1]
    text = "\n".join(lines) + "\n" + _caption()
    text += _variant_pairs(records, a_norms)
    if outside:
        text += "\nPaper values outside our 95 % interval of the same statistic, and why:\n\n"
        for method, label, a, c in outside:
            side = "below" if c.ours < c.paper else "above"
            other = (f" (our mean: {c.mean:.3f})" if c.statistic == "median" and _material(c.mean, c.median)
                     else "")
            text += (f"- {label}, ‖A‖₂ = {a:g}: our {c.statistic} {c.ours:.3f} [{c.ours_low:.3f}, "
                     f"{c.ours_high:.3f}]{other} is {side} the paper's {c.paper:.3f}. "
                     f"{_gap_note(method, c.ours, c.paper, c.ours_low, c.ours_high)}\n")
    if edge_gaps:
        text += "\nEdge counts outside our 95 % interval:\n\n"
        for label, a, mean, low, high, edges in edge_gaps:
            text += (f"- {label}, ‖A‖₂ = {a:g}: a mean of {mean:.1f} edges with self-loops "
                     f"[{low:.1f}, {high:.1f}] "
                     f"against the paper's {edges:.1f}.\n")
        text += f"\n{SPARSE_EDGES_NOTE}\n"
    if notes:
        text += "\nNon-optimal designs (left out of the statistics): " + "; ".join(notes) + "\n"
    return text


def _variant_pairs(records, a_norms) -> str:
    """Paired differences between the GRNN variants, instance by instance."""
    from .statistics import paired_difference

    variants = [m for m in _ROW_ORDER if m.startswith("grnn") and any(r.method == m for r in records)]
    if len(variants) < 2:
        return ""
    label = {r.method: r.label or r.method for r in records}
    lines = ["", "Paired differences between the GRNN variants (first minus second, per instance; negative: the "
             "first is better): instances where each is better, median difference and a distribution-free 95 % "
             "interval for it (with its achieved coverage where too few instances allow 95 %); the note says "
             "where that interval contains 0.", "",
             "| pair | ‖A‖₂ | instances | first better | second better | median Δ | 95 % interval | note |",
             "|---|---|---:|---:|---:|---:|---|---|"]
    for a in a_norms:
        costs = {m: {r.instance.key: r.cost for r in records if r.method == m and _a_norm(r) == a and r.ok}
                 for m in variants}
        keys = sorted(set().union(*(c.keys() for c in costs.values())))
        for i, first in enumerate(variants):
            for second in variants[i + 1:]:
                x = [costs[first].get(k, np.inf) for k in keys]
                y = [costs[second].get(k, np.inf) for k in keys]
                p = paired_difference(label[first], label[second], x, y)
                if not p.instances:
                    continue
                note = "interval contains 0" if p.inconclusive else ""
                interval = f"[{_signed(p.low, 4)}, {_signed(p.high, 4)}]" + (
                    f" ({p.coverage:.0%})" if p.too_few else "")
                lines.append(f"| {p.a} − {p.b} | {a:g} | {p.instances} | {p.a_wins} | {p.b_wins} | "
                             f"{_signed(p.median, 4)} | {interval} | {note} |")
    return "\n".join(lines) + "\n"


def _curves(records) -> dict[float, dict[str, list]]:
    """‖A‖₂ -> label -> the training curves of that label's usable designs."""
    curves: dict[float, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for record in as_records(records):
        curve = record.extras.get("curve")
        if curve and record.ok:
            curves[_a_norm(record)][record.label or record.method].append(curve)
    return curves


def _curve_axes(ax, panels: int):
    import matplotlib.pyplot as plt

    if ax is None:
        # Two panels to a row at most, 4.3 in each: two of 6 in (1,284 px) showed the legend's 8-point type 8.6 px
        # tall on an 800 px page.
        cols = min(2, max(1, panels))
        rows = -(-max(1, panels) // cols)
        fig, grid = plt.subplots(rows, cols, figsize=(4.3 * cols, 3.6 * rows), squeeze=False)
        flat = list(grid.ravel())
        for extra in flat[max(1, panels):]:
            extra.set_axis_off()
        return fig, flat[:max(1, panels)]
    axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
    if len(axes) not in (1, panels) and panels:
        raise ValueError(f"need one axis per ‖A‖₂ ({panels}) or a single axis, got {len(axes)}")
    return axes[0].figure, axes


def _markevery(points: int, k: int, curves: int) -> tuple[int, int]:
    """About eight markers per curve, the k-th of ``curves`` curves shifted so that their markers do not stack."""
    every = max(1, points // 8)
    return (k * every // max(curves, 1), every)


def training_curves_figure(records, ax=None, *, styles=None):
    """Median and quartiles of the selection-set cost against training step, per method (paper Fig. 2).

    The selection set is the fixed set of initial states on which a learned
    controller's cost is recorded during training and its ensemble member chosen
    (``curve_size`` draws, see :mod:`codesign.learned.grnn`), apart from the validation set
    that scores the final design.

    Parameters
    ----------
    records : Records or list of dict
        Records whose ``extras["curve"]`` holds ``step`` and ``cost`` lists;
        others are ignored.
    ax : matplotlib Axes or sequence of Axes, optional
        One axis per ‖A‖₂ present (a single axis is fine with one ‖A‖₂; with
        several, every curve goes on it with ‖A‖₂ in the legend and its own line
        style). A new figure with one panel per ‖A‖₂ is made when omitted.
    styles : dict, optional
        Label -> :class:`compare.report.styles.Style`, the report's, so that each method has
        the colour and marker it has in every other figure; by default
        :func:`compare.report.styles.label_styles` of ``records``.

    Returns
    -------
    (fig, axes) : the figure and the list of axes drawn on (never shown).
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from .styles import REFERENCE_COLOUR, label_styles

    records = as_records(records)
    styles = dict(label_styles(records), **(styles or {}))
    curves = _curves(records)
    a_norms = sorted(curves)
    fig, axes = _curve_axes(ax, len(a_norms))
    shared = len(axes) == 1 and len(a_norms) > 1
    norm_styles = ["-", "--", ":", "-."]
    final_hi: dict[int, float] = defaultdict(float)  # per axis: highest final upper quartile
    for i, a in enumerate(a_norms):
        axis = axes[0] if shared else axes[i]
        for k, (label, items) in enumerate(sorted(curves[a].items())):
            colour, marker = styles[label][0], styles[label][1]
            linestyle = getattr(styles[label], "linestyle", "-")
            steps = items[0]["step"]
            costs = np.array([c["cost"] for c in items if c["step"] == steps], dtype=float)
            med = np.median(costs, axis=0)
            lo, hi = np.quantile(costs, 0.25, axis=0), np.quantile(costs, 0.75, axis=0)
            name = f"{label} (‖A‖₂ = {a:g})" if shared else label
            axis.plot(steps, med, linestyle=norm_styles[i % len(norm_styles)] if shared else linestyle,
                      color=colour, marker=marker, markevery=_markevery(len(steps), k, len(curves[a])), markersize=5,
                      label=f"{name}, {len(costs)} instance{'' if len(costs) == 1 else 's'}", gid=f"method:{label}")
            axis.fill_between(steps, lo, hi, color=colour, alpha=0.15, linewidth=0)
            final_hi[id(axis)] = max(final_hi[id(axis)], float(hi[-1]))
        if not shared:
            axis.set_title(f"‖A‖₂ = {a:g}")
    for axis in axes[: (1 if shared else len(a_norms))]:
        axis.set_yscale("log")
        # Costs span a decade or so: plain 1-2-5 labels, not powers of ten.
        axis.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axis.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        axis.yaxis.set_minor_formatter(NullFormatter())
        # The untrained controllers start orders of magnitude higher: keep the
        # converged region readable (the first points run off the top).
        if final_hi.get(id(axis)):
            axis.set_ylim(0.9, 4.0 * final_hi[id(axis)])
        axis.set_xlabel("training step")
        axis.set_ylabel("selection-set cost  E[J] / trace(P)")
        axis.axhline(1.0, color=REFERENCE_COLOUR, linewidth=1.0, zorder=0)
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=8)
    return fig, axes
