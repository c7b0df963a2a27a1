"""Curvature-scaled capacity-constrained Smith dynamics: each generator revises at a rate set
by its own cost curve (exact mode's revision protocol; docs/exact-mode.md, "Revision rates").

Mass moves from generator ``j`` to a fitter generator ``i`` at the rate

    r_i r_j / R * [f_i - f_j]_+ * 1[x_i < hi_i] * 1[x_j > lo_j],    R = sum_k r_k,

with ``r_i`` generator ``i``'s revision rate, the inverse of its cost curve's curvature
``1 / (2 c_i)`` made dimensionless (:func:`revision_rates`). Near an interior rest point the
fitness is ``-kappa (b_i + 2 c_i p_i)`` (plus the line prices) and the set points move as

    p_i' = kappa P_d r_i (fbar - f_i) / kappa,   fbar = sum_j r_j f_j / R,

so each marginal cost ``b_i + 2 c_i p_i`` relaxes towards the rate-weighted mean at the same
speed whatever its curvature: a Newton step per generator (the economic dispatch's
participation factors ``1 / (2 c)``), where plain Smith moves a flat generator ``c`` times
slower than a steep one. Both weights are indicators times the rate (nothing flows into a
generator at ``hi`` or out of one at ``lo``), so a generator optimal exactly at a limit with
zero reduced cost reaches it at a rate linear in its distance, like
:mod:`~popdispatch.dynamics.capacity`'s receiver; the flux limiter lands senders and
receivers on their limits. The rest points are those of every capacity-constrained pairwise
protocol on the complete graph: interior generators with equal fitness, a generator at ``hi``
fitter and one at ``lo`` less fit than them (the KKT conditions, docs/exact-mode.md).

``R`` sums the rates of the generators strictly inside their limits. A generator at a limit
trades at a rate of at most ``R`` (:func:`own_rate`): a flat generator at ``Pmax`` beside
steep ones inside would otherwise move their set points at ``r_j / R`` times their own Newton
rate (a fleet of two, the flat one 50 times the steep one's rate, never left the warm start:
the adaptive steps could not resolve the first move). With the cap a pair's rate is at most
the smaller of ``r_i`` and ``R``, so no marginal cost relaxes faster than its own Newton step.

A linear generator (``c = 0``) has no curvature to scale by: its rate is capped at
:data:`RATE_CAP` (:func:`revision_rates`).

On a communication graph no generator knows ``R``: each normalises by its own closed
neighbourhood instead, ``w_i = r_i / R_i`` with ``R_i`` the rates of ``i`` and its neighbours
inside their limits, and caps its rate at a limit by ``R_i`` (:func:`neighbourhood_weights`);
on the complete graph that is ``R``. The weights stay positive, so the rest points are
unchanged.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.dynamics.capacity import ROOM_ULPS, box
from popdispatch.dynamics.law import FieldTag, FlowLaw

#: Largest revision rate, as a fraction of ``1 / (2 c)`` at the curvature ``S / P`` (a
#: generator whose marginal cost climbs the whole spread of marginal costs over the reference
#: demand has rate 0.5): a linear generator takes this one.
RATE_CAP = 50.0


def revision_rates(
    c: np.ndarray,
    spread: float,
    demand: float,
    cap: float = RATE_CAP,
    priced: np.ndarray | None = None,
    free_cap: float = np.inf,
) -> np.ndarray:
    """Each generator's revision rate ``r_i = (S / P) / (2 c_i)`` (dimensionless): ``c``
    EUR/MW^2h, ``spread`` ``S`` EUR/MWh and ``demand`` ``P`` MW (the scales of
    :func:`popdispatch.modes.exact.scales`).

    ``priced``: the generators whose output moves a priced row (a limited line above them, a
    monitored voltage; default all). Their rates are at most ``cap``: a price's proportional
    weight ``C`` adds to their curvature, and the field's fastest rate grows with ``r_i C``.
    The other quadratic generators' rates are capped only at ``free_cap``, far higher: the
    field near an interior rest point is ``p' = -kappa D (diag(r) - r r^T / R) (2 diag(c) + C
    A^T A)`` (``A`` the priced rows), whose eigenvalues are at most ``max_i r_i 2 c_i + C
    sum_(priced i) r_i``, so such a generator adds at most ``S / P`` whatever its rate, and its
    marginal cost relaxes as fast as a steep one's however flat it is (capped at ``cap``, a
    flat pair crawled where a steep generator made ``S`` large). Far from rest a very large
    rate costs the adaptive steps many evaluations on a flat generator's fast moves, which
    ``free_cap`` bounds. A linear generator (``c = 0``) keeps ``cap``: its weights are
    indicators times its rate, so a large rate makes it chatter along a limit it relays
    through, and the adaptive steps resolve that chatter at a cost that grows with the rate."""
    unit = spread / demand  # EUR/MW^2h
    c = np.asarray(c, dtype=float)
    with np.errstate(divide="ignore"):
        rate = unit / (2.0 * c)
    capped = (c <= 0.0) | (True if priced is None else np.asarray(priced, dtype=bool))
    return np.where(capped, np.minimum(rate, cap), np.minimum(rate, max(cap, free_cap)))


@nb.njit(cache=True, inline="always")
def own_rate(rate, inside, total):
    """The rate a generator trades at: its own ``rate`` strictly inside its limits, at a limit
    at most ``total``, the rates of those inside (when there are any to compare with)."""
    return rate if inside or not total > 0.0 else min(rate, total)


@nb.njit(cache=True, inline="always")
def newton_weights(x, lo, hi, active, rate, w, v, room, mass):
    """Receiver weight ``r_i / R`` below ``hi``, sender weight ``r_j`` above ``lo`` (a rate at
    a limit at most ``R``, :func:`own_rate`), room ``hi - x`` and movable mass ``x - lo``
    (shares); ``R`` sums the rates of the generators taking part (online, with ``hi > lo``)
    strictly inside their limits, else with room. Room or mass of at most
    :data:`~popdispatch.dynamics.capacity.ROOM_ULPS` units in the last place of ``hi`` is none
    (the limiter lands on a limit up to round-off)."""
    for i in range(x.shape[0]):
        if hi[i] <= lo[i] or not active[i]:
            w[i] = 0.0
            v[i] = 0.0
            room[i] = 0.0
            mass[i] = 0.0
            continue
        near = ROOM_ULPS * np.spacing(hi[i])
        room[i] = max(hi[i] - x[i], 0.0)
        if room[i] <= near:
            room[i] = 0.0
        mass[i] = max(x[i] - lo[i], 0.0)
        if mass[i] <= near:
            mass[i] = 0.0
    # R: the rates of the generators strictly inside their limits (those at a limit trade one
    # way only and take no part in the Newton step), else of the receivers
    inside = 0.0
    receivers = 0.0
    for i in range(x.shape[0]):
        if room[i] > 0.0:
            receivers += rate[i]
            if mass[i] > 0.0:
                inside += rate[i]
    total = inside if inside > 0.0 else receivers
    for i in range(x.shape[0]):
        own = own_rate(rate[i], room[i] > 0.0 and mass[i] > 0.0, total)
        w[i] = own / total if room[i] > 0.0 else 0.0
        v[i] = own if mass[i] > 0.0 else 0.0


@nb.njit(cache=True)
def neighbourhood_weights(indptr, indices, rate, w, v, room, mass):
    """The weights on a communication graph, in place, normalised by each generator's closed
    neighbourhood in the graph of CSR adjacency ``indptr``, ``indices``: ``R_i`` the rates of
    generator ``i`` and its neighbours strictly inside their limits (room and movable mass),
    else of those with room; receiver weight ``r_i / R_i`` (where ``w > 0``), sender weight
    ``r_i`` (where ``v > 0``), each rate of a generator at a limit at most ``R_i``
    (:func:`own_rate`)."""
    for i in range(w.shape[0]):
        if w[i] <= 0.0 and v[i] <= 0.0:
            continue
        inside_i = room[i] > 0.0 and mass[i] > 0.0
        inside = rate[i] if inside_i else 0.0
        receivers = rate[i] if room[i] > 0.0 else 0.0
        for e in range(indptr[i], indptr[i + 1]):
            j = indices[e]
            if room[j] > 0.0:
                receivers += rate[j]
                if mass[j] > 0.0:
                    inside += rate[j]
        total = inside if inside > 0.0 else receivers
        own = own_rate(rate[i], inside_i, total)
        if w[i] > 0.0:
            w[i] = own / total
        if v[i] > 0.0:
            v[i] = own


@nb.njit(cache=True, inline="always")
def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """The law's weights (:class:`~popdispatch.dynamics.law.FlowLaw`): :func:`newton_weights`."""
    newton_weights(x, lo, hi, active, rate, w, v, room, mass)


def reference(tag, x, f, lo, hi, active, rate):
    """Plain numpy: receiver weight ``r_i / R`` below ``hi``, sender weight ``r_j`` above
    ``lo`` (``R``: the rates strictly inside their limits, else of those with room; a rate at
    a limit at most ``R``)."""
    room, mass = box(x, lo, hi, active)
    mass = np.where(mass <= ROOM_ULPS * np.spacing(hi), 0.0, mass)
    inside = (room > 0.0) & (mass > 0.0)
    total = rate[inside].sum() if inside.any() else rate[room > 0.0].sum()
    own = np.where(inside | (total <= 0.0), rate, np.minimum(rate, total))
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(room > 0.0, own / total, 0.0)
    return w, np.where(mass > 0.0, own, 0.0), room, mass


def reference_local(adjacency, rate, w, v, room, mass):
    """Plain numpy: the weights on a communication graph, ``(w, v)``: ``R_i`` the rates of
    ``i``'s closed neighbourhood inside their limits (else with room), receiver weight
    ``r_i / R_i``, sender weight ``r_i``, a rate at a limit at most ``R_i``."""
    closed = (adjacency + np.eye(len(w))) > 0
    inside = (room > 0) & (mass > 0)
    total = closed @ np.where(inside, rate, 0.0)
    total = np.where(total > 0, total, closed @ np.where(room > 0, rate, 0.0))
    own = np.where(inside | (total <= 0), rate, np.minimum(rate, total))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(w > 0, own / total, 0.0), np.where(v > 0, own, 0.0)


class CapacityNewtonTag(FieldTag):
    """Curvature-scaled capacity-constrained Smith weights (:func:`newton_weights`), which
    read the game's per-generator revision rates."""

    __slots__ = ()


LAW = FlowLaw("CAPACITY_NEWTON", CapacityNewtonTag, weights, reference,
              local=neighbourhood_weights, reference_local=reference_local)  # fmt: skip
LAWS = (LAW,)
DYNAMICS = ()  # exact mode's curvature-scaled revision of smith (RunSettings.field)
