"""Pairwise-comparison flows: the common kernel of every dynamic in this package.

All of the paper's dynamics move mass from a strategy ``j`` to a better strategy ``i`` at the
rate ``g_ij * w_i * v_j * [f_i - f_j]_+``: ``g`` is the communication graph, ``w_i`` the
receiver weight and ``v_j`` the sender weight (the *movable* mass of ``j``). Each dynamic only
chooses ``w`` and ``v`` (see :mod:`popdispatch.dynamics.fields`); this module sums the flows:

    inflow_i  = w_i * sum_j g_ij [f_i - f_j]_+ v_j,
    outflow_j = v_j * sum_i g_ij [f_i - f_j]_+ w_i,     x' = inflow - outflow.

On the complete graph both sums come from one sort of the fitness and running sums, in
O(n log n) instead of O(n^2) pairs; on a communication graph (CSR adjacency) they cost O(edges).
The running sums add only non-negative terms (fitness steps times partial sums), so equal
fitness gives exactly zero flow and there is no cancellation.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def sort_by_fitness(f, order):
    """Sort ``order`` (a permutation, usually last call's) by ascending ``f``, in place.

    Insertion sort from the previous order: O(n) when fitness ranks barely change, as between
    two stages of an integrator; falls back to a full sort when ranks moved a lot.
    """
    n = order.shape[0]
    moves = 0
    for r in range(1, n):
        item = order[r]
        key = f[item]
        s = r - 1
        while s >= 0 and f[order[s]] > key:
            order[s + 1] = order[s]
            s -= 1
            moves += 1
        order[s + 1] = item
        if moves > 8 * n + 64:
            order[:] = np.argsort(f, kind="mergesort")
            return


@nb.njit(cache=True, inline="always")
def complete_graph_flows(f, w, v, order, inflow, outflow):
    """``inflow``/``outflow`` (see module docstring) on the complete graph; ``order`` sorts f."""
    n = f.shape[0]
    below_v = 0.0  # sum of v over strategies ranked lower
    gain_in = 0.0  # sum_j (f_i - f_j) v_j over lower-ranked j
    for r in range(n):
        i = order[r]
        if r > 0:
            gain_in += (f[i] - f[order[r - 1]]) * below_v
        inflow[i] = w[i] * gain_in
        below_v += v[i]
    above_w = 0.0
    gain_out = 0.0
    for r in range(n - 1, -1, -1):
        j = order[r]
        if r < n - 1:
            gain_out += (f[order[r + 1]] - f[j]) * above_w
        outflow[j] = v[j] * gain_out
        above_w += w[j]


@nb.njit(cache=True, inline="always")
def graph_flows(f, w, v, indptr, indices, inflow, outflow):
    """``inflow``/``outflow`` on a communication graph in CSR form (symmetric), O(edges)."""
    inflow[:] = 0.0
    outflow[:] = 0.0
    for i in range(f.shape[0]):
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            gap = f[i] - f[j]
            if gap > 0.0:
                rate = gap * w[i] * v[j]
                inflow[i] += rate
                outflow[j] += rate


@nb.njit(cache=True, inline="always")
def pairwise_flows(f, w, v, complete, indptr, indices, order, inflow, outflow):
    """Dispatch to :func:`complete_graph_flows` (``order`` already sorted) or
    :func:`graph_flows`."""
    if complete:
        complete_graph_flows(f, w, v, order, inflow, outflow)
    else:
        graph_flows(f, w, v, indptr, indices, inflow, outflow)
