"""Reports: findings first, then the figures and tables behind them, and a folder that rebuilds itself.

Everything here is computed from the records alone (a store's, or a report folder's
``runs.csv`` and ``report.json``), so ``compare report`` regenerates the same files
that ``compare run`` wrote. The order of a report: what the data support (Findings,
from the forest plot), the budget fronts, the delayed-information fronts, cost
against links per setting, the detailed tables, the sections an experiment asks for
(Table 1, training curves, topologies, compute), and how it was all computed.
"""

from __future__ import annotations

import textwrap
from collections import Counter
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from codesign.status import OPTIMAL  # noqa: E402

from .answer import answer_lines  # noqa: E402
from .cost_links import Point, aggregate, pareto_front, plot_cost_vs_links, quartiles  # noqa: E402
from .figures import LINESTYLES, MAX_BANDS, OFF_SCALE, bands_drawn, drawn_styles, plot_budget_fronts  # noqa: E402
from ..run.meta import StoreMeta  # noqa: E402
from .pattern_gaps import pattern_gap_section  # noqa: E402
from ..run.records import Records, as_records  # noqa: E402
from .sections import delayed_section, experiments_with, learning_sections  # noqa: E402
from .tables import (  # noqa: E402
    asked_pairs,
    budget_tables,
    environment_lines,
    fingerprint_lines,
    paired_lines,
    pareto_tables,
    precision_text,
    software_versions,
    summary_tables,
    systems_table,
    uncertain_text,
)
from .statistics import best_tables, budget_fronts, panel_budgets, panel_title  # noqa: E402
from .styles import label_styles  # noqa: E402

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
    "report_records",
]

#: Line style per information model, so that a zero-delay static gain and a
#: one-step-delay dynamic controller with the same link count never look alike.
INFO_STYLE = {info: {"linestyle": style, "description": text} for info, (style, text) in LINESTYLES.items()}

_GRAPH_NAMES = {"plant^2": "plant² graph", "plant^3": "plant³ graph"}


def budget_costs(records, budgets=None) -> dict:
    """Per (panel, label): median over instances of the best cost within each link budget.

    For each instance, a method's best cost under budget b is the lowest cost among
    its designs with at most b links (None = any number); instances where no design
    fits count as missing. ``budgets`` default to each panel's own (1, 3 and 7 links
    per node, then any: :func:`compare.report.statistics.panel_budgets`). Returns
    ``{(panel, label): [(median, instances), ...]}``, one pair per budget.
    """
    out = {}
    for _, in_panel in sorted(as_records(records).by_panel.items()):
        grid = [np.inf if b is None else b for b in (panel_budgets(in_panel) if budgets is None else budgets)]
        out.update({key: [(quartiles(column)[1], int(np.isfinite(column).sum())) for column in best.T]
                    for key, best in best_tables(in_panel, grid).items() if np.isfinite(best).any()})
    return out


def plant_links(records) -> dict:
    """Median off-diagonal plant-graph links per panel: the QI boundary.

    Below this many links no communication graph relaying one hop per step is
    quadratically invariant, so no convex delay-constrained (SLS) design exists
    there. Link counts are the instance facts the store holds; the instance is never
    rebuilt, so a panel none of whose instances has a stored count (instances the
    runner could not build, a store written before facts were recorded) has no entry,
    and no boundary is drawn there.
    """
    out = {}
    for panel, rs in as_records(records).by_panel.items():
        links = [inst.plant_links for inst in rs.instances if inst.plant_links is not None]
        if links:
            out[panel] = float(np.median(links))
    return out


def report_records(records) -> Records:
    """The records as the report shows them: sorted, one label per kind of design, one name per method.

    ``sls_topologies`` runs SLS on several graphs under one label; the report gives each
    graph its own label ("SLS (plant graph, 1 hop/step)", ...), so that the infeasible
    given graph, the plant graph and the complete-graph bound are never one row. A label
    stored with the runs that only rewords the method's registered label ("Sparse K,
    delayed (l1)" for "Sparse delayed K (l1)") becomes the registered label
    (:func:`compare.report.tables.canonical_label`), so that a method has one name in
    every report.
    """
    from .tables import canonical_label, registered_labels

    registry = registered_labels()
    out = []
    for r in as_records(records):
        if r.method == "sls_topologies" and "graph" in r.params:
            graph = str(r.params["graph"])
            speed = r.params.get("speed", 1.0)
            hop = "1 hop/step" if speed == 1.0 else f"{speed:g} hops/step"
            r = replace(r, label=f"SLS ({_GRAPH_NAMES.get(graph, graph + ' graph')}, {hop})")
        else:
            name = canonical_label(r.method, r.label, registry)
            if name != r.label:
                r = replace(r, label=name)
        out.append(r)
    return Records(sorted(out, key=lambda r: (r.instance.key, r.label, r.run_key, r.idx)))


def _save(out: Path, files: dict, drawn: dict):
    """A ``save(fig, stem)`` that writes PNG and SVG and records the styles each figure drew."""

    def save(fig, stem: str) -> None:
        drawn[stem] = {label: sorted(list(pair) for pair in pairs) for label, pairs in drawn_styles(fig).items()}
        with plt.rc_context({"svg.hashsalt": "compare-report", "svg.fonttype": "path"}):
            files[f"{stem}.png"] = out / f"{stem}.png"
            files[f"{stem}.svg"] = out / f"{stem}.svg"
            fig.savefig(files[f"{stem}.png"], dpi=130, bbox_inches="tight", metadata={"Software": None})
            fig.savefig(files[f"{stem}.svg"], bbox_inches="tight", metadata={"Date": None, "Creator": None})
        plt.close(fig)

    return save


def _missing_lines(records: Records, points: list[Point], boundaries: dict) -> list[str]:
    """What the figures cannot show: methods with no usable design on a panel, paths that stop short."""
    notes = []
    empty = {key: rs for key, rs in records.by_panel_label.items() if not any(r.ok for r in rs)}
    # a method without a usable design on any of its panels (SLS on graphs it cannot design on): said once
    nowhere = {label for label, rs in records.by_label.items()
               if len({r.instance.panel for r in rs}) > 1 and not any(r.ok for r in rs)}
    for label in sorted(nowhere):
        rs = records.by_label[label]
        statuses = ", ".join(f"{s} {k}" for s, k in sorted(Counter(r.status for r in rs).items()))
        panels = len({r.instance.panel for r in rs})
        notes.append(f"{label} has no usable design on any of its {panels} panels ({statuses}); it is absent from "
                     "the figures' panels.")
    for (panel, label), rs in sorted(empty.items()):
        if label not in nowhere:
            statuses = ", ".join(f"{s} {k}" for s, k in sorted(Counter(r.status for r in rs).items()))
            notes.append(f"{label} has no usable design on {panel_title(panel)} ({statuses}); it is absent there.")
    given = {panel: float(np.median([i.comm_links for i in rs.instances if i.comm_links is not None] or [np.nan]))
             for panel, rs in records.by_panel.items()}
    for (panel, label), rs in sorted(records.by_panel_label.items()):
        settings = [p for p in points if p.panel == panel and p.label == label and p.ok]
        if len(settings) < 3 or rs[0].info_model != "delayed":
            continue
        sparsest = min(p.x for p in settings)
        short = [f"the given communication graph's {given[panel]:g}"] if sparsest > given.get(panel, np.inf) else []
        short += [f"the plant graph's {boundaries[panel]:g}"] if sparsest > boundaries.get(panel, np.inf) else []
        if short:
            notes.append(f"{label}'s sparsest setting on {panel_title(panel)} has {sparsest:g} links (median), more "
                         f"than {' and '.join(short)}: its grid does not reach sparser designs.")
    return (["What the figures cannot show:", ""] + [f"- {n}" for n in notes] + [""]) if notes else []


def write_report(records, out, *, specs: dict | None = None, title: str = "Comparison report",
                 commands: list[str] | None = None, load_controller=None, meta: Mapping | StoreMeta | None = None,
                 members: dict | None = None, superseded: int = 0, software: dict | None = None) -> dict[str, Path]:
    """Write the report into ``out``: report.md, report.html, figures, and the data that rebuild them.

    Parameters
    ----------
    records : Records or list of dict
        :meth:`compare.run.store.Store.records` (dicts shaped like the store's rows are
        converted, :meth:`compare.run.records.Records.from_rows`). No instance is built:
        what the report draws about an instance comes from the facts stored with
        its runs, and is left out where there are none.
    out : str or Path
        Output folder (created).
    specs : dict, optional
        Experiment name -> spec TOML text, shown verbatim.
    title : str
    commands : list of str, optional
        Commands that regenerate the report, shown at the top: the ``compare run``
        commands in order, then the one that rebuilds it from the folder alone.
    load_controller : callable, optional
        ``(run_key, idx) -> controller`` (e.g. :meth:`Store.controller`), for the
        designed-topology figure.
    meta : dict or StoreMeta, optional
        :meth:`Store.meta` (or its :class:`compare.run.meta.StoreMeta`, parsed once here
        otherwise): the sections each experiment asks for, what each method declares
        it produces and code fingerprints. Sections come from these declarations
        only. ``report.json`` keeps it as given.
    members : dict, optional
        :meth:`Store.members`: experiment name -> its run keys.
    superseded : int
        Stored runs of code that has changed since (not in ``records``), said in the report.
    software : dict, optional
        Package -> version to print; default the installed versions (a rebuild from a
        report folder passes the versions the folder recorded).

    Returns
    -------
    dict
        Name -> path of every file written.
    """
    from .decomposition import decomposition_section
    from .graph_gaps import graph_gap_section
    from .findings import select_comparisons, unresolved
    from .findings_text import findings_markdown
    from .folder import write_folder
    from .forest import forest_figures, splice_forest
    from .html import render_html, write_plotly_js
    from .interactive import budget_fronts_figure, cost_links_figure, figure_div

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    records = report_records(records)
    meta, members = StoreMeta.of(meta), dict(members or {})
    software = dict(software) if software else software_versions()
    styles = label_styles(records)
    points = aggregate(records)
    boundaries = plant_links(records)
    instances = {panel: len(rs.by_instance) for panel, rs in records.by_panel.items()}
    files, drawn = {}, {}
    save = _save(out, files, drawn)

    comparisons = select_comparisons(records, pairs=asked_pairs(records, meta))
    forest_stems = []  # the forest in parts of at most 20 rows (forest.png, forest-2.png, ...)
    if comparisons:
        for stem, fig in forest_figures(comparisons, styles):
            save(fig, stem)
            forest_stems.append(stem)
    for stale in out.glob("forest-*.*"):  # parts of an earlier, longer forest
        if stale.suffix in (".png", ".svg") and stale.stem not in forest_stems:
            stale.unlink()
    fronts = budget_fronts(records)
    if fronts:
        fig, _ = plot_budget_fronts(fronts, styles=styles, boundaries=boundaries)
        save(fig, "budget_fronts")
    fig, _ = plot_cost_vs_links(points, records=records, styles=styles, boundaries=boundaries, instances=instances)
    save(fig, "cost_vs_links")

    runs = {r.run_key for r in records}
    statuses = Counter(r.status for r in records)
    lines = [f"# {title}", ""]
    lines += answer_lines(records, comparisons, meta=meta, members=members)
    if comparisons:
        lines += splice_forest(findings_markdown(comparisons, excluded_total=len(unresolved(records)),
                                                 records=records), forest_stems, comparisons)
    lines += graph_gap_section(records, save)
    lines += decomposition_section(records, save)
    lines += [
        "## What was compared", "",
        f"{_count(len(runs), 'run')} on {_count(len(records.instances), 'instance')} ({_panels_text(instances)}), "
        f"{_count(len(records), 'design')} by {_count(len(records.by_label), 'method')}. Costs are E[J] / trace(P) over the horizon, so centralized LQR "
        "costs 1 and figures show the *excess cost* J − 1 over it (0.1 % = 0.001); links are directed "
        "off-diagonal communication links. Every method runs on the same instances, so methods are compared "
        "instance by instance. How it was computed, and how to rebuild it, is at the end.",
        "",
    ]
    lines += systems_table(records)
    if fronts:
        lines += [
            "## Best cost within a link budget", "", "![budget fronts](budget_fronts.png)", "",
            "For a budget of L links, each method's best cost on an instance is the lowest cost among its designs "
            "there with at most L directed off-diagonal links. The curve, the method's *budget front*, is the median "
            "of that over the instances "
            "the method ran on, an instance without a design within the budget counting as worse than any, so it "
            "starts (at its marker) where more than half of them have one, and every point of it is reached on at "
            "least half of them; these are the per-instance quantities the findings compare. "
            + ("The band is the 25–75 % range across those instances (their spread, not the uncertainty of the "
               "median). " if bands_drawn(fronts) else
               f"The 25–75 % bands across instances are left out: a panel has more than {MAX_BANDS} methods, "
               "and their bands would cover each other. ")
            + "Line styles give the information model; designs closer to LQR than the axis reaches (LQR itself "
            "among them) sit on its bottom edge.", "",
        ]
        lines += budget_tables(records)
    lines += _missing_lines(records, points, boundaries)
    lines += pattern_gap_section(records)
    lines += delayed_section(records, save, styles, boundaries)
    lines += [
        "## Cost against links", "", "![cost versus links](cost_vs_links.png)", "",
        "Each faint dot is one instance's design, and each line a method's budget front, as above, in its "
        "information model's line style ("
        + "; ".join(f"{v['linestyle']} {v['description']}" for v in INFO_STYLE.values())
        + "). Each marker is one *setting* of a method, one value of its path's weight (γ or β), as the paper's "
        "Fig. 3 draws it: the median link count of its designs (the lower median, a count some design has) against "
        "their median cost. The two "
        "medians are taken separately, not per instance, so a marker is drawn only where it lies on or above its "
        "method's front at its link count: then at least half of the instances reach it (some design of the "
        "method there has no more links and no more cost), and no marker stands below the front it summarizes"
        + _hidden_settings_text(points) + f". Medians above {OFF_SCALE:g} × LQR are triangles on the top edge "
        "with their value.", "",
    ]
    lines += paired_lines(records, meta)
    lines += ["## Medians by method", ""]
    lines += summary_tables(points, records)
    lines += ["## Pareto fronts", "", "Settings no other setting of the same method beats on both links and median "
              "cost, among the settings whose summary point some design reaches (as drawn).", ""]
    lines += pareto_tables(points)
    if boundaries:
        lines += ["The dotted vertical line in the figures (\"QI boundary\" in their legends) is the median "
                  "number of off-diagonal plant-graph links: below it no communication graph relaying one "
                  "hop per step is quadratically invariant on this family, so no convex delay-constrained "
                  "design with the GRNN's information model exists there (docs/information-models.md).", ""]
    learning, supports = learning_sections(records, save, styles, load_controller, meta, members)
    lines += learning
    _, timed = experiments_with("compute", records, meta, members)
    if timed:
        from .compute_report import compute_section

        lines += compute_section(timed, save, styles)
    lines += _provenance_lines(records, meta, commands, superseded, statuses, software)
    lines += ["## Files", ""]
    lines += [f"- `{p.name}`" for key, p in sorted(files.items()) if key.endswith((".png", ".svg"))]
    lines += ["- `runs.csv`: every design of every run, with its run's timings", "- `curves.csv`: training curves",
              "- `report.json`: what the report needs besides (store metadata, supports drawn, software)",
              "- `report.html` and `plotly.min.js`: this page with interactive figures, no network needed", ""]
    for name, text in sorted((specs or {}).items()):
        lines += [f"## Spec `{name}`", "", "```toml", text.strip(), "```", ""]

    files.update(write_folder(records, out, meta=meta.to_mapping(), members=members, superseded=superseded,
                              software=software, supports=supports, figures=drawn))
    files["md"] = out / "report.md"
    files["md"].write_text("\n".join(lines) + "\n")
    interactive = {"cost_vs_links.png": figure_div(
        cost_links_figure(records, styles, boundaries=boundaries, instances=instances), "fig-cost-vs-links")}
    if fronts:
        interactive["budget_fronts.png"] = figure_div(budget_fronts_figure(fronts, styles, boundaries=boundaries),
                                                      "fig-budget-fronts")
    files["plotly.min.js"] = write_plotly_js(out)
    files["html"] = out / "report.html"
    files["html"].write_text(render_html(files["md"].read_text(), out, title, interactive))
    return files


def _hidden_settings_text(points: list[Point]) -> str:
    """How many settings' medians the figure leaves out because they lie below their method's front."""
    usable = [p for p in points if p.ok]
    hidden = [p for p in usable if not p.reached]
    if not hidden:
        return f" (all {len(usable)} settings here are)"
    return (f"; {len(hidden)} of the {len(usable)} settings here are not, and have no marker (the medians table "
            "below lists every setting)")


def _count(k: int, noun: str) -> str:
    """"1 run", "3 runs": a count in plain words."""
    return f"{k} {noun}{'' if k == 1 else 's'}"


def _panels_text(instances: dict) -> str:
    counts = sorted(set(instances.values()))
    each = (f"{counts[0]} instance{'s' if counts[0] != 1 else ''} per panel" if len(counts) == 1
            else "instances per panel: " + ", ".join(map(str, counts)))
    return f"{len(instances)} panel{'s' if len(instances) != 1 else ''}, {each}"


def _provenance_lines(records: Records, meta: StoreMeta, commands, superseded: int, statuses: Counter,
                      software: dict) -> list[str]:
    """How the report was computed: where, with what estimator and precision, by which code, with what outcome."""
    lines = ["## How this report was computed", ""]
    if commands:
        *run_commands, rebuild = commands
        how = "Regenerate with " + " then ".join(f"`{c}`" for c in run_commands) if run_commands else ""
        how += (" (runs already in the store are skipped), or rebuild this report from its folder alone "
                "(`runs.csv`, `curves.csv`, `report.json`) with " if run_commands
                else "Rebuild this report from its folder alone with ") + f"`{rebuild}`."
        lines += [how, ""]
    lines += environment_lines(meta)
    lines += [
        "Exact closed-form costs for linear controllers; for learned ones an estimate on the validation set "
        "(the same initial states for every method on an instance)" + precision_text(records) + "."
        + uncertain_text(records)
        + (f" The store also holds {superseded} runs made by code that has changed since; they are not "
           "shown (see Code fingerprints)." if superseded else ""), "",
    ]
    lines += fingerprint_lines(records, meta)
    lines += ["## Runs by status", "", "| status | designs |", "|---|---:|"]
    lines += [f"| {status} | {count} |" for status, count in sorted(statuses.items())]
    failures = records.filter(lambda r: r.status != OPTIMAL)
    if failures:
        lines += ["", f"Non-optimal designs ({min(20, len(failures))} of {len(failures)}):", "",
                  "| instance | method | status | message |", "|---|---|---|---|"]
        for r in failures[:20]:
            inst = ", ".join(f"{k}={v}" for k, v in r.instance.spec.items() if k != "family")
            message = textwrap.shorten(r.message or "", width=200, placeholder=" …")
            lines.append(f"| {inst} | {r.label} | {r.status} | {message} |")
    lines += ["", "## Software", "", "| package | version |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in software.items()]
    return lines + [""]
