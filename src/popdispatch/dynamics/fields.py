"""Compiled dispatch from a vector field (:class:`Field`) to its weights.

Every dynamic is a pairwise-comparison flow (:mod:`popdispatch.dynamics.pairwise`) defined by a
receiver weight ``w``, a sender weight ``v`` (the movable mass) and the ``room`` each strategy
has left below its upper limit (``inf`` when unbounded). The integrator calls
:func:`field_weights` with an integer code rather than receiving a function: numba caches kernels
that take functions as arguments poorly (every new process recompiled them, about 9 s), while a
static dispatch caches on disk. Adding a dynamic means adding its weights to its module, a code
here and a branch below; the integrator does not change.

The engine picks the weights at compile time instead (:func:`weights`): the field travels into
the kernels as a :class:`FieldTag`, one small record class per weight kernel, and numba
compiles for each class only the kernel it names. A run thus compiles one dynamic's weights,
not all of them (a run-time choice would compile every field, mode and graph at once).
:func:`field_weights` keeps the integer code for callers that choose at run time (the agents).
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba as nb
from numba.extending import overload

from popdispatch.dynamics.capacity import capacity_smith_weights
from popdispatch.dynamics.newton import neighbourhood_receivers, newton_weights
from popdispatch.dynamics.pairwise import SparseGraph
from popdispatch.dynamics.replicator import replicator_weights
from popdispatch.dynamics.smith import smith_weights


class Field(IntEnum):
    """The vector fields, by their weights (see :mod:`popdispatch.dynamics`)."""

    SMITH = 0
    REPLICATOR = 1
    LOCAL_REPLICATOR = 2
    CAPACITY_SMITH = 3
    CAPACITY_NEWTON = 4


SMITH, REPLICATOR, LOCAL_REPLICATOR, CAPACITY_SMITH, CAPACITY_NEWTON = Field


@nb.njit(cache=True, inline="always")
def field_weights(code, x, lo, hi, active, w, v, room):
    """Fill ``w``, ``v``, ``room`` for the field ``code`` (a :class:`Field`) at ``x``."""
    if code == Field.SMITH:
        smith_weights(x, lo, hi, active, w, v, room)
    elif code == Field.REPLICATOR or code == Field.LOCAL_REPLICATOR:
        replicator_weights(x, lo, hi, active, w, v, room)
    else:
        capacity_smith_weights(x, lo, hi, active, w, v, room)


@nb.njit(cache=True)
def rated_field_weights(code, x, lo, hi, active, rate, w, v, room, mass):
    """:func:`field_weights` for every field, those that read per-generator revision rates
    ``rate`` included, with the movable mass into ``mass``."""
    if code == Field.CAPACITY_NEWTON:
        newton_weights(x, lo, hi, active, rate, w, v, room, mass)
        return
    field_weights(code, x, lo, hi, active, w, v, room)
    for i in range(x.shape[0]):
        mass[i] = v[i]


class FieldTag(NamedTuple):
    """A field as the compiled kernels take it: its :class:`Field` value in ``code``; the
    *class* (one per weight kernel) is what :func:`weights` dispatches on, at compile time."""

    code: int


class SmithTag(FieldTag):
    """Smith's weights (:func:`~popdispatch.dynamics.smith.smith_weights`)."""

    __slots__ = ()


class ReplicatorTag(FieldTag):
    """The replicator's weights, complete or local
    (:func:`~popdispatch.dynamics.replicator.replicator_weights`)."""

    __slots__ = ()


class CapacitySmithTag(FieldTag):
    """Capacity-constrained Smith weights
    (:func:`~popdispatch.dynamics.capacity.capacity_smith_weights`)."""

    __slots__ = ()


class CapacityNewtonTag(FieldTag):
    """Curvature-scaled capacity-constrained Smith weights
    (:func:`~popdispatch.dynamics.newton.newton_weights`), which read the game's per-generator
    revision rates."""

    __slots__ = ()


_TAGS = {
    Field.SMITH: SmithTag,
    Field.REPLICATOR: ReplicatorTag,
    Field.LOCAL_REPLICATOR: ReplicatorTag,
    Field.CAPACITY_SMITH: CapacitySmithTag,
    Field.CAPACITY_NEWTON: CapacityNewtonTag,
}
#: Weight kernels whose sender weight is the movable mass, ``(x, lo, hi, active, w, v, room)``.
_KERNELS = {
    SmithTag: smith_weights,
    ReplicatorTag: replicator_weights,
    CapacitySmithTag: capacity_smith_weights,
}
#: Weight kernels that take the revision rates and give the movable mass apart,
#: ``(x, lo, hi, active, rate, w, v, room, mass)``.
_RATE_KERNELS = {CapacityNewtonTag: newton_weights}


def field_tag(field: Field) -> FieldTag:
    """The compile-time record of ``field`` (see :func:`weights`)."""
    return _TAGS[Field(field)](int(field))


def weights(tag, x, lo, hi, active, rate, w, v, room, mass):
    """Fill ``w``, ``v``, ``room`` and ``mass`` at ``x`` with the weights of the field ``tag``
    (a :class:`FieldTag`; ``rate``: the game's per-generator revision rates, read by the fields
    that take them); compiled code only (the kernel is chosen by the tag's class when numba
    types the call)."""
    raise TypeError("weights() runs in compiled code only; use field_weights")


@overload(weights, inline="always")
def _weights(tag, x, lo, hi, active, rate, w, v, room, mass):
    cls = getattr(tag, "instance_class", None)
    rated = _RATE_KERNELS.get(cls)
    if rated is not None:

        def rated_impl(tag, x, lo, hi, active, rate, w, v, room, mass):
            rated(x, lo, hi, active, rate, w, v, room, mass)

        return rated_impl
    kernel = _KERNELS.get(cls)
    if kernel is None:
        return None

    def impl(tag, x, lo, hi, active, rate, w, v, room, mass):
        kernel(x, lo, hi, active, w, v, room)
        for i in range(x.shape[0]):  # the sender weight is the movable mass
            mass[i] = v[i]

    return impl


def local_receivers(tag, graph, rate, w, room, mass):
    """On a communication graph, the curvature-scaled field's receiver weights normalised by
    each receiver's own neighbourhood (:func:`~popdispatch.dynamics.newton.
    neighbourhood_receivers`); nothing for any other field or graph. Compiled code only."""
    raise TypeError("local_receivers() runs in compiled code only")


@overload(local_receivers, inline="always")
def _local_receivers(tag, graph, rate, w, room, mass):
    field_cls = getattr(tag, "instance_class", None)
    graph_cls = getattr(graph, "instance_class", None)
    if field_cls is CapacityNewtonTag and graph_cls is SparseGraph:

        def local(tag, graph, rate, w, room, mass):
            neighbourhood_receivers(graph.indptr, graph.indices, rate, w, room, mass)

        return local

    def nothing(tag, graph, rate, w, room, mass):
        pass

    return nothing
