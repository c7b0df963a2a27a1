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
not all of them (issue 13: the first run compiled every field, mode and graph at once).
:func:`field_weights` keeps the integer code for callers that choose at run time (the agents).
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba as nb
from numba.extending import overload

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


_TAGS = {
    Field.SMITH: SmithTag,
    Field.REPLICATOR: ReplicatorTag,
    Field.LOCAL_REPLICATOR: ReplicatorTag,
    Field.CAPACITY_SMITH: CapacitySmithTag,
}
_KERNELS = {
    SmithTag: smith_weights,
    ReplicatorTag: replicator_weights,
    CapacitySmithTag: capacity_smith_weights,
}


def field_tag(field: Field) -> FieldTag:
    """The compile-time record of ``field`` (see :func:`weights`)."""
    return _TAGS[Field(field)](int(field))


def weights(tag, x, lo, hi, active, w, v, room):
    """Fill ``w``, ``v``, ``room`` at ``x`` with the weights of the field ``tag`` (a
    :class:`FieldTag`); compiled code only (the kernel is chosen by the tag's class when numba
    types the call)."""
    raise TypeError("weights() runs in compiled code only; use field_weights")


@overload(weights, inline="always")
def _weights(tag, x, lo, hi, active, w, v, room):
    kernel = _KERNELS.get(getattr(tag, "instance_class", None))
    if kernel is None:
        return None

    def impl(tag, x, lo, hi, active, w, v, room):
        kernel(x, lo, hi, active, w, v, room)

    return impl
