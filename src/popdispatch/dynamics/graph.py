"""Communication graphs between generators (strategies), as adjacency matrices."""

from __future__ import annotations

import networkx as nx
import numpy as np

GRAPHS = ("complete", "ring", "path", "star")


def communication_graph(kind: str | nx.Graph, generators: list[str]) -> np.ndarray:
    """Symmetric 0/1 adjacency (float, zero diagonal) over ``generators``, in their order.

    ``kind`` is a name of :data:`GRAPHS` or a networkx graph whose nodes are generator names
    (or positions ``0..n-1``). A disconnected graph is an error: mass could never reach some
    strategies, so the dynamics could not find the dispatch.
    """
    n = len(generators)
    if isinstance(kind, nx.Graph):
        graph = _relabel(kind, generators)
    elif kind == "complete":
        graph = nx.complete_graph(n)
    elif kind == "ring":
        graph = nx.cycle_graph(n)
    elif kind == "path":
        graph = nx.path_graph(n)
    elif kind == "star":
        graph = nx.star_graph(n - 1)
    else:
        raise ValueError(f"unknown communication graph {kind!r} (known: {', '.join(GRAPHS)})")
    if n > 1 and not nx.is_connected(graph):
        lonely = next(iter(min(nx.connected_components(graph), key=len)))
        raise ValueError(
            f"communication graph is disconnected: generator {generators[lonely]!r} "
            "cannot exchange information with the others"
        )
    adjacency = nx.to_numpy_array(graph, nodelist=range(n), weight=None)
    np.fill_diagonal(adjacency, 0.0)
    return adjacency


def _relabel(graph: nx.Graph, generators: list[str]) -> nx.Graph:
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
