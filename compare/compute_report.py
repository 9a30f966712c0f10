"""What each method costs to run as the network grows: seconds and peak memory against N.

The runner records every run's wall time (scoring included) and its worker
process's peak resident memory (:func:`compare.runner.execute_run`); this module
summarizes them per method label and number of nodes, fits how the time grows,
and draws the compute figure of the ``compute`` report section.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .records import Records, as_records

__all__ = ["ComputeCell", "compute_cells", "growth_exponent", "plot_compute", "compute_markdown"]


@dataclass(frozen=True)
class ComputeCell:
    """One method label at one number of nodes: what its runs cost.

    Parameters
    ----------
    label : str
    n : int
        Nodes of the instances.
    runs : int
        Runs of this label at this size.
    completed : int
        Runs with at least one usable design (optimal or inaccurate, finite cost) and no
        design refused by a size guard (``extras["size_guard"]``); only these enter the
        timing, so that an instant refusal (beside, say, a path's free diagonal end) is
        not a fast design.
    seconds_per_design : float
        Median over completed runs of run seconds / designs in the run (NaN if none completed).
    seconds_per_run : float
        Median over completed runs of run seconds.
    peak_mb : float
        Largest peak resident memory of the worker process over the runs (MB; NaN if unknown).
    why_not : str
        The message of a run with no usable design (e.g. a size guard), else "".
    """

    label: str
    n: int
    runs: int
    completed: int
    seconds_per_design: float
    seconds_per_run: float
    peak_mb: float
    why_not: str = ""


def compute_cells(records) -> list[ComputeCell]:
    """One :class:`ComputeCell` per (label, n) in ``records``, sorted by label then n."""
    records = as_records(records)
    runs: dict[tuple, dict] = {}
    for r in records:
        n = r.instance.n if r.instance.n is not None else r.instance.spec.get("n")
        run = runs.setdefault((r.label, int(n), r.run_key), {"ok": False, "seconds": r.run_seconds,
                                                            "designs": r.run_designs, "peak": r.run_peak_mb,
                                                            "message": "", "refused": False})
        run["ok"] |= r.ok
        run["refused"] |= bool(r.extras.get("size_guard"))
        if not r.ok and r.message and not run["message"]:
            run["message"] = r.message
    cells: dict[tuple, list] = {}
    for (label, n, _), run in runs.items():
        cells.setdefault((label, n), []).append(run)
    out = []
    for (label, n), group in sorted(cells.items()):
        done = [g for g in group if g["ok"] and not g["refused"] and g["seconds"] is not None]
        per_design = [g["seconds"] / max(g["designs"] or 1, 1) for g in done]
        peaks = [g["peak"] for g in group if g["peak"] is not None]
        failed = [g["message"] for g in group if (g["refused"] or not g["ok"]) and g["message"]]
        out.append(ComputeCell(label, n, len(group), len(done),
                               float(np.median(per_design)) if per_design else math.nan,
                               float(np.median([g["seconds"] for g in done])) if done else math.nan,
                               float(max(peaks)) if peaks else math.nan, failed[0] if failed else ""))
    return out


def growth_exponent(ns, seconds) -> float | None:
    """Least-squares slope of log(seconds) against log(n): time grows like n^slope (None below two sizes)."""
    pairs = [(n, s) for n, s in zip(ns, seconds) if n > 0 and s > 0 and math.isfinite(s)]
    if len({n for n, _ in pairs}) < 2:
        return None
    x, y = np.log([p[0] for p in pairs]), np.log([p[1] for p in pairs])
    return float(np.polyfit(x, y, 1)[0])


def plot_compute(cells, *, axes=None, styles: dict | None = None):
    """Seconds per design and peak memory against N, log-log, one line per method.

    Parameters
    ----------
    cells : list of ComputeCell
    axes : pair of matplotlib Axes, optional
        Time panel and memory panel; a new figure is made if omitted.
    styles : dict, optional
        Label -> (colour, marker), from :func:`compare.figures.label_styles`.

    Returns
    -------
    fig, axes
    """
    from .figures import label_styles, plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    labels = sorted({c.label for c in cells})
    styles = styles or label_styles(labels)
    own_figure = axes is None
    if own_figure:
        fig, axes = plt.subplots(1, 2, figsize=(13, 6.2), constrained_layout=True)
    else:
        fig = axes[0].figure
    time_ax, memory_ax = axes
    sizes = sorted({c.n for c in cells})
    for label in labels:
        mine = sorted((c for c in cells if c.label == label), key=lambda c: c.n)
        colour, marker = styles[label]
        timed = [c for c in mine if math.isfinite(c.seconds_per_design)]
        slope = growth_exponent([c.n for c in timed], [c.seconds_per_design for c in timed])
        name = label + (f"  (∝ N^{slope:.1f})" if slope is not None else "")
        if timed:
            time_ax.plot([c.n for c in timed], [c.seconds_per_design for c in timed], color=colour, marker=marker,
                         label=name)
        refused = [c for c in mine if c.completed == 0]
        if refused and timed:
            # A size where the method produced nothing usable: an open marker on the last timed value's level.
            time_ax.plot([c.n for c in refused], [timed[-1].seconds_per_design] * len(refused), color=colour,
                         marker=marker, markerfacecolor="none", linestyle="none")
        measured = [c for c in mine if math.isfinite(c.peak_mb)]
        if measured:
            memory_ax.plot([c.n for c in measured], [c.peak_mb for c in measured], color=colour, marker=marker,
                           label=label)
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(sizes)
        ax.set_xticklabels([str(n) for n in sizes])
        ax.minorticks_off()
        ax.set_xlabel("N (nodes)")
        ax.grid(True, which="major", alpha=0.3)
    time_ax.set_ylabel("seconds per design (median over runs; 1 core)")
    time_ax.set_title("Time per design (fitted growth in the legend)")
    memory_ax.set_ylabel("peak resident memory of the worker (MB)")
    memory_ax.set_title("Peak memory per run (largest over runs)")
    # Memory spans less than a decade or two: label 1-2-5 steps in plain MB, not one power of ten.
    memory_ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    memory_ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    memory_ax.yaxis.set_minor_formatter(NullFormatter())
    if own_figure:  # one legend for both panels, below them, so that no entry covers a line
        handles, names = time_ax.get_legend_handles_labels()
        fig.legend(handles, names, loc="outside lower center", ncol=3, fontsize=8, frameon=False)
    else:
        time_ax.legend(fontsize=7)
    return fig, axes


def _fmt_seconds(value: float) -> str:
    if not math.isfinite(value):
        return "–"
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def compute_markdown(cells) -> str:
    """The compute table: per method and N, seconds per design and per run, peak memory, runs completed."""
    sizes = sorted({c.n for c in cells})
    labels = sorted({c.label for c in cells})
    by = {(c.label, c.n): c for c in cells}
    head = "| method | " + " | ".join(f"N = {n}: s/design, s/run, MB" for n in sizes) + " | time ∝ N^k |"
    lines = [head, "|---|" + "---|" * (len(sizes) + 1)]
    notes = {}
    for label in labels:
        row = [label]
        timed = []
        for n in sizes:
            c = by.get((label, n))
            if c is None:
                row.append("not run")
                continue
            if c.completed < c.runs:
                notes.setdefault(label, (n, c))
            if c.completed == 0:
                row.append(f"none of {c.runs} runs completed")
                continue
            timed.append(c)
            mb = f"{c.peak_mb:.0f}" if math.isfinite(c.peak_mb) else "?"
            row.append(f"{_fmt_seconds(c.seconds_per_design)}, {_fmt_seconds(c.seconds_per_run)}, {mb}"
                       + (f" ({c.completed}/{c.runs} runs completed)" if c.completed < c.runs else ""))
        slope = growth_exponent([c.n for c in timed], [c.seconds_per_design for c in timed])
        row.append(f"{slope:.2f}" if slope is not None else "–")
        lines.append("| " + " | ".join(row) + " |")
    text = "\n".join(lines)
    if notes:
        text += "\n\nRuns that did not complete (no usable design, or refused by a size guard):\n\n" + "\n".join(
            f"- {label}, N = {n}: {c.runs - c.completed} of {c.runs}" + (f": {c.why_not[:200]}" if c.why_not else "")
            for label, (n, c) in sorted(notes.items()))
    return text


def compute_section(records: Records, out, files: dict, styles: dict, save) -> list[str]:
    """The report's ``compute`` section: the figure (saved with ``save(fig, out, stem, files)``) and the table."""
    cells = compute_cells(records)
    if len({c.n for c in cells}) < 1 or not cells:
        return []
    fig, _ = plot_compute(cells, styles={c.label: styles[c.label] for c in cells if c.label in styles} or None)
    save(fig, out, "compute", files)
    return [
        "## Compute against network size",
        "",
        "![compute](compute.png)",
        "",
        "Left: seconds per design against the number of nodes N, log–log: the median over runs of the run's "
        "wall time (designing and scoring, one single-threaded worker) divided by the designs it returned (a "
        "γ or β path returns one per weight; batched learned runs share their batch's time equally). The "
        "legend gives the slope k of a least-squares fit of log time against log N (time ∝ N^k over the sizes "
        "shown). Only runs with at least one usable design and none refused by a size guard count; an open "
        "marker is a size where no run counted (see the table). Right: the largest peak resident memory of the "
        "worker process during a run, which includes the interpreter and the loaded libraries (about 300 MB "
        "once torch is loaded) but not memory that earlier runs in the same worker freed (it is handed back "
        "to the system before each run).",
        "",
        compute_markdown(cells),
        "",
    ]
