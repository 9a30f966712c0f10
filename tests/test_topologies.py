"""The designed-topology figure: spy plots for large networks, chains laid out so that their links show."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from compare.report.topologies import SPY_ABOVE, _collinear, node_order, plot_topology_path, topology_caption  # noqa: E402


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


# -- the drawing stored with an instance's facts ------------------------------------

PAPER = {"family": "paper", "n": 12, "a_norm": 1.1, "b_norm": 1.0, "degree": 4, "hops": 2, "horizon": 10, "seed": 3}
MASS_SPRING = {"family": "mass_spring", "n": 6, "seed": 1, "dt": 0.2, "horizon": 10, "r": 10.0}


@pytest.mark.parametrize("spec", [PAPER, MASS_SPRING], ids=["paper", "mass_spring"])
def test_the_stored_drawing_gives_the_built_instances_arrays_exactly(spec):
    """Through the runner's facts and JSON (as the store keeps them), bit for bit the built instance's drawing."""
    import json

    from compare.run.records import InstanceRecord
    from compare.run.runner import build_instance, instance_facts
    from compare.run.drawing import InstanceDrawing, node_colours

    instance = build_instance(spec)
    stored = json.loads(json.dumps(instance_facts(instance)))
    drawing = InstanceRecord.from_spec(spec, stored).drawing
    built = InstanceDrawing.of(instance)
    assert drawing.nodes == built.nodes == instance.nodes == spec["n"]
    for name in ("plant_adj", "comm_adj", "colours"):
        assert getattr(drawing, name).dtype == getattr(built, name).dtype
        assert np.array_equal(getattr(drawing, name), getattr(built, name)), name
    assert np.array_equal(drawing.plant_adj, instance.plant_adj != 0)
    assert np.array_equal(drawing.comm_adj, instance.comm_adj != 0)
    assert np.array_equal(drawing.colours, node_colours(instance))
    assert drawing.plant_adj.diagonal().all()  # self-loops kept: spy plots draw them
    if spec is MASS_SPRING:  # two states per node: one colour per node, the norm of its two entries
        assert instance.n == 2 * instance.nodes and drawing.colours.shape == (instance.nodes,)
    with pytest.raises(ValueError):
        drawing.colours[0] = 1.0  # read-only


def test_an_instance_and_its_stored_drawing_draw_the_same_figure():
    import json

    from compare.run.runner import build_instance
    from compare.run.drawing import InstanceDrawing, drawing_facts

    instance = build_instance(MASS_SPRING)
    drawing = InstanceDrawing.from_facts(json.loads(json.dumps(drawing_facts(instance))))
    path = _path(SimpleNamespace(nodes=instance.nodes, plant_adj=instance.plant_adj))
    drawn = []
    for source in (instance, drawing):
        fig, axes = plot_topology_path(source, path)
        nodes = axes[0].collections[-1]
        drawn.append((np.asarray(nodes.get_offsets()), nodes.get_array(), [ax.get_title() for ax in axes]))
        plt.close(fig)
    (offsets, colours, titles), (offsets2, colours2, titles2) = drawn
    assert np.array_equal(offsets, offsets2) and np.array_equal(colours, colours2) and titles == titles2


def test_no_drawing_is_stored_above_the_node_limit():
    from compare.run.drawing import DRAWN_NODES_AT_MOST, drawing_facts

    assert drawing_facts(SimpleNamespace(nodes=DRAWN_NODES_AT_MOST + 1)) is None
    small = _chain(5)
    facts = drawing_facts(small)
    assert facts["plant"][0] == [0, 1] and facts["plant"][2] == [1, 2, 3] and len(facts["colours"]) == 5


@pytest.mark.parametrize("facts, problem", [
    ({"plant": [[0]], "comm": [[0]]}, 'must be {"plant"'),
    ({"plant": [[0]], "comm": [[0]], "colours": []}, "colours must be one finite number"),
    ({"plant": [[0]], "comm": [[0]], "colours": [float("nan")]}, "colours must be one finite number"),
    ({"plant": [[0], [1]], "comm": [[0]], "colours": [1.0]}, "plant must list the sending nodes of each of its 1"),
    ({"plant": [[0]], "comm": [[1]], "colours": [1.0]}, "comm row 0 must be a list of node numbers 0 to 0"),
    ({"plant": [[0]], "comm": [[True]], "colours": [1.0]}, "comm row 0"),
])
def test_a_malformed_stored_drawing_is_refused_naming_the_problem(facts, problem):
    from compare.run.drawing import InstanceDrawing

    with pytest.raises(ValueError, match="a stored drawing") as error:
        InstanceDrawing.from_facts(facts)
    assert problem in str(error.value)


def test_an_instance_record_carries_its_drawing_and_is_still_keyed_by_its_spec_alone():
    from compare.run.records import InstanceRecord

    facts = {"n": 5, "plant_links": 8, "comm_links": 8}
    drawn = InstanceRecord.from_spec(PAPER, {**facts, "drawing": _chain_drawing(5)})
    bare = InstanceRecord.from_spec(PAPER, facts)
    assert bare.drawing is None and InstanceRecord.from_spec(PAPER).drawing is None
    assert drawn.drawing.nodes == 5 and drawn.has_facts and bare.has_facts
    assert drawn == bare and hash(drawn) == hash(bare) and len({drawn, bare}) == 1
    with pytest.raises(ValueError, match="a stored drawing's colours"):
        InstanceRecord.from_spec(PAPER, {**facts, "drawing": {"plant": [], "comm": [], "colours": []}})


def _chain_drawing(n: int) -> dict:
    from compare.run.drawing import drawing_facts

    return drawing_facts(_chain(n))
