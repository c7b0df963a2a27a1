"""Compiled dispatch from a vector-field code to its field.

The integrator calls :func:`vector_field` with an integer code instead of receiving the field
as a function argument: numba caches kernels that take functions as arguments poorly (every
new process recompiled them, about 9 s), while a static dispatch caches on disk. Adding a
dynamic means adding its field module, a code here and a branch below; the integrator does not
change.
"""

from __future__ import annotations

import numba as nb

from popdispatch.dynamics.capacity import capacity_smith_rates
from popdispatch.dynamics.replicator import local_replicator_rates, replicator_rates
from popdispatch.dynamics.smith import smith_rates

SMITH, REPLICATOR, LOCAL_REPLICATOR, CAPACITY_SMITH = range(4)


@nb.njit(cache=True)
def vector_field(code, x, f, graph, lo, hi):
    """``(inflow, out_rate, rate_bound)`` of the field ``code`` (see the module constants)."""
    if code == SMITH:
        return smith_rates(x, f, graph, lo, hi)
    if code == REPLICATOR:
        return replicator_rates(x, f, graph, lo, hi)
    if code == LOCAL_REPLICATOR:
        return local_replicator_rates(x, f, graph, lo, hi)
    return capacity_smith_rates(x, f, graph, lo, hi)
