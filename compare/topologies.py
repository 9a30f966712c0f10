"""Designed communication topologies along a regularization path (paper Fig. 4)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import networkx as nx
import numpy as np

from .records import DesignRecord, as_records

__all__ = ["plot_topology_path", "topology_path_records"]


def _leading_eigenvector(A: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eig(A)
    return np.abs(np.real(V[:, np.argmax(np.abs(w))]))


def _collinear(pos) -> bool:
    """Whether a layout puts every node on one line (a chain's): straight edges would hide behind each other."""
    xy = np.array(list(pos.values()), dtype=float)
    xy -= xy.mean(axis=0)
    s = np.linalg.svd(xy, compute_uv=False)
    return bool(s.size < 2 or s[1] <= 1e-2 * s[0])


def _draw(ax, adj, pos, colors, title):
    graph = nx.DiGraph()
    graph.add_nodes_from(range(adj.shape[0]))
    graph.add_edges_from((j, i) for i, j in zip(*np.nonzero(adj)) if i != j)  # S_ij != 0: j sends to i
    # On a line, arcs (an arc diagram: links one way bend to one side, the other way to the other).
    style = "arc3,rad=0.4" if _collinear(pos) else "arc3"
    nx.draw_networkx_edges(graph, pos, ax=ax, width=0.6, alpha=0.5, arrows=True, arrowsize=5, node_size=60,
                           connectionstyle=style)
    nodes = nx.draw_networkx_nodes(graph, pos, ax=ax, node_size=60, node_color=colors, cmap="Reds",
                                   vmin=0, vmax=max(colors.max(), 1e-12), edgecolors="0.3", linewidths=0.5)
    ax.set_title(title, fontsize=8)
    ax.set_axis_off()
    return nodes


def plot_topology_path(instance, path, *, axes=None):
    """Draw the plant graph, then each designed topology of a path.

    Parameters
    ----------
    instance : codesign.Instance
        Its plant graph is drawn first; nodes are coloured by the magnitude of
        the leading eigenvector of A (its norm over the node's states).
    path : list of (weight, links, cost, support)
        One entry per regularization weight, support as an (n, n) array
        (nonzero = link).
    axes : sequence of Axes, optional
        ``len(path) + 1`` axes; a new figure is made if omitted.

    Returns
    -------
    fig, axes
    """
    if axes is None:
        fig, axes = plt.subplots(1, len(path) + 1, figsize=(2.3 * (len(path) + 1), 2.6), squeeze=False)
        axes = axes[0]
    else:
        fig = axes[0].figure
    pos = nx.kamada_kawai_layout(nx.from_numpy_array((instance.comm_adj != 0).astype(int)))
    colors = _leading_eigenvector(instance.A)
    if colors.size != instance.nodes:  # several states per node: the norm of each node's entries
        colors = np.sqrt(np.bincount(instance.state_nodes, weights=colors**2, minlength=instance.nodes))
    plant_links = int(np.count_nonzero(instance.plant_adj) - np.count_nonzero(np.diag(instance.plant_adj)))
    nodes = _draw(axes[0], instance.plant_adj, pos, colors, f"plant graph\n|E| = {plant_links}")
    for ax, (weight, links, cost, support) in zip(axes[1:], path):
        _draw(ax, np.asarray(support), pos, colors, f"β = {weight:.3g}\n|E| = {links}, J = {cost:.3f}")
    fig.tight_layout()
    bar = fig.colorbar(nodes, ax=list(axes), fraction=0.015, pad=0.01)
    bar.set_label("|leading eigenvector of A| at each node", fontsize=7)
    bar.ax.tick_params(labelsize=6)
    return fig, axes


def topology_path_records(records, *, method: str = "grnn_sparse", weight: str = "beta",
                          prefer_a_norm: float = 1.1) -> list[DesignRecord]:
    """The records of one instance's regularization path, for :func:`plot_topology_path`.

    A path is one instance and one setting of every other hyperparameter (a
    Table 1 run at β = 1 with 750 training steps is not on the trade-off
    sweep's 150-step path). Picks a path on ``a_norm == prefer_a_norm``, as
    the paper's Fig. 4 does, when one has two or more weights; then the paper's
    tanh GRNN over the linear ablation; then the most weights, then the lowest seed.
    """
    paths: dict[tuple, dict] = {}
    for r in as_records(records):
        if r.method != method or r.status != "optimal" or weight not in r.params:
            continue
        paths.setdefault((r.instance.key, r.params_key_without(weight)), {})[r.params[weight]] = r
    if not paths:
        return []

    def rank(item):
        (_, others), path = item
        design = next(iter(path.values()))
        preferred = design.instance.a_norm == prefer_a_norm and len(path) >= 2
        linear = design.params.get("activation") == "identity"
        return (not preferred, linear, -len(path), design.instance.spec.get("seed", 0), others)

    _, path = min(paths.items(), key=rank)
    return [path[w] for w in sorted(path)]
