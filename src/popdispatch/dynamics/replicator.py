"""Replicator dynamics (paper eqs. 9-10) and local replicator dynamics (eq. 12).

``x_i' = x_i (f_i - f_bar)`` with ``f_bar = sum_j x_j f_j`` equals
``sum_j x_i x_j (f_i - f_j)``: a pairwise flow (:mod:`popdispatch.dynamics.pairwise`) with
receiver weight ``x_i`` and sender weight ``x_j``. On a communication graph the sum runs over
neighbours, which is eq. 12: ``x_i' = x_i (f_i sum_{j in N_i} x_j - sum_{j in N_i} f_j x_j)``.

Extinction: a strategy with ``x_i = 0`` receives nothing and stays at zero forever.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, inline="always")
def replicator_weights(x, lo, hi, active, w, v, room):
    """Receiver and sender weight ``x`` (dimensionless shares), unbounded room."""
    for i in range(x.shape[0]):
        share = max(x[i], 0.0) if active[i] else 0.0
        w[i] = share
        v[i] = share
        room[i] = np.inf
