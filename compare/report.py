"""Reports: the cost-versus-links figure, the Markdown summary, the CSV of every run.

Everything here is computed from the store's records alone, so ``compare report``
regenerates the same files that ``compare run`` wrote.
"""

from __future__ import annotations

import csv
import json
import platform
from collections import Counter, defaultdict
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter  # noqa: E402

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

#: Marker and line style per information model, so that a zero-delay static gain and
#: a one-step-delay dynamic controller with the same link count never look alike.
INFO_STYLE = {
    "instantaneous": {"marker": "o", "linestyle": "-", "description": "instantaneous (zero-delay links)"},
    "delayed": {"marker": "s", "linestyle": "--", "description": "delayed (one step per hop)"},
    "none": {"marker": "D", "linestyle": ":", "description": "no communication"},
}

_PACKAGES = ("grnn-codesign", "numpy", "scipy", "cvxpy", "clarabel", "control", "torch", "networkx", "matplotlib")


def quartiles(values) -> tuple[float, float, float]:
    """(25th percentile, median, 75th percentile) of the finite values; NaNs if none."""
    finite = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    if finite.size == 0:
        return (float("nan"),) * 3
    q1, med, q3 = np.percentile(finite, [25, 50, 75])
    return float(q1), float(med), float(q3)


def panel_key(instance: dict) -> tuple:
    return (instance.get("family", "?"), instance.get("n", 0), instance.get("a_norm", float("nan")))


def panel_title(key: tuple) -> str:
    family, n, a_norm = key
    return f"N = {n}, ‖A‖₂ = {a_norm:g}" if np.isfinite(a_norm) else f"{family}, N = {n}"


@dataclass(frozen=True)
class Point:
    """One design setting (label + hyperparameters) aggregated over instances."""

    panel: tuple
    label: str
    info_model: str
    params: str
    designs: int
    ok: int
    links: tuple[float, float, float]
    self_loops: float
    cost: tuple[float, float, float]
    cost_mean: float
    statuses: dict


def aggregate(records: list[dict]) -> list[Point]:
    """Group records by (panel, label, info model, params) into quartile summaries."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[(panel_key(r["instance"]), r["label"], r["info_model"], json.dumps(r["params"], sort_keys=True))].append(r)
    points = []
    for (panel, label, info, params), rs in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][3])):
        ok = [r for r in rs if r["status"] in ("optimal", "inaccurate") and np.isfinite(r["cost"])]
        costs = [r["cost"] for r in ok]
        points.append(
            Point(
                panel=panel,
                label=label,
                info_model=info,
                params=params,
                designs=len(rs),
                ok=len(ok),
                links=quartiles([r["links"] for r in ok]) if ok else quartiles([r["links"] for r in rs]),
                self_loops=quartiles([r["self_loops"] for r in rs])[1],
                cost=quartiles(costs),
                cost_mean=float(np.mean(costs)) if costs else float("nan"),
                statuses=dict(Counter(r["status"] for r in rs)),
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


def budget_costs(records: list[dict], budgets=(20, 60, 140, None)) -> dict:
    """Per (panel, label): median over instances of the best cost within each link budget.

    For each instance, a method's best cost under budget b is the lowest cost among
    its designs with at most b links (None = any number); instances where no design
    fits count as missing. Returns ``{(panel, label): [(median, instances), ...]}``.
    """
    best: dict[tuple, dict] = defaultdict(lambda: defaultdict(dict))
    for r in records:
        if r["status"] not in ("optimal", "inaccurate") or not np.isfinite(r["cost"]):
            continue
        key = (panel_key(r["instance"]), r["label"])
        inst = json.dumps(r["instance"], sort_keys=True)
        for b in budgets:
            if b is None or r["links"] <= b:
                current = best[key][b].get(inst, float("inf"))
                best[key][b][inst] = min(current, r["cost"])
    return {
        key: [(quartiles(list(per[b].values()))[1], len(per[b])) for b in budgets]
        for key, per in sorted(best.items())
    }


def plant_links(records: list[dict], facts: dict | None = None) -> dict:
    """Median off-diagonal plant-graph links per panel: the QI boundary.

    Below this many links no communication graph relaying one hop per step is
    quadratically invariant, so no convex delay-constrained (SLS) design exists
    there. ``facts`` maps an instance's JSON to what the runner stored about it
    (``plant_links``); instances without stored facts are rebuilt.
    """
    from codesign import count_links

    from .runner import build_instance

    facts = facts or {}
    per_panel = defaultdict(list)
    for inst in {json.dumps(r["instance"], sort_keys=True) for r in records}:
        if inst not in facts:
            facts[inst] = {"plant_links": count_links(build_instance(json.loads(inst)).plant_adj)[0]}
        per_panel[panel_key(json.loads(inst))].append(facts[inst]["plant_links"])
    return {panel: float(np.median(v)) for panel, v in per_panel.items()}


#: Designs whose median cost is more than this times centralized LQR's are off the
#: interesting range: they are drawn as labelled triangles on the top edge so that
#: the open loop (up to ~1e7 on unstable instances) does not flatten everyone else.
OFF_SCALE = 2.0


def _label_colors(labels) -> dict:
    # tab10, then Dark2's hues: 18 colours that stay distinct (tab20's light shades
    # are hard to tell from their dark twins).
    palette = list(plt.get_cmap("tab10").colors) + list(plt.get_cmap("Dark2").colors)
    return {label: palette[i % len(palette)] for i, label in enumerate(labels)}


def _panel_top(points) -> float | None:
    """Upper y limit of a panel, or None to show everything (no design is off the scale)."""
    shown = [p for p in points if p.cost[1] <= OFF_SCALE]
    if not shown or len(shown) == len(points):
        return None
    return min(OFF_SCALE, max(p.cost[2] for p in shown)) * 1.03


def plot_cost_vs_links(points: list[Point], *, axes=None, colors: dict | None = None,
                       boundaries: dict | None = None):
    """Median cost against median links per design setting, one panel per instance family/size/a_norm.

    Error bars span the 25–75 % quantiles on both axes; the x-axis is symmetric-log
    so that zero-link designs stay visible; markers and line styles encode the
    information model.

    Parameters
    ----------
    points : list of Point
        From :func:`aggregate`.
    axes : sequence of matplotlib Axes, optional
        One per panel; a new figure is made if omitted.
    colors : dict, optional
        Label -> colour.
    boundaries : dict, optional
        Panel -> link count of the plant graph, drawn as the QI boundary.

    Returns
    -------
    fig, axes
    """
    panels = sorted({p.panel for p in points})
    labels = list(dict.fromkeys(p.label for p in sorted(points, key=lambda p: p.label)))
    colors = colors or _label_colors(labels)
    spare = None
    if axes is None:
        ncols = min(3, max(1, len(panels)))
        nrows = -(-max(1, len(panels)) // ncols)
        fig, grid = plt.subplots(nrows, ncols, figsize=(6.0 * ncols, 4.8 * nrows), squeeze=False)
        axes = list(grid.ravel())
        for extra in axes[max(1, len(panels)):]:
            extra.set_axis_off()
        spare = axes[-1] if len(axes) > len(panels) else None  # the legend goes there
        axes = axes[:max(1, len(panels))]
    else:
        fig = axes[0].figure
    for ax, panel in zip(axes, panels):
        usable = [p for p in points if p.panel == panel and p.ok > 0]
        top = _panel_top(usable)
        for label in labels:
            pts = [p for p in usable if p.label == label]
            for info in sorted({p.info_model for p in pts}):
                series = sorted((p for p in pts if p.info_model == info), key=lambda p: (p.links[1], p.cost[1]))
                style = INFO_STYLE[info]
                x = np.array([p.links[1] for p in series])
                y = np.array([p.cost[1] for p in series])
                xerr = np.array([[p.links[1] - p.links[0] for p in series], [p.links[2] - p.links[1] for p in series]])
                yerr = np.array([[p.cost[1] - p.cost[0] for p in series], [p.cost[2] - p.cost[1] for p in series]])
                ax.errorbar(
                    x, y, xerr=xerr, yerr=yerr, color=colors[label], marker=style["marker"],
                    linestyle=style["linestyle"] if len(series) > 1 else "none",
                    markersize=6, capsize=2, elinewidth=0.8, linewidth=1.2,
                )
        ax.set_xscale("symlog", linthresh=1.0)
        plain = FuncFormatter(lambda value, _: f"{value:g}")
        if top is None:
            ax.set_yscale("log")
            ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            ax.yaxis.set_major_formatter(plain)
            ax.yaxis.set_minor_formatter(NullFormatter())
        else:
            low = min(0.98, min(p.cost[0] for p in usable) * 0.99)
            ax.set_ylim(low, top)
            for p in usable:
                if p.cost[1] > top:
                    ax.plot(p.links[1], top, marker="^", color=colors[p.label], markersize=8, clip_on=False,
                            linestyle="none", zorder=5)
                    ax.annotate(f"{p.cost[1]:.3g}", (p.links[1], top), xytext=(0, -4), textcoords="offset points",
                                ha="center", va="top", fontsize=7, color=colors[p.label])
        ax.xaxis.set_major_formatter(plain)
        ax.set_xlim(left=-0.4)
        ax.set_xlabel("directed off-diagonal links (median, IQR bars)")
        ax.set_ylabel("normalized cost E[J] / tr(P) (median, IQR bars)")
        ax.set_title(panel_title(panel))
        ax.axhline(1.0, color="0.6", linewidth=0.8, zorder=0)
        if boundaries and panel in boundaries:
            ax.axvline(boundaries[panel], color="0.35", linestyle=(0, (1, 2)), linewidth=1.0, zorder=0)
            ax.annotate("plant graph\n(QI boundary)", (boundaries[panel], 1.0), xytext=(-4, 4),
                        textcoords="offset points", ha="right", va="bottom", fontsize=7, color="0.35")
        ax.grid(True, which="major", alpha=0.3)
    handles = [Line2D([], [], color=colors[label], marker="o", linestyle="-", label=label) for label in labels]
    used = sorted({p.info_model for p in points if p.ok > 0}, key=list(INFO_STYLE).index)
    handles += [
        Line2D([], [], color="0.3", marker=INFO_STYLE[i]["marker"], linestyle=INFO_STYLE[i]["linestyle"],
               label=INFO_STYLE[i]["description"])
        for i in used
    ]
    if spare is not None:
        spare.legend(handles=handles, loc="center", ncol=1 if len(handles) <= 16 else 2, frameon=False)
        fig.tight_layout()
        return fig, axes
    ncol = min(4, len(handles))
    rows = -(-len(handles) // ncol)
    fig.legend(handles=handles, loc="lower center", ncol=ncol, frameon=False, bbox_to_anchor=(0.5, 0.0))
    fig.tight_layout(rect=(0, min(0.5, (0.25 * rows + 0.2) / fig.get_figheight()), 1, 1))
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


def _params_text(params: str) -> str:
    def text(value):
        # Grid values such as 0.0021544346900318843 read better at 4 digits; the
        # store and the CSV keep them exact.
        return _fmt(value) if isinstance(value, float) and np.isfinite(value) else str(value)

    data = json.loads(params)
    return ", ".join(f"{k}={text(v)}" for k, v in sorted(data.items())) or "—"


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
                                            p.cost[1] if np.isfinite(p.cost[1]) else np.inf, p.params)):
            lines.append(
                f"| {p.label} | {p.info_model} | {_params_text(p.params)} | {p.designs} | {p.ok} | "
                f"{_fmt_iqr(p.links, 3)} | {_fmt(p.self_loops, 3)} | {_fmt_iqr(p.cost)} |"
            )
        lines.append("")
    return lines


def _budget_tables(records: list[dict], budgets=(20, 60, 140, None)) -> list[str]:
    table = budget_costs(records, budgets)
    heads = [f"≤ {b} links" if b is not None else "any" for b in budgets]
    lines = []
    for panel in sorted({key[0] for key in table}):
        lines += [f"### {panel_title(panel)}", "", "| method | " + " | ".join(heads) + " |",
                  "|---|" + "---:|" * len(budgets)]
        for (pnl, label), cells in table.items():
            if pnl != panel:
                continue
            text = [f"{_fmt(m)} ({k})" if k else "—" for m, k in cells]
            lines.append(f"| {label} | " + " | ".join(text) + " |")
        lines.append("")
    return lines


def _pareto_tables(points: list[Point]) -> list[str]:
    lines = []
    for panel in sorted({p.panel for p in points}):
        lines += [f"### {panel_title(panel)}", "", "| method | front: (median links, median cost) |", "|---|---|"]
        for label in sorted({p.label for p in points if p.panel == panel}):
            front = pareto_front([p for p in points if p.panel == panel and p.label == label])
            lines.append(f"| {label} | " + ", ".join(f"({_fmt(p.links[1], 3)}, {_fmt(p.cost[1])})" for p in front) + " |")
        lines.append("")
    return lines


def _fingerprint_lines(records: list[dict], meta: dict) -> list[str]:
    """Which code produced the runs: one row per (method, fingerprint)."""
    runs = defaultdict(set)
    for r in records:
        runs[(r["method"], r.get("fingerprint") or "—")].add(r["run_key"])
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


def _write_csv(records: list[dict], path: Path) -> None:
    instance_keys = sorted({k for r in records for k in r["instance"]})
    columns = ["label", "method", "params", "status", "cost", "cost_stderr", "cost_kind", "links", "self_loops",
               "info_model", "seconds", "message", "extras", "run_key", "idx", "fingerprint"]
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow([f"instance_{k}" for k in instance_keys] + columns)
        for r in records:
            scalars = {k: v for k, v in r["extras"].items() if isinstance(v, (int, float, str, bool))}
            row = [r["instance"].get(k, "") for k in instance_keys]
            for col in columns:
                value = r.get(col, "")
                if col == "params":
                    value = json.dumps(value, sort_keys=True)
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


def _experiments_with(section: str, records: list[dict], meta: dict, members: dict) -> tuple[list[str], list[dict]]:
    """The experiments that ask for ``section`` and the records of their runs."""
    names = sorted(k.split(":", 1)[1] for k, v in meta.items() if k.startswith("sections:") and section in v)
    keys = set().union(*(members.get(n, set()) for n in names)) if names else set()
    # A store written before experiments recorded their members: a run belongs to the one that computed it.
    unlisted = {n for n in names if not members.get(n)}
    return names, [r for r in records if r["run_key"] in keys or r.get("experiment") in unlisted]


def _producing(product: str, meta: dict) -> dict:
    """Method name -> its stored declaration, for methods that declare ``product``."""
    return {k.split(":", 1)[1]: v for k, v in meta.items() if k.startswith("method:") and product in v.get("produces", [])}


def _learning_sections(records: list[dict], out: Path, files: dict, load_controller, meta: dict,
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
    curved = [r for r in curved if r["method"] in _producing("training_curve", meta) and "curve" in r["extras"]]
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
        spec = {k: v for k, v in path[0]["instance"].items() if k != "family"}
        weight = next(v["path_param"] for k, v in _producing("topology_path", meta).items() if k == path[0]["method"])
        entries = []
        for r in path:
            controller = load_controller(r["run_key"], r["idx"])
            support = getattr(controller, "support", None)
            if support is not None:
                entries.append((r["params"][weight], r["links"], r["cost"], support))
        if len(entries) >= 2:
            fig, _ = plot_topology_path(build_instance(path[0]["instance"]), entries)
            _save_figure(fig, out, "topologies", files)
            inst = ", ".join(f"{k} = {v}" for k, v in spec.items())
            symbol = "β" if weight == "beta" else weight
            lines += [f"## Designed topologies along the {symbol} path (paper Fig. 4)", "",
                      f"{path[0]['label']} on one instance ({inst}); nodes coloured by the magnitude of the leading "
                      f"eigenvector of A. Under each graph: the weight {symbol}, the directed off-diagonal links "
                      "|E| and the normalized cost J.", "", "![designed topologies](topologies.png)", ""]
    return lines


def write_report(records: list[dict], out, *, specs: dict | None = None, title: str = "Comparison report",
                 commands: list[str] | None = None, load_controller=None, meta: dict | None = None,
                 members: dict | None = None, superseded: int = 0) -> dict[str, Path]:
    """Write ``cost_vs_links.png/.svg``, ``runs.csv`` and ``report.md`` into ``out``.

    Parameters
    ----------
    records : list of dict
        :meth:`compare.store.Store.records`.
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
        declares it produces, code fingerprints and stored instance facts. Sections
        come from these declarations only.
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
    records = sorted(records, key=lambda r: (json.dumps(r["instance"], sort_keys=True), r["label"], r["run_key"], r["idx"]))
    meta, members = dict(meta or {}), dict(members or {})
    points = aggregate(records)
    facts = {k.split(":", 1)[1]: v for k, v in meta.items() if k.startswith("instance:")}
    boundaries = plant_links(records, facts)
    files = {}
    fig, _ = plot_cost_vs_links(points, boundaries=boundaries)
    _save_figure(fig, out, "cost_vs_links", files)
    files["csv"] = out / "runs.csv"
    _write_csv(records, files["csv"])

    instances = {json.dumps(r["instance"], sort_keys=True) for r in records}
    runs = {r["run_key"] for r in records}
    statuses = Counter(r["status"] for r in records)
    lines = [f"# {title}", ""]
    if commands:
        *run_commands, rebuild = commands
        how = "Regenerate with " + " then ".join(f"`{c}`" for c in run_commands) if run_commands else ""
        how += (" (runs already in the store are skipped), or from the stored results alone with "
                if run_commands else "Regenerate from the stored results with ") + f"`{rebuild}`."
        lines += [how, ""]
    lines += [
        f"{len(runs)} runs on {len(instances)} instances, {len(records)} designs. "
        "Costs are E[J] / trace(P) over the horizon (centralized LQR = 1); links are directed off-diagonal "
        "communication links (self-loops are local feedback and listed separately). "
        "Exact closed-form costs for linear controllers, validation-set estimates for learned ones."
        + (f" The store also holds {superseded} runs made by code that has changed since; they are not "
           "shown (see Code fingerprints)." if superseded else ""),
        "",
        "![cost versus links](cost_vs_links.png)",
        "",
        "Markers and line styles give the information model: "
        + "; ".join(f"{v['marker']!r} {v['description']}" for v in INFO_STYLE.values())
        + ". Points are medians over instances with 25–75 % bars on both axes. Where some design's median "
        f"cost is above {OFF_SCALE:g} (twice centralized LQR), that design is a triangle on the panel's top "
        "edge with its median printed under it.",
        "",
        "## Medians by method",
        "",
    ]
    lines += _summary_tables(points)
    lines += [
        "## Best cost within a link budget",
        "",
        "Per instance, the lowest cost a method reaches with at most that many links; the median over "
        "instances, with the number of instances where some design fits in parentheses.",
        "",
    ]
    lines += _budget_tables(records)
    lines += ["## Pareto fronts", "", "Settings no other setting of the same method beats on both median "
              "links and median cost.", ""]
    lines += _pareto_tables(points)
    if boundaries:
        lines += ["The dotted vertical line in the figure is the median number of off-diagonal plant-graph "
                  "links: below it no communication graph relaying one hop per step is quadratically "
                  "invariant on this family, so no convex delay-constrained design with the GRNN's "
                  "information model exists there (docs/information-models.md).", ""]
    lines += _learning_sections(records, out, files, load_controller, meta, members)
    lines += _fingerprint_lines(records, meta)
    lines += ["## Runs by status", "", "| status | designs |", "|---|---:|"]
    lines += [f"| {status} | {count} |" for status, count in sorted(statuses.items())]
    failures = [r for r in records if r["status"] != "optimal"]
    if failures:
        lines += ["", "Non-optimal designs (first 20):", "", "| instance | method | status | message |", "|---|---|---|---|"]
        for r in failures[:20]:
            inst = ", ".join(f"{k}={v}" for k, v in r["instance"].items() if k != "family")
            lines.append(f"| {inst} | {r['label']} | {r['status']} | {r['message'][:160]} |")
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
