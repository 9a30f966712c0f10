"""Graph against controller: which part of a method's excess is its graph, which its controller.

Every design reads a communication graph G (its off-diagonal support; the harness
stamps its hash, ``extras["graph"]``, and refits carry the graph they were given).
Per instance and information model, the *graph's value* V(G) is the lowest cost of
any usable design on exactly G in that model: its refits (:func:`baselines.refit`:
delayed static gain, SLS, warm-started GRNN; instantaneous static gain) and the
designs that chose G themselves, so that no design costs less than its graph's
value. Designs that need no information (``none``: u = 0, the diagonal gain) count
in both models. Within a link budget b, the best value is the lowest V over every
graph the experiment found with at most b links. A method's best design within b,
on graph G, then splits its excess over that best value into

    graph gap      = V(G) − min {V(G') : G' found with ≤ b links}     (≥ 0)
    controller gap = cost(design) − V(G)                               (≥ 0)

which add up to its excess. Each is paired over the instances of a system (a family
at one size, its panels pooled) and summarized by its median and a distribution-free
95 % interval (:func:`compare.report.statistics.median_interval`); medians do not add.

The learned controller on the best static graph: per instance and budget, the graph
G* among those with ≤ b links that carry both a delayed static refit and a GRNN refit
where the delayed static gain costs least, and the GRNN's refit cost on G* minus the
static gain's (negative: the trained GRNN beats the static gain on the same graph
with the same information).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..run.records import OK_STATUSES, as_records
from .decomposition import system_of, system_title
from .names import MAX_WORDS, join_words, short_names, words
from .statistics import median_interval, panel_budgets

__all__ = ["GapRow", "LearnedRow", "graph_values", "graph_gaps", "learned_on_best_graph", "graph_gap_section",
           "graph_gap_sentences", "plot_graph_gaps", "MODELS", "L1_PATHS", "OPENING_BUDGETS", "is_refit"]

#: The information models a graph is valued in (``none`` designs count in both).
MODELS = ("delayed", "instantaneous")
_DELAYED_STATIC = "delayed_static_gain"
#: The methods the opening calls the l1 paths: sparse gains from a weighted-l1 penalty swept over a grid.
L1_PATHS = ("sparse_delayed", "sparse_admm", "sparse_newton", "sparse_sdp")
#: The budgets the opening states the gaps at (links; those of them the system's panels have).
OPENING_BUDGETS = (20, 60)


def is_refit(r) -> bool:
    return r.method == "refit"


def _graph(r):
    return (r.extras or {}).get("graph")


def _graph_links(r):
    return int((r.extras or {}).get("graph_links", r.links))


def _models(r) -> tuple:
    return MODELS if r.info_model == "none" else (r.info_model,) if r.info_model in MODELS else ()


def _usable(r) -> bool:
    return r.status in OK_STATUSES and np.isfinite(r.cost) and _graph(r) is not None


def graph_values(records) -> dict:
    """(instance key, model, graph hash) -> (links, V): the lowest usable cost on exactly that graph."""
    values: dict = {}
    for r in as_records(records):
        if not _usable(r):
            continue
        for model in _models(r):
            key = (r.instance.key, model, _graph(r))
            links = _graph_links(r)
            if key not in values or r.cost < values[key][1]:
                values[key] = (links, float(r.cost))
    return values


def _best_values(values: dict, instance: str, model: str, budgets) -> dict:
    """Budget -> the lowest V over the graphs of ``instance`` in ``model`` with at most that many links."""
    mine = [(links, v) for (i, m, _), (links, v) in values.items() if i == instance and m == model]
    return {b: min((v for links, v in mine if b is None or links <= b), default=np.inf) for b in budgets}


@dataclass(frozen=True)
class Part:
    """A paired median over instances with its interval and the count it rests on."""

    median: float
    low: float
    high: float
    coverage: float
    instances: int

    @classmethod
    def of(cls, values) -> "Part":
        values = np.asarray(values, dtype=float)
        low, high, coverage = median_interval(values)
        return cls(float(np.median(values)) if values.size else float("nan"), low, high, coverage, int(values.size))


@dataclass(frozen=True)
class GapRow:
    """One method's graph and controller gaps on one system within one budget (LQR-normalized)."""

    system: tuple
    label: str
    model: str
    budget: int | None
    excess: Part
    graph: Part
    controller: Part
    method: str = ""


def _method_designs(records) -> dict:
    """(system, label, model) -> instance key -> usable designs with a graph (refits excluded)."""
    out: dict = defaultdict(lambda: defaultdict(list))
    for r in as_records(records):
        if is_refit(r) or r.method == "lqr" or not _usable(r) or r.info_model not in MODELS:
            continue
        out[(system_of(r), r.label, r.info_model)][r.instance.key].append(r)
    return out


def _method_of(by_instance) -> str:
    return next((r.method for designs in by_instance.values() for r in designs), "")


def _refit_graphs(records) -> set:
    """(instance key, model, graph) of every graph refit in that model, whatever the refit's status."""
    return {(r.instance.key, model, _graph(r)) for r in records if is_refit(r) and _graph(r) is not None
            for model in _models(r)}


def graph_gaps(records) -> list[GapRow]:
    """Every method's gaps per system and budget (:data:`GapRow`).

    An instance counts where the method's best design within the budget is on a graph refit in
    its information model (else its graph's value would be its own cost, by no search).
    """
    records = as_records(records)
    if not any(is_refit(r) for r in records):
        return []
    values = graph_values(records)
    refit = _refit_graphs(records)
    budgets_of = {s: panel_budgets(rs) for s, rs in records.group(system_of).items()}
    rows = []
    for (system, label, model), by_instance in sorted(_method_designs(records).items(), key=lambda kv: str(kv[0])):
        for budget in budgets_of[system]:
            excess, graph, controller = [], [], []
            for instance, designs in by_instance.items():
                within = [r for r in designs if budget is None or r.links <= budget]
                if not within:
                    continue
                best = min(within, key=lambda r: (r.cost, r.links))
                if (instance, model, _graph(best)) not in refit:
                    continue
                value = values[(instance, model, _graph(best))][1]
                floor = _best_values(values, instance, model, [budget])[budget]
                excess.append(best.cost - floor)
                graph.append(value - floor)
                controller.append(best.cost - value)
            if excess:
                rows.append(GapRow(system, label, model, budget, Part.of(excess), Part.of(graph), Part.of(controller),
                                   method=_method_of(by_instance)))
    return rows


@dataclass(frozen=True)
class LearnedRow:
    """GRNN refit − delayed static refit on each instance's best static graph within a budget."""

    system: tuple
    activation: str
    budget: int | None
    difference: Part
    grnn_wins: int
    static_wins: int
    links: float  # median links of the graphs compared


def _refits_by_graph(records) -> dict:
    """(instance, graph) -> {"static": cost, ("grnn", activation): cost} of the refits there."""
    out: dict = defaultdict(dict)
    for r in as_records(records):
        if not _usable(r) or r.info_model != "delayed":
            continue
        cls = (r.extras or {}).get("controller_class")
        key = (r.instance.key, _graph(r))
        if cls == "grnn" and is_refit(r):
            arm = ("grnn", r.params.get("activation", "tanh"))
        elif cls == "delayed" or r.controller_kind == _DELAYED_STATIC:
            arm = "static"
        else:
            continue
        if arm not in out[key] or r.cost < out[key][arm][0]:
            out[key][arm] = (float(r.cost), _graph_links(r))
    return out


def learned_on_best_graph(records) -> list[LearnedRow]:
    """Per system, GRNN activation and budget: the GRNN against the static gain on the best static graph."""
    records = as_records(records)
    by_graph = _refits_by_graph(records)
    rows = []
    for system, rs in sorted(records.group(system_of).items(), key=lambda kv: str(kv[0])):
        instances = {r.instance.key for r in rs}
        activations = sorted({arm[1] for (i, _), arms in by_graph.items() if i in instances
                              for arm in arms if isinstance(arm, tuple)})
        for activation in activations:
            for budget in panel_budgets(rs):
                diffs, links = [], []
                for instance in sorted(instances):
                    here = [(arms["static"][0], arms[("grnn", activation)][0], arms["static"][1])
                            for (i, _), arms in by_graph.items()
                            if i == instance and "static" in arms and ("grnn", activation) in arms
                            and (budget is None or arms["static"][1] <= budget)]
                    if here:
                        static, grnn, n_links = min(here)
                        diffs.append(grnn - static)
                        links.append(n_links)
                if diffs:
                    d = np.asarray(diffs)
                    rows.append(LearnedRow(system, activation, budget, Part.of(d), int((d < 0).sum()),
                                           int((d > 0).sum()), float(np.median(links))))
    return rows


# -- text ------------------------------------------------------------------------------
def _budget(b) -> str:
    return "any" if b is None else f"≤ {b:g}"


def _pct(x: float) -> str:
    """A cost difference (× LQR) in per cent of LQR's cost, at a precision the 4th decimal supports."""
    if not np.isfinite(x):
        return "–"
    text = f"{100 * x:+.2f} %".replace("-", "−")
    return "0 %" if text in ("+0.00 %", "−0.00 %") else text


def _cell(p: Part) -> str:
    if not p.instances:
        return "–"
    if p.instances == 1:  # one instance: its value, no interval
        return _pct(p.median)
    cover = f" ({p.coverage:.0%})" if p.coverage < 0.95 else ""
    return f"{_pct(p.median)} [{_pct(p.low)}, {_pct(p.high)}]{cover}"


def _main_system(rows) -> tuple:
    """The system the opening speaks of: the one with the most paired instances (then by name)."""
    return max({r.system for r in rows},
               key=lambda s: (sum(r.excess.instances for r in rows if r.system == s), str(s)))


def _opening_budgets(rows) -> list:
    found = {r.budget for r in rows}
    return [b for b in OPENING_BUDGETS if b in found] or sorted(b for b in found if b is not None)[:1]


def _within(budgets) -> str:
    return f"within {join_words([f'{b:g}' for b in budgets])} links"


def _stated(*candidates) -> str | None:
    """The first candidate sentence of at most :data:`MAX_WORDS` words (None if none is)."""
    return next((c for c in candidates if c and words(c) <= MAX_WORDS), None)


def _grnn_sentence(here, budgets, title: str) -> str | None:
    """GRNN-Sparse's graph gap and controller gap at each opening budget, with intervals."""
    grnn = [r for r in here if r.method == "grnn_sparse" and r.budget in budgets and r.graph.instances]
    if not grnn:
        return None
    names = short_names({r.label for r in grnn})
    label = min({r.label for r in grnn}, key=lambda x: (names[x] != "GRNN-Sparse", x))
    mine = sorted((r for r in grnn if r.label == label), key=lambda r: budgets.index(r.budget))
    parts = [f"{_pct(r.graph.median)} {_interval(r.graph)} and {_pct(r.controller.median)} {_interval(r.controller)} "
             f"within {r.budget:g} links" for r in mine]
    short = [f"{_pct(r.graph.median)} and {_pct(r.controller.median)} within {r.budget:g} links" for r in mine]
    lead = f"On {title}, {names[label]}'s graph gap and controller gap, in % of LQR's cost, are"
    return _stated(f"{lead} {'; '.join(parts)}.", f"{lead} {'; '.join(short)} (medians).")


def _zero(p: Part) -> bool:
    return p.median == 0 and p.high == 0 and p.low == 0


def _paths_sentence(here, budgets) -> str | None:
    """Which graphs the l1 paths pick (their graph gaps) and their controller gaps at the opening budgets."""
    paths = [r for r in here if r.method in L1_PATHS and r.budget in budgets and r.graph.instances]
    if not paths:
        return None
    labels = list(dict.fromkeys(r.label for r in sorted(paths, key=lambda r: r.label)))
    names = short_names(labels)
    by_label = {x: sorted((r for r in paths if r.label == x), key=lambda r: budgets.index(r.budget)) for x in labels}

    def controller(x, intervals: bool) -> str:
        rows = by_label[x]
        if all(_zero(r.controller) for r in rows):
            return f"0 % for {names[x]}"
        values = [_pct(r.controller.median) + (f" {_interval(r.controller)}" if intervals else "") for r in rows]
        return f"{join_words(values)} for {names[x]}"

    if all(r.graph.median == 0 for r in paths):
        top = max(r.graph.high for r in paths)
        lead = (f"The ℓ1 paths pick the best graphs {_within(budgets)} (median graph gap 0"
                + (")" if top == 0 else f", intervals up to {_pct(top)})"))
    else:
        lead = "The ℓ1 paths' graph gaps are " + join_words(
            f"{names[x]}'s {join_words(_pct(r.graph.median) for r in by_label[x])}" for x in labels) + \
            f" {_within(budgets)}"
    return _stated(f"{lead}; controller gaps: {', '.join(controller(x, True) for x in labels)}.",
                   f"{lead}; controller gaps: {', '.join(controller(x, False) for x in labels)}.",
                   f"{lead}.")


def _verdict(p: Part) -> str:
    return "beats" if p.high < 0 else "costs more than" if p.low > 0 else "does not clearly beat"


def _learned_sentence(learned, system, budgets) -> str | None:
    """Whether the trained GRNN on the best static graph beats the static gain on it, per opening budget."""
    mine = [x for x in learned if x.system == system and x.budget in budgets]
    activation = "tanh" if any(x.activation == "tanh" for x in mine) else min((x.activation for x in mine),
                                                                             default=None)
    mine = sorted((x for x in mine if x.activation == activation), key=lambda x: budgets.index(x.budget))
    if not mine:
        return None
    verdicts = {_verdict(x.difference) for x in mine}
    values = [f"{_pct(x.difference.median)} {_interval(x.difference)}" for x in mine]
    subject = f"the trained {activation} GRNN"
    if len(verdicts) == 1:
        lead = f"On the best static graph {_within([x.budget for x in mine])}, {subject} {verdicts.pop()} the static gain"
        return _stated(f"{lead} on it: {join_words(values)}.", f"{lead} on it.")
    bare = [f"within {x.budget:g} links it {_verdict(x.difference)} it" for x in mine]
    lead = f"Against the static gain on the best static graph, {subject}:"
    return _stated(f"{lead} {'; '.join(f'{b} ({v})' for b, v in zip(bare, values))}.", f"{lead} {'; '.join(bare)}.")


def graph_gap_sentences(records) -> list[str]:
    """The opening's three sentences where the records hold refits (:mod:`compare.report.answer`, rule (0'')).

    On the system with the most instances: GRNN-Sparse's graph gap and controller gap within
    :data:`OPENING_BUDGETS` links, with intervals; which graphs the l1 paths pick (their graph gaps)
    and their controller gaps; and whether the trained GRNN on the best static graph beats
    the static gain on it. Each at most :data:`~compare.report.names.MAX_WORDS` words; every
    number one the section's tables print.
    """
    records = as_records(records)
    rows = graph_gaps(records)
    if not rows:
        return []
    system = _main_system(rows)
    here = [r for r in rows if r.system == system]
    budgets = _opening_budgets(here)
    title = system_title(system)
    learned = learned_on_best_graph(records)
    return [s for s in (_grnn_sentence(here, budgets, title), _paths_sentence(here, budgets),
                        _learned_sentence(learned, system, budgets)) if s]


def _interval(p: Part) -> str:
    return f"[{_pct(p.low)}, {_pct(p.high)}]"


def graph_gap_section(records, save=None) -> list[str]:
    """The report section: the split per system, method and budget, and the GRNN on the best static graph."""
    records = as_records(records)
    rows = graph_gaps(records)
    if not rows:
        return []
    learned = learned_on_best_graph(records)
    lines = ["## Graph against controller", ""]  # its answer is the report's opening (graph_gap_sentences)
    if save is not None:
        from .styles import label_styles

        fig, _ = plot_graph_gaps(rows, styles=label_styles(records))
        save(fig, "graph_gaps")
        lines += ["![graph and controller gaps](graph_gaps.png)", ""]
    lines += [
        "Every design reads a communication graph. A *refit* keeps a design's graph and fits the best controller "
        "of each class on it again (delayed static gain, SLS, a warm-started GRNN; the instantaneous static "
        "gain for designs with instantaneous information). The graph's *value* V(G) is the lowest cost any "
        "design reaches on exactly that graph in the same information model. Within a budget, a method's best "
        "design splits its excess over the best value of any graph found with that many links into its *graph "
        "gap* (its graph's value minus that best) and its *controller gap* (its cost minus its graph's value). "
        "Entries: median over instances in per cent of LQR's cost, 95 % interval in brackets (its coverage "
        "where fewer instances allow less); medians do not add.", ""]
    for system in dict.fromkeys(r.system for r in rows):
        here = [r for r in rows if r.system == system]
        lines += [f"### {system_title(system)}", "",
                  "| method | information | budget | instances | excess | graph gap | controller gap |",
                  "|---|---|---|---:|---:|---:|---:|"]
        lines += [f"| {r.label} | {r.model} | {_budget(r.budget)} | {r.excess.instances} | {_cell(r.excess)} | "
                  f"{_cell(r.graph)} | {_cell(r.controller)} |" for r in here]
        lines += [""]
    if learned:
        lines += ["### The learned controller on the best static graph", "",
                  "Per instance and budget, the graph with at most that many links on which the delayed static "
                  "gain costs least among those refit with both; the GRNN's cost there minus the static gain's "
                  "(negative: the trained GRNN is better with the same graph and the same information).", "",
                  "| system | activation | budget | instances | median links | GRNN − static | GRNN better |",
                  "|---|---|---|---:|---:|---:|---:|"]
        lines += [f"| {system_title(x.system)} | {x.activation} | {_budget(x.budget)} | {x.difference.instances} | "
                  f"{x.links:g} | {_cell(x.difference)} | {x.grnn_wins} of {x.difference.instances} |"
                  for x in learned]
        lines += [""]
    return lines


# -- figure ----------------------------------------------------------------------------
def _budget_order(budgets) -> list:
    return sorted(set(budgets), key=lambda b: (b is None, b or 0))


def plot_graph_gaps(rows, *, axes=None, styles=None):
    """Per system, each method's graph gap and controller gap side by side at each budget (median, 95 % interval).

    One panel per system (two across); within a budget's group each method has two bars, its graph gap
    (hatched, pale) and its controller gap (solid), in the method's colour (``styles``: label -> Style,
    as :func:`compare.report.styles.label_styles` gives). Returns (Figure, list of Axes).
    """
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    systems = list(dict.fromkeys(r.system for r in rows))
    labels = list(dict.fromkeys(r.label for r in rows))
    across = min(2, len(systems))
    down = -(-len(systems) // across)
    if axes is None:
        fig, grid = plt.subplots(down, across, figsize=(4.8 * across, 3.4 * down + 0.3 * (len(labels) + 3) // 2),
                                 squeeze=False)
        axes = list(grid.flat)
        for ax in axes[len(systems):]:
            ax.set_visible(False)
    fig = axes[0].figure
    palette = plt.get_cmap("tab10")

    def colour(label):
        style = (styles or {}).get(label)
        return style.colour if style is not None else palette(labels.index(label) % 10)

    for ax, system in zip(axes, systems):
        here = [r for r in rows if r.system == system]
        budgets = _budget_order(r.budget for r in here)
        mine = [label for label in labels if any(r.label == label for r in here)]
        width = 0.8 / (2 * max(1, len(mine)))
        for k, label in enumerate(mine):
            for part in ("graph", "controller"):
                xs, ys, lo, hi, kept = [], [], [], [], []
                for j, budget in enumerate(budgets):
                    row = next((r for r in here if r.label == label and r.budget == budget), None)
                    if row is None:
                        continue
                    kept.append(budget)
                    p = getattr(row, part)
                    xs.append(j - 0.4 + (2 * k + (part == "controller") + 0.5) * width)
                    ys.append(100 * p.median)
                    lo.append(100 * (p.median - p.low))
                    hi.append(100 * (p.high - p.median))
                graph = part == "graph"
                bars = ax.bar(xs, ys, width, color=colour(label), alpha=0.45 if graph else 0.95,
                              hatch="///" if graph else None, edgecolor="white" if graph else colour(label),
                              linewidth=0.0)
                for bar, budget in zip(bars, kept):  # what tests/test_graph_gaps_figure.py reads back
                    bar.set_gid(f"graph_gaps:{system_title(system)}:{label}:{part}:{_budget(budget)}")
                ax.errorbar(xs, ys, yerr=[lo, hi], fmt="none", ecolor="0.25", elinewidth=0.8, capsize=1.5)
        ax.axhline(0.0, color="0.5", linewidth=0.8)
        ax.set_xticks(range(len(budgets)), [_budget(b) for b in budgets])
        ax.set_xlim(-0.5, len(budgets) - 0.5)
        ax.set_xlabel("link budget")
        ax.set_ylabel("gap (% of LQR's cost)")
        ax.set_title(system_title(system), fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    handles = [Patch(facecolor="0.55", alpha=0.45, hatch="///", edgecolor="white", label="graph gap"),
               Patch(facecolor="0.3", label="controller gap")]
    handles += [Patch(facecolor=colour(label), label=label) for label in labels]
    rows_of_legend = (len(handles) + 1) // 2
    height = fig.get_size_inches()[1]
    fig.tight_layout(rect=(0, (0.22 * rows_of_legend + 0.05) / height, 1, 1))
    fig.legend(handles=handles, loc="lower center", ncol=2, fontsize=9, frameon=False, bbox_to_anchor=(0.5, 0.0))
    return fig, axes
