"""Flows on the limited lines and the controllers' broadcast, on the tree of limited lines.

Only limited lines have node controllers, so the engine works on the *tree of limited lines*:
each limited line knows the nearest limited line above it (``line_up``, towards the source) and
each generator the nearest limited line above its node (``generator_line``). With the lines
visited in tree pre-order (``line_preorder``):

- the generation below every limited line is one bottom-up accumulation, and its flow is
  ``load_flow - generation below`` (radial lossless DC flow, eq. 1d: a line carries the net
  demand of its subtree);
- the signal a generator receives from all controllers (eq. 8) is one top-down accumulation:
  every line sends its parent-side value to all generators, plus (child-side minus
  parent-side) value to those below it.

Both cost O(limited lines + generators) per evaluation, with no dense (lines x generators)
matrix: a 100,000-line feeder with 1,000 generators costs two passes over 100,000 numbers.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def limited_ancestors(preorder, parent, parent_line, limited_index):
    """Per node, the limited line at or above it (index among the limited lines, -1 if none).

    ``preorder``: nodes in DFS pre-order; ``parent``/``parent_line``: per node (-1 at the root);
    ``limited_index``: per line, its index among the limited lines (-1 if unlimited).
    """
    nearest = np.full(parent.shape[0], -1, dtype=np.int64)
    for node in preorder:
        line = parent_line[node]
        if line < 0:
            continue
        own = limited_index[line]
        nearest[node] = own if own >= 0 else nearest[parent[node]]
    return nearest


@nb.njit(cache=True, inline="always")
def limited_line_flows(load_flow, p, generator_line, line_up, line_preorder, flow):
    """Flows (MW, + away from the source) on the limited lines into ``flow``.

    ``load_flow``: the flow the loads alone cause (MW); ``p``: set points (MW).
    """
    flow[:] = 0.0
    for i in range(p.shape[0]):
        k = generator_line[i]
        if k >= 0:
            flow[k] += p[i]
    for r in range(line_preorder.shape[0] - 1, -1, -1):
        k = line_preorder[r]
        up = line_up[k]
        if up >= 0:
            flow[up] += flow[k]
    for k in range(flow.shape[0]):
        flow[k] = load_flow[k] - flow[k]


@nb.njit(cache=True, inline="always")
def broadcast(to_parent_side, to_child_side, generator_line, line_up, line_preorder, path, signal):
    """Sum over limited lines of the value each generator receives, into ``signal``.

    Line ``k`` sends ``to_child_side[k]`` to the generators below it and ``to_parent_side[k]``
    to all others. ``path`` is scratch of one value per limited line.
    """
    common = 0.0
    for r in range(line_preorder.shape[0]):
        k = line_preorder[r]
        common += to_parent_side[k]
        up = line_up[k]
        path[k] = (path[up] if up >= 0 else 0.0) + to_child_side[k] - to_parent_side[k]
    for i in range(signal.shape[0]):
        k = generator_line[i]
        signal[i] = common + (path[k] if k >= 0 else 0.0)


@nb.njit(cache=True, inline="always")
def mesh_line_flows(load_flow, p, factor, flow):
    """Flows (MW) on the limited lines of a meshed network into ``flow``: ``load_flow - D p``
    with the distribution factors ``factor`` = ``D`` (limited lines x generators,
    :mod:`popdispatch.game.mesh`); ``p``: set points (MW). One pass over ``D``."""
    for k in range(flow.shape[0]):
        total = 0.0
        for i in range(p.shape[0]):
            total += factor[k, i] * p[i]
        flow[k] = load_flow[k] - total


@nb.njit(cache=True, inline="always")
def mesh_broadcast(to_parent_side, to_child_side, factor, signal):
    """:func:`broadcast` on a meshed network: generator ``i`` weighs line ``k``'s two values by
    its own distribution factor ``D_ki`` (``factor``), ``signal_i = sum_k to_parent_side[k] +
    D_ki (to_child_side[k] - to_parent_side[k])``; on a radial feeder (``D`` 0/1) the values
    of the side the generator is on, as :func:`broadcast` sends them."""
    common = 0.0
    for k in range(to_parent_side.shape[0]):
        common += to_parent_side[k]
    for i in range(signal.shape[0]):
        signal[i] = common
    for k in range(to_parent_side.shape[0]):
        step = to_child_side[k] - to_parent_side[k]
        if step != 0.0:
            for i in range(signal.shape[0]):
                signal[i] += factor[k, i] * step


def generator_spans(
    generator_line: np.ndarray, line_up: np.ndarray, line_preorder: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(order, span)``: the generators in an order where those below each limited line are
    consecutive, ``order[span[k, 0]:span[k, 1]]`` for line ``k`` (generators below no limited
    line first). The order sorts the generators by the pre-order position of the nearest
    limited line above them: a line's subtree is a run of consecutive positions."""
    n_lines = len(line_preorder)
    position = np.empty(n_lines, dtype=np.int64)
    position[line_preorder] = np.arange(n_lines)
    size = np.ones(n_lines, dtype=np.int64)  # lines in each line's subtree, itself included
    for k in line_preorder[::-1]:
        if line_up[k] >= 0:
            size[line_up[k]] += size[k]
    key = np.where(generator_line >= 0, position[np.maximum(generator_line, 0)], -1)
    order = np.argsort(key, kind="stable").astype(np.int64)
    sorted_key = key[order]
    span = np.stack([np.searchsorted(sorted_key, position, "left"),
                     np.searchsorted(sorted_key, position + size, "left")], axis=1)  # fmt: skip
    return order, np.ascontiguousarray(span, dtype=np.int64)
