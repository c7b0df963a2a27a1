"""Capacity-constrained Smith dynamics (exact mode): generator limits without a barrier.

Mass moves from strategy ``j`` to a better strategy ``i`` at the rate
``kappa * (x_j - lo_j) * [f_i - f_j]_+ * 1[x_i < hi_i]`` on every edge of the communication
graph, so no mass flows into a strategy at its upper limit ``hi`` and none out of one at its
lower limit ``lo`` (shares ``x = p / P_d``; ``lo = Pmin / P_d``, ``hi = Pmax / P_d``).
Its rest points are exactly the box-constrained equilibria: interior strategies have equal
fitness, a strategy at ``hi`` may be better and one at ``lo`` worse. That is the KKT condition
of the economic dispatch with generator limits. ``kappa`` = 1 here; the exact mode scales the
fitness instead (see :mod:`popdispatch.modes`). As a flow law
(:mod:`popdispatch.dynamics.law`, summed by :mod:`~popdispatch.dynamics.pairwise`): receiver
weight ``1[x_i < hi_i]``, sender weight ``x_j - lo_j``; the integrator's flux limiter stops a
receiver exactly at ``hi``.

Why an indicator and not the room fraction ``(hi_i - x_i) / (hi_i - lo_i)``: with the
fraction, the inflow into a generator vanishes with the room it has left.
At a degenerate optimum (demand equal to the capacity of the cheap generators, so the dear
one's movable mass ``x_j - lo_j`` equals the room left, or a generator optimal exactly at
``Pmax`` with zero reduced cost, so the fitness gap vanishes with the room) both factors of the
rate vanish together, the distance to the optimum obeys ``d' = -k d^2`` and decays like
``1 / t``: a 5-bus feeder with 20 kW of demand on 10 + 10 kW of cheap generators ran 6000
iterations unconverged. With the indicator the rate is linear in the distance, ``d' = -k d``,
and the limit is reached (the flux limiter lands on it exactly): that case converges at
iteration 10. Sender side: Smith's mass-proportional weight ``x_j - lo_j`` is kept, so a
generator optimal exactly at ``Pmin`` with *zero* reduced cost (gap vanishing with its mass)
is still approached like ``1 / t``.

Cf. the capacity-constrained pairwise-comparison protocols of the popgames library and
Martinez-Piazuelo, Quijano and Ocampo-Martinez (primal-dual evolutionary dynamics).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.dynamics.law import FieldTag, FlowLaw, copy_into

#: Room (in units in the last place of the upper limit) below which a strategy counts as at its
#: upper limit.
ROOM_ULPS = 16.0


@nb.njit(cache=True, inline="always")
def capacity_smith_weights(x, lo, hi, active, w, v, room):
    """Receiver weight ``1[x < hi]``, movable mass ``x - lo``, room ``hi - x`` (dimensionless
    shares); a strategy with no width (offline, ``hi = lo``) takes no part. Room of at most
    :data:`ROOM_ULPS` units in the last place of ``hi`` is none: the limiter lands a receiver on
    its limit up to round-off, and a full generator left a few ulp below it would stay a
    receiver, its inflow limited (the flows summed again) at every step."""
    for i in range(x.shape[0]):
        width = hi[i] - lo[i]
        if width <= 0.0 or not active[i]:
            w[i] = 0.0
            v[i] = 0.0
            room[i] = 0.0
            continue
        room[i] = max(hi[i] - x[i], 0.0)
        if room[i] <= ROOM_ULPS * np.spacing(hi[i]):
            room[i] = 0.0  # a few ulp below its limit: at it (not a receiver)
        w[i] = 1.0 if room[i] > 0.0 else 0.0
        v[i] = max(x[i] - lo[i], 0.0)


@nb.njit(cache=True, inline="always")
def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """The law's weights (:class:`~popdispatch.dynamics.law.FlowLaw`):
    :func:`capacity_smith_weights`, the sender weight being the movable mass."""
    capacity_smith_weights(x, lo, hi, active, w, v, room)
    copy_into(v, mass)


def box(x, lo, hi, active):
    """Plain numpy: ``(room, mass)`` of the strategies taking part (online, ``hi > lo``):
    ``hi - x`` (none within :data:`ROOM_ULPS` ulp of ``hi``) and ``x - lo``; 0 elsewhere."""
    part = active & (hi - lo > 0.0)
    room = np.where(part, np.maximum(hi - x, 0.0), 0.0)
    room = np.where(room <= ROOM_ULPS * np.spacing(hi), 0.0, room)  # at its limit
    return room, np.where(part, np.maximum(x - lo, 0.0), 0.0)


def reference(tag, x, f, lo, hi, active, rate):
    """Plain numpy: receiver weight ``1[room > 0]``, sender weight and mass ``x - lo``."""
    room, mass = box(x, lo, hi, active)
    return np.where(room > 0.0, 1.0, 0.0), mass, room, mass


class CapacitySmithTag(FieldTag):
    """Capacity-constrained Smith weights (:func:`capacity_smith_weights`)."""

    __slots__ = ()


LAW = FlowLaw("CAPACITY_SMITH", CapacitySmithTag, weights, reference)
LAWS = (LAW,)
DYNAMICS = ()  # exact mode's variant of smith (dynamics/smith.py)


@nb.njit(cache=True)
def project_to_box(x, lo, hi):
    """Euclidean projection of ``x`` onto ``{lo <= x <= hi, sum x = 1}`` (bisection on a shift).

    Used when the demand changes between minutes: ``hi = Pmax / P_d`` moves, and a warm-started
    share may sit above its new limit. Written as loops (the same operations in the same order
    as ``np.minimum(np.maximum(x - shift, lo), hi).sum()``): numba compiles array expressions
    with their broadcasting checks several times slower (on the first run).
    """
    n = x.shape[0]
    low = np.inf
    high = -np.inf
    for i in range(n):
        low = min(low, x[i] - hi[i])
        high = max(high, x[i] - lo[i])
    low -= 1.0
    high += 1.0
    for _ in range(200):
        shift = 0.5 * (low + high)
        if _clipped_sum(x, lo, hi, shift) > 1.0:
            low = shift
        else:
            high = shift
    shift = 0.5 * (low + high)
    out = np.empty(n)
    for i in range(n):
        out[i] = min(max(x[i] - shift, lo[i]), hi[i])
    return out


@nb.njit(cache=True, inline="always")
def _clipped_sum(x, lo, hi, shift):
    """``sum_i min(max(x_i - shift, lo_i), hi_i)``, summed in index order."""
    total = 0.0
    for i in range(x.shape[0]):
        total += min(max(x[i] - shift, lo[i]), hi[i])
    return total
