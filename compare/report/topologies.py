"""Designed communication topologies along a regularization path (paper Fig. 4).

Small networks are drawn as graphs, nodes coloured by the magnitude of the
leading eigenvector of A. A chain (a communication graph whose layout puts every
node on one line) is laid out on an open circle in chain order, so that a link
between far-apart nodes is a chord instead of an arc over the chain. Beyond
:data:`SPY_ABOVE` nodes a node-link drawing is a blot; each graph is then drawn as
its adjacency pattern (a spy plot): row = receiving node, column = sending node.

The figure needs no instance's matrices: an :class:`InstanceDrawing` holds what it
draws (both graphs and the node colours), which the runner stores with each
instance's facts (:func:`drawing_facts`), so that a report draws it from the store
or from its folder alone.
"""

from __future__ import annotations

import numpy as np

from codesign.status import OPTIMAL

from ..run.drawing import DRAWN_NODES_AT_MOST, InstanceDrawing, drawing_facts, node_colours  # noqa: F401
from ..run.records import DesignRecord, as_records
from .styles import grnn_kinds

__all__ = ["plot_topology_path", "topology_path_records", "topology_caption", "SPY_ABOVE", "node_order",
           "InstanceDrawing", "node_colours", "drawing_facts", "DRAWN_NODES_AT_MOST"]

#: Networks with more nodes than this are drawn as adjacency (spy) plots.
SPY_ABOVE = 40
#: Graphs side by side at most; the type of every label (compare.report.figures.MIN_POINTS).
TOPOLOGY_COLUMNS, _POINTS = 4, 8
#: Spy plot colours: a designed link, a plant-graph link the design does not use, and a self-loop.
_LINK, _PLANT_ONLY, _SELF = "#1A1A1A", "#DDDDDD", "#8C8C8C"


def _collinear(pos) -> bool:
    """Whether a layout puts every node on one line (a chain's): straight edges would hide behind each other."""
    xy = np.array(list(pos.values()), dtype=float)
    xy -= xy.mean(axis=0)
    s = np.linalg.svd(xy, compute_uv=False)
    return bool(s.size < 2 or s[1] <= 1e-2 * s[0])


def _chain_on_circle(pos, *, gap: float = np.pi / 6) -> dict:
    """The nodes of a collinear layout on a circle, in their order along the line, the chain's ends ``gap`` apart."""
    nodes = list(pos)
    xy = np.array([pos[k] for k in nodes], dtype=float)
    xy -= xy.mean(axis=0)
    axis = np.linalg.svd(xy, full_matrices=False)[2][0]
    order = np.argsort(xy @ axis, kind="stable")
    angles = np.pi / 2 + gap / 2 + np.linspace(0.0, 2 * np.pi - gap, len(nodes))
    return {nodes[k]: (float(np.cos(a)), float(np.sin(a))) for k, a in zip(order, angles)}


def _links(adj) -> int:
    adj = np.asarray(adj) != 0
    return int(np.count_nonzero(adj) - np.count_nonzero(np.diag(adj)))


def node_order(adj) -> np.ndarray:
    """An order of the nodes that puts neighbours near each other (reverse Cuthill-McKee on the symmetrized graph).

    A spy plot in this order shows a graph's locality as a band around the
    diagonal, instead of the scatter of the nodes' arbitrary numbering.
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    pattern = (np.asarray(adj) != 0).astype(np.int8)
    return np.asarray(reverse_cuthill_mckee(csr_matrix(pattern | pattern.T), symmetric_mode=True))


def _draw(ax, adj, pos, colors, title):
    """A node-link drawing; returns the nodes' collection (for the colour bar)."""
    import networkx as nx

    graph = nx.DiGraph()
    graph.add_nodes_from(range(adj.shape[0]))
    graph.add_edges_from((j, i) for i, j in zip(*np.nonzero(adj)) if i != j)  # S_ij != 0: j sends to i
    # Two links between a pair of nodes, one each way, bend apart so that both arrows show.
    nx.draw_networkx_edges(graph, pos, ax=ax, width=0.6, alpha=0.5, arrows=True, arrowsize=5, node_size=60,
                           connectionstyle="arc3,rad=0.08")
    nodes = nx.draw_networkx_nodes(graph, pos, ax=ax, node_size=60, node_color=colors, cmap="Reds",
                                   vmin=0, vmax=max(colors.max(), 1e-12), edgecolors="0.3", linewidths=0.5)
    ax.set_title(title, fontsize=_POINTS)
    ax.set_axis_off()
    return nodes


def _spy(ax, adj, order, colors, title, *, plant=None):
    """An adjacency (spy) plot in ``order``, with the nodes' colour strip along the rows; returns the strip's image.

    Parameters
    ----------
    adj : (N, N) array
        Nonzero ``adj[i, j]``: node j sends to node i (row = receiving, column = sending).
    order : (N,) int array
        Node order of rows and columns.
    colors : (N,) array
        The leading-eigenvector magnitude of each node.
    plant : (N, N) array, optional
        The plant graph, drawn faintly under the links so that a design's links read against it.
    """
    from matplotlib.colors import to_rgba

    n = len(order)
    linked = (np.asarray(adj) != 0)[np.ix_(order, order)]
    image = np.ones((n, n, 4))
    if plant is not None:
        image[(np.asarray(plant) != 0)[np.ix_(order, order)]] = to_rgba(_PLANT_ONLY)
    image[linked] = to_rgba(_LINK)
    diagonal = np.arange(n)
    image[diagonal[linked[diagonal, diagonal]], diagonal[linked[diagonal, diagonal]]] = to_rgba(_SELF)
    ax.imshow(image, interpolation="nearest", extent=(-0.5, n - 0.5, n - 0.5, -0.5))
    # The receiving nodes' colour, in a strip left of the matrix: where the links concentrate.
    width = max(1.0, 0.05 * n)
    strip = ax.imshow(colors[order][:, None], cmap="Reds", vmin=0, vmax=max(colors.max(), 1e-12),
                      interpolation="nearest", extent=(-0.5 - 1.4 * width, -0.5 - 0.4 * width, n - 0.5, -0.5))
    ax.set_xlim(-0.5 - 1.4 * width, n - 0.5)
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for side in ax.spines.values():
        side.set_linewidth(0.5)
    ax.set_title(title, fontsize=_POINTS)
    return strip


def plot_topology_path(instance, path, *, axes=None, symbol: str = "β"):
    """Draw the plant graph, then each designed topology of a path.

    Networks of up to :data:`SPY_ABOVE` nodes are node-link drawings (a chain on an
    open circle in chain order); larger ones adjacency (spy) plots, rows and
    columns in :func:`node_order` of the plant and communication graphs.

    Parameters
    ----------
    instance : InstanceDrawing or codesign.Instance
        Its plant graph is drawn first; nodes are coloured by the magnitude of
        the leading eigenvector of A (its norm over the node's states). An
        instance is drawn through :meth:`InstanceDrawing.of`, exactly as the
        drawing stored with its facts.
    path : list of (weight, links, cost, support)
        One entry per regularization weight, support as an (n, n) array
        (nonzero = link).
    axes : sequence of Axes, optional
        ``len(path) + 1`` axes; a new figure is made if omitted.
    symbol : str
        The regularization weight's name in the panels' titles.

    Returns
    -------
    fig, axes
    """
    import matplotlib.pyplot as plt
    import networkx as nx

    drawing = instance if isinstance(instance, InstanceDrawing) else InstanceDrawing.of(instance)
    n = drawing.nodes
    spy = n > SPY_ABOVE
    if axes is None:
        # Rows of at most TOPOLOGY_COLUMNS panels: seven graphs in a row made a 2,122 px figure, its titles 4 px
        # tall on an 800 px page.
        width = 2.1 if spy else 1.95
        cols = min(len(path) + 1, TOPOLOGY_COLUMNS)
        rows = -(-(len(path) + 1) // cols)
        fig, grid = plt.subplots(rows, cols, figsize=(width * cols + 0.6, (width + 0.55) * rows), squeeze=False)
        flat = list(grid.ravel())
        for extra in flat[len(path) + 1:]:
            extra.set_axis_off()
        axes = flat[:len(path) + 1]
    else:
        fig = axes[0].figure
    colors = drawing.colours
    plant_title = f"plant graph\n|E| = {_links(drawing.plant_adj)}"
    titles = [f"{symbol} = {weight:.3g}\n|E| = {links}, J = {cost:.3f}" for weight, links, cost, _ in path]
    if spy:
        order = node_order(drawing.plant_adj | drawing.comm_adj)
        mappable = _spy(axes[0], drawing.plant_adj, order, colors, plant_title)
        for ax, (_, _, _, support), title in zip(axes[1:], path, titles):
            _spy(ax, support, order, colors, title, plant=drawing.plant_adj)
        axes[0].set_ylabel("receiving node", fontsize=_POINTS)
        for ax in axes:
            ax.set_xlabel("sending node", fontsize=_POINTS)
            if ax.get_subplotspec() is not None and ax.get_subplotspec().is_first_col():
                ax.set_ylabel("receiving node", fontsize=_POINTS)
    else:
        pos = nx.kamada_kawai_layout(nx.from_numpy_array(drawing.comm_adj.astype(int)))
        if _collinear(pos):  # a chain: straight edges along one line would all hide behind each other
            pos = _chain_on_circle(pos)
        mappable = _draw(axes[0], drawing.plant_adj, pos, colors, plant_title)
        for ax, (_, _, _, support), title in zip(axes[1:], path, titles):
            _draw(ax, np.asarray(support), pos, colors, title)
    fig.tight_layout()
    bar = fig.colorbar(mappable, ax=list(axes), fraction=0.015, pad=0.01)
    bar.set_label("|leading eigenvector of A| at each node", fontsize=_POINTS)
    bar.ax.tick_params(labelsize=_POINTS)
    return fig, axes


def topology_caption(nodes: int, *, symbol: str = "β") -> str:
    """How :func:`plot_topology_path` draws a network of ``nodes`` nodes, for the figure's caption."""
    under = (f"Above each panel: the weight {symbol}, the directed off-diagonal links |E| and the normalized "
             "cost J.")
    if nodes > SPY_ABOVE:
        return ("Each graph as its adjacency pattern: row = receiving node, column = sending node, nodes "
                "ordered so that neighbours in the plant and communication graphs are near each other "
                "(reverse Cuthill–McKee); black: a link, mid grey on the diagonal: a self-loop (local "
                "feedback), light grey: a plant-graph link the design does not use. The strip left of each "
                "matrix colours the receiving node by the magnitude of the leading eigenvector of A. " + under)
    return ("Nodes coloured by the magnitude of the leading eigenvector of A; an arrow points from the sending "
            "to the receiving node. A chain is laid out on an open circle in chain order (its ends at the gap), "
            "so that a link between distant nodes is a chord across the circle. " + under)


def topology_path_records(records, *, method: str = "grnn_sparse", weight: str = "beta",
                          prefer_a_norm: float = 1.1) -> list[DesignRecord]:
    """The records of one instance's regularization path, for :func:`plot_topology_path`.

    A path is one instance and one setting of every other hyperparameter (a
    Table 1 run at β = 1 with 750 training steps is not on the trade-off
    sweep's 150-step path). Picks a path on ``a_norm == prefer_a_norm``, as
    the paper's Fig. 4 does, when one has two or more weights; then the paper's
    tanh GRNN over the linear ablation, and the paper's shared readout from a random draw
    over a per-node readout or a warm start; then the most weights, then the lowest seed.
    """
    paths: dict[tuple, dict] = {}
    for r in as_records(records):
        if r.method != method or r.status != OPTIMAL or weight not in r.params:
            continue
        paths.setdefault((r.instance.key, r.params_key_without(weight)), {})[r.params[weight]] = r
    if not paths:
        return []

    def rank(item):
        (_, others), path = item
        design = next(iter(path.values()))
        preferred = design.instance.a_norm == prefer_a_norm and len(path) >= 2
        linear = design.params.get("activation") == "identity"
        other_kind = bool(grnn_kinds(design.method, design.params))  # a per-node readout or a warm start
        return (not preferred, linear, other_kind, -len(path), design.instance.spec.get("seed", 0), others)

    _, path = min(paths.items(), key=rank)
    return [path[w] for w in sorted(path)]
