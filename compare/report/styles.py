"""One visual identity for every figure of every report: each method's colour and marker.

A method keeps its colour and marker in every figure and every report, because
the style is looked up from what the design *is* (its method, and the one
hyperparameter that makes a different kind of design: the activation of a GRNN,
the graph of an SLS design), never from its position in a list of labels.
Colours come in families by information model, from the colour-blind safe
palettes of Okabe & Ito and of Paul Tol:

- instantaneous (zero-delay links): blues and teals;
- delayed (one step per hop, the GRNN's model): reds, oranges and purples;
- no communication: greens and greys.

A GRNN's other arms, its readout (shared or per node) and its start (random, or warm
from another method's design), each have a hue pair of their own (:data:`GRNN_KIND_COLOURS`),
dark for tanh and light for the linear (identity) activation, and the start's marker; so
that the eight arms a report such as learned-class compares never share a colour (they
once shared GRNN-Sparse's orange, and their bands fused). Those hues come from Paul Tol's
vibrant and ColorBrewer's PuOr and BrBG schemes; ``tests/test_arm_styles.py`` checks that
every two of them stay apart in simulated deuteranopia and protanopia.

A plug-in method gets a stable colour and marker derived from its name (a hash,
not the order in which methods happen to appear), from colours no built-in uses.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

__all__ = ["Style", "INFO_MODELS", "INFO_ORDER", "METHOD_STYLES", "style_key", "style_for", "label_styles",
           "grnn_kinds", "kind_suffix", "REFERENCE_COLOUR", "BOUND_COLOUR", "GRNN_KIND_COLOURS"]

#: Information model -> (matplotlib line style, plotly dash, description). The line style of
#: every curve drawn for a method is its information model's.
INFO_MODELS = {
    "instantaneous": ("-", "solid", "instantaneous (zero-delay links)"),
    "delayed": ("--", "dash", "delayed (one step per hop)"),
    "none": (":", "dot", "no communication"),
}
#: Order of the legend's groups.
INFO_ORDER = ("delayed", "instantaneous", "none")

#: The centralized-LQR = 1 reference line: lighter than any method's colour.
REFERENCE_COLOUR = "#BBBBBB"
#: A lower bound (SLS on the complete graph) drawn as a line.
BOUND_COLOUR = "#000000"


@dataclass(frozen=True)
class Style:
    """How one method is drawn: colour (hex), matplotlib marker, and its information model's line style."""

    colour: str
    marker: str
    info_model: str = "instantaneous"
    #: Drawn hollow whatever the (colour, marker) pair; :data:`HOLLOW` lists the built-in ones.
    hollow: bool = False

    @property
    def linestyle(self) -> str:
        return INFO_MODELS.get(self.info_model, INFO_MODELS["instantaneous"])[0]

    @property
    def dash(self) -> str:
        """The plotly dash of the information model's line style."""
        return INFO_MODELS.get(self.info_model, INFO_MODELS["instantaneous"])[1]

    @property
    def plotly_symbol(self) -> str:
        return _PLOTLY_SYMBOLS.get(self.marker, "circle")

    @property
    def face(self) -> str:
        """Marker face colour: "none" (see-through) for the variants drawn hollow (:data:`HOLLOW`), else the colour."""
        return "none" if self.hollow or (self.colour, self.marker) in _HOLLOW_PAIRS else self.colour

    @property
    def edge(self) -> str:
        """Marker edge colour: white around a solid filled marker (it stands out from its line),
        else the colour: hollow markers, and those drawn by their edges alone ("x", "+"), which a
        white edge erases (the autonomous loop's "x" was invisible in every figure until 2026-11-26)."""
        from matplotlib.markers import MarkerStyle

        solid = self.face == self.colour and MarkerStyle(self.marker).is_filled()
        return "white" if solid else self.colour

    @property
    def edge_width(self) -> float:
        """Marker edge width in points: a thin white ring around a solid marker, else a line
        heavy enough to draw a hollow or edge-only marker."""
        return 0.6 if self.edge == "white" else 1.2

    # A Style unpacks as (colour, marker), as the figures' older label -> (colour, marker) tables did.
    def __iter__(self):
        return iter((self.colour, self.marker))

    def __getitem__(self, i):
        return (self.colour, self.marker)[i]

    def __len__(self):
        return 2


#: Style key -> (colour, marker, information model) of every built-in method.
METHOD_STYLES: dict[str, tuple[str, str, str]] = {
    # instantaneous: blues and teals
    "lqr": ("#000000", "*", "instantaneous"),
    "sparse_admm": ("#0072B2", "o", "instantaneous"),
    "sparse_newton": ("#0072B2", "v", "instantaneous"),
    "sparse_sdp": ("#56B4E9", "s", "instantaneous"),
    "truncated_lqr": ("#332288", "D", "instantaneous"),
    "gcnn": ("#44AA99", "P", "instantaneous"),
    "sparse_budget": ("#4477AA", "^", "instantaneous"),
    "best_pattern": ("#009988", "*", "instantaneous"),
    # delayed: reds, oranges, purples
    "grnn_sparse": ("#D55E00", "o", "delayed"),
    "grnn_sparse_linear": ("#E69F00", "s", "delayed"),
    "sparse_delayed": ("#CC79A7", "D", "delayed"),
    "grnn": ("#882255", "^", "delayed"),
    "grnn_linear": ("#882255", "v", "delayed"),
    "grnn_dense": ("#AA4499", "v", "delayed"),
    "grnn_fixed": ("#EE6677", "<", "delayed"),
    # a GRNN-Sparse's readout and start (:data:`GRNN_KIND_COLOURS`): dark tanh, light (hollow) linear
    "grnn_sparse_per_node": ("#222255", "p", "delayed"),
    "grnn_sparse_linear_per_node": ("#33BBEE", "p", "delayed"),
    "grnn_sparse_per_node_warm_delayed": ("#542788", "D", "delayed"),
    "grnn_sparse_linear_per_node_warm_delayed": ("#998EC3", "D", "delayed"),
    "grnn_sparse_per_node_warm_diagonal": ("#8C510A", "h", "delayed"),
    "grnn_sparse_linear_per_node_warm_diagonal": ("#BFA25F", "h", "delayed"),
    "grnn_sparse_per_node_init_auto": ("#01665E", "H", "delayed"),
    "grnn_sparse_linear_per_node_init_auto": ("#5AB4AC", "H", "delayed"),
    "sls_complete": ("#661100", "X", "delayed"),
    "sls_plant": ("#AA3377", "p", "delayed"),
    "sls_plant^2": ("#AA3377", "h", "delayed"),
    "sls_plant^3": ("#AA3377", "H", "delayed"),
    "sls_given": ("#EE3377", "d", "delayed"),
    "sls_path": ("#994455", "8", "delayed"),
    "sls_local": ("#CC6677", ">", "delayed"),
    "sparse_budget_delayed": ("#EE7733", "^", "delayed"),
    "best_pattern_delayed": ("#CC3311", "*", "delayed"),
    # no communication: greens and greys
    "decentralized": ("#117733", "h", "none"),
    "autonomous": ("#555555", "x", "none"),
}

#: Variants drawn with hollow markers, so that a filled marker they coincide with shows through
#: (the linear GRNN-Sparse path lies on the tanh one within a percent; the prox-Newton path on ADMM's).
HOLLOW = ("grnn_sparse_linear", "grnn_linear", "sls_plant^2", "sls_plant^3", "sparse_newton",
          "grnn_sparse_linear_per_node", "grnn_sparse_linear_per_node_warm_delayed",
          "grnn_sparse_linear_per_node_warm_diagonal", "grnn_sparse_linear_per_node_init_auto")
_HOLLOW_PAIRS = {METHOD_STYLES[k][:2] for k in HOLLOW}

# Colours no built-in method uses, for plug-ins (Tol's muted and light schemes).
_SPARE_COLOURS = ("#88CCEE", "#DDCC77", "#999933", "#6699CC", "#997700", "#BBCC33", "#77AADD", "#EEDD88",
                  "#FFAABB", "#99DDFF", "#44BB99", "#AAAA00")
_SPARE_MARKERS = ("o", "s", "D", "^", "v", "P", "X", "<", ">", "h", "*", "p")

_PLOTLY_SYMBOLS = {"o": "circle", "s": "square", "D": "diamond", "d": "diamond-tall", "^": "triangle-up",
                   "v": "triangle-down", "<": "triangle-left", ">": "triangle-right", "P": "cross", "X": "x",
                   "x": "x-thin-open", "*": "star", "p": "pentagon", "h": "hexagon", "H": "hexagon2",
                   "8": "octagon"}


#: A GRNN's readout and initialization make other kinds of design too: (key suffix, label words, marker).
#: The marker of a warm start is that of the method whose design it starts from (decentralized's hexagon,
#: sparse_delayed's diamond); the colour is the kind's (:data:`GRNN_KIND_COLOURS`).
GRNN_KINDS = {
    "per_node": ("_per_node", "per-node", "p"),
    "warm_diagonal": ("_warm_diagonal", "warm: diagonal", "h"),
    "warm_delayed": ("_warm_delayed", "warm: delayed", "D"),
    "warm_auto": ("_init_auto", "init: auto", "H"),
}


#: A GRNN kind's (its last: the start where warm, else the readout) colours: (tanh, linear). Each kind its
#: own hue, so that an arm is told apart by its colour where its marker is small or hidden (a band, a line).
GRNN_KIND_COLOURS = {
    "per_node": ("#222255", "#33BBEE"),
    "warm_delayed": ("#542788", "#998EC3"),
    "warm_diagonal": ("#8C510A", "#BFA25F"),
    "warm_auto": ("#01665E", "#5AB4AC"),
}


def grnn_kinds(method: str, params: Mapping | None = None) -> list[str]:
    """The :data:`GRNN_KINDS` of a GRNN design: its readout ("per_node") and warm start ("warm_<init>").

    Empty for the paper's GRNN (shared readout, random initialization) and for other methods.
    """
    params = params or {}
    if not method.startswith("grnn"):
        return []
    kinds = ["per_node"] if params.get("readout", "shared") == "per_node" else []
    init = params.get("init", "random")
    if init != "random":
        kinds.append(f"warm_{init}")
    return kinds


def kind_suffix(method: str, params: Mapping | None = None) -> str:
    """What tells a GRNN design's kind apart in a label: " (per-node)", " (per-node, warm: delayed)", or ""."""
    words = [GRNN_KINDS[k][1] if k in GRNN_KINDS else k.replace("_", " ") for k in grnn_kinds(method, params)]
    return f" ({', '.join(words)})" if words else ""


def style_key(method: str, params: Mapping | None = None) -> str:
    """The key of :data:`METHOD_STYLES` for a design of ``method`` with hyperparameters ``params``.

    The activation of a GRNN (identity: a linear controller), its readout and warm start
    (:func:`grnn_kinds`: ``grnn_sparse_per_node_warm_diagonal``), the graph of an SLS
    design, the information model of an exact-budget search and the controller class of a
    refit (with its activation) make different kinds of design; other hyperparameters (γ, β,
    steps, a refit's graph) do not.
    """
    params = params or {}
    if method == "refit":
        key = f"refit_{params.get('controller', 'delayed')}"
        return f"{key}_linear" if params.get("activation") == "identity" else key
    if method.startswith("grnn"):
        key = f"{method}_linear" if params.get("activation") == "identity" else method
        return key + "".join(GRNN_KINDS[k][0] if k in GRNN_KINDS else f"_{k}" for k in grnn_kinds(method, params))
    if method in ("sls", "sls_topologies"):
        return f"sls_{params.get('graph', 'plant')}"
    if method in ("sparse_budget", "best_pattern") and params.get("info_model") == "delayed":
        return f"{method}_delayed"
    return method


def _spare(key: str) -> tuple[str, str]:
    digest = int(hashlib.sha256(key.encode()).hexdigest(), 16)
    return _SPARE_COLOURS[digest % len(_SPARE_COLOURS)], _SPARE_MARKERS[(digest // 97) % len(_SPARE_MARKERS)]


def style_for(method: str, params: Mapping | None = None, info_model: str | None = None) -> Style:
    """The :class:`Style` of a design: the built-in table's, or a stable one derived from the name."""
    key = style_key(method, params)
    if key in METHOD_STYLES:
        colour, marker, info = METHOD_STYLES[key]
        return Style(colour, marker, info_model or info)
    kinds = grnn_kinds(method, params)
    if kinds and kinds[-1] in GRNN_KIND_COLOURS:
        # another GRNN's readout or warm start: the kind's colour (light and hollow where linear), its marker
        linear = (params or {}).get("activation") == "identity"
        return Style(GRNN_KIND_COLOURS[kinds[-1]][linear], GRNN_KINDS[kinds[-1]][2], info_model or "delayed",
                     hollow=linear)
    colour, marker = _spare(key)
    return Style(colour, marker, info_model or "instantaneous")


def label_styles(records: Iterable) -> dict[str, Style]:
    """Label -> :class:`Style` for the labels of ``records`` (each label styled by its first design).

    ``records``: :class:`~compare.run.records.Records` or any iterable of objects with
    ``label``, ``method``, ``params`` and ``info_model``. Two labels of the same kind of
    design in one report (say, one method run with two settings under two labels) share
    the colour; the second gets another marker so that both stay apart.
    """
    out: dict[str, Style] = {}
    used: dict[tuple, str] = {}
    for r in records:
        if r.label in out:
            continue
        style = style_for(r.method, r.params, r.info_model)
        if (style.colour, style.marker) in used:
            taken = {s.marker for s in out.values() if s.colour == style.colour}
            free = [m for m in _SPARE_MARKERS if m not in taken]
            style = Style(style.colour, free[0] if free else style.marker, style.info_model, style.hollow)
        used[(style.colour, style.marker)] = r.label
        out[r.label] = style
    return out
