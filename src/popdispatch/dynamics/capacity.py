"""Capacity-constrained Smith dynamics (exact mode): generator limits without a barrier.

Mass moves from strategy ``j`` to a better strategy ``i`` at the rate
``kappa * (x_j - lo_j) * [f_i - f_j]_+ * (hi_i - x_i) / (hi_i - lo_i)`` on every edge of the
communication graph, so no mass flows into a strategy at its upper limit ``hi`` and none out of
one at its lower limit ``lo`` (shares ``x = p / P_d``; ``lo = Pmin / P_d``, ``hi = Pmax / P_d``).
Its rest points are exactly the box-constrained equilibria: interior strategies have equal
fitness, a strategy at ``hi`` may be better and one at ``lo`` worse. That is the KKT condition
of the economic dispatch with generator limits. ``kappa`` = 1 here; the exact mode scales the
fitness instead (see :mod:`popdispatch.modes`). As a pairwise flow
(:mod:`popdispatch.dynamics.pairwise`): receiver weight ``(hi_i - x_i) / (hi_i - lo_i)``, sender
weight ``x_j - lo_j``.

Cf. the capacity-constrained pairwise-comparison protocols of the popgames library and
Martinez-Piazuelo, Quijano and Ocampo-Martinez (primal-dual evolutionary dynamics).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def capacity_smith_weights(x, lo, hi, active, w, v, room):
    """Receiver weight ``(hi - x) / (hi - lo)``, movable mass ``x - lo``, room ``hi - x``
    (dimensionless shares); a strategy with no width (offline, ``hi = lo``) takes no part."""
    for i in range(x.shape[0]):
        width = hi[i] - lo[i]
        if width <= 0.0 or not active[i]:
            w[i] = 0.0
            v[i] = 0.0
            room[i] = 0.0
            continue
        room[i] = max(hi[i] - x[i], 0.0)
        w[i] = room[i] / width
        v[i] = max(x[i] - lo[i], 0.0)


@nb.njit(cache=True)
def project_to_box(x, lo, hi):
    """Euclidean projection of ``x`` onto ``{lo <= x <= hi, sum x = 1}`` (bisection on a shift).

    Used when the demand changes between minutes: ``hi = Pmax / P_d`` moves, and a warm-started
    share may sit above its new limit.
    """
    low = np.min(x - hi) - 1.0
    high = np.max(x - lo) + 1.0
    for _ in range(200):
        shift = 0.5 * (low + high)
        if np.minimum(np.maximum(x - shift, lo), hi).sum() > 1.0:
            low = shift
        else:
            high = shift
    return np.minimum(np.maximum(x - 0.5 * (low + high), lo), hi)
