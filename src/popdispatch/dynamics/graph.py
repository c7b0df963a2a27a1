"""Communication graphs between generators (strategies), as adjacency matrices.

The named graphs are built with numpy (connected by construction); networkx is imported only
for a user's own graph (importing it would weigh on every command's start-up).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import networkx as nx

GRAPHS = ("complete", "ring", "path", "star", "circulant")


def communication_graph(kind: str | nx.Graph, generators: list[str]) -> np.ndarray:
    """Symmetric 0/1 adjacency (float, zero diagonal) over ``generators``, in their order.

    ``kind`` is a name of :data:`GRAPHS` or a networkx graph whose nodes are generator names
    (or positions ``0..n-1``). A disconnected graph is an error: mass could never reach some
    strategies, so the dynamics could not find the dispatch.
    """
    if isinstance(kind, str):
        return named_graph(kind, len(generators))
    import networkx as nx

    n = len(generators)
    graph = _relabel(kind, generators)
    if n > 1 and not nx.is_connected(graph):
        lonely = next(iter(min(nx.connected_components(graph), key=len)))
        raise ValueError(
            f"communication graph is disconnected: generator {generators[lonely]!r} "
            "cannot exchange information with the others"
        )
    adjacency = nx.to_numpy_array(graph, nodelist=range(n), weight=None)
    np.fill_diagonal(adjacency, 0.0)
    return adjacency


def named_graph(kind: str, n: int) -> np.ndarray:
    """The adjacency of the named graph ``kind`` (:data:`GRAPHS`) on ``n`` nodes: complete,
    ring (``i ~ i + 1 mod n``), path (``i ~ i + 1``), star (node 0 the hub) or circulant (the
    ring with chords ``i ~ i + s mod n``, ``s = round(sqrt(n))``: four partners each and a
    diameter of about ``sqrt(n)`` instead of the ring's ``n / 2``; mass crosses a sparse
    graph hop by hop, so a large fleet on a ring converges slowly)."""
    adjacency = np.zeros((n, n))
    nodes = np.arange(n)
    if kind == "complete":
        adjacency[:] = 1.0
    elif kind in ("ring", "path"):
        last = n if kind == "ring" and n > 2 else n - 1
        adjacency[nodes[:last], (nodes[:last] + 1) % n] = 1.0
    elif kind == "star":
        adjacency[:1, 1:] = 1.0
    elif kind == "circulant":
        for offset in (1, round(np.sqrt(n))):
            adjacency[nodes, (nodes + offset) % n] = 1.0
    else:
        raise ValueError(f"unknown communication graph {kind!r} (known: {', '.join(GRAPHS)})")
    adjacency = np.maximum(adjacency, adjacency.T)
    np.fill_diagonal(adjacency, 0.0)
    return adjacency


def _relabel(graph: nx.Graph, generators: list[str]) -> nx.Graph:
    import networkx as nx

    position = {name: i for i, name in enumerate(generators)}
    mapping = {}
    for node in graph.nodes:
        if node in position:
            mapping[node] = position[node]
        elif isinstance(node, int) and 0 <= node < len(generators):
            mapping[node] = node
        else:
            raise ValueError(f"communication graph node {node!r} is not a generator")
    relabelled = nx.relabel_nodes(graph, mapping)
    relabelled.add_nodes_from(range(len(generators)))
    return relabelled
