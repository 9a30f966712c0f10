"""What each method costs to run as the network grows: design seconds, scoring seconds and peak memory against N.

The runner records every run's wall time and its worker process's peak resident
memory (:func:`compare.runner.execute_run`), and every design records the
seconds its method spent making it (:attr:`compare.records.DesignRecord.seconds`).
A run's wall time is both: the method's own time (the sum of its designs'
seconds) and the time spent scoring those designs (closed-form costs or
simulation), which is the rest. This module keeps the two apart, per design,
summarizes them per method label and number of nodes, fits how the method's own
time grows where there are enough sizes to fit, and draws the figure of the
``compute`` report section.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .records import Records, as_records

__all__ = ["ComputeCell", "compute_cells", "growth_exponent", "plot_compute", "compute_markdown",
           "compute_section", "instances_per_size", "MIN_SIZES", "FEW_RUNS"]

#: Sizes a method needs timings at before a growth exponent is fitted: through three points
#: almost any curve looks like a power law, and a slope through two is no fit at all.
MIN_SIZES = 4
#: A cell resting on fewer completed runs than this is drawn hollow and annotated with its run count.
FEW_RUNS = 3


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
        timing, so that an instant refusal is not a fast design. The number of runs
        behind the cell's seconds.
    design_seconds : float
        Median over completed runs of the method's own seconds per design: the sum of the
        run's designs' ``seconds`` over its number of designs (NaN if none completed, or
        if no design recorded its seconds).
    scoring_seconds : float
        Median over completed runs of the scoring seconds per design: the run's wall
        seconds minus its designs' seconds (never below 0), over its number of designs.
    seconds_per_run : float
        Median over completed runs of the run's wall seconds (designing and scoring).
    peak_mb : float
        Largest peak resident memory of the worker process over the runs (MB; NaN if unknown).
    why_not : str
        The message of a run with no usable design (e.g. a size guard), else "".
    """

    label: str
    n: int
    runs: int
    completed: int
    design_seconds: float
    scoring_seconds: float
    seconds_per_run: float
    peak_mb: float
    why_not: str = ""


def _nodes(record) -> int:
    """N of the record's instance: the spec's node count, else the stored state count, else 0 (unknown)."""
    return record.instance.nodes or 0


def _runs(records: Records) -> dict[tuple, dict]:
    """(label, n, run key) -> what the run cost: wall seconds, designs, their seconds, peak, outcome."""
    runs: dict[tuple, dict] = {}
    for r in records:
        run = runs.setdefault((r.label, _nodes(r), r.run_key),
                              {"ok": False, "seconds": r.run_seconds, "designs": r.run_designs,
                               "design_seconds": 0.0, "timed_designs": 0, "peak": r.run_peak_mb,
                               "message": "", "refused": False})
        run["ok"] |= r.ok
        run["refused"] |= bool(r.extras.get("size_guard"))
        if r.seconds is not None and math.isfinite(r.seconds):
            run["design_seconds"] += float(r.seconds)
            run["timed_designs"] += 1
        if not r.ok and r.message and not run["message"]:
            run["message"] = r.message
    return runs


def _median(values) -> float:
    return float(np.median(values)) if len(values) else math.nan


def compute_cells(records) -> list[ComputeCell]:
    """One :class:`ComputeCell` per (label, n) in ``records``, sorted by label then n."""
    cells: dict[tuple, list] = {}
    for (label, n, _), run in _runs(as_records(records)).items():
        cells.setdefault((label, n), []).append(run)
    out = []
    for (label, n), group in sorted(cells.items()):
        done = [g for g in group if g["ok"] and not g["refused"] and g["seconds"] is not None]
        # A batched run's wall seconds are its batch's share, as are its designs' seconds, so the
        # difference is still this run's scoring; timer noise can make it slightly negative.
        per = [max(g["designs"] or 1, 1) for g in done]
        design = [g["design_seconds"] / k for g, k in zip(done, per) if g["timed_designs"]]
        scoring = [max(g["seconds"] - g["design_seconds"], 0.0) / k for g, k in zip(done, per) if g["timed_designs"]]
        peaks = [g["peak"] for g in group if g["peak"] is not None]
        failed = [g["message"] for g in group if (g["refused"] or not g["ok"]) and g["message"]]
        out.append(ComputeCell(label, n, len(group), len(done), _median(design), _median(scoring),
                               _median([g["seconds"] for g in done]), float(max(peaks)) if peaks else math.nan,
                               failed[0] if failed else ""))
    return out


def instances_per_size(records) -> dict[int, int]:
    """N -> the number of distinct instances of that size in ``records``."""
    sizes: dict[int, set] = {}
    for r in as_records(records):
        sizes.setdefault(_nodes(r), set()).add(r.instance.key)
    return {n: len(keys) for n, keys in sorted(sizes.items())}


def growth_exponent(ns, seconds, *, min_sizes: int = MIN_SIZES) -> float | None:
    """Least-squares slope k of log(seconds) against log(n), time ∝ n^k; None below ``min_sizes`` sizes."""
    pairs = [(n, s) for n, s in zip(ns, seconds) if n > 0 and s > 0 and math.isfinite(s)]
    if len({n for n, _ in pairs}) < max(min_sizes, 2):
        return None
    x, y = np.log([p[0] for p in pairs]), np.log([p[1] for p in pairs])
    return float(np.polyfit(x, y, 1)[0])


def _design_exponent(cells) -> float | None:
    timed = [c for c in cells if math.isfinite(c.design_seconds)]
    return growth_exponent([c.n for c in timed], [c.design_seconds for c in timed])


def _exponent_text(cells) -> str:
    """The table's growth column: the fitted k, or why there is none."""
    slope = _design_exponent(cells)
    if slope is not None:
        return f"{slope:.2f}"
    timed = {c.n for c in cells if math.isfinite(c.design_seconds)}
    if timed and not any(c.design_seconds > 0 for c in cells if math.isfinite(c.design_seconds)):
        return "no measurable design time"
    positive = {c.n for c in cells if math.isfinite(c.design_seconds) and c.design_seconds > 0}
    return f"too few sizes ({len(positive)})"


def _resolve_styles(labels, styles, records=None) -> dict:
    """Label -> :class:`compare.styles.Style`: the given ones, else from ``records``, else derived from the label."""
    from .styles import Style, label_styles, style_for

    styles = dict(styles or {})
    derived = label_styles(records) if records is not None else {}
    out = {}
    for label in labels:
        given = styles.get(label)
        if isinstance(given, Style):
            out[label] = given
        elif label in derived:
            out[label] = derived[label]
        elif given is not None:  # an older (colour, marker) pair: keep its look, with a solid line
            out[label] = Style(given[0], given[1])
        else:
            out[label] = style_for(label)
    return out


def _coincidence_ranks(series: dict[str, tuple[list, list]], *, rtol: float = 0.01) -> dict[str, int]:
    """Label -> how many lines drawn before it run (within ``rtol`` at every shared N) where it runs.

    Two labels timed together (say, two variants of one method in one batch) draw the
    same line; the later one is then drawn smaller and on top so that both stay visible.
    """
    ranks: dict[str, int] = {}
    drawn: list[dict] = []
    for label, (xs, ys) in series.items():
        mine = dict(zip(xs, ys))
        rank = 0
        for other in drawn:
            shared = set(mine) & set(other)
            if shared and all(abs(mine[n] - other[n]) <= rtol * max(abs(mine[n]), abs(other[n])) for n in shared):
                rank += 1
        ranks[label] = rank
        drawn.append(mine)
    return ranks


def _draw_series(ax, xs, ys, counts, style, rank: int, label: str, *, annotate: bool = True):
    """One method's line, hollow markers and (if ``annotate``) a run count where a point rests on few runs.

    A point rests on few runs when fewer than :data:`FEW_RUNS` runs are behind it.
    """
    # A line that coincides with one drawn before it: smaller and on top, so that both show.
    size, width = (7.5, 1.6) if rank == 0 else (4.5, 1.0)
    linestyle = style.linestyle
    if rank and linestyle != "-":
        # Dashes of another period and phase than the line beneath: both colours alternate along it.
        linestyle = (3.0, (3.0, 3.0) if linestyle == "--" else (1.0, 2.0))
    line, = ax.plot(xs, ys, color=style.colour, marker=style.marker, linestyle=linestyle, markersize=size,
                    linewidth=width, alpha=0.85, zorder=2 + rank, label=label, gid=f"method:{label}")
    few = [(x, y, k) for x, y, k in zip(xs, ys, counts) if k < FEW_RUNS]
    if few:
        # Over the filled marker: white inside, the method's colour around it.
        ax.plot([p[0] for p in few], [p[1] for p in few], linestyle="none", marker=style.marker,
                markersize=size, markerfacecolor="white", markeredgecolor=style.colour, zorder=2.5 + rank)
        for x, y, k in few if annotate else ():
            ax.annotate(f"{k} run{'s' if k != 1 else ''}", (x, y), xytext=(6, -3),
                        textcoords="offset points", fontsize=6, color=style.colour)
    return line


def _grouped_legend_entries(labels, styles, names: dict) -> tuple[list, list, int]:
    """Legend handles and texts in one column per information model, each headed by its line style.

    Returns handles, texts and the number of columns; the entries are padded so that
    matplotlib's column-major legend puts each information model in a column of its own.
    """
    from matplotlib.lines import Line2D

    from .styles import INFO_MODELS, INFO_ORDER

    models = [m for m in INFO_ORDER if any(styles[lb].info_model == m for lb in labels)]
    models += sorted({styles[lb].info_model for lb in labels} - set(models))
    columns = []
    for model in models:
        linestyle, _, description = INFO_MODELS.get(model, ("-", "solid", model))
        column = [(Line2D([], [], color="0.25", linestyle=linestyle, linewidth=1.2), description + ":")]
        column += [(Line2D([], [], color=styles[lb].colour, marker=styles[lb].marker,
                           linestyle=styles[lb].linestyle), names.get(lb, lb))
                   for lb in labels if styles[lb].info_model == model]
        columns.append(column)
    height = max(len(c) for c in columns)
    handles, texts = [], []
    for column in columns:
        column += [(Line2D([], [], linestyle="none"), "")] * (height - len(column))
        handles += [h for h, _ in column]
        texts += [t for _, t in column]
    return handles, texts, len(columns)


def plot_compute(cells, *, axes=None, styles: dict | None = None, instances: dict | None = None):
    """Design seconds per design, scoring seconds per design and peak memory against N, log-log.

    Parameters
    ----------
    cells : list of ComputeCell
    axes : sequence of three matplotlib Axes, optional
        Design-time, scoring-time and memory panels; a new figure is made if omitted.
    styles : dict, optional
        Label -> :class:`compare.styles.Style` (colour, marker and the information model's
        line style); derived from the labels where omitted.
    instances : dict, optional
        N -> instances of that size (:func:`instances_per_size`), said in the title.

    Returns
    -------
    fig, axes
    """
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    from .figures import plt

    labels = sorted({c.label for c in cells})
    styles = _resolve_styles(labels, styles)
    own_figure = axes is None
    if own_figure:
        fig, axes = plt.subplots(1, 3, figsize=(17, 6.4), constrained_layout=True)
    else:
        fig = axes[0].figure
    design_ax, scoring_ax, memory_ax = axes
    sizes = sorted({c.n for c in cells})
    by_label = {lb: sorted((c for c in cells if c.label == lb), key=lambda c: c.n) for lb in labels}
    names = {}
    # Where every point rests on the same few runs, the title says so once instead of a label at each point.
    run_counts = {c.completed for c in cells if c.completed} | {c.runs for c in cells}
    uniform = len(run_counts) == 1 and min(run_counts) < FEW_RUNS
    for ax, value, count in ((design_ax, "design_seconds", "completed"), (scoring_ax, "scoring_seconds", "completed"),
                             (memory_ax, "peak_mb", "runs")):
        series = {}
        for label in labels:
            # A log axis cannot show 0 s (scoring that took no measurable time): such points are left out.
            points = [c for c in by_label[label] if math.isfinite(getattr(c, value)) and getattr(c, value) > 0]
            if points:
                series[label] = ([c.n for c in points], [getattr(c, value) for c in points],
                                 [getattr(c, count) for c in points])
        ranks = _coincidence_ranks({lb: s[:2] for lb, s in series.items()})
        for label, (xs, ys, counts) in series.items():
            _draw_series(ax, xs, ys, counts, styles[label], ranks[label], label, annotate=not uniform)
    for label in labels:
        slope = _design_exponent(by_label[label])
        names[label] = label + (f"  (∝ N^{slope:.1f})" if slope is not None else "")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(sizes)
        ax.set_xticklabels([str(n) for n in sizes])
        ax.minorticks_off()
        ax.set_xlabel("N (nodes)")
        ax.grid(True, which="major", alpha=0.3)
    design_ax.set_ylabel("method's own seconds per design (median over runs; 1 core)")
    design_ax.set_title("Design time per design")
    scoring_ax.set_ylabel("scoring seconds per design (median over runs)")
    scoring_ax.set_title("Scoring time per design (instance, cost evaluation, simulation)")
    memory_ax.set_ylabel("peak resident memory of the worker (MB)")
    memory_ax.set_title("Peak memory per run (largest over runs)")
    # Memory spans less than a decade or two: label 1-2-5 steps in plain MB, not one power of ten.
    memory_ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    memory_ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    memory_ax.yaxis.set_minor_formatter(NullFormatter())
    few = (f"every point rests on {min(run_counts)} run{'s' if min(run_counts) != 1 else ''} (hollow markers)"
           if uniform else f"hollow marker: fewer than {FEW_RUNS} runs behind it")
    fig.suptitle("Compute against network size (" + (f"{_instances_text(instances)}; " if instances else "")
                 + f"{few})", fontsize=11)
    handles, texts, columns = _grouped_legend_entries(labels, styles, names)
    if own_figure:  # one legend for all panels, below them, so that no entry covers a line
        fig.legend(handles, texts, loc="outside lower center", ncol=columns, fontsize=8, frameon=False)
    else:
        design_ax.legend(handles, texts, ncol=columns, fontsize=6)
    return fig, axes


def _fmt_seconds(value: float) -> str:
    if not math.isfinite(value):
        return "?"
    if value == 0:
        return "0"
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def compute_markdown(cells) -> str:
    """The compute table: per method and N, design and scoring seconds per design, peak memory and runs timed."""
    sizes = sorted({c.n for c in cells})
    labels = sorted({c.label for c in cells})
    by = {(c.label, c.n): c for c in cells}
    head = ("| method | " + " | ".join(f"N = {n}: design s, scoring s, MB (runs)" for n in sizes)
            + " | design time ∝ N^k |")
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
                notes[(label, n)] = c
            if c.completed == 0:
                row.append(f"none of {c.runs} runs completed")
                continue
            timed.append(c)
            mb = f"{c.peak_mb:.0f}" if math.isfinite(c.peak_mb) else "?"
            runs = f"{c.completed}" if c.completed == c.runs else f"{c.completed} of {c.runs} completed"
            row.append(f"{_fmt_seconds(c.design_seconds)}, {_fmt_seconds(c.scoring_seconds)}, {mb} ({runs})")
        row.append(_exponent_text(timed))
        lines.append("| " + " | ".join(row) + " |")
    text = "\n".join(lines)
    if notes:
        text += "\n\nRuns that did not complete (no usable design, or refused by a size guard):\n\n" + "\n".join(
            f"- {label}, N = {n}: {c.runs - c.completed} of {c.runs}" + (f": {c.why_not[:200]}" if c.why_not else "")
            for (label, n), c in sorted(notes.items()))
    return text


def _instances_text(instances: dict) -> str:
    """"6 instances at each N", or the count at each N where they differ."""
    counts = set(instances.values())
    if len(counts) == 1:
        return f"{counts.pop()} instances at each N"
    return ", ".join(f"{k} instances at N = {n}" for n, k in instances.items())


def _caption(instances: dict) -> str:
    return (
        f"Runs on {_instances_text(instances)}, one single-threaded worker each. Left: the method's own "
        "seconds per design, log–log: "
        "for each run the sum of its designs' recorded seconds divided by the designs it returned (a γ or β path "
        "returns one per weight; batched learned runs share their batch's time equally), the median over runs. "
        "Middle: the scoring seconds per design, the rest of the run's wall time (building the instance, its "
        "Riccati solve included, and computing each design's cost: closed form for linear controllers, "
        "simulation for learned ones), per design and median over runs. A "
        "median of 0 s (a method that takes no measurable time, such as doing nothing) cannot be drawn on a "
        "log axis and is only in the table. Right: the largest peak "
        "resident memory of the worker process during a run, which includes the interpreter and the loaded "
        "libraries (about 300 MB once torch is loaded) but not memory that earlier runs in the same worker "
        "freed (it is handed back to the system before each run). Only runs with at least one usable design "
        "and none refused by a size guard are timed; a size where none was is absent from the figure (see the "
        f"table). A hollow marker, annotated with its count, rests on fewer than {FEW_RUNS} runs. The legend "
        "groups methods by information model (its line style heads each column) and gives, where a method has "
        f"design timings at {MIN_SIZES} or more sizes, the slope k of a least-squares fit of log design time "
        f"against log N (time ∝ N^k); with fewer sizes no growth is fitted (\"too few sizes\" in the table). "
        "Table cells: design seconds per design, scoring seconds per design, peak MB, and in parentheses the "
        "runs behind the seconds."
    )


def compute_section(records: Records, save, styles: dict) -> list[str]:
    """The report's ``compute`` section: the figure (saved with ``save(fig, stem)``, as the other sections) and the table.

    ``styles``: label -> :class:`compare.styles.Style`; labels it lacks (or gives as an older
    (colour, marker) pair) are styled by :func:`compare.styles.label_styles` of ``records``.
    """
    records = as_records(records)
    cells = compute_cells(records)
    if not cells:
        return []
    instances = instances_per_size(records)
    resolved = _resolve_styles(sorted({c.label for c in cells}), styles, records)
    fig, _ = plot_compute(cells, styles=resolved, instances=instances)
    save(fig, "compute")
    return [
        "## Compute against network size",
        "",
        "![compute](compute.png)",
        "",
        _caption(instances),
        "",
        compute_markdown(cells),
        "",
    ]
