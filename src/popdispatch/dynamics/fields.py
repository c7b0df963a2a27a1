"""The registry of flow laws and their compile-time dispatch.

Every dynamic is one module of this package that states its flow law(s) and names its
dynamics (:mod:`popdispatch.dynamics.law`: ``LAWS``, ``DYNAMICS``); :data:`MODULES` lists
them, and everything else here is built from that list: the :class:`Field` codes (in the
order of :data:`MODULES`, then of each module's ``LAWS``), the record class of each field,
and the kernels numba compiles for a run.

The engine picks a field's kernels at compile time: the field travels into the kernels as
its record (:func:`field_tag`), one small class per weight kernel, and the stubs below
(:func:`weights`, :func:`local_weights`, :func:`order_for`, :func:`law_flows`) have numba
``@overload`` implementations that return, when numba types the call, the kernels the
record's class names: its weights, and the sums of its kernel on the run's graph (the
records' classes of law and graph together: pairwise comparison,
:mod:`popdispatch.dynamics.pairwise`; target, :mod:`popdispatch.dynamics.targets`).
A run thus compiles one law's kernels, not all of them. A class no law names has no kernels:
numba refuses to type the call (never a fallback to another law).

:func:`field_weights` keeps an integer code for callers that choose at run time (the agents);
it knows the weights the agents trade with and raises for any other code.
"""

from __future__ import annotations

from enum import IntEnum

import numba as nb
from numba.extending import overload

from popdispatch.dynamics import bnn, capacity, logit, newton, replicator, smith
from popdispatch.dynamics.capacity import CapacitySmithTag, capacity_smith_weights
from popdispatch.dynamics.law import Dynamics, FieldTag, FlowLaw, Kernel
from popdispatch.dynamics.newton import CapacityNewtonTag
from popdispatch.dynamics.pairwise import (
    CompleteGraph,
    SparseGraph,
    complete_graph_flows,
    graph_flows,
    relay_flows,
    sort_by_fitness,
)
from popdispatch.dynamics.replicator import ReplicatorTag, replicator_weights
from popdispatch.dynamics.smith import SmithTag, smith_weights
from popdispatch.dynamics.targets import target_flows

#: The registry: every dynamic's module, in the order of its field codes (a new one goes last).
MODULES = (smith, replicator, capacity, newton, bnn, logit)

#: Every flow law, in the order of its code.
LAWS: tuple[FlowLaw, ...] = tuple(law for module in MODULES for law in module.LAWS)
#: Every dynamic people can name, in the order of :data:`MODULES`.
NAMED: tuple[Dynamics, ...] = tuple(d for module in MODULES for d in module.DYNAMICS)

#: The vector fields, by their flow laws: ``Field.SMITH``, ``Field.LOGIT``, ...
Field = IntEnum("Field", [(law.name, code) for code, law in enumerate(LAWS)],
                module=__name__)  # fmt: skip
Field.__doc__ = "The vector fields, by their flow laws (see :data:`MODULES`)."

SMITH, REPLICATOR, LOCAL_REPLICATOR = Field.SMITH, Field.REPLICATOR, Field.LOCAL_REPLICATOR
CAPACITY_SMITH, CAPACITY_NEWTON = Field.CAPACITY_SMITH, Field.CAPACITY_NEWTON

#: The laws by their record class (a class names one weight kernel; two fields may share it).
_BY_TAG: dict[type, FlowLaw] = {}
for _law in LAWS:
    _BY_TAG.setdefault(_law.tag, _law)


def law_of(field: Field | int | tuple) -> FlowLaw:
    """The flow law of a field, given as its :class:`Field` (code) or its record."""
    if isinstance(field, tuple):
        return _BY_TAG[type(field)]
    return LAWS[Field(field)]


def field_of(dynamics: Dynamics, bounded: bool) -> Field | None:
    """The :class:`Field` of ``dynamics`` in a mode with (``bounded``) or without generator
    limits in its revision rule; ``None`` where it has none."""
    law = dynamics.bounded_law if bounded else dynamics.law
    return None if law is None else Field[law.name]


def field_tag(field: Field | int | tuple, **parameters: float) -> tuple:
    """The compile-time record of ``field`` (see :func:`weights`), with the values of the
    parameters its law takes (``eta``, ``gain``: :class:`~popdispatch.dynamics.logit.
    LogitTag`) from ``parameters`` (others ignored). A record is returned as it is."""
    if isinstance(field, tuple):
        return field
    law = law_of(field)
    missing = [name for name in law.parameters if name not in parameters]
    if missing:
        raise ValueError(f"the {law.name.lower()} field needs {', '.join(missing)}")
    return law.tag(int(field), *(float(parameters[name]) for name in law.parameters))


def _law(tag) -> FlowLaw | None:
    return _BY_TAG.get(getattr(tag, "instance_class", None))


def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """Fill ``w``, ``v``, ``room`` and ``mass`` at shares ``x`` and fitness ``f`` with the
    weights of the field ``tag`` (its record; ``rate``: the game's per-generator revision
    rates, read by the fields that take them); compiled code only (the kernel is chosen by the
    record's class when numba types the call)."""
    raise TypeError("weights() runs in compiled code only; use field_rate")


@overload(weights, inline="always")
def _weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    law = _law(tag)
    if law is None:
        return None
    kernel = law.weights

    def impl(tag, x, f, lo, hi, active, rate, w, v, room, mass):
        kernel(tag, x, f, lo, hi, active, rate, w, v, room, mass)

    return impl


def local_weights(tag, graph, rate, w, v, room, mass):
    """On a communication graph, the receiver and sender weights of a law that normalises
    them over each generator's neighbourhood (:attr:`FlowLaw.local`: the curvature-scaled
    field, :func:`~popdispatch.dynamics.newton.neighbourhood_weights`); nothing for any other
    law or graph. Compiled code only."""
    raise TypeError("local_weights() runs in compiled code only")


@overload(local_weights, inline="always")
def _local_weights(tag, graph, rate, w, v, room, mass):
    law = _law(tag)
    local = None if law is None else law.local
    if local is not None and getattr(graph, "instance_class", None) is SparseGraph:

        def neighbourhood(tag, graph, rate, w, v, room, mass):
            local(graph.indptr, graph.indices, rate, w, v, room, mass)

        return neighbourhood

    def nothing(tag, graph, rate, w, v, room, mass):
        pass

    return nothing


def order_for(tag, graph, f, order):
    """Sort ``order`` by fitness where the law's sums read it (a comparison law on the
    complete graph, :func:`~popdispatch.dynamics.pairwise.sort_by_fitness`); nothing
    otherwise. Compiled code only."""
    raise TypeError("order_for() runs in compiled code only")


def _graph_class(graph) -> type | None:
    cls = getattr(graph, "instance_class", None)
    return cls if cls in (CompleteGraph, SparseGraph) else None


@overload(order_for, inline="always")
def _order_for(tag, graph, f, order):
    law, cls = _law(tag), _graph_class(graph)
    if law is None or cls is None:
        return None
    if law.kernel == Kernel.COMPARISON and cls is CompleteGraph:

        def complete(tag, graph, f, order):
            sort_by_fitness(f, order)

        return complete

    def unsorted(tag, graph, f, order):
        pass

    return unsorted


def law_flows(tag, graph, f, w, v, mass, room, order, inflow, outflow):
    """The raw ``inflow``/``outflow`` (shares/s) of the law of ``tag`` on ``graph`` from the
    weights ``w``, ``v`` (``mass``, ``room``: who is blocked, for the relay of a comparison
    law on a sparse graph; ``order``: sorted by :func:`order_for`, the relay's scratch on a
    sparse graph). Compiled code only: the sums are chosen by the classes of the records when
    numba types the call."""
    raise TypeError("law_flows() runs in compiled code only")


@overload(law_flows, inline="always")
def _law_flows(tag, graph, f, w, v, mass, room, order, inflow, outflow):
    law, cls = _law(tag), _graph_class(graph)
    if law is None or cls is None:
        return None
    if law.kernel == Kernel.COMPARISON and cls is CompleteGraph:

        def complete(tag, graph, f, w, v, mass, room, order, inflow, outflow):
            complete_graph_flows(f, w, v, order, inflow, outflow)

        return complete
    if law.kernel == Kernel.COMPARISON:

        def sparse(tag, graph, f, w, v, mass, room, order, inflow, outflow):
            indptr, indices = graph.indptr, graph.indices
            graph_flows(f, w, v, indptr, indices, inflow, outflow)
            relay_flows(f, w, v, mass, room, graph.slow, indptr, indices, order, inflow,
                        outflow)  # fmt: skip

        return sparse
    if cls is SparseGraph:
        return None  # a target needs the whole population (Dynamics.uses_graph is false)

    def target(tag, graph, f, w, v, mass, room, order, inflow, outflow):
        target_flows(w, v, inflow, outflow)

    return target


@nb.njit(cache=True, inline="always")
def field_weights(code, x, lo, hi, active, w, v, room):
    """Fill ``w``, ``v``, ``room`` for the field ``code`` (a :class:`Field`) at ``x``, chosen at
    run time: the fields whose sender weight is their movable mass and whose weights need no
    fitness (Smith, the replicators, capacity-constrained Smith); any other code raises."""
    if code == SMITH:
        smith_weights(x, lo, hi, active, w, v, room)
    elif code == REPLICATOR or code == LOCAL_REPLICATOR:  # noqa: SIM109 (numba: no tuple)
        replicator_weights(x, lo, hi, active, w, v, room)
    elif code == CAPACITY_SMITH:
        capacity_smith_weights(x, lo, hi, active, w, v, room)
    else:
        raise ValueError("field_weights: this field has no run-time weights (see Field)")


#: The record classes that lived here before each law's module held its own: numba's disk
#: cache indexes name the classes of a compiled signature by module and unpickle an index
#: before they check it, so a cache written by an older version must still find them here
#: (then it is found stale and the kernels are compiled again, instead of an AttributeError).
FORMER_TAGS = (FieldTag, SmithTag, ReplicatorTag, CapacitySmithTag, CapacityNewtonTag)

__all__ = ["LAWS", "MODULES", "NAMED", "Field", "FieldTag", "field_tag", "field_weights",
           "law_flows", "law_of", "local_weights", "order_for", "weights"]  # fmt: skip
