"""The designed-topology figure: spy plots for large networks, chains laid out so that their links show."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from compare.topologies import SPY_ABOVE, _collinear, node_order, plot_topology_path, topology_caption  # noqa: E402


def _chain(n: int, hops: int = 1, shuffle: int | None = None):
    """A chain of ``n`` nodes linked to ``hops`` neighbours each way, its nodes numbered in a shuffled order."""
    adj = sum(np.eye(n, k=k) for k in range(-hops, hops + 1))
    if shuffle is not None:
        perm = np.random.default_rng(shuffle).permutation(n)
        adj = adj[np.ix_(perm, perm)]
    A = 0.5 * adj + 0.01 * np.diag(np.arange(n))
    return SimpleNamespace(A=A, plant_adj=adj, comm_adj=(adj != 0).astype(int), nodes=n, state_nodes=np.arange(n))


def _path(inst):
    n = inst.nodes
    dense = np.ones((n, n))
    return [(0.1, n * (n - 1), 1.01, dense), (1.0, int(inst.plant_adj.astype(bool).sum() - n), 1.1, inst.plant_adj),
            (10.0, 0, 1.5, np.eye(n))]


def test_large_networks_are_spy_plots_with_receiving_rows_and_the_link_count_in_the_title():
    inst = _chain(SPY_ABOVE + 10, shuffle=0)
    fig, axes = plot_topology_path(inst, _path(inst))
    assert len(axes) == 4
    for ax in axes:
        assert not ax.collections  # no node-link drawing
        assert len(ax.images) == 2  # the adjacency pattern and the nodes' colour strip
    assert axes[0].get_ylabel() == "receiving node" and axes[1].get_xlabel() == "sending node"
    assert axes[0].get_title() == f"plant graph\n|E| = {2 * (inst.nodes - 1)}"
    assert axes[2].get_title().startswith("β = 1\n|E| = 98")
    # The autonomous end of the path: only the diagonal (self-loops) is dark, in the self-loop grey.
    pattern = axes[3].images[0].get_array()
    dark = np.argwhere(pattern[..., 0] < 0.6)
    assert len(dark) == inst.nodes and (dark[:, 0] == dark[:, 1]).all()
    plt.close(fig)


def test_node_order_turns_a_shuffled_chain_back_into_a_band():
    inst = _chain(60, shuffle=1)
    order = node_order(inst.plant_adj)
    assert sorted(order) == list(range(60))
    rows, cols = np.nonzero(inst.plant_adj[np.ix_(order, order)])
    assert np.abs(rows - cols).max() == 1
    shuffled_rows, shuffled_cols = np.nonzero(inst.plant_adj)
    assert np.abs(shuffled_rows - shuffled_cols).max() > 10


def test_a_small_chain_is_drawn_on_a_circle_not_on_a_line():
    inst = _chain(12, hops=2)
    inst.comm_adj = _chain(12).comm_adj  # the communication graph a chain: its layout a line
    fig, axes = plot_topology_path(inst, _path(inst))
    positions = np.asarray(axes[0].collections[0].get_offsets())
    assert not _collinear(dict(enumerate(positions)))
    radii = np.hypot(positions[:, 0], positions[:, 1])
    assert radii == pytest.approx(np.ones(12))
    # chain order around the circle: neighbours along the chain are neighbours on the circle
    steps = np.hypot(*np.diff(positions, axis=0).T)
    assert steps.max() == pytest.approx(steps.min())
    assert not axes[0].images and axes[1].get_title().startswith("β = 0.1")
    plt.close(fig)


def test_caption_says_how_the_figure_reads():
    assert "row = receiving node" in topology_caption(SPY_ABOVE + 1)
    assert "circle" in topology_caption(SPY_ABOVE) and "β" in topology_caption(20)
    assert "γ" in topology_caption(20, symbol="γ")
