"""Every arm of a learned-class comparison is its own mark, in the static and the interactive figures (issue 61).

learned-class compares eight GRNN-Sparse arms: readout (shared or per node) × start
(random, warm from the ℓ1 delayed design, or from the diagonal gain) × activation (tanh or
linear). They once shared GRNN-Sparse's orange, and their bands fused into brown blocks. Here
the figures are drawn from records shaped like learned-class's and read back: each label's
colours, markers, faces and line styles (the artists' and the plotly traces'), all distinct,
and the arms' colours apart in simulated deuteranopia and protanopia too.
"""

from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402

from compare.report.cost_links import aggregate, plot_cost_vs_links  # noqa: E402
from compare.report.figures import legend_handles, plot_budget_fronts  # noqa: E402
from compare.report.interactive import budget_fronts_figure, cost_links_figure  # noqa: E402
from compare.report.statistics import budget_fronts  # noqa: E402
from compare.report.styles import GRNN_KIND_COLOURS, METHOD_STYLES, label_styles, style_for, style_key  # noqa: E402
from compare.run.records import Records, canonical_key  # noqa: E402

REPORTS = Path(__file__).resolve().parents[1] / "reports"

#: learned-class's arms: label -> params (all grnn_sparse, delayed), as its spec names them.
ARMS = {
    "GRNN-Sparse (β path)": {},
    "Linear GRNN-Sparse (β path)": {"activation": "identity"},
    "Per-node GRNN-Sparse": {"readout": "per_node"},
    "Linear per-node GRNN-Sparse": {"readout": "per_node", "activation": "identity"},
    "Per-node GRNN-Sparse, warm start": {"readout": "per_node", "init": "delayed"},
    "Linear per-node GRNN-Sparse, warm start": {"readout": "per_node", "init": "delayed", "activation": "identity"},
    "Per-node GRNN-Sparse, diagonal start": {"readout": "per_node", "init": "diagonal"},
    "Linear per-node GRNN-Sparse, diagonal start": {"readout": "per_node", "init": "diagonal",
                                                    "activation": "identity"},
}


def _row(spec, method, label, params, cost, links, info, idx):
    return {"run_key": f"{label}-{canonical_key(spec)}-{idx}", "idx": idx, "experiment": "arms", "instance": spec,
            "method": method, "label": label, "params": params, "cost": cost, "cost_stderr": 0.001,
            "cost_kind": "exact", "links": links, "self_loops": spec["n"], "info_model": info, "status": "optimal",
            "message": None, "seconds": 0.1, "controller_kind": "static", "extras": {}, "fingerprint": "f"}


def arm_records() -> Records:
    """Two panels of six instances: the eight arms' β paths, the ℓ1 delayed path, the diagonal gain, the bound and
    LQR."""
    rows, facts = [], {}
    for a_norm in (0.995, 1.1):
        for seed in range(6):
            spec = {"family": "paper", "n": 8, "a_norm": a_norm, "seed": seed}
            facts[canonical_key(spec)] = {"n": 8, "plant_links": 20, "comm_links": 20}
            rows.append(_row(spec, "lqr", "LQR (centralized)", {}, 1.0, 56, "instantaneous", 0))
            rows.append(_row(spec, "decentralized", "Decentralized (diagonal K)", {}, 1.3, 0, "none", 0))
            rows.append(_row(spec, "sls", "SLS bound (complete graph)", {"graph": "complete"}, 1.05, 56, "delayed", 0))
            for i in range(3):
                rows.append(_row(spec, "sparse_delayed", "Sparse delayed K (l1)", {"gamma": 10.0 ** -i},
                                 1.25 - 0.05 * i, 10 * i, "delayed", i))
            for k, (label, params) in enumerate(ARMS.items()):
                for i in range(3):
                    rows.append(_row(spec, "grnn_sparse", label, {**params, "beta": 10.0 ** -i},
                                     1.24 - 0.05 * i + 0.004 * k + 0.002 * seed, 10 * i + k + 1, "delayed", i))
    return Records.from_rows(rows, facts=facts)


@pytest.fixture(scope="module")
def records():
    return arm_records()


def _distinct(marks: dict) -> None:
    """``marks``: label -> set of its drawn signatures; each label draws one, and no two labels the same."""
    for label, seen in marks.items():
        assert len(seen) == 1, (label, seen)
    signatures = [next(iter(seen)) for seen in marks.values()]
    assert len(set(signatures)) == len(signatures), marks


def test_every_arm_has_its_own_style(records):
    styles = label_styles(records)
    arms = {label: styles[label] for label in ARMS}
    assert len({(s.colour, s.marker, s.face) for s in arms.values()}) == len(ARMS)
    assert len({s.colour for s in arms.values()}) == len(ARMS)  # colour alone: a band or a line tells them apart
    # the linear arms hollow, the tanh ones filled: the activation reads off every marker
    assert all((s.face == "none") == ("Linear" in label) for label, s in arms.items())
    # the built-in table holds every arm's colour (the one visual identity of every report)
    table = {c for c, _, _ in METHOD_STYLES.values()}
    assert all(s.colour in table for s in arms.values())


def test_the_static_figures_draw_each_arm_apart(records):
    styles = label_styles(records)
    fronts = budget_fronts(records)
    for fig, axes in (plot_budget_fronts(fronts, styles=styles),
                      plot_cost_vs_links(aggregate(records), records=records, styles=styles)):
        lines, markers = {}, {}
        for ax in axes.values():
            for line in ax.lines:
                gid = line.get_gid() or ""
                if gid.startswith("front:"):
                    lines.setdefault(gid[6:], set()).add((to_hex(line.get_color()), str(line.get_linestyle())))
                elif gid.startswith("method:") and line.get_marker() not in (None, "None", "none", ""):
                    face = line.get_markerfacecolor()
                    markers.setdefault(gid[7:], set()).add(
                        (to_hex(line.get_color()), line.get_marker(), "none" if face == "none" else to_hex(face)))
        assert set(ARMS) <= set(lines) and set(ARMS) <= set(markers)
        _distinct(lines)
        _distinct(markers)
        # the legend names them as the findings do: by their labels
        names = [t.get_text() for t in fig.legends[0].get_texts()]
        assert set(ARMS) <= set(names)
        plt.close(fig)


def test_the_interactive_figures_draw_each_arm_apart(records):
    styles = label_styles(records)
    for fig in (budget_fronts_figure(budget_fronts(records), styles),
                cost_links_figure(records, styles)):
        lines, markers = {}, {}
        for t in fig.data:
            label, kind = t.meta["label"], t.meta["kind"]
            if kind == "front":
                lines.setdefault(label, set()).add((t.line.color, t.line.dash))
            if kind == "setting" or (kind == "front" and t.marker.symbol):
                markers.setdefault(label, set()).add((t.marker.color, t.marker.symbol, t.marker.line.color))
        assert set(ARMS) <= set(lines) and set(ARMS) <= set(markers)
        _distinct(lines)
        _distinct(markers)
        legend = {entry["name"]: (entry["colour"], entry["symbol"], entry["hollow"])
                  for entry in fig.layout.meta["legend"]}
        assert set(ARMS) <= set(legend)
        assert len({legend[label] for label in ARMS}) == len(ARMS)


# --- colour-blind simulation (Machado, Oliveira & Fernandes 2009, severity 1) -------------------------------------

_MACHADO = {
    "deuteranopia": np.array([[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                              [-0.011820, 0.042940, 0.968881]]),
    "protanopia": np.array([[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                            [-0.003882, -0.048116, 1.051998]]),
}


def _linear(colour: str) -> np.ndarray:
    c = np.array([int(colour.lstrip("#")[i:i + 2], 16) / 255 for i in (0, 2, 4)])
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _lab(rgb: np.ndarray) -> np.ndarray:
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]) @ rgb
    f = xyz / np.array([0.95047, 1.0, 1.08883])
    f = np.where(f > 0.008856, np.cbrt(f), 7.787 * f + 16 / 116)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def test_the_arms_colours_stay_apart_for_colour_blind_readers():
    """CIELAB ΔE between every two arm colours, seen normally and with either red-green deficiency: at least 8
    (the markers and the hollow linear arms tell them apart besides)."""
    colours = [style_for("grnn_sparse", params).colour for params in ARMS.values()]
    assert len(set(colours)) == len(ARMS)
    # and apart from what learned-class draws beside them: the ℓ1 delayed path, the bound, the diagonal gain
    colours += [style_for(m, p).colour for m, p in (("sparse_delayed", {}), ("sls", {"graph": "complete"}),
                                                    ("decentralized", {}))]
    for name, matrix in [("normal vision", np.eye(3)), *_MACHADO.items()]:
        seen = {c: _lab(np.clip(matrix @ _linear(c), 0, 1)) for c in colours}
        worst = min((float(np.linalg.norm(seen[a] - seen[b])), a, b) for a, b in itertools.combinations(colours, 2))
        assert worst[0] >= 8.0, (name, worst)
    assert set(GRNN_KIND_COLOURS) == {"per_node", "warm_delayed", "warm_diagonal", "warm_auto"}


def test_the_shipped_learned_class_arms_are_styled_apart():
    folder = REPORTS / "learned-class"
    if not (folder / "runs.csv").is_file():
        pytest.skip("reports/learned-class is not shipped")
    kinds = {}
    with (folder / "runs.csv").open() as handle:
        for row in csv.DictReader(handle):
            kinds.setdefault(row["label"], (row["method"], json.loads(row["params"]), row["info_model"]))
    grnn = {label: style_for(*kind) for label, kind in kinds.items() if kind[0] == "grnn_sparse"}
    assert len(grnn) >= 8
    assert len({(s.colour, s.marker, s.face) for s in grnn.values()}) == len(grnn)
    assert len({s.colour for s in grnn.values()}) == len(grnn)
    handles = legend_handles(grnn, sorted(grnn))
    assert [h.get_label() for h in handles if h.get_label() in grnn] == sorted(grnn)


def test_each_refit_class_is_its_own_kind_of_design():
    """A refit's controller class and activation tell its arms apart (the topology report draws five)."""
    kinds = [{"controller": c} for c in ("delayed", "instantaneous", "sls", "grnn")]
    kinds.append({"controller": "grnn", "activation": "identity"})
    keys = [style_key("refit", dict(k, graph="0-1")) for k in kinds]
    assert len(set(keys)) == 5 and style_key("refit", {"controller": "sls", "graph": "1-2"}) == keys[2]
    colours = {style_for("refit", k).colour for k in kinds}
    assert len(colours) == 5
