"""Rooted radial trees and lossless DC flows on them (paper eq. 1d).

Nodes are numbered ``0..n-1`` and lines ``0..n-2``. Every line joins a parent node (towards the
root) and a child node. **Sign convention:** the flow of a line is positive when power flows
*away from the root*, from its parent node to its child node.

In a lossless radial network the flow of a line equals the net demand (load minus generation)
of the subtree hanging below it. With the nodes in DFS pre-order every subtree is a contiguous
range, so all subtree sums come from one cumulative sum: O(n), no per-node Python loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np

from popdispatch.errors import FeederError


@dataclass(frozen=True)
class Tree:
    """A rooted tree over nodes ``0..n-1``.

    Attributes
    ----------
    root : root node (the source).
    line_parent, line_child : per line, its parent-side and child-side node.
    parent : per node, its parent node (``-1`` at the root).
    parent_line : per node, the line to its parent (``-1`` at the root).
    preorder : nodes in DFS pre-order from the root.
    start : per node, its position in ``preorder``.
    size : per node, the number of nodes in its subtree (itself included).
    """

    root: int
    line_parent: np.ndarray
    line_child: np.ndarray
    parent: np.ndarray
    parent_line: np.ndarray
    preorder: np.ndarray
    start: np.ndarray
    size: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.parent)

    @property
    def n_lines(self) -> int:
        return len(self.line_child)


def build_tree(n_nodes: int, ends_a: np.ndarray, ends_b: np.ndarray, root: int = 0) -> Tree:
    """Orient the undirected lines ``ends_a[k] -- ends_b[k]`` away from ``root``.

    Raises :class:`FeederError` if the lines do not form one tree over all nodes.
    """
    ends_a = np.asarray(ends_a, dtype=np.int64)
    ends_b = np.asarray(ends_b, dtype=np.int64)
    if len(ends_a) != n_nodes - 1:
        raise FeederError(
            f"a radial feeder with {n_nodes} nodes needs {n_nodes - 1} lines, got {len(ends_a)}"
        )
    g = nx.Graph()
    g.add_nodes_from(range(n_nodes))
    g.add_edges_from(
        (int(a), int(b), {"line": k}) for k, (a, b) in enumerate(zip(ends_a, ends_b, strict=True))
    )
    if not nx.is_tree(g):
        raise FeederError("lines do not form a tree: network is meshed or disconnected")
    preorder = np.fromiter(nx.dfs_preorder_nodes(g, root), dtype=np.int64, count=n_nodes)
    parent = np.full(n_nodes, -1, dtype=np.int64)
    for child, par in nx.dfs_predecessors(g, root).items():
        parent[child] = par
    line_child = np.where(parent[ends_b] == ends_a, ends_b, ends_a)
    line_parent = np.where(line_child == ends_b, ends_a, ends_b)
    parent_line = np.full(n_nodes, -1, dtype=np.int64)
    parent_line[line_child] = np.arange(n_nodes - 1)
    start = np.empty(n_nodes, dtype=np.int64)
    start[preorder] = np.arange(n_nodes)
    size = _subtree_sizes(parent, preorder)
    return Tree(root, line_parent, line_child, parent, parent_line, preorder, start, size)


def _subtree_sizes(parent: np.ndarray, preorder: np.ndarray) -> np.ndarray:
    # Depth-level sweep (deepest level first): one numpy call per level, none per node.
    depth = np.zeros(len(parent), dtype=np.int64)
    for node in preorder[1:]:
        depth[node] = depth[parent[node]] + 1
    size = np.ones(len(parent), dtype=np.int64)
    order = preorder[np.argsort(-depth[preorder], kind="stable")]
    levels = np.split(order, np.flatnonzero(np.diff(depth[order])) + 1)
    for level in levels:
        if depth[level[0]] > 0:
            np.add.at(size, parent[level], size[level])
    return size


def subtree_sums(tree: Tree, values: np.ndarray) -> np.ndarray:
    """Sum of ``values`` (per node, last axis) over each node's subtree.

    ``values`` may carry leading axes (e.g. minutes x nodes); sums are along the last axis.
    """
    ordered = np.take(values, tree.preorder, axis=-1)
    zero = np.zeros(ordered.shape[:-1] + (1,))
    cumulative = np.concatenate([zero, np.cumsum(ordered, axis=-1)], axis=-1)
    return np.take(cumulative, tree.start + tree.size, axis=-1) - np.take(
        cumulative, tree.start, axis=-1
    )


def line_flows(tree: Tree, injections: np.ndarray) -> np.ndarray:
    """DC flow of every line from nodal injections (generation minus load; last axis = nodes).

    Positive flow = from the line's parent node to its child node (away from the root).
    Any unit; the result is in the unit of ``injections``.
    """
    return -np.take(subtree_sums(tree, injections), tree.line_child, axis=-1)


def downstream(tree: Tree, nodes: np.ndarray) -> np.ndarray:
    """Boolean matrix ``(lines, len(nodes))``: is ``nodes[j]`` below line ``k`` (child side)?

    Its complement is the parent side. This is what a node controller needs to know to broadcast
    a penalty to the sending side of a congested line and an incentive to the other side.
    """
    first = tree.start[tree.line_child][:, None]
    position = tree.start[np.asarray(nodes, dtype=np.int64)][None, :]
    return (position >= first) & (position < first + tree.size[tree.line_child][:, None])


def path_lines(tree: Tree, node_a: int, node_b: int) -> np.ndarray:
    """Indices of the lines on the path between two nodes (from ``node_a`` towards ``node_b``)."""
    ancestors_a = _ancestors(tree, node_a)
    ancestors_b = _ancestors(tree, node_b)
    common = set(ancestors_a) & set(ancestors_b)
    up = [n for n in ancestors_a if n not in common]
    down = [n for n in ancestors_b if n not in common]
    return np.array([tree.parent_line[n] for n in up + down[::-1]], dtype=np.int64)


def _ancestors(tree: Tree, node: int) -> list[int]:
    chain = [node]
    while tree.parent[chain[-1]] >= 0:
        chain.append(int(tree.parent[chain[-1]]))
    return chain
