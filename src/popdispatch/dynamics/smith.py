"""Smith dynamics (paper eq. 13) and distributed Smith dynamics (eq. 14).

``x_i' = sum_j g_ij x_j [f_i - f_j]_+ - x_i sum_j g_ij [f_j - f_i]_+``: every strategy ``j``
sends its mass to each better strategy ``i`` at a rate proportional to the fitness gap. With the
complete graph ``g`` this is eq. 13; with a communication graph, eq. 14. As a pairwise flow
(:mod:`popdispatch.dynamics.pairwise`): receiver weight 1, sender weight ``x_j``, no upper limit.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def smith_weights(x, lo, hi, active, w, v, room):
    """Receiver weight 1, movable mass ``x`` (dimensionless shares), unbounded room."""
    for i in range(x.shape[0]):
        w[i] = 1.0 if active[i] else 0.0
        v[i] = max(x[i], 0.0) if active[i] else 0.0
        room[i] = np.inf
