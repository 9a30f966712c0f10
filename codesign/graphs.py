"""Communication graphs as values: a design's graph, its text form and its hash.

Every co-design picks a graph and fits a controller on it. To ask which part of a
method's cost is its graph and which its controller (:func:`baselines.refit`), a
graph must be a value that a spec, a run key and a report can carry:

- :func:`design_graph`: the (N, N) off-diagonal node support a design's controller
  reads, None where it cannot be recovered (no controller, or a controller whose
  support is not its links, such as SLS's maps, whose links are the graph it was
  constrained to);
- :func:`graph_text` / :func:`parse_graph`: the graph as ``"i-j,i-j,..."`` (node i
  reads node j), sorted, ``""`` for no link: a JSON string that keys a run;
- :func:`graph_hash`: 12 hex digits of its SHA-256, what a report joins designs by.
"""

from __future__ import annotations

import hashlib
import re

import numpy as np

__all__ = ["GRAPH_PATTERN", "graph_text", "parse_graph", "graph_hash", "graph_links", "design_graph"]

#: What :func:`graph_text` writes: comma-separated ``i-j`` pairs (node i reads node j), or nothing.
GRAPH_PATTERN = r"(\d+-\d+(,\d+-\d+)*)?"


def _off_diagonal(adj) -> np.ndarray:
    adj = np.asarray(adj) != 0
    if adj.ndim != 2 or adj.shape[0] != adj.shape[1]:
        raise ValueError(f"a graph is a square (N, N) adjacency, got shape {adj.shape}")
    out = adj.copy()
    np.fill_diagonal(out, False)
    return out


def graph_text(adj) -> str:
    """``"i-j,..."``: the off-diagonal edges of ``adj`` (nonzero = node i reads node j), row-major."""
    rows, cols = np.nonzero(_off_diagonal(adj))
    return ",".join(f"{i}-{j}" for i, j in zip(rows.tolist(), cols.tolist()))


def parse_graph(text: str, nodes: int) -> np.ndarray:
    """The (N, N) bool adjacency of :func:`graph_text`'s ``text`` (no self-loops); ValueError naming the problem."""
    if not isinstance(text, str) or re.fullmatch(GRAPH_PATTERN, text) is None:
        raise ValueError(f"graph must be comma-separated 'i-j' pairs (node i reads node j), got {text!r}")
    adj = np.zeros((nodes, nodes), dtype=bool)
    for pair in filter(None, text.split(",")):
        i, j = (int(k) for k in pair.split("-"))
        if i >= nodes or j >= nodes:
            raise ValueError(f"graph edge {pair!r} names a node outside 0..{nodes - 1}")
        if i == j:
            raise ValueError(f"graph edge {pair!r} is a self-loop: a node's own state needs no link")
        if adj[i, j]:
            raise ValueError(f"graph edge {pair!r} appears twice")
        adj[i, j] = True
    return adj


def graph_hash(adj_or_text) -> str:
    """12 hex digits naming a graph: the SHA-256 of its :func:`graph_text` (the same edges, the same hash)."""
    text = adj_or_text if isinstance(adj_or_text, str) else graph_text(adj_or_text)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def graph_links(adj) -> int:
    """Directed off-diagonal links of ``adj``."""
    return int(_off_diagonal(adj).sum())


def design_graph(instance, design) -> np.ndarray | None:
    """The (N, N) bool off-diagonal node support the design's controller reads, or None.

    None where the design has no controller (it failed), its controller exposes no
    ``support`` and counts links (one that counts none, u = 0, reads the empty graph),
    or that support's links are not the design's ``links`` (SLS:
    its maps spread over every hop of the graph it was constrained to, while its
    links are that graph's edges). The check makes a recovered graph the one the
    design was counted on.
    """
    controller = getattr(design, "controller", None)
    support = getattr(controller, "support", None)
    if support is None:
        # A controller that says nothing of what it reads but counts no link (u = 0) reads no other node.
        empty = controller is not None and int(design.links) == 0
        return np.zeros((instance.nodes, instance.nodes), dtype=bool) if empty else None
    entries = np.asarray(support() if callable(support) else support) != 0  # a method or a property
    if entries.shape != (instance.nodes, instance.nodes):
        if entries.shape != (instance.m, instance.n):
            return None
        entries = instance.node_support(entries)
    adj = _off_diagonal(entries)
    return adj if int(adj.sum()) == int(design.links) else None
