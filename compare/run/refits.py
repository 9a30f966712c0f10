"""The harness's second stage: refit runs planned from the graphs of stored designs.

A ``[[methods]]`` entry with ``sources`` names other entries (by method name or
label) whose designs' communication graphs it refits (:func:`baselines.refit`)::

    [[methods]]
    method = "refit"
    label = "Refit: delayed static gain"
    params = { controller = "delayed" }
    sources = ["grnn_sparse", "sparse_delayed"]
    budgets = [20, 60, "any"]     # optional: per instance, source and budget, only the graph
                                  # of the source's cheapest design within it

Its runs cannot be planned before the sources are stored: :func:`refit_runs` reads
the sources' designs from the store once the first stage is done, recovers each
usable design's graph (:func:`codesign.graphs.design_graph`), and plans one run per
distinct graph and instance, its ``graph`` parameter the graph's text. A refit is
keyed, stored, fingerprinted and resumed like any run; the same graph found by two
sources is one run. A source design with no graph (it failed, or its controller
does not say which links it reads) is not refit, and :func:`refit_runs` counts it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from codesign.graphs import design_graph, graph_links, graph_text

from .records import canonical_key
from .spec import ExperimentSpec, Run

__all__ = ["RefitPlan", "refit_runs", "has_refits"]


@dataclass
class RefitPlan:
    """The refit runs of an experiment and what was left out: source designs with no usable graph."""

    runs: list = field(default_factory=list)
    graphless: int = 0


def has_refits(spec: ExperimentSpec) -> bool:
    """Whether any entry of ``spec`` refits the graphs of other entries."""
    return any(m.sources for m in spec.methods)


class _Stored:
    """A stored source design as :func:`design_graph` reads it: its controller and its links."""

    def __init__(self, controller, links):
        self.controller, self.links = controller, links


def _chosen(records, budgets) -> list:
    """The usable records to refit: all, or per source entry and budget its cheapest within it (each once)."""
    usable = [r for r in records if r.ok and r.links is not None]
    if not budgets:
        return usable
    chosen = {}
    for label in dict.fromkeys(r.label for r in usable):
        for budget in budgets:
            within = [r for r in usable if r.label == label and (budget is None or r.links <= budget)]
            if within:
                best = min(within, key=lambda r: (r.cost, r.links))
                chosen[(best.run_key, best.idx)] = best
    return list(chosen.values())


def refit_runs(spec: ExperimentSpec, store, first: list[Run]) -> RefitPlan:
    """The refit runs of ``spec``'s ``sources`` entries, from the designs ``store`` holds of the ``first`` runs."""
    from .execution import build_instance
    from .registry import get_method
    from .fingerprint import fingerprint

    plan = RefitPlan()
    entries = [m for m in spec.methods if m.sources]
    if not entries:
        return plan
    keys = {run.key for run in first}
    records = store.records().filter(lambda r: r.run_key in keys)
    by_instance: dict = {}
    for r in records:
        by_instance.setdefault(r.instance.key, []).append(r)
    runs_of = {run.key: run for run in first}
    for entry in entries:
        prints = fingerprint(get_method(entry.method))
        for instance_spec in spec.instances.expand():
            if not entry.applies_to(instance_spec):
                continue
            mine = [r for r in by_instance.get(canonical_key(instance_spec), [])
                    if runs_of[r.run_key].method in entry.sources or runs_of[r.run_key].label in entry.sources]
            chosen = _chosen(mine, entry.budgets)
            if not chosen:
                continue
            instance = build_instance(instance_spec)
            graphs = {}
            for r in chosen:
                adj = design_graph(instance, _Stored(store.controller(r.run_key, r.idx), r.links))
                if adj is None:
                    plan.graphless += 1
                    continue
                graphs.setdefault(graph_text(adj), graph_links(adj))
            for text in sorted(graphs, key=lambda t: (graphs[t], t)):
                for params in entry.expand():
                    plan.runs.append(Run(instance_spec, entry.method, entry.label, {**params, "graph": text},
                                         spec.evaluation, prints, entry.timeout))
    plan.runs = list({run.key: run for run in plan.runs}.values())
    return plan

