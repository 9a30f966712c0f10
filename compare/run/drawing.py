"""What the topology figure draws of an instance, stored with its facts so that no report builds it.

:class:`InstanceDrawing` holds the plant and communication graphs and the node
colours; the runner stores :func:`drawing_facts` with each instance's facts, the
records carry it back (:class:`compare.run.records.InstanceRecord`), and
:func:`compare.report.topologies.plot_topology_path` draws it. This module imports nothing
else of the project, so records and figures can both use it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

__all__ = ["InstanceDrawing", "node_colours", "drawing_facts", "DRAWN_NODES_AT_MOST"]

#: Instances with more nodes than this get no stored drawing (and so no topology figure): it would outweigh
#: every other fact of the instance, and a spy plot of more nodes shows little.
DRAWN_NODES_AT_MOST = 200


def _leading_eigenvector(A: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eig(A)
    return np.abs(np.real(V[:, np.argmax(np.abs(w))]))


def node_colours(instance) -> np.ndarray:
    """Each node's colour in the figure: the magnitude of the leading eigenvector of A at the node.

    Where nodes hold several states, the norm of the node's entries. The one place
    this is computed, for a drawing made from an instance and for a stored one alike.

    Parameters
    ----------
    instance : codesign.Instance
        Its ``A``, ``nodes`` and ``state_nodes`` are read.

    Returns
    -------
    (N,) float array
    """
    colors = _leading_eigenvector(instance.A)
    if colors.size != instance.nodes:  # several states per node: the norm of each node's entries
        colors = np.sqrt(np.bincount(instance.state_nodes, weights=colors**2, minlength=instance.nodes))
    return colors


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _pattern_rows(adj: np.ndarray) -> list[list[int]]:
    return [np.flatnonzero(row).tolist() for row in adj]


def _pattern(rows, nodes: int, name: str) -> np.ndarray:
    """The (N, N) boolean pattern of stored rows (row i: the nodes that send to node i)."""
    if not isinstance(rows, list) or len(rows) != nodes:
        raise ValueError(f"a stored drawing's {name} must list the sending nodes of each of its {nodes} nodes")
    adj = np.zeros((nodes, nodes), dtype=bool)
    for i, row in enumerate(rows):
        if not (isinstance(row, list) and all(isinstance(j, int) and not isinstance(j, bool) and 0 <= j < nodes
                                              for j in row)):
            raise ValueError(f"a stored drawing's {name} row {i} must be a list of node numbers 0 to {nodes - 1}")
        adj[i, row] = True
    return adj


@dataclass(frozen=True, eq=False)
class InstanceDrawing:
    """What the topology figure draws of an instance: its two graphs and its nodes' colours.

    Built from an instance (:meth:`of`) or from the drawing stored with its facts
    (:meth:`from_facts`); both give the same arrays, bit for bit. The arrays are
    read-only.

    Attributes
    ----------
    plant_adj, comm_adj : (N, N) bool arrays
        ``[i, j]`` True where node j acts on (plant graph) or may send to
        (communication graph) node i, self-loops on the diagonal included.
    colours : (N,) float array
        :func:`node_colours` of the instance.
    """

    plant_adj: np.ndarray
    comm_adj: np.ndarray
    colours: np.ndarray

    @property
    def nodes(self) -> int:
        """N, the number of nodes."""
        return int(self.colours.size)

    @classmethod
    def of(cls, instance) -> InstanceDrawing:
        """The drawing of a :class:`codesign.Instance` (its ``A``, ``nodes``, ``state_nodes`` and graphs)."""
        return cls(_read_only(np.asarray(instance.plant_adj) != 0), _read_only(np.asarray(instance.comm_adj) != 0),
                   _read_only(np.array(node_colours(instance), dtype=float)))

    def to_facts(self) -> dict:
        """The drawing as JSON values: ``{"plant": rows, "comm": rows, "colours": [...]}``.

        Row i of a graph lists the nodes that send to node i (its nonzero columns,
        diagonal included), which is about half the size of ``[i, j]`` pairs.
        """
        return {"plant": _pattern_rows(self.plant_adj), "comm": _pattern_rows(self.comm_adj),
                "colours": [float(c) for c in self.colours]}

    @classmethod
    def from_facts(cls, facts: Mapping) -> InstanceDrawing:
        """The drawing stored by :meth:`to_facts`; ValueError naming what is malformed."""
        if not isinstance(facts, Mapping) or set(facts) != {"plant", "comm", "colours"}:
            raise ValueError('a stored drawing must be {"plant": [...], "comm": [...], "colours": [...]}')
        colours = facts["colours"]
        if not (isinstance(colours, list) and colours and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) and c >= 0
                for c in colours)):
            raise ValueError("a stored drawing's colours must be one finite number >= 0 per node")
        nodes = len(colours)
        return cls(_read_only(_pattern(facts["plant"], nodes, "plant")),
                   _read_only(_pattern(facts["comm"], nodes, "comm")),
                   _read_only(np.array(colours, dtype=float)))


def drawing_facts(instance) -> dict | None:
    """What the runner stores for the topology figure (:meth:`InstanceDrawing.to_facts`), or None.

    None for an instance of more than :data:`DRAWN_NODES_AT_MOST` nodes.
    """
    if instance.nodes > DRAWN_NODES_AT_MOST:
        return None
    return InstanceDrawing.of(instance).to_facts()
