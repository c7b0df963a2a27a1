"""Smith dynamics (paper eq. 13) and distributed Smith dynamics (eq. 14): pairwise comparison.

``x_i' = sum_j g_ij x_j [f_i - f_j]_+ - x_i sum_j g_ij [f_j - f_i]_+``: every strategy ``j``
sends its mass to each better strategy ``i`` at a rate proportional to the fitness gap. With the
complete graph ``g`` this is eq. 13; with a communication graph, eq. 14. As a flow law
(:mod:`popdispatch.dynamics.law`): kernel ``[f_i - f_j]_+``, receiver weight 1, sender weight
``x_j``, no upper limit.

Rest points: every strategy in use has the best fitness among its neighbours (on the complete
graph, the game's Nash equilibria). Extinction: a strategy at zero share receives from every
worse one, so Smith uses an efficient generator that starts at zero. With generator limits
(exact mode) its variant is :mod:`~popdispatch.dynamics.capacity` (or
:mod:`~popdispatch.dynamics.newton`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.dynamics import capacity
from popdispatch.dynamics.law import Dynamics, FieldTag, FlowLaw, copy_into, movable


@nb.njit(cache=True, inline="always")
def smith_weights(x, lo, hi, active, w, v, room):
    """Receiver weight 1, movable mass ``x`` (dimensionless shares), unbounded room."""
    for i in range(x.shape[0]):
        w[i] = 1.0 if active[i] else 0.0
        v[i] = max(x[i], 0.0) if active[i] else 0.0
        room[i] = np.inf


@nb.njit(cache=True, inline="always")
def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """The law's weights (:class:`~popdispatch.dynamics.law.FlowLaw`): :func:`smith_weights`,
    the sender weight being the movable mass."""
    smith_weights(x, lo, hi, active, w, v, room)
    copy_into(v, mass)


def reference(tag, x, f, lo, hi, active, rate):
    """Plain numpy: ``w = 1``, ``v = mass = x`` on the online strategies, no upper limit."""
    v = movable(x, active)
    return active * 1.0, v, np.full(len(x), np.inf), v


class SmithTag(FieldTag):
    """Smith's weights (:func:`smith_weights`)."""

    __slots__ = ()


LAW = FlowLaw("SMITH", SmithTag, weights, reference)
LAWS = (LAW,)
DYNAMICS = (
    Dynamics("smith", LAW, False, bounded_law=capacity.LAW),  # eq. 13
    Dynamics("distributed-smith", LAW, True, bounded_law=capacity.LAW),  # eq. 14
)
