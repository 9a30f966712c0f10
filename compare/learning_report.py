"""Paper Table 1 and the training-curve figure (paper Fig. 2) from stored records.

``records`` are :class:`compare.records.Records` (or dicts shaped like the store's
rows); learned controllers keep ``extras["curve"] = {"step": [...], "cost": [...]}``.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import scipy.stats

from .records import OK_STATUSES, as_records

__all__ = ["table1_markdown", "training_curves_figure", "bootstrap_interval", "PAPER_TABLE1", "PAPER_SPARSE_EDGES",
           "GAP_NOTES", "SPARSE_EDGES_NOTE"]

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


def _gap_note(method, stat, paper, low, high) -> str:
    """Why a paper value lies outside our interval: instance noise, or what else is known."""
    # The paper's statistic is computed on its own random instances (its code seeds
    # nothing) and carries the same sampling noise as ours: the difference has sqrt(2)
    # times the spread of one statistic, estimated from our bootstrap interval.
    spread = (high - low) / (2 * scipy.stats.norm.ppf(0.975))  # the interval is a 95 % one
    z = (stat - paper) / (np.sqrt(2) * spread) if spread > 0 else np.inf
    if abs(z) < _NOISE_Z:
        return (f"Within instance-sampling noise: {z:+.1f} standard deviations of the difference "
                "between two statistics over independent instance draws (the paper's instances cannot be "
                "redrawn: its code seeds nothing).")
    return f"Beyond instance-sampling noise ({z:+.1f} s.d.). " + GAP_NOTES.get(method, "No known cause.")

_ROW_ORDER = ["lqr", "autonomous", "grnn", "grnn_dense", "grnn_sparse", "grnn_fixed", "gcnn"]


def _a_norm(record) -> float:
    a_norm = record.instance.a_norm
    return float("nan") if a_norm is None else float(a_norm)


def _fmt(value, digits=3) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


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


def table1_markdown(records) -> str:
    """Markdown Table 1: our statistic per (method, ||A||) beside the paper's value.

    Costs are medians over instances (autonomous: the mean, as in the paper),
    with a 95 % bootstrap interval over instances; failed designs are left out
    of the statistic and counted in the ``ok`` column. Links are means over
    instances: directed off-diagonal links, and in parentheses with self-loops
    (the paper's edge convention). Below the table, every paper value outside
    our interval is listed with what is known to cause the gap
    (:data:`GAP_NOTES`).
    """
    records = as_records(records)
    groups = records.group(lambda r: (r.method, r.label or r.method))
    a_norms = sorted({_a_norm(r) for r in records if np.isfinite(_a_norm(r))})
    if not groups or not a_norms:
        return "_No records for Table 1._\n"

    def order(key):
        method, label = key
        return (_ROW_ORDER.index(method) if method in _ROW_ORDER else len(_ROW_ORDER), label)

    header = ["Method"]
    for a in a_norms:
        header += [f"‖A‖={a:g} ours", "95 % CI", "paper", "Δ", "ok", "links (w/ self-loops)"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    notes = []
    outside = []
    edge_gaps = []
    for method, label in sorted(groups, key=order):
        rows = groups[(method, label)]
        cells = [label]
        for a in a_norms:
            here = [r for r in rows if _a_norm(r) == a]
            good = [r for r in here if r.ok]
            costs = np.array([r.cost for r in good], dtype=float)
            statistic = np.mean if method == "autonomous" else np.median
            stat = float(statistic(costs)) if costs.size else float("nan")
            low, high = bootstrap_interval(costs, statistic)
            interval = f"[{_fmt(low)}, {_fmt(high)}]" if np.isfinite(low) else "–"
            linear = any(r.params.get("activation") == "identity" for r in rows)
            paper = None if linear else PAPER_TABLE1.get(method, {}).get(a)
            gap = f"{100 * (stat / paper - 1):+.1f} %" if paper and np.isfinite(stat) else "–"
            if paper and np.isfinite(low) and not low <= paper <= high:
                outside.append((method, label, a, stat, paper, low, high))
            links = np.array([np.nan if r.links is None else r.links for r in good], dtype=float)
            loops = np.array([np.nan if r.self_loops is None else r.self_loops for r in good], dtype=float)
            if links.size:
                link_cell = f"{links.mean():.1f} ({(links + loops).mean():.1f})"
            else:
                link_cell = "–"
            if method == "grnn_sparse" and not linear and a in PAPER_SPARSE_EDGES and links.size:
                edges = PAPER_SPARSE_EDGES[a]
                e_low, e_high = bootstrap_interval(links + loops, np.mean)
                link_cell += f" [{_fmt(e_low, 1)}, {_fmt(e_high, 1)}]; paper ({edges:.1f})"
                if np.isfinite(e_low) and not e_low <= edges <= e_high:
                    edge_gaps.append((label, a, float((links + loops).mean()), edges, e_low, e_high))
            cells += [_fmt(stat), interval, _fmt(paper) if paper else "–", gap, f"{len(good)}/{len(here)}",
                      link_cell]
        lines.append("| " + " | ".join(cells) + " |")
        if any(r.status not in OK_STATUSES for r in rows):
            statuses = defaultdict(int)
            for r in rows:
                statuses[r.status] += 1
            notes.append(f"{label}: " + ", ".join(f"{v} {k}" for k, v in sorted(statuses.items())))
    text = "\n".join(lines) + "\n"
    text += ("\nCosts: E[J]/trace(P), exact for linear controllers and a control-variate estimate on the "
             "validation set for learned ones (medians over instances; "
             "Autonomous: mean), with a 95 % bootstrap interval over instances. Links: mean directed "
             "off-diagonal links; in parentheses with self-loops, the convention of the paper's "
             "53.4 / 56.1 for GRNN-Sparse, with a 95 % bootstrap interval of that mean.\n")
    text += _variant_pairs(records, a_norms)
    if outside:
        text += "\nPaper values outside our 95 % interval, and why:\n\n"
        for method, label, a, stat, paper, low, high in outside:
            side = "below" if stat < paper else "above"
            text += (f"- {label}, ‖A‖={a:g}: ours {stat:.3f} [{low:.3f}, {high:.3f}] is {side} the paper's "
                     f"{paper:.3f}. {_gap_note(method, stat, paper, low, high)}\n")
    if edge_gaps:
        text += "\nEdge counts outside our 95 % interval:\n\n"
        for label, a, mean, edges, low, high in edge_gaps:
            text += (f"- {label}, ‖A‖={a:g}: {mean:.1f} edges with self-loops [{low:.1f}, {high:.1f}] against "
                     f"the paper's {edges:.1f}.\n")
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
             "interval for it.", "", "| pair | ‖A‖ | instances | first better | second better | median Δ | 95 % interval | |",
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
                lines.append(f"| {p.a} − {p.b} | {a:g} | {p.instances} | {p.a_wins} | {p.b_wins} | "
                             f"{p.median:+.4f} | {p.interval_text} | {note} |")
    return "\n".join(lines) + "\n"


def training_curves_figure(records, ax=None):
    """Median and quartiles of the validation cost against training step, per method (paper Fig. 2).

    Parameters
    ----------
    records : Records or list of dict
        Records whose ``extras["curve"]`` holds ``step`` and ``cost`` lists;
        others are ignored.
    ax : matplotlib Axes or sequence of Axes, optional
        One axis per ||A|| present (a single axis is fine with one ||A||; with
        several, every curve goes on it with ||A|| in the legend). A new figure
        with one panel per ||A|| is made when omitted.

    Returns
    -------
    (fig, axes) : the figure and the list of axes drawn on (never shown).
    """
    import matplotlib.pyplot as plt

    curves: dict[float, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for record in as_records(records):
        curve = record.extras.get("curve")
        if not curve or not record.ok:
            continue
        curves[_a_norm(record)][record.label or record.method].append(curve)
    a_norms = sorted(curves)
    if ax is None:
        fig, axes = plt.subplots(1, max(1, len(a_norms)), figsize=(6 * max(1, len(a_norms)), 4.2), squeeze=False)
        axes = list(axes[0])
    else:
        axes = list(ax) if isinstance(ax, (list, tuple, np.ndarray)) else [ax]
        fig = axes[0].figure
    if len(axes) not in (1, len(a_norms)) and a_norms:
        raise ValueError(f"need one axis per a_norm ({len(a_norms)}) or a single axis, got {len(axes)}")
    labels = sorted({label for by_label in curves.values() for label in by_label})
    colors = {label: plt.cm.tab10(i % 10) for i, label in enumerate(labels)}
    shared = len(axes) == 1 and len(a_norms) > 1
    styles = ["-", "--", ":", "-."]
    final_hi: dict[int, float] = defaultdict(float)  # per axis: highest final upper quartile
    for i, a in enumerate(a_norms):
        axis = axes[0] if shared else axes[i]
        for label, items in sorted(curves[a].items()):
            steps = items[0]["step"]
            costs = np.array([c["cost"] for c in items if c["step"] == steps], dtype=float)
            med = np.median(costs, axis=0)
            lo, hi = np.quantile(costs, 0.25, axis=0), np.quantile(costs, 0.75, axis=0)
            name = f"{label} (‖A‖={a:g})" if shared else label
            style = styles[i % len(styles)] if shared else "-"
            axis.plot(steps, med, style, color=colors[label], label=f"{name}, n={len(costs)}")
            axis.fill_between(steps, lo, hi, color=colors[label], alpha=0.2, linewidth=0)
            final_hi[id(axis)] = max(final_hi[id(axis)], float(hi[-1]))
        if not shared:
            axis.set_title(f"‖A‖ = {a:g}")
    for axis in axes[: (1 if shared else len(a_norms))]:
        axis.set_yscale("log")
        # The untrained controllers start orders of magnitude higher: keep the
        # converged region readable (the first points run off the top).
        if final_hi.get(id(axis)):
            axis.set_ylim(0.9, 4.0 * final_hi[id(axis)])
        axis.set_xlabel("training step")
        axis.set_ylabel("validation cost  E[J] / trace(P)")
        axis.axhline(1.0, color="0.5", linewidth=0.8)
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=8)
    return fig, axes
