"""Replicator dynamics (paper eqs. 9-10) and local replicator dynamics (eq. 12).

Extinction: a strategy with ``x_i = 0`` stays at zero forever (``x_i' = x_i (...)``).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def replicator_rates(x, f, graph, lo, hi):
    """Eq. 9: ``x_i' = x_i (f_i - f_bar)`` with ``f_bar = sum_j x_j f_j`` (eq. 10)."""
    growth = f - np.sum(x * f)
    out_rate = np.maximum(-growth, 0.0)
    return x * np.maximum(growth, 0.0), out_rate, out_rate.max()


@nb.njit(cache=True)
def local_replicator_rates(x, f, graph, lo, hi):
    """Eq. 12: ``x_i' = x_i (f_i sum_{j in N_i} x_j - sum_{j in N_i} f_j x_j)``."""
    growth = f * (graph @ x) - graph @ (f * x)
    out_rate = np.maximum(-growth, 0.0)
    return x * np.maximum(growth, 0.0), out_rate, out_rate.max()
