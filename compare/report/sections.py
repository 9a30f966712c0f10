"""Report sections that draw a figure of their own: delayed information, Table 1, training curves, topologies.

Each section function returns its Markdown lines and saves its figures through the
``save`` callable it is given (``save(fig, stem)``), so that the report decides where
files go and records what each figure drew.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ..run.meta import MethodMeta, StoreMeta
from ..run.records import OK_STATUSES, Records, as_records
from .figures import plot_budget_fronts
from .statistics import budget_fronts

__all__ = ["sls_bounds", "delayed_section", "learning_sections", "experiments_with", "topology_path"]


def sls_bounds(records) -> dict:
    """Panel -> (median, instances) of SLS on the complete graph at one hop per step, act_delay 1.

    No controller with the delayed information model beats it on its instance
    (partially nested information: the optimum is linear, and SLS finds it).
    """
    from .findings import is_sls_bound

    per_panel = defaultdict(list)
    for r in as_records(records):
        if is_sls_bound(r) and r.status in OK_STATUSES:
            per_panel[r.instance.panel].append(r.cost)
    return {panel: (float(np.median(v)), len(v)) for panel, v in per_panel.items()}


def delayed_section(records, save, styles: dict, boundaries: dict) -> list[str]:
    """Budget fronts of the methods with the delayed information model, under the SLS bound."""
    records = as_records(records)
    delayed = records.filter(lambda r: r.info_model == "delayed")
    if len(delayed.by_label) < 2:
        return []
    bounds = sls_bounds(records)
    fronts = budget_fronts(delayed)
    fig, _ = plot_budget_fronts(fronts, styles=styles, boundaries=boundaries,
                                bounds={k: (v, "SLS, complete graph (bound)") for k, (v, _) in bounds.items()})
    save(fig, "delayed_fronts")
    return ["## Delayed information only", "", "![delayed fronts](delayed_fronts.png)", "",
            "The budget fronts of the designs whose links carry information one step per hop, the GRNN's "
            "information model; the Findings above compare them instance by instance."
            + (" The dash-dotted line is the median over instances of SLS on the complete graph at one hop per "
               "step: with communication as fast as the plant the information is partially nested, so that SLS "
               "optimum is the best cost any controller, linear or not, reaches with this information on its "
               "instance (`tests/test_lower_bound.py` checks that none of the delayed designs beats it)."
               if bounds else ""), ""]


def experiments_with(section: str, records: Records, meta: StoreMeta, members: dict) -> tuple[list[str], Records]:
    """The experiments that ask for ``section`` and the records of their runs."""
    names = sorted(name for name, sections in meta.sections.items() if section in sections)
    keys = set().union(*(members.get(n, set()) for n in names)) if names else set()
    # A store written before experiments recorded their members: a run belongs to the one that computed it.
    unlisted = {n for n in names if not members.get(n)}
    return names, records.filter(lambda r: r.run_key in keys or r.experiment in unlisted)


def _producing(product: str, meta: StoreMeta) -> dict[str, MethodMeta]:
    """Method name -> its stored declaration, for methods that declare ``product``."""
    return {name: declared for name, declared in meta.methods.items() if product in declared.produces}


def topology_path(records, meta: StoreMeta) -> tuple[list, str | None]:
    """The designs the topology figure draws and the name of their path's weight (``[]``, None if none).

    The path of the first method, by name, that declares a ``topology_path``
    (:func:`compare.report.topologies.topology_path_records` picks the instance).
    """
    from .topologies import topology_path_records

    for name, declared in sorted(_producing("topology_path", meta).items()):
        path = topology_path_records(records, method=name, weight=declared.path_param)
        if path:
            return path, declared.path_param
    return [], None


def _drawing_of(instance, entries):
    """What the topology figure draws of ``instance``, or None to leave the figure out.

    The drawing the runner stored with the instance's facts; nothing is built. None
    for an instance without one (not built by the runner, more than
    :data:`compare.report.topologies.DRAWN_NODES_AT_MOST` nodes, a store or report folder
    written before drawings were stored) and where a support does not fit its nodes.
    """
    # getattr: a `compare run` that started before drawings were stored holds the older InstanceRecord
    # (its records module loaded then), while this module is imported only when it writes its report.
    drawing = getattr(instance, "drawing", None)
    if drawing is None or len(entries) < 2:
        return None
    shape = (drawing.nodes, drawing.nodes)
    return drawing if all(np.shape(support) == shape for *_, support in entries) else None


def learning_sections(records: Records, save, styles: dict, load_controller, meta: StoreMeta,
                      members: dict) -> tuple[list[str], dict]:
    """Sections the data asks for: Table 1 and training curves of the experiments that declare them,
    and the designed-topology path of a method that declares one.

    Returns the lines and the supports drawn in the topology figure,
    ``{(run_key, idx): support}``, so that the report folder can keep them.
    """
    from .learning_report import table1_markdown, training_curves_figure
    from .topologies import plot_topology_path, topology_caption

    lines, supports = [], {}
    names, table1 = experiments_with("table1", records, meta, members)
    if table1:
        lines += ["## Table 1 (paper §IV-A)", "", f"From experiment {', '.join(names)}.", "", table1_markdown(table1), ""]
    names, curved = experiments_with("training_curves", records, meta, members)
    producing = _producing("training_curve", meta)
    curved = curved.filter(lambda r: r.method in producing and "curve" in r.extras)
    if curved:
        fig, _ = training_curves_figure(curved, styles=styles)
        save(fig, "training_curves")
        lines += ["### Training curves (paper Fig. 2)", "", f"From experiment {', '.join(names)}: median and "
                  f"25–75 % band over the {len(curved.instances)} instance{'' if len(curved.instances) == 1 else 's'} "
                  "of the selection-set cost during training.", "", "![training curves](training_curves.png)", ""]
    path, weight = topology_path(records, meta)
    if len(path) >= 2 and load_controller is not None:
        instance = path[0].instance
        spec = {k: v for k, v in instance.spec.items() if k != "family"}
        entries = []
        for r in path:
            try:
                support = getattr(load_controller(r.run_key, r.idx), "support", None)
            except KeyError:
                support = None
            if support is not None:
                supports[(r.run_key, r.idx)] = np.asarray(support) != 0
                entries.append((r.params[weight], r.links, r.cost, support))
        drawing = _drawing_of(instance, entries)
        if drawing is not None:
            symbol = "β" if weight == "beta" else weight
            fig, _ = plot_topology_path(drawing, entries, symbol=symbol)
            save(fig, "topologies")
            inst = ", ".join(f"{k} = {v}" for k, v in spec.items())
            lines += [f"## Designed topologies along the {symbol} path (paper Fig. 4)", "",
                      f"{path[0].label} on one instance ({inst}). " + topology_caption(drawing.nodes, symbol=symbol), "",
                      "![designed topologies](topologies.png)", ""]
    return lines, supports
