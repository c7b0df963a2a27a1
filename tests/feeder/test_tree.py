"""Rooted radial trees and DC flows, checked against brute force on random trees."""

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from popdispatch.errors import FeederError
from popdispatch.feeder.tree import (
    build_tree,
    depths,
    downstream,
    line_flows,
    path_lines,
    path_sums,
    selected_line_flows,
    subtree_sums,
)

SETTINGS = settings(max_examples=150, deadline=None)
FINITE = st.floats(-100.0, 100.0, allow_nan=False, allow_infinity=False)


@st.composite
def random_trees(draw, min_nodes=1, max_nodes=30):
    """(n, ends_a, ends_b, root): a random tree with random labels, line order and orientation."""
    n = draw(st.integers(min_nodes, max_nodes))
    parent = [draw(st.integers(0, i - 1)) for i in range(1, n)]
    label = draw(st.permutations(range(n)))
    edges = [(label[i + 1], label[p]) for i, p in enumerate(parent)]
    edges = draw(st.permutations(edges)) if edges else []
    flips = draw(st.lists(st.booleans(), min_size=len(edges), max_size=len(edges)))
    edges = [(b, a) if flip else (a, b) for (a, b), flip in zip(edges, flips, strict=True)]
    ends_a = np.array([a for a, _ in edges], dtype=np.int64)
    ends_b = np.array([b for _, b in edges], dtype=np.int64)
    root = draw(st.integers(0, n - 1))
    return n, ends_a, ends_b, root


def _graph(n, ends_a, ends_b):
    g = nx.Graph()
    g.add_nodes_from(range(n))
    g.add_edges_from(zip(ends_a.tolist(), ends_b.tolist(), strict=True))
    return g


def _child_sides(n, ends_a, ends_b, root):
    """Per line, the set of nodes cut off from the root when the line is removed."""
    g = _graph(n, ends_a, ends_b)
    sides = []
    for a, b in zip(ends_a.tolist(), ends_b.tolist(), strict=True):
        g.remove_edge(a, b)
        side = set(range(n)) - set(nx.node_connected_component(g, root))
        g.add_edge(a, b)
        sides.append(side)
    return sides


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_tree_structure_matches_networkx(data, case):
    n, ends_a, ends_b, root = case
    tree = build_tree(n, ends_a, ends_b, root)
    assert tree.root == root and tree.n_nodes == n and tree.n_lines == n - 1
    sides = _child_sides(n, ends_a, ends_b, root)
    g = _graph(n, ends_a, ends_b)
    for k, side in enumerate(sides):
        # The child is the end cut off from the root, the parent the other end.
        assert int(tree.line_child[k]) in side
        assert int(tree.line_parent[k]) not in side
        assert {int(tree.line_parent[k]), int(tree.line_child[k])} == {
            int(ends_a[k]),
            int(ends_b[k]),
        }
        assert tree.parent[tree.line_child[k]] == tree.line_parent[k]
        assert tree.parent_line[tree.line_child[k]] == k
        assert tree.size[tree.line_child[k]] == len(side)
    assert tree.parent[root] == -1 and tree.parent_line[root] == -1
    assert tree.size[root] == n
    assert sorted(tree.preorder.tolist()) == list(range(n))
    assert tree.preorder[0] == root
    np.testing.assert_array_equal(tree.preorder[tree.start], np.arange(n))
    # Every subtree is the contiguous pre-order range [start, start + size).
    for node in range(n):
        below = set(tree.preorder[tree.start[node] : tree.start[node] + tree.size[node]].tolist())
        expected = {node} | (nx.descendants(nx.bfs_tree(g, root), node))
        assert below == expected


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_line_flows_match_brute_force(data, case):
    n, ends_a, ends_b, root = case
    injections = data.draw(arrays(np.float64, n, elements=FINITE))
    tree = build_tree(n, ends_a, ends_b, root)
    flows = line_flows(tree, injections)
    assert flows.shape == (n - 1,)
    sides = _child_sides(n, ends_a, ends_b, root)
    expected = np.array([-injections[sorted(side)].sum() for side in sides])
    np.testing.assert_allclose(flows, expected, rtol=1e-12, atol=1e-9)


@SETTINGS
@given(data=st.data(), case=random_trees(min_nodes=2))
def test_selected_line_flows_match_brute_force(data, case):
    """The node-major flows of chosen lines, over several steps, equal the brute-force
    subtree sums of each step."""
    n, ends_a, ends_b, root = case
    steps = data.draw(st.integers(1, 5))
    injections = data.draw(arrays(np.float64, (steps, n), elements=FINITE))
    chosen = np.array(data.draw(st.lists(st.integers(0, n - 2), max_size=n)), dtype=np.int64)
    tree = build_tree(n, ends_a, ends_b, root)
    flows = selected_line_flows(tree, injections, chosen)
    assert flows.shape == (steps, len(chosen))
    sides = _child_sides(n, ends_a, ends_b, root)
    expected = np.array(
        [[-row[sorted(sides[k])].sum() for k in chosen] for row in injections]
    ).reshape(steps, len(chosen))
    np.testing.assert_allclose(flows, expected, rtol=1e-12, atol=1e-9)


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_flow_conservation_with_balanced_injections(data, case):
    n, ends_a, ends_b, root = case
    injections = data.draw(arrays(np.float64, n, elements=FINITE))
    injections = injections - injections.mean()  # total injection zero: the root balances
    tree = build_tree(n, ends_a, ends_b, root)
    flows = line_flows(tree, injections)
    for node in range(n):
        inflow = flows[tree.parent_line[node]] if node != root else 0.0
        outflow = flows[tree.line_parent == node].sum()
        assert injections[node] + inflow - outflow == pytest.approx(0.0, abs=1e-9)
    # The root's lines carry exactly what the root injects.
    assert flows[tree.line_parent == root].sum() == pytest.approx(injections[root], abs=1e-9)


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_subtree_sums_with_leading_axes(data, case):
    n, ends_a, ends_b, root = case
    rows = data.draw(st.integers(1, 4))
    values = data.draw(arrays(np.float64, (rows, n), elements=FINITE))
    tree = build_tree(n, ends_a, ends_b, root)
    sums = subtree_sums(tree, values)
    assert sums.shape == (rows, n)
    bfs = nx.bfs_tree(_graph(n, ends_a, ends_b), root)
    for r in range(rows):
        np.testing.assert_allclose(sums[r], subtree_sums(tree, values[r]), atol=1e-12)
        expected = [values[r, [v, *nx.descendants(bfs, v)]].sum() for v in range(n)]
        np.testing.assert_allclose(sums[r], expected, rtol=1e-12, atol=1e-9)
    # Three axes too, and line flows keep the leading axes.
    cube = np.stack([values, 2 * values])
    np.testing.assert_allclose(subtree_sums(tree, cube)[1], 2 * sums, atol=1e-9)
    flows = line_flows(tree, values)
    assert flows.shape == (rows, n - 1)
    np.testing.assert_allclose(flows[-1], line_flows(tree, values[-1]), atol=1e-12)


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_path_sums_and_depths_match_networkx(data, case):
    n, ends_a, ends_b, root = case
    values = data.draw(arrays(np.float64, (2, n), elements=FINITE))
    tree = build_tree(n, ends_a, ends_b, root)
    paths = nx.shortest_path(_graph(n, ends_a, ends_b), root)  # root -> every node
    np.testing.assert_array_equal(depths(tree), [len(paths[v]) - 1 for v in range(n)])
    sums = path_sums(tree, values)
    assert sums.shape == (2, n)
    expected = [[values[r, paths[v]].sum() for v in range(n)] for r in range(2)]
    np.testing.assert_allclose(sums, expected, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(path_sums(tree, values[1]), sums[1], atol=1e-12)


def test_deep_chain():
    # A 50,000-node path graph (lines listed leaf first, reversed): depths and sizes still exact.
    n = 50_000
    tree = build_tree(n, np.arange(n - 1, 0, -1), np.arange(n - 2, -1, -1), root=0)
    np.testing.assert_array_equal(tree.parent, np.arange(-1, n - 1))
    np.testing.assert_array_equal(tree.size, np.arange(n, 0, -1))
    np.testing.assert_array_equal(depths(tree), np.arange(n))
    np.testing.assert_array_equal(tree.line_child, np.arange(n - 1, 0, -1))


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_downstream_matches_brute_force(data, case):
    n, ends_a, ends_b, root = case
    nodes = np.array(data.draw(st.lists(st.integers(0, n - 1), max_size=12)), dtype=np.int64)
    tree = build_tree(n, ends_a, ends_b, root)
    matrix = downstream(tree, nodes)
    assert matrix.shape == (n - 1, len(nodes)) and matrix.dtype == bool
    sides = _child_sides(n, ends_a, ends_b, root)
    expected = np.array([[int(v) in side for v in nodes] for side in sides], dtype=bool)
    np.testing.assert_array_equal(matrix.reshape(expected.shape), expected)


@SETTINGS
@given(data=st.data(), case=random_trees())
def test_path_lines_match_networkx(data, case):
    n, ends_a, ends_b, root = case
    a = data.draw(st.integers(0, n - 1))
    b = data.draw(st.integers(0, n - 1))
    tree = build_tree(n, ends_a, ends_b, root)
    g = nx.Graph()
    g.add_nodes_from(range(n))
    g.add_edges_from(
        (int(u), int(v), {"line": k}) for k, (u, v) in enumerate(zip(ends_a, ends_b, strict=True))
    )
    path = nx.shortest_path(g, a, b)
    expected = [g.edges[u, v]["line"] for u, v in zip(path[:-1], path[1:], strict=True)]
    got = path_lines(tree, a, b)
    assert got.dtype == np.int64
    assert got.tolist() == expected


@SETTINGS
@given(data=st.data(), case=random_trees(min_nodes=3))
def test_build_tree_rejects_meshed(data, case):
    n, ends_a, ends_b, root = case
    g = _graph(n, ends_a, ends_b)
    u, v = data.draw(st.sampled_from(list(nx.non_edges(g))))  # exists for any tree, n >= 3
    # One line too many: a loop.
    with pytest.raises(FeederError, match=f"needs {n - 1} lines, got {n}"):
        build_tree(n, np.append(ends_a, u), np.append(ends_b, v), root)
    # Right number of lines, but one of them closes a loop (and so another bus is cut off).
    k = data.draw(st.integers(0, n - 2))
    swapped_a, swapped_b = ends_a.copy(), ends_b.copy()
    swapped_a[k], swapped_b[k] = u, v
    if nx.is_tree(_graph(n, swapped_a, swapped_b)):
        return  # the new line happened to reconnect the cut: still a tree
    with pytest.raises(FeederError, match="meshed or disconnected"):
        build_tree(n, swapped_a, swapped_b, root)


@SETTINGS
@given(data=st.data(), case=random_trees(min_nodes=2))
def test_build_tree_rejects_disconnected(data, case):
    n, ends_a, ends_b, root = case
    k = data.draw(st.integers(0, n - 2))
    with pytest.raises(FeederError, match=f"needs {n - 1} lines, got {n - 2}"):
        build_tree(n, np.delete(ends_a, k), np.delete(ends_b, k), root)
    # An isolated extra node.
    with pytest.raises(FeederError, match=f"needs {n} lines, got {n - 1}"):
        build_tree(n + 1, ends_a, ends_b, root)


def test_build_tree_rejects_parallel_line_with_right_count():
    # 0-1 twice and node 2 unconnected: n - 1 lines but not a tree.
    with pytest.raises(FeederError, match="meshed or disconnected"):
        build_tree(3, np.array([0, 1]), np.array([1, 0]), 0)


def test_build_tree_rejects_unknown_nodes():
    with pytest.raises(FeederError, match="meshed or disconnected"):
        build_tree(3, np.array([0, 5]), np.array([1, 2]), 0)
    with pytest.raises(FeederError, match="meshed or disconnected"):
        build_tree(3, np.array([0, -1]), np.array([1, 2]), 0)
    with pytest.raises(FeederError, match="root node 3"):
        build_tree(3, np.array([0, 1]), np.array([1, 2]), 3)


def test_small_tree_by_hand():
    #      0 (root)
    #     / \
    #    1   2        lines: 0: 1-0 (stored child first), 1: 0-2, 2: 3-1
    #    |
    #    3
    tree = build_tree(4, np.array([1, 0, 3]), np.array([0, 2, 1]), root=0)
    np.testing.assert_array_equal(tree.line_parent, [0, 0, 1])
    np.testing.assert_array_equal(tree.line_child, [1, 2, 3])
    np.testing.assert_array_equal(tree.size, [4, 2, 1, 1])
    # Root generates 10, node 3 consumes 6, node 2 consumes 4.
    flows = line_flows(tree, np.array([10.0, 0.0, -4.0, -6.0]))
    np.testing.assert_allclose(flows, [6.0, 4.0, 6.0])
    # Node 3 generates 5 and exports 1 to the root through line 0 (reverse flow).
    flows = line_flows(tree, np.array([-1.0, 0.0, 0.0, 1.0]))
    np.testing.assert_allclose(flows, [-1.0, 0.0, -1.0])
    np.testing.assert_array_equal(
        downstream(tree, np.array([0, 3])), [[False, True], [False, False], [False, True]]
    )
    assert path_lines(tree, 3, 2).tolist() == [2, 0, 1]
    assert path_lines(tree, 2, 2).tolist() == []
