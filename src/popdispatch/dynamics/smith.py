"""Smith dynamics (paper eq. 13) and distributed Smith dynamics (eq. 14).

Every vector field in :mod:`popdispatch.dynamics` has the signature
``rates(x, f, graph, lo, hi) -> (inflow, out_rate, rate_bound)`` with
``x' = inflow - x * out_rate``, ``inflow >= 0`` and ``out_rate >= 0``; ``rate_bound`` (1/s) bounds
how fast any share moves relative to its room, so an explicit step ``h <= 1 / rate_bound`` keeps
``x`` in its domain (``x >= 0``, and ``lo <= x <= hi`` for capacity-constrained fields).
``graph`` is the symmetric 0/1 adjacency of the communication graph between strategies;
``lo``/``hi`` are share bounds (used by capacity-constrained protocols, ignored here).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def smith_rates(x, f, graph, lo, hi):
    """Eq. 14: ``x_i' = sum_j g_ij x_j [f_i - f_j]_+ - x_i sum_j g_ij [f_j - f_i]_+``.

    With the complete graph this is the Smith dynamics of eq. 13.
    """
    n = x.shape[0]
    inflow = np.zeros(n)
    out_rate = np.zeros(n)
    for i in range(n):
        for j in range(n):
            if graph[i, j] == 0.0:
                continue
            gap = f[i] - f[j]
            if gap > 0.0:
                inflow[i] += x[j] * gap
            else:
                out_rate[i] -= gap
    return inflow, out_rate, out_rate.max()
