"""Pairwise-comparison flows: the sums of the flow laws whose kernel compares fitness.

The paper's dynamics (Smith, the replicators) and their capacity-constrained variants move
mass from a strategy ``j`` to a better strategy ``i`` at the rate
``g_ij * w_i * v_j * [f_i - f_j]_+`` (:mod:`popdispatch.dynamics.law`): ``g`` is the
communication graph, ``w_i`` the receiver weight and ``v_j`` the sender weight. Each law only
chooses ``w`` and ``v``; this module sums the flows:

    inflow_i  = w_i * sum_j g_ij [f_i - f_j]_+ v_j,
    outflow_j = v_j * sum_i g_ij [f_i - f_j]_+ w_i,     x' = inflow - outflow.

On the complete graph both sums come from one sort of the fitness and running sums, in
O(n log n) instead of O(n^2) pairs; on a communication graph (CSR adjacency) they cost O(edges).
The running sums add only non-negative terms (fitness steps times partial sums), so equal
fitness gives exactly zero flow and there is no cancellation.

The engine passes the graph as a :class:`CompleteGraph` or :class:`SparseGraph` record; the
record's class (with the law's) picks the sums when numba compiles
(:func:`popdispatch.dynamics.fields.law_flows`), so a run compiles the sums of its own graph
only.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from popdispatch.jit import ALLOCATING


class Graph(NamedTuple):
    """The communication graph as the compiled kernels take it: its symmetric adjacency in
    CSR form (``indptr``, ``indices``; empty for the complete graph) and the strategies that
    always relay (``slow``, bool, length n on a sparse graph: :func:`slow_relays`). The class
    says which sums run (see :func:`popdispatch.dynamics.fields.law_flows`)."""

    indptr: np.ndarray
    indices: np.ndarray
    slow: np.ndarray


class CompleteGraph(Graph):
    """The complete graph: sorted running sums, O(n log n)."""

    __slots__ = ()


class SparseGraph(Graph):
    """A communication graph: sums over its edges and the relay, O(edges)."""

    __slots__ = ()


def graph_of(complete: bool, indptr: np.ndarray, indices: np.ndarray,
             rate: np.ndarray | None = None, held: np.ndarray | None = None,
             idle_rate: np.ndarray | None = None) -> Graph:  # fmt: skip
    """The graph record: complete, else the CSR adjacency ``indptr``, ``indices`` (int64) with
    the strategies that relay always: by their revision rates ``rate`` or, where the rates in
    force move between ``rate`` and ``idle_rate`` (:func:`popdispatch.modes.exact.rates_in_force`),
    by either (:func:`slow_relays`; none without rates), and those of ``held`` (bool; the
    mode's choice, :meth:`popdispatch.modes.mechanism.Mode.held_relays`)."""
    if complete:
        return CompleteGraph(indptr, indices, np.zeros(0, dtype=np.bool_))
    n = len(indptr) - 1
    slow = np.zeros(n, dtype=np.bool_)
    for rates in (rate, idle_rate):
        if rates is not None and len(rates) == n:
            slow |= slow_relays(np.asarray(rates, dtype=float), indptr, indices)
    if held is not None and len(held) == n:
        slow = slow | np.asarray(held, dtype=np.bool_)
    return SparseGraph(indptr, indices, slow)


#: A strategy whose revision rate is below this fraction of its fastest neighbour's relays
#: always (:func:`slow_relays`).
SLOW_RELAY = 0.1


def slow_relays(rate: np.ndarray, indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Which strategies relay by their revision rate (bool): those whose rate ``r_k`` is below
    :data:`SLOW_RELAY` times the largest rate among their neighbours on the graph of CSR
    adjacency ``indptr``, ``indices``.

    Mass crosses a strategy on a path only through its own trades, whose weights are its
    rate: a steep generator (the curvature-scaled rates go as ``1 / c``) between two others
    passes mass on that much slower, and distributed Smith crawled (a generator with ``c`` =
    1888 EUR/MW^2h between the others was 39 kW from the DC-OPF after 1000 iterations). Such a
    strategy relays as one at a limit does (:func:`relay_flows`), while it also trades on its
    own. A property of the fleet and the graph, fixed for a run: it switches nothing."""
    slow = np.zeros(len(rate), dtype=np.bool_)
    for k in range(len(rate)):
        neighbours = indices[indptr[k]:indptr[k + 1]]
        if len(neighbours) and rate[k] < SLOW_RELAY * rate[neighbours].max():
            slow[k] = True
    return slow


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
            merge_sort(f, order)
            return


@nb.njit(cache=True, **ALLOCATING)
def merge_sort(f, order):
    """``order[:] = np.argsort(f, kind="mergesort")`` (the same permutation: a stable sort of
    ``0..n-1`` by ``f``), bottom-up. numba's ``argsort`` would add seconds to every first
    run's compilation for this fallback, which a run rarely takes."""
    n = order.shape[0]
    for k in range(n):
        order[k] = k
    scratch = np.empty(n, dtype=order.dtype)
    width = 1
    passes = 0
    source, target = order, scratch
    while width < n:
        for left in range(0, n, 2 * width):
            middle = min(left + width, n)
            right = min(left + 2 * width, n)
            a, b, out = left, middle, left
            while a < middle and b < right:
                if f[source[b]] < f[source[a]]:  # ties keep the left run first: stable
                    target[out] = source[b]
                    b += 1
                else:
                    target[out] = source[a]
                    a += 1
                out += 1
            while a < middle:
                target[out] = source[a]
                a += 1
                out += 1
            while b < right:
                target[out] = source[b]
                b += 1
                out += 1
        source, target = target, source
        width *= 2
        passes += 1
    if passes % 2 == 1:  # the sorted run is in the scratch
        for k in range(n):
            order[k] = source[k]


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


#: Movable mass (shares) at or below which a strategy counts as at its lower limit for the
#: relay. A sender's mass decays to its limit exponentially and never reaches it exactly, and
#: until it does it would neither relay nor pass the mass on; the run then comes to rest
#: (set points moving less than the tolerance) before the relay opens: a generator worse than
#: its neighbours holding its last 7e-11 of a share held a random tree 4.6 kW from the
#: DC-OPF. 1e-7 is ten times below the engine's relative tolerance (1e-6 of the demand), at
#: which the KKT check counts a generator as at its limit anyway.
RELAY_MASS = 1e-7

#: Share of its own range (``Pmax - Pmin``) within which a generator of bounded room relays
#: as if at that limit (it also keeps trading on its own). A receiver on the only path to the
#: others fills its last room geometrically, and until its room fell below
#: :data:`RELAY_MASS` the mass behind it waited: a linear generator optimal at ``Pmax``
#: between the source and the rest held a random fleet 224 iterations. Relaying from 1e-3 of
#: the range opens the path while the room closes (docs/exact-mode.md).
NEAR_LIMIT = 1e-3


@nb.njit(cache=True, inline="always")
def relay_margin(mass, room):
    """Movable ``mass`` or ``room`` (shares) at or below which a strategy relays: the larger
    of :data:`RELAY_MASS` and :data:`NEAR_LIMIT` of its range ``mass + room``, where the room
    is bounded (the box dynamics of exact mode; the paper's fields have unbounded room)."""
    if room == np.inf:
        return RELAY_MASS
    return max(RELAY_MASS, NEAR_LIMIT * (mass + room))


@nb.njit(cache=True, inline="always")
def relays_at_limit(w, mass, room):
    """Whether a strategy with receiver weight ``w``, movable ``mass`` and ``room`` (shares)
    relays: offline (``w = 0``), or room or movable mass at most :func:`relay_margin` (at or
    near its upper limit, or its lower limit). A generator just below its limit would
    otherwise stay a receiver that passes on only what it can still absorb, and cut a path in
    two."""
    margin = relay_margin(mass, room)
    return not (w > 0.0 and mass > margin and room > margin)


@nb.njit(cache=True, inline="always")
def receives_relayed(w, room):
    """Whether a strategy with receiver weight ``w`` and ``room`` (shares) receives within a
    relay group: ``w > 0`` and room above :data:`RELAY_MASS`."""
    return w > 0.0 and room > RELAY_MASS


@nb.njit(cache=True, inline="always")
def blocked(w, mass, room, k):
    """:func:`relays_at_limit` of strategy ``k`` of the weight, mass and room arrays."""
    return relays_at_limit(w[k], mass[k], room[k])


@nb.njit(cache=True, inline="always")
def relay_root(label, k):
    """Root of ``k``'s relay group in the union-find forest ``label`` (parents ``>= 0``, roots
    ``-2``: see :func:`relay_groups`), halving the path on the way."""
    while label[k] >= 0:
        parent = label[k]
        grand = label[parent]
        if grand >= 0:
            label[k] = grand
            k = grand
        else:
            k = parent
    return k


@nb.njit(cache=True, inline="always")
def relay_groups(w, mass, room, slow, indptr, indices, label):
    """The relaying strategies' connected sets into ``label`` (int, length n), a union-find
    forest: a parent index, ``-2`` at a root, ``-1`` for a strategy that does not relay
    (neither :func:`blocked` nor ``slow``); False if none relays. A relay group is such a set
    ``S`` together with its neighbours ``N(S)``: any two members are joined by a path whose
    inner strategies are all in ``S``."""
    n = w.shape[0]
    any_relays = False
    for k in range(n):
        if slow[k] or blocked(w, mass, room, k):
            label[k] = -2
            any_relays = True
        else:
            label[k] = -1
    if not any_relays:
        return False
    for a in range(n):
        if label[a] == -1:
            continue
        for e in range(indptr[a], indptr[a + 1]):
            b = indices[e]
            if b > a and label[b] != -1:
                ra = relay_root(label, a)
                rb = relay_root(label, b)
                if ra != rb:
                    label[rb] = ra
    return True


@nb.njit(cache=True, inline="always")
def group_memberships(label, indptr, indices, group, member):
    """Every (group, member) pair into ``group``, ``member`` (int, length at least n + edges):
    a strategy belongs to its own set's group if it relays and to the group of each relaying
    neighbour's set, once each; returns the number of pairs."""
    count = 0
    for k in range(label.shape[0]):
        own = relay_root(label, k) if label[k] != -1 else -1
        if own >= 0:
            group[count] = own
            member[count] = k
            count += 1
        for e in range(indptr[k], indptr[k + 1]):
            b = indices[e]
            if label[b] == -1:
                continue
            r = relay_root(label, b)
            seen = r == own
            for e2 in range(indptr[k], e):  # a group reached through an earlier neighbour
                b2 = indices[e2]
                if not seen and label[b2] != -1 and relay_root(label, b2) == r:
                    seen = True
            if not seen:
                group[count] = r
                member[count] = k
                count += 1
    return count


@nb.njit(cache=True, inline="always")
def group_order(f, group, member, count, n):
    """The first ``count`` memberships sorted by group, then by ascending fitness of the
    member: a merge sort by fitness (:func:`merge_sort`, stable) followed by a stable
    counting sort by group (groups are indexed by their root, below ``n``)."""
    key = np.empty(count)
    for m in range(count):
        key[m] = f[member[m]]
    by_fitness = np.empty(count, dtype=np.int64)
    merge_sort(key, by_fitness)
    start = np.zeros(n + 1, dtype=np.int64)
    for m in range(count):
        start[group[m] + 1] += 1
    for r in range(n):
        start[r + 1] += start[r]
    ordered = np.empty(count, dtype=np.int64)
    for m in by_fitness:
        ordered[start[group[m]]] = member[m]
        start[group[m]] += 1
    return ordered, start


@nb.njit(cache=True, inline="always")
def group_flows(f, w, v, room, members, inflow, outflow):
    """Add Smith's flows among ``members`` (sorted by ascending ``f``) to ``inflow``/``outflow``:
    every member ``a`` sends to every better member ``b`` that can receive (``w_b > 0``, room
    above :data:`RELAY_MASS`) at ``w_b v_a [f_b - f_a]_+``, by running sums as on the complete
    graph (:func:`complete_graph_flows`)."""
    below_v = 0.0
    gain_in = 0.0
    for r in range(members.shape[0]):
        i = members[r]
        if r > 0:
            gain_in += (f[i] - f[members[r - 1]]) * below_v
        if receives_relayed(w[i], room[i]):
            inflow[i] += w[i] * gain_in
        below_v += v[i]
    above_w = 0.0
    gain_out = 0.0
    for r in range(members.shape[0] - 1, -1, -1):
        j = members[r]
        if r < members.shape[0] - 1:
            gain_out += (f[members[r + 1]] - f[j]) * above_w
        outflow[j] += v[j] * gain_out
        if receives_relayed(w[j], room[j]):
            above_w += w[j]


@nb.njit(cache=True, inline="always")
def relay_flows(f, w, v, mass, room, slow, indptr, indices, label, inflow, outflow):
    """Add the relayed flows of distributed Smith on a graph to ``inflow``/``outflow``
    (``slow``: the strategies that relay by their rates, :func:`slow_relays`; ``label``: int
    scratch of length n); nothing when no strategy relays.

    On a communication graph a strategy that cannot take part in a comparison (at a limit:
    :func:`blocked`) cuts its neighbours apart: a generator at ``Pmax`` receives nothing and
    passes nothing on, so two interior generators on either side of it never trade and
    distributed Smith rests away from the dispatch (docs/agents.md). The relay: within each
    relay group (:func:`relay_groups`) every sender ``a`` (``v_a > 0``) also sends to every
    better member ``b`` that can receive, at the pairwise rate ``w_b v_a [f_b - f_a]_+``,
    once per group the two share; the blocked strategies between them pass the mass on and
    keep their own. Each term moves mass from a worse to a better strategy, like the direct
    ones, so the flux limiter and the rest-point argument of the pairwise flows apply
    unchanged: at rest no strategy that can send is worse than one that can receive anywhere
    in the graph, the box-constrained equilibrium of the complete graph (docs/agents.md, "the
    relay"). The terms are continuous in the fitness: where two receivers tie, a sender's
    relayed flow is shared between them, not switched from one to the other (a jump in the
    field that an error-controlled step resolves only with steps of the tolerance over the
    jump). The member lists (n + edges entries) are allocated when a strategy is blocked
    (:func:`grouped_flows`).
    """
    if relay_groups(w, mass, room, slow, indptr, indices, label):
        grouped_flows(f, w, v, room, indptr, indices, label, inflow, outflow)


@nb.njit(cache=True, **ALLOCATING)
def grouped_flows(f, w, v, room, indptr, indices, label, inflow, outflow):
    """The relayed flows within each relay group of ``label`` (:func:`relay_flows`), added to
    ``inflow``/``outflow``. It allocates the member lists (n + edges entries), so it is
    compiled with reference counting (:mod:`popdispatch.jit`)."""
    n = f.shape[0]
    group = np.empty(n + indices.shape[0], dtype=np.int64)
    member = np.empty(n + indices.shape[0], dtype=np.int64)
    count = group_memberships(label, indptr, indices, group, member)
    ordered, start = group_order(f, group, member, count, n)
    begin = 0
    for r in range(n):
        end = start[r]
        if end - begin > 1:
            group_flows(f, w, v, room, ordered[begin:end], inflow, outflow)
        begin = end
