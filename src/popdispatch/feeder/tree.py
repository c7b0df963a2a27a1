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

import numpy as np
from scipy.sparse import csr_array

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

    Raises :class:`FeederError` if the lines do not form one tree over all nodes. O(n) in
    compiled code (one depth-first search by :mod:`scipy.sparse.csgraph`) plus an
    O(n log depth) numpy sweep for the subtree sizes: no per-node Python loop.
    """
    ends_a = np.asarray(ends_a, dtype=np.int64)
    ends_b = np.asarray(ends_b, dtype=np.int64)
    if len(ends_a) != n_nodes - 1:
        raise FeederError(
            f"a radial feeder with {n_nodes} nodes needs {n_nodes - 1} lines, got {len(ends_a)}"
        )
    if len(ends_b) != len(ends_a):
        raise FeederError(f"{len(ends_a)} line start nodes but {len(ends_b)} line end nodes")
    if not 0 <= root < n_nodes:
        raise FeederError(f"root node {root} is not one of the nodes 0..{n_nodes - 1}")
    ends = np.concatenate([ends_a, ends_b])
    if len(ends) and (ends.min() < 0 or ends.max() >= n_nodes):
        raise FeederError("lines do not form a tree: network is meshed or disconnected")
    # imported here: scipy.sparse.csgraph imports scipy.linalg (slow to import), which a run on
    # a cached problem (popdispatch.cases.cached) never needs
    from scipy.sparse.csgraph import depth_first_order

    graph = csr_array(
        (np.ones(len(ends_a), dtype=np.int8), (ends_a, ends_b)), shape=(n_nodes, n_nodes)
    )
    preorder, predecessors = depth_first_order(
        graph, root, directed=False, return_predecessors=True
    )
    # n - 1 lines that reach every node form a tree (a loop, a parallel line or a self-loop
    # would leave some node unreached).
    if len(preorder) != n_nodes:
        raise FeederError("lines do not form a tree: network is meshed or disconnected")
    preorder = preorder.astype(np.int64)
    parent = predecessors.astype(np.int64)
    parent[root] = -1
    line_child = np.where(parent[ends_b] == ends_a, ends_b, ends_a)
    line_parent = np.where(line_child == ends_b, ends_a, ends_b)
    parent_line = np.full(n_nodes, -1, dtype=np.int64)
    parent_line[line_child] = np.arange(n_nodes - 1)
    start = np.empty(n_nodes, dtype=np.int64)
    start[preorder] = np.arange(n_nodes)
    size = _subtree_sizes(parent, preorder, start)
    return Tree(root, line_parent, line_child, parent, parent_line, preorder, start, size)


def _subtree_sizes(parent: np.ndarray, preorder: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Subtree sizes from where each subtree's pre-order range ends.

    A node's range ends where its next sibling starts; a last child's range ends where its
    parent's does. Following "last child -> parent" hops by pointer doubling finds, for every
    node, the first ancestor-or-self with a next sibling (or the root, whose range ends at n):
    O(n log depth) in numpy, however deep or branched the tree.
    """
    n = len(parent)
    children = preorder[1:]  # every non-root node; siblings end up in pre-order
    grouped = children[np.argsort(parent[children], kind="stable")]
    same_parent = parent[grouped[1:]] == parent[grouped[:-1]]
    end = np.full(n, n, dtype=np.int64)
    end[grouped[:-1][same_parent]] = start[grouped[1:][same_parent]]
    last_child = grouped[np.append(~same_parent, True)] if len(grouped) else grouped
    hop = np.arange(n, dtype=np.int64)
    hop[last_child] = parent[last_child]
    while True:
        further = hop[hop]
        if np.array_equal(further, hop):
            break
        hop = further
    return end[hop] - start


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


def selected_line_flows(tree: Tree, injections: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """``(steps, len(lines))``: the DC flows of the lines ``lines`` only, from nodal injections
    ``(steps, nodes)`` (as :func:`line_flows`, same sign convention and unit).

    Node-major inside (one transposed copy, rows gathered in pre-order, one cumulative sum
    down the nodes): a year of hourly steps on a feeder of thousands of nodes takes a fraction
    of a second, where gathering columns of the step-major array takes seconds.
    """
    injections = np.atleast_2d(np.asarray(injections, dtype=float))
    lines = np.asarray(lines, dtype=np.int64)
    if not len(lines):
        return np.zeros((injections.shape[0], 0))
    ordered = np.ascontiguousarray(injections.T)[tree.preorder]  # (nodes, steps)
    cumulative = np.empty((ordered.shape[0] + 1, ordered.shape[1]))
    cumulative[0] = 0.0
    np.cumsum(ordered, axis=0, out=cumulative[1:])
    child = tree.line_child[lines]
    below = cumulative[tree.start[child] + tree.size[child]] - cumulative[tree.start[child]]
    return np.ascontiguousarray(-below.T)


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


def path_sums(tree: Tree, values: np.ndarray) -> np.ndarray:
    """Sum of ``values`` (per node, last axis) over each node's path from the root.

    The path includes the node itself and the root: ``path_sums(tree, ones) - 1`` is the depth,
    ``path_sums`` of per-node line lengths (0 at the root) the distance from the source. Any unit;
    the result is in the unit of ``values``. A value enters the cumulative sum where its node's
    pre-order range starts and leaves where it ends: O(n), no per-node Python loop.
    """
    values = np.asarray(values)
    n = tree.n_nodes
    dtype = np.result_type(values.dtype, np.int64)
    delta = np.zeros(values.shape[:-1] + (n + 1,), dtype=dtype)
    delta[..., tree.start] = values
    np.subtract.at(delta, (Ellipsis, tree.start + tree.size), values)
    return np.take(np.cumsum(delta, axis=-1), tree.start, axis=-1)


def depths(tree: Tree) -> np.ndarray:
    """Number of lines between each node and the root (0 at the root)."""
    return path_sums(tree, np.ones(tree.n_nodes, dtype=np.int64)) - 1
