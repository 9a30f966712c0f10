"""What each method costs to run as the network grows: design seconds, scoring seconds and memory against N.

The runner records every run's wall time, the seconds it spent scoring its designs
(timed around the scoring calls, apart from the method's), and its worker process's
resident memory at the start of the run and at its peak
(:class:`compare.run.execution.RunResult`); every design records the seconds its method
spent making it (:attr:`compare.run.records.DesignRecord.seconds`). This module
summarizes them per method label and number of nodes (design and scoring seconds per
design, the memory a run added over what its worker already held), fits how design
time and memory grow where there are enough sizes to fit, states those growths in
words, and draws the figure of the ``compute`` report section. Runs stored before
scoring seconds and the memory baseline were recorded have them unknown: they are
reported as not measured, never estimated from the wall time or the whole peak.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..run.records import Records, as_records
from .figures import MIN_POINTS

__all__ = ["ComputeCell", "compute_cells", "growth_exponent", "growth_sentences", "plot_compute", "compute_markdown",
           "compute_section", "instances_per_size", "MIN_SIZES", "FEW_RUNS", "NOT_MEASURED"]

#: Sizes a method needs timings at before a growth exponent is fitted: through three points
#: almost any curve looks like a power law, and a slope through two is no fit at all.
MIN_SIZES = 4
#: A cell resting on fewer completed runs than this is drawn hollow and annotated with its run count.
FEW_RUNS = 3
#: What the figure and the notes say of a quantity the report's runs did not record.
NOT_MEASURED = "not measured in this report's runs"


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
        Median over completed runs of the scoring seconds per design: the seconds the run
        spent scoring its designs, as measured around those calls, over its number of
        designs (NaN where no completed run has them measured: runs stored before they were).
    seconds_per_run : float
        Median over completed runs of the run's wall seconds (designing and scoring).
    peak_mb : float
        Largest peak resident memory of the worker process over the runs (MB; NaN if unknown),
        everything the process held included.
    memory_mb : float
        Median over completed runs of the memory the run added: its process's peak resident
        memory less the resident memory it started the run from (MB; NaN where no completed
        run has both measured).
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
    memory_mb: float = math.nan
    why_not: str = ""


def _nodes(record) -> int:
    """N of the record's instance: the spec's node count, else the stored state count, else 0 (unknown)."""
    return record.instance.nodes or 0


def _added_mb(record) -> float | None:
    """The memory the record's run added (its peak less its start, MB), None where either is unknown."""
    if record.run_peak_mb is None or record.run_baseline_mb is None:
        return None
    return float(record.run_peak_mb) - float(record.run_baseline_mb)


def _runs(records: Records) -> dict[tuple, dict]:
    """(label, n, run key) -> what the run cost: wall and scoring seconds, designs, their seconds, memory, outcome."""
    runs: dict[tuple, dict] = {}
    for r in records:
        run = runs.setdefault((r.label, _nodes(r), r.run_key),
                              {"ok": False, "seconds": r.run_seconds, "designs": r.run_designs,
                               "design_seconds": 0.0, "timed_designs": 0, "scoring": r.run_scoring_seconds,
                               "peak": r.run_peak_mb, "added": _added_mb(r), "message": "", "refused": False})
        run["ok"] |= r.ok
        run["refused"] |= bool(r.extras.get("size_guard"))
        if r.seconds is not None and math.isfinite(r.seconds):
            run["design_seconds"] += float(r.seconds)
            run["timed_designs"] += 1
        # A learned method simulates its designs to precision itself, after its timer stops, and the
        # harness then has nothing left to score: that simulation is the design's scoring.
        own = r.extras.get("scoring_seconds")
        if run["scoring"] is not None and isinstance(own, (int, float)) and math.isfinite(own):
            run["scoring"] += float(own)
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
        per = [max(g["designs"] or 1, 1) for g in done]
        design = [g["design_seconds"] / k for g, k in zip(done, per) if g["timed_designs"]]
        # Measured, never the wall time less the designs' seconds: a path's designs can record more
        # seconds than its run took (a shared computation counted in two of them).
        scoring = [g["scoring"] / k for g, k in zip(done, per) if g["scoring"] is not None]
        peaks = [g["peak"] for g in group if g["peak"] is not None]
        failed = [g["message"] for g in group if (g["refused"] or not g["ok"]) and g["message"]]
        out.append(ComputeCell(label, n, len(group), len(done), _median(design), _median(scoring),
                               _median([g["seconds"] for g in done]), float(max(peaks)) if peaks else math.nan,
                               memory_mb=_median([g["added"] for g in done if g["added"] is not None]),
                               why_not=failed[0] if failed else ""))
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


def _exponent(cells, value: str = "design_seconds") -> float | None:
    """:func:`growth_exponent` of the cells' ``value`` (a :class:`ComputeCell` field) against their N."""
    known = [c for c in cells if c.completed and math.isfinite(getattr(c, value))]
    return growth_exponent([c.n for c in known], [getattr(c, value) for c in known])


def _design_exponent(cells) -> float | None:
    return _exponent(cells, "design_seconds")


#: What :func:`_growth_text` calls a quantity with no measurable value: ComputeCell field -> words.
_NOTHING_MEASURABLE = {"design_seconds": "no measurable design time", "memory_mb": "no measurable memory added"}


def _growth_text(cells, value: str = "design_seconds") -> str:
    """The table's growth column for ``value``: the fitted k, or why there is none."""
    slope = _exponent(cells, value)
    if slope is not None:
        return f"{slope:.2f}"
    known = [getattr(c, value) for c in cells if c.completed and math.isfinite(getattr(c, value))]
    if not known:
        return "not measured" if any(c.completed for c in cells) else "too few sizes (0)"
    if not any(v > 0 for v in known):
        return _NOTHING_MEASURABLE[value]
    positive = {c.n for c in cells if c.completed and math.isfinite(getattr(c, value)) and getattr(c, value) > 0}
    return f"too few sizes ({len(positive)})"


def _growth_phrase(text: str) -> str:
    """What :func:`_growth_text` found, as the end of a sentence about a quantity: "grows as N^k", or why not."""
    try:
        return f"grows as N^{float(text):.1f}"
    except ValueError:
        pass
    if text == "not measured":
        return f"was {NOT_MEASURED}"
    if text in _NOTHING_MEASURABLE.values():
        return "is too small to measure"
    return f"is measurable at {text} to fit"  # "too few sizes (k)"


def growth_sentences(cells) -> list[str]:
    """How design time and memory grow with N, in words, for each method completed at :data:`MIN_SIZES` or more sizes.

    Parameters
    ----------
    cells : list of ComputeCell

    Returns
    -------
    list of str
        Markdown lines: an introduction and one bullet per such method ("design time grows
        as N^k; memory added grows as N^m", or why a growth is not fitted), then one line naming
        the methods completed at fewer sizes; empty when no method has the sizes.
    """
    by_label: dict[str, list] = {}
    for c in cells:
        by_label.setdefault(c.label, []).append(c)
    sized = {label: sorted(group, key=lambda c: c.n) for label, group in sorted(by_label.items())}
    fitted = {label: group for label, group in sized.items()
              if len({c.n for c in group if c.completed}) >= MIN_SIZES}
    if not fitted:
        return []
    intro = (f"How each method's cost grows with N, where it completed runs at {MIN_SIZES} or more sizes (the slope "
             "k of a least-squares fit of the log of the median against log N, so that the value grows as N^k):")
    lines = [intro, ""]
    for label, group in fitted.items():
        lines.append(f"- {label}: design time {_growth_phrase(_growth_text(group, 'design_seconds'))}; "
                     f"memory added {_growth_phrase(_growth_text(group, 'memory_mb'))}.")
    fewer = [label for label in sized if label not in fitted]
    if fewer:
        lines += ["", f"Completed at fewer than {MIN_SIZES} sizes, so no growth is stated: {', '.join(fewer)}."]
    return lines


def _resolve_styles(labels, styles, records=None) -> dict:
    """Label -> :class:`compare.report.styles.Style`: the given ones, else from ``records``, else derived from the label."""
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
                        textcoords="offset points", fontsize=MIN_POINTS, color=style.colour)
    return line


def _grouped_legend_entries(labels, styles, names: dict, *, one_column: bool = False) -> tuple[list, list, int]:
    """Legend handles and texts in one column per information model, each headed by its line style.

    Returns handles, texts and the number of columns; the entries are padded so that
    matplotlib's column-major legend puts each information model in a column of its own.
    With ``one_column`` the groups follow each other in one column, a blank row between them.
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
    for k, column in enumerate(columns):
        blanks = (k < len(columns) - 1) if one_column else height - len(column)
        column += [(Line2D([], [], linestyle="none"), "")] * blanks
        handles += [h for h, _ in column]
        texts += [t for _, t in column]
    return handles, texts, 1 if one_column else len(columns)


def plot_compute(cells, *, axes=None, styles: dict | None = None, instances: dict | None = None):
    """Design seconds per design, scoring seconds per design and the memory a run added against N, log-log.

    A panel whose quantity no completed run measured (runs stored before it was recorded)
    says so (:data:`NOT_MEASURED`) instead of drawing anything.

    Parameters
    ----------
    cells : list of ComputeCell
    axes : sequence of three matplotlib Axes, optional
        Design-time, scoring-time and memory panels; a new figure is made if omitted.
    styles : dict, optional
        Label -> :class:`compare.report.styles.Style` (colour, marker and the information model's
        line style); derived from the labels where omitted.
    instances : dict, optional
        N -> instances of that size (:func:`instances_per_size`), said in the title.

    Returns
    -------
    fig, axes
    """
    from .figures import plt

    labels = sorted({c.label for c in cells})
    styles = _resolve_styles(labels, styles)
    own_figure = axes is None
    if own_figure:
        # Two by two, the legend in the fourth place: in one row of three the page's 800 px
        # shrank the legend's text to about 5 px. At most MAX_WIDTH wide, so that 8-point type
        # (and the 10^k ticks' exponents) stays 9 px tall on that page.
        fig, grid = plt.subplots(2, 2, figsize=(8.6, 8.4), constrained_layout=True)
        grid[1, 1].axis("off")
        axes = (grid[0, 0], grid[0, 1], grid[1, 0])
    else:
        fig = axes[0].figure
    by_label = {lb: sorted((c for c in cells if c.label == lb), key=lambda c: c.n) for lb in labels}
    # Where every point rests on the same few runs, the title says so once instead of a label at each point.
    run_counts = {c.completed for c in cells if c.completed} | {c.runs for c in cells}
    uniform = len(run_counts) == 1 and min(run_counts) < FEW_RUNS
    empty = [ax for ax, value in zip(axes, ("design_seconds", "scoring_seconds", "memory_mb"))
             if not _draw_quantity(ax, value, cells, by_label, styles, annotate=not uniform)]
    _label_compute_axes(axes, sorted({c.n for c in cells}), empty)
    few = (f"every point rests on {min(run_counts)} run{'s' if min(run_counts) != 1 else ''} (hollow markers)"
           if uniform else f"hollow marker: fewer than {FEW_RUNS} runs behind it")
    fig.suptitle("Compute against network size (" + (f"{_instances_text(instances)}; " if instances else "")
                 + f"{few})", fontsize=11)
    names = {}
    for label in labels:
        slope = _design_exponent(by_label[label])
        names[label] = label + (f"  (∝ N^{slope:.1f})" if slope is not None else "")
    handles, texts, columns = _grouped_legend_entries(labels, styles, names, one_column=own_figure)
    if own_figure:  # one legend for all panels, in the fourth place, so that no entry covers a line
        _legend_in_place(fig, grid[1, 1], handles, texts)
    else:
        axes[0].legend(handles, texts, ncol=columns, fontsize=MIN_POINTS)
    return fig, axes


def _draw_quantity(ax, value: str, cells, by_label: dict, styles: dict, *, annotate: bool) -> bool:
    """One panel: each method's median ``value`` (a :class:`ComputeCell` field) against N; False, and the panel
    says so, where no completed run measured it (runs stored before it was recorded)."""
    if any(c.completed for c in cells) and not any(c.completed and math.isfinite(getattr(c, value)) for c in cells):
        ax.text(0.5, 0.5, NOT_MEASURED, transform=ax.transAxes, ha="center", va="center", fontsize=9,
                color="0.35", gid=f"not-measured:{value}")
        return False
    series = {}
    for label, mine in by_label.items():
        # A log axis cannot show 0 (scoring or memory too small to measure): such points are left out.
        points = [c for c in mine if math.isfinite(getattr(c, value)) and getattr(c, value) > 0]
        if points:
            series[label] = ([c.n for c in points], [getattr(c, value) for c in points],
                             [c.completed for c in points])
    ranks = _coincidence_ranks({lb: s[:2] for lb, s in series.items()})
    for label, (xs, ys, counts) in series.items():
        _draw_series(ax, xs, ys, counts, styles[label], ranks[label], label, annotate=annotate)
    return True


def _label_compute_axes(axes, sizes: list, empty: list) -> None:
    """Log-log axes with the sizes as ticks, their titles and labels; ``empty`` panels get no values."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, NullLocator

    design_ax, scoring_ax, memory_ax = axes
    for ax in axes:
        ax.set_xscale("log")
        ax.set_yscale("log")
        # 11 points: the exponents of 10^k are drawn at 70 % of it, 7.7 points, 9 px on an 800 px page
        ax.tick_params(axis="both", labelsize=11)
        ax.set_xticks(sizes)
        ax.set_xticklabels([str(n) for n in sizes])
        ax.minorticks_off()
        ax.set_xlabel("N (nodes)")
        ax.grid(True, which="major", alpha=0.3)
    design_ax.set_ylabel("method's own seconds per design\n(median over runs; 1 core)")
    design_ax.set_title("Design time per design\n")
    scoring_ax.set_ylabel("scoring seconds per design\n(median over runs)")
    scoring_ax.set_title("Scoring time per design\n(cost evaluation, simulation)")
    memory_ax.set_ylabel("memory added by a run: its peak above\nits start (MB, median over runs)")
    memory_ax.set_title("Memory added per run\n(peak less the worker's baseline)")
    # Label 1-2-5 steps in plain MB, not one power of ten: megabytes are read as numbers.
    memory_ax.yaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    memory_ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    memory_ax.yaxis.set_minor_formatter(NullFormatter())
    for ax in empty:  # the sizes' range, as the drawn panels have it, and no values on an axis with none
        ax.set_xlim(sizes[0] / 1.25, sizes[-1] * 1.25)
        ax.yaxis.set_major_locator(NullLocator())


def _legend_in_place(fig, place, handles, texts, *, largest: float = 11.0, smallest: float = 8.0) -> None:
    """A figure legend centred in the empty axes ``place``, in one column or two, at the largest type that fits;
    below the panels at ``smallest`` type where even that does not fit (the figure grows to take it).

    A legend's extent grows in proportion to its type size, so one layout at ``largest``
    gives the size at which each column count fits; more methods get smaller type,
    never a legend that spills over the panels.
    """
    fig.draw_without_rendering()  # the constrained layout settles the place first
    anchor = place.get_position().bounds  # figure fraction, as fig.legend reads bbox_to_anchor
    best = None
    for ncol in (1, 2):
        legend = fig.legend(handles, texts, loc="center", bbox_to_anchor=anchor, ncol=ncol, fontsize=largest,
                            frameon=False)
        fig.draw_without_rendering()
        box, room = legend.get_window_extent(), place.get_window_extent()
        size = largest * min(1.0, 0.97 * room.width / box.width, 0.97 * room.height / box.height)
        legend.remove()
        if best is None or size > best[1] + 1e-9:
            best = (ncol, size)
    if best[1] < smallest:
        # Too many methods for the fourth place at legible type: below the panels, the figure taller by its height.
        legend = fig.legend(handles, texts, loc="outside lower center", ncol=2, fontsize=smallest, frameon=False)
        fig.draw_without_rendering()
        width, height = fig.get_size_inches()
        fig.set_size_inches(width, height + legend.get_window_extent().height / fig.dpi)
        return
    fig.legend(handles, texts, loc="center", bbox_to_anchor=anchor, ncol=best[0], fontsize=best[1], frameon=False)


def _fmt_mb(value: float) -> str:
    """Megabytes as the table gives them: whole above 10 MB, else two significant digits; ? if unknown."""
    if not math.isfinite(value):
        return "?"
    return f"{value:.0f}" if abs(value) >= 10 else f"{value:.2g}"


def _fmt_seconds(value: float) -> str:
    if not math.isfinite(value):
        return "?"
    if value == 0:
        return "0"
    return f"{value:.3g}" if value < 100 else f"{value:.0f}"


def _not_measured_note(cells) -> str:
    """The note under the table for the "?" of scoring seconds and memory added that runs did not measure, or ""."""
    done = [c for c in cells if c.completed]
    missing = {what: [not math.isfinite(getattr(c, value)) for c in done]
               for what, value in (("scoring seconds", "scoring_seconds"), ("memory added", "memory_mb"))}
    missing = {what: flags for what, flags in missing.items() if any(flags)}
    if not missing:
        return ""
    # A store can mix runs from before the measurements with later ones: then only some cells lack them.
    everywhere = all(all(flags) for flags in missing.values())
    where = NOT_MEASURED if everywhere else "not measured in some of this report's runs"
    return (f"? : {' and '.join(missing)} {'were' if len(missing) > 1 else 'was'} {where} (runs stored before "
            "they were recorded, or memory on a platform without Linux's /proc); they are not estimated from the "
            "wall time or the whole peak.")


def compute_markdown(cells) -> str:
    """The compute tables: per method and N, design and scoring seconds per design, memory added and runs timed;
    then per method how design time and memory grow with N.

    A value the runs did not measure is "?", and a note under the table says which
    (scoring seconds and memory added are not recorded in stores and report folders
    written before them).
    """
    sizes = sorted({c.n for c in cells})
    labels = sorted({c.label for c in cells})
    by = {(c.label, c.n): c for c in cells}
    # Long format, one row per method and N, and the growth exponents in a table of their own: a column per
    # N with three numbers per cell ran off the page at 800 px (issue 61).
    lines = ["| method | N | design s | scoring s | MB added | runs |", "|---|---:|---:|---:|---:|---|"]
    growth = ["| method | design time ∝ N^k | memory added ∝ N^m |", "|---|---|---|"]
    notes = {}
    for label in labels:
        timed = []
        for n in sizes:
            c = by.get((label, n))
            if c is None:
                continue
            if c.completed < c.runs:
                notes[(label, n)] = c
            if c.completed == 0:
                lines.append(f"| {label} | {n} | – | – | – | none of {c.runs} runs completed |")
                continue
            timed.append(c)
            runs = f"{c.completed}" if c.completed == c.runs else f"{c.completed} of {c.runs} completed"
            lines.append(f"| {label} | {n} | {_fmt_seconds(c.design_seconds)} | {_fmt_seconds(c.scoring_seconds)} | "
                         f"{_fmt_mb(c.memory_mb)} | {runs} |")
        growth.append(f"| {label} | {_growth_text(timed, 'design_seconds')} | {_growth_text(timed, 'memory_mb')} |")
    lines += [""] + growth
    text = "\n".join(lines)
    note = _not_measured_note(cells)
    if note:
        text += "\n\n" + note
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
        f"Runs on {_instances_text(instances)}, one single-threaded worker each. Top left: the method's own "
        "seconds per design, log–log: "
        "for each run the sum of its designs' recorded seconds divided by the designs it returned (a γ or β path "
        "returns one per weight; batched learned runs share their batch's time equally), the median over runs. "
        "Top right: the scoring seconds per design, timed around the harness's scoring of the designs a method "
        "returned (codesign.scoring.evaluate), per design and median over runs. A design that comes back already "
        "scored keeps its cost: an exact cost a method computed is in its own seconds, and the learned methods "
        "simulate their designs to the harness's precision inside their call, after their training's timer "
        "stops; they record that simulation's seconds, and this panel adds them to the harness's. The rest of a "
        "run's wall time (building its instance) is in neither panel. A "
        "median of 0 (a method that takes no measurable time, such as doing nothing) cannot be drawn on a "
        "log axis and is only in the table. Bottom left: the memory a run added, its worker's peak resident memory "
        "during the run less the worker's resident memory when the run started (the interpreter, the libraries "
        "loaded so far and what earlier runs kept; memory they freed is handed back to the system first), "
        "median over runs; the runs of one batch share one start and one peak, and a run that is the first in "
        "its worker to load a library counts the library. Only runs with at least one usable design "
        "and none refused by a size guard are timed; a size where none was is absent from the figure (see the "
        f"table). A hollow marker, annotated with its count, rests on fewer than {FEW_RUNS} runs. The legend "
        "(bottom right) groups methods by information model (its line style heads each group) and gives, "
        f"where a method has design timings at {MIN_SIZES} or more sizes, the slope k of a least-squares fit of log design time "
        f"against log N (time ∝ N^k); with fewer sizes no growth is fitted (\"too few sizes\"). "
        "The first table gives, per method and N, the design seconds per design, the scoring seconds per "
        "design, the MB added and the runs behind them; the second, the fitted growth of design time and "
        "of memory added."
    )


def compute_section(records: Records, save, styles: dict) -> list[str]:
    """The report's ``compute`` section: the figure (saved with ``save(fig, stem)``, as the other sections) and the table.

    Above the figure, :func:`growth_sentences` state how each method's design time and memory
    grow with N where it completed runs at :data:`MIN_SIZES` or more sizes.

    ``styles``: label -> :class:`compare.report.styles.Style`; labels it lacks (or gives as an older
    (colour, marker) pair) are styled by :func:`compare.report.styles.label_styles` of ``records``.
    """
    records = as_records(records)
    cells = compute_cells(records)
    if not cells:
        return []
    instances = instances_per_size(records)
    resolved = _resolve_styles(sorted({c.label for c in cells}), styles, records)
    fig, _ = plot_compute(cells, styles=resolved, instances=instances)
    save(fig, "compute")
    growth = growth_sentences(cells)
    return [
        "## Compute against network size",
        "",
        *(growth + [""] if growth else []),
        "![compute](compute.png)",
        "",
        _caption(instances),
        "",
        compute_markdown(cells),
        "",
    ]
