"""Compiled dispatch from a vector field (:class:`Field`) to its weights.

Every dynamic is a pairwise-comparison flow (:mod:`popdispatch.dynamics.pairwise`) defined by a
receiver weight ``w``, a sender weight ``v`` (the movable mass) and the ``room`` each strategy
has left below its upper limit (``inf`` when unbounded). The integrator calls
:func:`field_weights` with an integer code rather than receiving a function: numba caches kernels
that take functions as arguments poorly (every new process recompiled them, about 9 s), while a
static dispatch caches on disk. Adding a dynamic means adding its weights to its module, a code
here and a branch below; the integrator does not change.
"""

from __future__ import annotations

from enum import IntEnum

import numba as nb

from popdispatch.dynamics.capacity import capacity_smith_weights
from popdispatch.dynamics.replicator import replicator_weights
from popdispatch.dynamics.smith import smith_weights


class Field(IntEnum):
    """The vector fields, by their weights (see :mod:`popdispatch.dynamics`)."""

    SMITH = 0
    REPLICATOR = 1
    LOCAL_REPLICATOR = 2
    CAPACITY_SMITH = 3


SMITH, REPLICATOR, LOCAL_REPLICATOR, CAPACITY_SMITH = Field


@nb.njit(cache=True, inline="always")
def field_weights(code, x, lo, hi, active, w, v, room):
    """Fill ``w``, ``v``, ``room`` for the field ``code`` (a :class:`Field`) at ``x``."""
    if code == Field.SMITH:
        smith_weights(x, lo, hi, active, w, v, room)
    elif code == Field.REPLICATOR or code == Field.LOCAL_REPLICATOR:
        replicator_weights(x, lo, hi, active, w, v, room)
    else:
        capacity_smith_weights(x, lo, hi, active, w, v, room)
