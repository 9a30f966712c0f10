"""Figure conventions shared by the report's figures, and the budget-front figure.

Each method (label) gets a colour and a marker shape, so that twenty methods stay
distinguishable; the information model is the line style. Cost axes are linear
unless the costs span more than a decade.
"""

from __future__ import annotations

import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter  # noqa: E402

from .statistics import panel_title  # noqa: E402

__all__ = ["LINESTYLES", "label_styles", "cost_axis", "plot_budget_fronts", "OFF_SCALE", "legend_handles"]

#: Line style per information model.
LINESTYLES = {
    "instantaneous": ("-", "instantaneous (zero-delay links)"),
    "delayed": ("--", "delayed (one step per hop)"),
    "none": (":", "no communication"),
}
#: Costs above this many times centralized LQR's are off the interesting range:
#: the axis stops there and the figure says which methods lie above.
OFF_SCALE = 2.0
_MARKERS = ("o", "s", "D", "^", "v", "P", "X", "<", ">", "h", "*", "p")


def label_styles(labels) -> dict:
    """Label -> (colour, marker): tab10 then Dark2 (18 hues), and a marker cycle of another length."""
    palette = list(plt.get_cmap("tab10").colors) + list(plt.get_cmap("Dark2").colors)
    return {label: (palette[i % len(palette)], _MARKERS[i % len(_MARKERS)]) for i, label in enumerate(labels)}


def cost_axis(ax, low: float, high: float) -> None:
    """Cost y-axis on [low, high]: linear with several ticks, or log with labelled ticks beyond a decade."""
    plain = FuncFormatter(lambda value, _: f"{value:g}")
    if high / max(low, 1e-12) > 10:
        ax.set_yscale("log")
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(plain)
        ax.yaxis.set_minor_formatter(NullFormatter())
    else:
        ax.yaxis.set_major_locator(MaxNLocator(nbins=7))
    ax.set_ylim(low, high)


def legend_handles(styles: dict, labels, info_models) -> list:
    handles = [Line2D([], [], color=styles[lb][0], marker=styles[lb][1], linestyle="-", label=lb) for lb in labels]
    handles += [Line2D([], [], color="0.3", linestyle=LINESTYLES[i][0], label=LINESTYLES[i][1])
                for i in LINESTYLES if i in info_models]
    return handles


def _grid(panels: int):
    ncols = min(3, max(1, panels))
    nrows = -(-max(1, panels) // ncols)
    fig, grid = plt.subplots(nrows, ncols, figsize=(6.0 * ncols, 4.8 * nrows), squeeze=False)
    axes = list(grid.ravel())
    for extra in axes[max(1, panels):]:
        extra.set_axis_off()
    spare = axes[-1] if len(axes) > panels else None
    return fig, axes[:max(1, panels)], spare


def finish_legend(fig, axes, spare, handles) -> None:
    if spare is not None:
        spare.legend(handles=handles, loc="center", ncol=1 if len(handles) <= 16 else 2, frameon=False)
        fig.tight_layout()
        return
    ncol = min(4, len(handles))
    rows = -(-len(handles) // ncol)
    fig.legend(handles=handles, loc="lower center", ncol=ncol, frameon=False, bbox_to_anchor=(0.5, 0.0))
    fig.tight_layout(rect=(0, min(0.5, (0.25 * rows + 0.2) / fig.get_figheight()), 1, 1))


def draw_boundary(ax, x: float, *, below: float = 0.0) -> None:
    """The plant graph's link count: below it no delayed graph is quadratically invariant.

    The label starts ``below`` points under the top edge (clear of off-scale labels there).
    """
    ax.axvline(x, color="0.35", linestyle=(0, (1, 2)), linewidth=1.0, zorder=0)
    ax.annotate(" plant graph (QI boundary) ", (x, 1.0), xycoords=ax.get_xaxis_transform(),
                xytext=(-1, -4 - below), textcoords="offset points", rotation=90, ha="right", va="top",
                fontsize=7, color="0.35", zorder=1,  # under the markers: SLS on the plant graph sits on this line
                bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1})


def plot_budget_fronts(fronts, *, axes=None, styles: dict | None = None, boundaries: dict | None = None,
                       bounds: dict | None = None):
    """Best cost within each link budget: median over instances (step curve) and 25–75 % band.

    Parameters
    ----------
    fronts : list of :class:`compare.statistics.Front`
    axes : sequence of matplotlib Axes, optional
        One per panel; a new figure is made if omitted.
    styles : dict, optional
        Label -> (colour, marker), from :func:`label_styles`.
    boundaries : dict, optional
        Panel -> plant-graph link count, drawn when a delayed method is present.
    bounds : dict, optional
        Panel -> (cost, text): a lower bound drawn as a horizontal line.

    Returns
    -------
    fig, axes
    """
    panels = sorted({f.panel for f in fronts})
    labels = sorted({f.label for f in fronts})
    styles = styles or label_styles(labels)
    spare = None
    if axes is None:
        fig, axes, spare = _grid(len(panels))
    else:
        fig = axes[0].figure
    above = {}
    for ax, panel in zip(axes, panels):
        mine = [f for f in fronts if f.panel == panel]
        right = max(float(f.budgets[-1]) for f in mine)
        finite = np.concatenate([f.cost[1][np.isfinite(f.cost[1])] for f in mine])
        if finite.size == 0:
            continue
        if bounds and panel in bounds:
            finite = np.append(finite, bounds[panel][0])
        low = min(0.97, float(finite.min()) * 0.98)
        shown = finite[finite <= OFF_SCALE]
        top = float(finite.max()) * 1.03 if shown.size == finite.size else min(OFF_SCALE, float(shown.max())) * 1.05
        for f in mine:
            colour, marker = styles[f.label]
            x = np.append(f.budgets, max(right, f.budgets[-1]) * 1.15 + 1)
            q1, med, q3 = (np.append(row, row[-1]) for row in f.cost)
            linestyle = LINESTYLES.get(f.info_model, ("-", ""))[0]
            # inf (the budget fits too few instances' designs) leaves a gap, not a line off the axis.
            q1, med, q3 = (np.where(np.isfinite(v), v, np.nan) for v in (q1, med, q3))
            ax.step(x, med, where="post", color=colour, linestyle=linestyle, linewidth=1.5)
            ax.fill_between(x, q1, q3, step="post", color=colour, alpha=0.08, linewidth=0)
            reached = np.isfinite(f.cost[1])
            if reached.any():
                k = int(np.argmax(reached))  # the first budget with a finite median: where the curve starts
                ax.plot(f.budgets[k], f.cost[1][k], marker=marker, color=colour, linestyle="none", markersize=6)
            if reached.any() and f.cost[1][reached].min() > top:
                above.setdefault(panel, []).append(f"{f.label} ({np.nanmin(f.cost[1][reached]):.3g})")
        cost_axis(ax, low, top)
        ax.set_xscale("symlog", linthresh=1.0)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
        ax.set_xlim(-0.4, right * 1.15 + 1)
        ax.set_xlabel("link budget L (directed off-diagonal links)")
        ax.set_ylabel("best cost with ≤ L links (median, 25–75 %)")
        # Wrapped to the panel's width: with several panels side by side a long list ran into the next title.
        note = textwrap.fill("above the axis: " + ", ".join(above[panel]), 60) if panel in above else ""
        ax.set_title(panel_title(panel) + ("\n" + note if note else ""), fontsize=10 if note else None)
        ax.axhline(1.0, color="0.6", linewidth=0.8, zorder=0)
        if bounds and panel in bounds:
            value, text = bounds[panel]
            ax.axhline(value, color="black", linewidth=1.0, linestyle=(0, (4, 2, 1, 2)), zorder=1)
            ax.text(0.01, value, f" {text}", transform=ax.get_yaxis_transform(), ha="left", va="top", fontsize=7)
        if boundaries and panel in boundaries and any(f.info_model == "delayed" for f in mine):
            draw_boundary(ax, boundaries[panel])
        ax.grid(True, which="major", alpha=0.3)
    finish_legend(fig, axes, spare, legend_handles(styles, labels, {f.info_model for f in fronts}))
    return fig, axes


