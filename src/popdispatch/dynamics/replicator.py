"""Replicator dynamics (paper eqs. 9-10) and local replicator dynamics (eq. 12): imitation.

``x_i' = x_i (f_i - f_bar)`` with ``f_bar = sum_j x_j f_j`` equals
``sum_j x_i x_j (f_i - f_j)``: a flow law (:mod:`popdispatch.dynamics.law`) with kernel
``[f_i - f_j]_+``, receiver weight ``x_i`` and sender weight ``x_j``. On a communication graph
the sum runs over neighbours, which is eq. 12: ``x_i' = x_i (f_i sum_{j in N_i} x_j -
sum_{j in N_i} f_j x_j)``.

Rest points: every strategy in use has the same fitness (on a graph: as its neighbours in
use); unused strategies may be better. Extinction: a strategy with ``x_i = 0`` receives nothing
and stays at zero forever, so a mode with generator limits refuses it (the DC-OPF uses
generators a run may have at zero).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.dynamics.law import Dynamics, FieldTag, FlowLaw, copy_into, movable

#: Why a mode with generator limits refuses imitative dynamics.
EXTINCTION = (
    "they are imitative, so a generator at zero share stays at zero (extinction) and the "
    "DC-OPF is out of reach whenever it uses one"
)


@nb.njit(cache=True, inline="always")
def replicator_weights(x, lo, hi, active, w, v, room):
    """Receiver and sender weight ``x`` (dimensionless shares), unbounded room."""
    for i in range(x.shape[0]):
        share = max(x[i], 0.0) if active[i] else 0.0
        w[i] = share
        v[i] = share
        room[i] = np.inf


@nb.njit(cache=True, inline="always")
def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """The law's weights (:class:`~popdispatch.dynamics.law.FlowLaw`):
    :func:`replicator_weights`, the sender weight being the movable mass."""
    replicator_weights(x, lo, hi, active, w, v, room)
    copy_into(v, mass)


def reference(tag, x, f, lo, hi, active, rate):
    """Plain numpy: ``w = v = mass = x`` on the online strategies, no upper limit."""
    share = movable(x, active)
    return share, share, np.full(len(x), np.inf), share


class ReplicatorTag(FieldTag):
    """The replicator's weights, complete or local (:func:`replicator_weights`)."""

    __slots__ = ()


LAW = FlowLaw("REPLICATOR", ReplicatorTag, weights, reference)
LOCAL_LAW = FlowLaw("LOCAL_REPLICATOR", ReplicatorTag, weights, reference)
LAWS = (LAW, LOCAL_LAW)
DYNAMICS = (
    Dynamics("replicator", LAW, False, refusal=EXTINCTION),  # eq. 9
    Dynamics("local-replicator", LOCAL_LAW, True, refusal=EXTINCTION),  # eq. 12
)
