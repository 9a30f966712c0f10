"""Why a learned design loses: its excess over the best delayed static design, in model class and training.

A GRNN-Sparse design with the paper's settings (one readout shared by every node, weights
drawn at random) costs more than the best static gain with the same information (own state
now, neighbours' one step late) on the paper's family (docs/methods.md, "What the GRNN can
represent"). Two reasons are possible: the model class (a shared readout cannot give two
nodes different local gains, while a per-node readout contains every delayed static gain)
and the training (a random start, far from a stabilizing controller). A report whose
records hold three kinds of GRNN-Sparse design of one activation,

- **paper**: shared readout, random start;
- **per-node**: per-node readout, random start;
- **warm**: per-node readout started from a delayed static design (``init = "delayed"``),

beside the delayed static designs, splits, per instance and link budget (each arm's best
cost within the budget, LQR-normalized),

    paper − static = (paper − per-node) + (per-node − warm) + (warm − static)
                   =   model class       +   training        +   what remains

where *static* is the best delayed static design on the instance within the budget (the
ℓ1 path's, or an exact-budget search's). Each part is a paired difference over instances
(:func:`compare.report.statistics.paired_difference`): its median with a distribution-free 95 %
interval. Medians do not add, so the parts' medians need not sum to the total's. Panels
of one family and size (the paper family's five ‖A‖₂) are pooled: every difference is
taken within its own instance, so the pooled differences are paired as the panels' are.

Beside it: each arm's excess over the SLS bound (the best cost any controller with the
delayed information reaches on its instance, whatever its links); tanh against linear at
equal information and links, per kind; and divergence, per system and arm: instances on
which some design diverged (every ensemble member's training), and, for warm starts, runs
whose training diverged or ended above the start, where the start was kept.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from codesign.status import DIVERGED

from .findings import is_sls_bound, is_unresolved
from .names import join_words
from ..run.records import Records, as_records
from .statistics import Paired, best_within, paired_difference, panel_budgets
from .styles import grnn_kinds

__all__ = ["ARMS", "Decomposition", "Nonlinearity", "Divergence", "decompose", "nonlinearity", "divergence",
           "decomposition_sentences", "decomposition_section", "plot_decomposition", "undecomposed", "system_of",
           "system_title"]

#: The arms, in order, and what each is.
ARMS = {"paper": "shared readout, random start", "per-node": "per-node readout, random start",
        "warm": "per-node readout, warm start from a delayed static design"}
#: The parts of the paper design's excess over the static one: (name, minuend arm, subtrahend arm).
PARTS = (("total", "paper", "static"), ("model class", "paper", "per-node"), ("training", "per-node", "warm"),
         ("remains", "warm", "static"))
_LEARNED = ("grnn", "grnn_sparse", "grnn_dense", "grnn_fixed", "gcnn")


def _arm(r) -> str | None:
    """Which arm a design belongs to, or None."""
    if r.method != "grnn_sparse":
        return None
    kinds = grnn_kinds(r.method, r.params)
    if not kinds:
        return "paper"
    if kinds == ["per_node"]:
        return "per-node"
    if len(kinds) == 2 and kinds[0] == "per_node" and kinds[1].startswith("warm_"):
        return "warm"
    return None


def _activation(r) -> str:
    return "linear" if r.params.get("activation") == "identity" else "tanh"


def _is_static_delayed(r) -> bool:
    return (r.info_model == "delayed" and r.method not in _LEARNED and not r.method.startswith("sls")
            and not is_sls_bound(r))


def system_of(r) -> tuple:
    """Panels pooled into one system: a family at one size; a published grid at one damping on its own
    (its panel's name, "ieee39 (d = 2)": two dampings of one grid are two systems)."""
    if "case" in r.instance.spec:
        return (r.instance.panel[0], None)
    return (r.instance.family, r.instance.nodes)


def system_title(system: tuple) -> str:
    family, n = system
    return f"{family}, N = {n}" if n is not None else str(family)


@dataclass(frozen=True)
class Decomposition:
    """The parts of one activation's paper-design excess on one system within one budget."""

    system: tuple
    activation: str
    budget: float | None
    panels: int
    instances: int  # the system's; each part pairs those where every arm has a design within the budget
    parts: dict  # part name -> Paired
    over_bound: dict  # arm ("paper", "per-node", "warm", "static") -> median excess over the SLS bound


@dataclass(frozen=True)
class Nonlinearity:
    """tanh − linear for one kind of GRNN-Sparse on one system within one budget."""

    system: tuple
    arm: str
    budget: float | None
    paired: Paired


@dataclass(frozen=True)
class Divergence:
    """How often one arm diverged on one system."""

    system: tuple
    arm: str
    activation: str
    instances: int
    diverged_instances: int  # instances with a design whose training diverged in every member
    designs: int
    diverged_designs: int
    kept_starts: int  # warm runs whose training diverged or ended above the start (the start kept)
    radius: float | None  # median open-loop spectral radius of the system's instances


def _usable(records: Records) -> Records:
    return records.filter(lambda r: r.ok and not is_unresolved(r))


def _tables(records: Records):
    """Per system: (instances, budgets, {(arm, activation) or "static" or "bound": best-within table})."""
    out = {}
    for system, rs in sorted(records.group(system_of).items(), key=lambda kv: tuple(map(str, kv[0]))):
        instances = sorted(rs.by_instance)
        budgets = tuple(panel_budgets(rs))
        grid = [np.inf if b is None else b for b in budgets]
        usable = _usable(rs)
        tables = {}
        for key, arm_rs in usable.group(lambda r: (_arm(r), _activation(r))).items():
            if key[0] is not None:
                tables[key] = best_within(arm_rs, instances, grid)
        static = usable.filter(_is_static_delayed)
        if len(static):
            tables["static"] = best_within(static, instances, grid)
        bound = usable.filter(is_sls_bound)
        if len(bound):
            tables["bound"] = best_within(bound, instances, [np.inf])[:, 0]
        out[system] = (instances, budgets, tables, len(rs.by_panel))
    return out


def decompose(records) -> list[Decomposition]:
    """The decomposition on every system whose records hold the paper, per-node and warm arms and a static design."""
    out = []
    for system, (instances, budgets, tables, panels) in _tables(as_records(records)).items():
        for activation in ("tanh", "linear"):
            arms = {arm: tables.get((arm, activation)) for arm in ARMS}
            if any(t is None for t in arms.values()) or "static" not in tables:
                continue
            arms["static"] = tables["static"]
            for j, budget in enumerate(budgets):
                # One set of instances for every part: those where each arm has a design within the budget.
                both = np.all([np.isfinite(t[:, j]) for t in arms.values()], axis=0)
                parts = {name: paired_difference(a, b, arms[a][both, j], arms[b][both, j], budget)
                         for name, a, b in PARTS}
                over = {}
                if "bound" in tables:
                    for arm, t in arms.items():
                        d = t[both, j] - tables["bound"][both]
                        d = d[np.isfinite(d)]
                        over[arm] = float(np.median(d)) if d.size else float("nan")
                out.append(Decomposition(system, activation, budget, panels, len(instances), parts, over))
    return sorted(out, key=lambda d: -d.instances)  # the largest system first (a stable sort keeps the rest)


def undecomposed(records) -> list[str]:
    """Why a system with some of the arms has no decomposition: the arms without any usable design there."""
    out = []
    for system, (_, _, tables, _) in _tables(as_records(records)).items():
        present = {key for key in tables if isinstance(key, tuple)}
        if not present:
            continue
        for activation in ("tanh", "linear"):
            missing = [arm for arm in ARMS if (arm, activation) not in tables]
            if missing and any(key[1] == activation for key in present):
                what = ", ".join(missing) + ("" if "static" in tables else "; no delayed static design")
                out.append(f"{system_title(system)}, {activation}: no usable design of {what}")
    return out


def nonlinearity(records) -> list[Nonlinearity]:
    """tanh − linear GRNN-Sparse per kind, system and budget (negative: the nonlinearity helps)."""
    out = []
    for system, (_, budgets, tables, _) in _tables(as_records(records)).items():
        for arm in ARMS:
            tanh, linear = tables.get((arm, "tanh")), tables.get((arm, "linear"))
            if tanh is None or linear is None:
                continue
            out += [Nonlinearity(system, arm, b, paired_difference(f"{arm} tanh", f"{arm} linear", tanh[:, j],
                                                                   linear[:, j], b)) for j, b in enumerate(budgets)]
    return out


def divergence(records) -> list[Divergence]:
    """Divergence of every arm on every system (all designs, usable or not)."""
    out = []
    for system, rs in sorted(as_records(records).group(system_of).items(), key=lambda kv: tuple(map(str, kv[0]))):
        radii = sorted(i.radius for i in rs.instances if i.radius is not None)
        # The upper median, a radius some instance has: what the systems table gives.
        radius = float(radii[len(radii) // 2]) if radii else None
        for (arm, activation), arm_rs in sorted(rs.group(lambda r: (_arm(r), _activation(r))).items(),
                                                key=lambda kv: (str(kv[0][0]), kv[0][1])):
            if arm is None:
                continue
            diverged = arm_rs.filter(lambda r: r.status == DIVERGED)
            kept = sum(bool(r.extras.get("kept_start")) for r in arm_rs)
            out.append(Divergence(system, arm, activation, len(arm_rs.by_instance), len(diverged.by_instance),
                                  len(arm_rs), len(diverged), kept, radius))
    return out


# --------------------------------------------------------------------------- wording


def _budget(b) -> str:
    return "any number of links" if b is None else f"≤ {b:g} links"


def _within(b) -> str:
    return "with any number of links" if b is None else f"within {b:g} links"


def _signed(p: Paired) -> str:
    """A paired median with its 95 % interval, at the precision the interval supports (as the tables print it)."""
    from .findings_text import estimate_text

    return estimate_text(p, coverage=True)


def _pct(x: float) -> str:
    if not np.isfinite(x):
        return "—"
    text = f"{100 * x:+.1f}"
    return "0 %" if float(text) == 0 else text.replace("-", "−") + " %"


_STARTS = {"delayed": "the delayed ℓ1 path's design", "diagonal": "the diagonal gain",
           "auto": "the diagonal gain or a random draw (init auto)"}


def _starts(records: Records, system: tuple) -> str:
    """What the warm starts on ``system`` started from, in words."""
    inits = sorted({str(r.params.get("init")) for r in records if _arm(r) == "warm" and system_of(r) == system})
    return " or ".join(_STARTS.get(i, i) for i in inits) or "a static design"


def _largest_sentence(rows: Sequence[Decomposition]) -> str:
    """Where the paper design's excess over the best delayed static design is largest, and what a warm start
    leaves of it there."""
    d = max((r for r in rows if r.parts["total"].instances), key=lambda r: r.parts["total"].median)
    p = d.parts
    name = "linear GRNN-Sparse" if d.activation == "linear" else "GRNN-Sparse"
    text = (f"On {system_title(d.system)}, the paper's {name} costs most above the best delayed static design "
            f"{_within(d.budget)}: {_signed(p['total'])} × LQR on {p['total'].instances} instances")
    remains = p["remains"]
    if remains.instances and remains.low > 0:
        text += f"; warm-started from a static design, a per-node one still costs {_signed(remains)} more"
    elif remains.instances and remains.high < 0:
        text += f"; warm-started from a static design, a per-node one costs {_signed(remains)} less than it"
    return text + "."


def _parts_sentence(rows: Sequence[Decomposition]) -> str:
    """With any number of links (or the largest budget): the excess, and what the shared output layer and the
    random start each account for."""
    d = next((r for r in rows if r.budget is None), rows[-1])
    p = d.parts
    largest = max((r for r in rows if r.parts["total"].instances), key=lambda r: r.parts["total"].median)
    lead = (f"{_within(d.budget)[0].upper()}{_within(d.budget)[1:]} the excess falls to {_signed(p['total'])}"
            if largest is not d else f"{_within(d.budget)[0].upper()}{_within(d.budget)[1:]}")
    return (f"{lead}: {_signed(p['model class'])} from sharing one output layer among the nodes and "
            f"{_signed(p['training'])} from the random start (against a warm start).")


def _arm_names(arms: list) -> str:
    """"the tanh paper arm", "both per-node arms and the tanh paper arm": (activation, arm) as the divergence
    table names them, an arm whose two activations go together named once."""
    by_arm: dict[str, list] = {}
    for activation, arm in arms:
        by_arm.setdefault(arm, []).append(activation)
    both = [arm for arm, acts in by_arm.items() if len(acts) == 2]
    single = [f"{acts[0]} {arm}" for arm, acts in by_arm.items() if len(acts) == 1]
    parts = [f"both {arm} arms" for arm in both]
    if single:
        parts.append(f"the {join_words(single)} arm{'s' if len(single) > 1 else ''}")
    return join_words(parts)


def _divergence_sentence(records: Records) -> str | None:
    """Divergence from random weights against a warm start, on the system with the largest open-loop radius: the
    designs that diverged, arm by arm (counts as the divergence table gives them)."""
    div = [v for v in divergence(records) if v.radius is not None]
    if not div:
        return None
    worst = max({v.system for v in div}, key=lambda s: next(v.radius for v in div if v.system == s))
    here = [v for v in div if v.system == worst]
    cold = [v for v in here if v.arm != "warm"]
    warm = [v for v in here if v.arm == "warm"]
    if not any(v.diverged_designs for v in cold):
        return None
    groups: dict[tuple, list] = {}
    for v in cold:
        groups.setdefault((v.diverged_designs, v.designs), []).append((v.activation, v.arm))
    ranked = sorted(groups.items(), key=lambda kv: (-kv[0][0], kv[0][1]))
    counts = [f"{k} of {n} designs of {_arm_names(arms)}" if i == 0 else f"{k} of {n} of {_arm_names(arms)}"
              for i, ((k, n), arms) in enumerate(ranked)]
    text = (f"On {system_title(worst)} (open-loop spectral radius {here[0].radius:.4g}), random weights diverged in "
            f"{join_words(counts)}")
    if warm:
        diverged = sum(v.diverged_designs for v in warm)
        designs = sum(v.designs for v in warm)
        text += f"; from {_starts(records, worst)}, {'none' if not diverged else f'{diverged} of {designs}'} did"
    return text + "."


def _nonlinearity_sentence(records: Records, system: tuple) -> str | None:
    """tanh against linear at equal information and links: only the budgets whose interval excludes 0 are claimed."""
    nl = [x for x in nonlinearity(records) if x.system == system and x.arm == "paper" and x.paired.instances]
    if not nl:
        return None
    helps = [x for x in nl if x.paired.high < 0 and not x.paired.too_few]
    hurts = [x for x in nl if x.paired.low > 0 and not x.paired.too_few]

    def span(xs) -> str:
        values = sorted(xs, key=lambda x: x.paired.median)
        if len(values) == 1:
            return _signed(values[0].paired)
        return f"{_signed(values[0].paired)} to {_signed(values[-1].paired)}"

    if helps:
        verdict = (f"the tanh nonlinearity lowers the cost {join_words(_within(x.budget) for x in helps)} "
                   f"(tanh − linear {span(helps)})")
    elif hurts:
        verdict = (f"the tanh nonlinearity adds nothing: {join_words(_within(x.budget) for x in hurts)} the linear "
                   f"GRNN-Sparse costs less (tanh − linear {span(hurts)})")
    else:
        verdict = "tanh and linear GRNN-Sparse cannot be told apart (every interval of tanh − linear holds 0)"
    return f"At equal information and links on {system_title(system)}, {verdict}."


def decomposition_sentences(records) -> list[str]:
    """The answer's sentences: where the excess is largest, its parts with any number of links, divergence with and
    without a stable start (and the nonlinearity, which the answer's three sentences leave out)."""
    records = as_records(records)
    rows = decompose(records)
    if not rows:
        return []
    by_system: dict = {}
    for d in rows:
        by_system.setdefault(d.system, []).append(d)
    system = max(by_system, key=lambda s: (by_system[s][0].instances, str(s)))
    tanh = [d for d in by_system[system] if d.activation == "tanh"] or by_system[system]
    sentences = [_largest_sentence(tanh), _parts_sentence(tanh), _divergence_sentence(records),
                 _nonlinearity_sentence(records, system)]
    return [x for x in sentences if x]


def _interval_cell(p: Paired) -> str:
    return "—" if not p.instances else _signed(p)


def decomposition_section(records, save=None) -> list[str]:
    """The report section: tables of the parts, the excess over the bound, the nonlinearity and divergence."""
    records = as_records(records)
    rows = decompose(records)
    if not rows:
        return []
    lines = ["## Why the learned designs lose: model class against training", ""]
    if save is not None:
        fig, _ = plot_decomposition(rows)
        save(fig, "decomposition")
        lines += ["![decomposition](decomposition.png)", ""]
    lines += [
        "Per instance and link budget, the excess of the paper's GRNN-Sparse over the best delayed static design "
        "(the same information: own state now, neighbours' one step late) splits into three parts. The GRNN's "
        "*readout* is its output layer, which turns a node's hidden state into its input; the paper shares one "
        "among all nodes. *Model class*: the paper's design against the same with one readout per node, both "
        "trained from random weights. *Training*: that per-node design against the same with a warm start, "
        "trained from a static design on its instance (the delayed ℓ1 path's design at γ = β / trace(P), "
        "or the diagonal gain). *Remains*: the warm-started design against the static one; a per-node readout "
        "holds every delayed static gain exactly (docs/methods.md), so a positive value is what training could "
        "not recover, a negative one what the dynamic controller adds. Each entry is the median of the paired "
        "difference (LQR-normalized best costs within the budget; positive: the first costs more) over the "
        "instances where every arm has a design within the budget (column *instances*), with a distribution-free "
        "95 % interval (a percentage after it: its coverage, where too few instances allow 95 %). Medians do not "
        "add, so the parts need not sum to the total.", ""]
    for system in dict.fromkeys(d.system for d in rows):
        here = [d for d in rows if d.system == system]
        pooled = f", {here[0].panels} panels pooled" if here[0].panels > 1 else ""
        lines += [f"### {system_title(system)} ({here[0].instances} instances{pooled}; warm starts from "
                  f"{_starts(records, system)})", "",
                  "| activation | budget | instances | total | model class | training | remains |",
                  "|---|---|---:|---:|---:|---:|---:|"]
        lines += [f"| {d.activation} | {_budget(d.budget)} | {d.parts['total'].instances} | "
                  + " | ".join(_interval_cell(d.parts[name]) for name, *_ in PARTS) + " |" for d in here]
        if any(d.over_bound for d in here):
            lines += ["", "Median excess over the SLS bound (complete graph, one hop per step), in per cent of LQR's cost, "
                      "on the same instances:", "",
                      "| activation | budget | paper | per-node | warm | best delayed static |", "|---|---|---:|---:|---:|---:|"]
            lines += [f"| {d.activation} | {_budget(d.budget)} | "
                      + " | ".join(_pct(d.over_bound.get(arm, np.nan)) for arm in ("paper", "per-node", "warm", "static"))
                      + " |" for d in here]
        lines.append("")
    missing = undecomposed(records)
    if missing:
        lines += ["Not decomposed (an arm without any usable design on the system, see the divergence table):", ""]
        lines += [f"- {m}" for m in missing] + [""]
    nl = nonlinearity(records)
    if nl:
        lines += ["### tanh against linear at equal information and links", "",
                  "tanh − linear, each kind of GRNN-Sparse with the same training (negative: the nonlinearity helps).", "",
                  "| system | kind | budget | tanh − linear |", "|---|---|---|---:|"]
        lines += [f"| {system_title(x.system)} | {x.arm} | {_budget(x.budget)} | {_interval_cell(x.paired)} |" for x in nl]
        lines.append("")
    div = divergence(records)
    if div:
        lines += ["### Divergence with and without a stable start", "",
                  "Instances on which some design of the arm diverged (every ensemble member's training), the designs "
                  "that did, and for warm starts the runs that kept their start (training diverged or ended above it).", "",
                  "| system | open-loop radius | arm | activation | instances diverged | designs diverged | starts kept |",
                  "|---|---:|---|---|---:|---:|---:|"]
        lines += [f"| {system_title(v.system)} | {'—' if v.radius is None else f'{v.radius:.4g}'} | {v.arm} | {v.activation} | "
                  f"{v.diverged_instances} of {v.instances} | {v.diverged_designs} of {v.designs} | "
                  f"{v.kept_starts if v.arm == 'warm' else '—'} |" for v in div]
        lines.append("")
    return lines


# --------------------------------------------------------------------------- figure


_PART_COLOURS = {"total": "#332288", "model class": "#CC6677", "training": "#117733", "remains": "#999933"}
_PART_MARKERS = {"total": "o", "model class": "s", "training": "^", "remains": "D"}


def plot_decomposition(rows: Sequence[Decomposition], *, axes=None):
    """The parts of each system's decomposition against the budget: medians with their 95 % intervals.

    One row of panels per system, one panel per activation; each budget a group of four bars (total, model
    class, training, what remains), every one a paired median difference with its
    interval, the quantities the tables and the answer state.

    Returns
    -------
    (Figure, list of Axes)
    """
    columns = list(dict.fromkeys((d.system, d.activation) for d in rows))
    if axes is None:
        fig, axes = _decomposition_axes(rows, columns)
    else:
        fig = axes[0].figure
    for ax, (system, activation) in zip(axes, columns):
        here = [d for d in rows if d.system == system and d.activation == activation]
        for k, (name, *_) in enumerate(PARTS):
            _draw_part(ax, here, name, k, legend=ax is axes[0])
        ax.axhline(0.0, color="0.5", linewidth=0.8)
        ax.set_xticks(range(len(here)), ["any" if d.budget is None else f"≤ {d.budget:g}" for d in here])
        ax.set_xlim(-0.5, len(here) - 0.5)  # every budget's group whole, also where a budget has no part drawn
        ax.set_xlabel("link budget")
        few = min((d.parts["total"] for d in here if d.parts["total"].instances), key=lambda q: q.coverage, default=None)
        cover = f", {few.coverage:.0%} intervals" if few is not None and few.too_few else ""
        ax.set_title(f"{system_title(system)}, {activation} ({here[0].instances} instances{cover})", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    for ax in axes:
        spec = ax.get_subplotspec()
        if spec is None or spec.colspan.start == 0:
            ax.set_ylabel("paired difference (× LQR)")
    axes[0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig, axes


def _decomposition_axes(rows: Sequence[Decomposition], columns: list[tuple]) -> tuple:
    """A row of panels per system, its activations side by side (two panels across read at 800 px);
    returns the figure and one Axes per (system, activation) of ``columns``, in that order."""
    import matplotlib.pyplot as plt

    systems = list(dict.fromkeys(d.system for d in rows))
    across = max(sum(1 for c in columns if c[0] == s) for s in systems)
    fig, grid = plt.subplots(len(systems), across, figsize=(4.2 * across + 0.8, 3.2 * len(systems)),
                             sharey=True, squeeze=False)
    place = {}
    for i, system in enumerate(systems):
        for j, column in enumerate(c for c in columns if c[0] == system):
            place[column] = grid[i][j]
    for ax in grid.flat:
        if ax not in place.values():
            ax.set_visible(False)
    return fig, [place[c] for c in columns]


def _draw_part(ax, here: list, name: str, k: int, *, legend: bool) -> None:
    """Part ``name`` (the k-th of PARTS) at each budget of one panel: its paired median and 95 % interval,
    offset within the budget's group of four."""
    width = 0.18
    xs, ys, lo, hi = [], [], [], []
    for j, d in enumerate(here):
        p = d.parts[name]
        if not p.instances:
            continue
        xs.append(j + (k - 1.5) * width)
        ys.append(p.median)
        lo.append(p.median - p.low)
        hi.append(p.high - p.median)
    drawn = ax.errorbar(xs, ys, yerr=[lo, hi], fmt=_PART_MARKERS[name], color=_PART_COLOURS[name],
                        capsize=2, markersize=5, linewidth=1.2, label=name if legend else None)
    drawn.lines[0].set_gid(f"decomposition:{name}")  # read back by the tests
