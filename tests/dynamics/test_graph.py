"""The named communication graphs (built with numpy, dynamics/graph.py) equal networkx's own
generators of the same graphs, and a user's networkx graph is read by generator name."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from popdispatch.dynamics.graph import communication_graph

NETWORKX = {
    "complete": nx.complete_graph,
    "ring": nx.cycle_graph,
    "path": nx.path_graph,
    "star": lambda n: nx.star_graph(n - 1),
    "circulant": lambda n: nx.circulant_graph(n, [1, round(n**0.5)]),
}


@pytest.mark.parametrize("kind", sorted(NETWORKX))
@pytest.mark.parametrize("n", [1, 2, 3, 4, 6, 11, 69])
def test_named_graphs_equal_networkx(kind, n):
    names = [f"G{i}" for i in range(n)]
    expected = nx.to_numpy_array(NETWORKX[kind](n), nodelist=range(n), weight=None)
    np.fill_diagonal(expected, 0.0)
    np.testing.assert_array_equal(communication_graph(kind, names), expected)


def test_a_users_graph_by_generator_name():
    graph = nx.Graph([("G2", "G0"), ("G0", "G1")])
    adjacency = communication_graph(graph, ["G0", "G1", "G2"])
    np.testing.assert_array_equal(adjacency, [[0, 1, 1], [1, 0, 0], [1, 0, 0]])


def test_unknown_and_disconnected_graphs_are_named():
    with pytest.raises(ValueError, match="unknown communication graph 'tree'"):
        communication_graph("tree", ["G0", "G1"])
    with pytest.raises(ValueError, match="disconnected: generator 'G2'"):
        communication_graph(nx.Graph([("G0", "G1")]), ["G0", "G1", "G2"])


@pytest.mark.parametrize("n", [9, 69, 300])
def test_the_circulant_graph_is_short_across(n):
    """Four partners each and a diameter of about sqrt(n), where the ring's is n / 2."""
    graph = nx.from_numpy_array(communication_graph("circulant", [f"G{i}" for i in range(n)]))
    assert max(d for _, d in graph.degree) == 4
    assert nx.diameter(graph) <= round(n**0.5) < nx.diameter(nx.cycle_graph(n))
