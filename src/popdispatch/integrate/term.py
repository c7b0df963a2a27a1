"""The ODE term: evaluation of the vector field at a state (game + weights + flows).

``x' = inflow - outflow`` of the dynamic's flow law (:mod:`popdispatch.dynamics.law`) whose
fitness is the mode's payoff map (``payoff`` of the mode's module in :mod:`popdispatch.modes`,
reached by its :class:`~popdispatch.modes.mechanism.ModeTag`, :func:`payoff`) and whose
weights and sums are the law's (:func:`popdispatch.dynamics.fields.weights`,
:func:`~popdispatch.dynamics.fields.law_flows`); ``z' = z_rate``, the mode's controller-state
map. One evaluation fills a :class:`Stage`; the steppers combine stages.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
from numba.extending import overload

from popdispatch.dynamics.fields import (
    Field,
    field_tag,
    law_flows,
    local_weights,
    order_for,
    weights,
)
from popdispatch.dynamics.pairwise import CompleteGraph, Graph, graph_of


class Term(NamedTuple):
    """Which field and game: the dynamic's field record
    (:class:`~popdispatch.dynamics.law.FieldTag`, or its law's own record with parameters),
    the mode's :class:`~popdispatch.modes.mechanism.ModeTag` and the communication
    :class:`~popdispatch.dynamics.pairwise.Graph` (complete, else its symmetric adjacency in
    CSR form).

    Each is a small record whose *class* names the kernel (one class per weight kernel, mode
    and kind of graph): numba compiles the term once per combination of classes and, in each,
    only the kernels it names, where a branch on an integer code would compile every mode,
    field and graph into every run. Build it with :meth:`of`.
    """

    field: tuple  # a FieldTag, or a law's own record (code first)
    mode: tuple  # a ModeTag record: its class carries the payoff kernel
    graph: Graph

    @classmethod
    def of(cls, field: Field | tuple, mode, complete: bool, indptr, indices,
           rate=None, held=None, idle_rate=None) -> Term:  # fmt: skip
        """The term of ``field`` (a :class:`~popdispatch.dynamics.fields.Field` whose law takes
        no parameters, or its record, :meth:`popdispatch.online.RunSettings.field_tag`) and the
        mode's record ``mode`` (a :class:`~popdispatch.modes.mechanism.ModeTag`:
        :func:`popdispatch.modes.mode_tag`) on the complete graph, else on the graph of CSR
        adjacency ``indptr``, ``indices`` (``rate``: the revision rates, which say who relays
        by rate: :func:`~popdispatch.dynamics.pairwise.slow_relays`; ``held``: who else relays
        always, bool per strategy; ``idle_rate``: the rates while the lines above are idle,
        where the rates follow the lines)."""
        graph = graph_of(complete, indptr, indices, rate, held, idle_rate)
        return cls(field_tag(field), mode, graph)

    @property
    def complete(self) -> bool:
        """Is the communication graph complete?"""
        return isinstance(self.graph, CompleteGraph)




def payoff(mode, p, z, params, minute, work, f, z_rate):
    """The payoff map of ``mode`` (a :class:`~popdispatch.modes.mechanism.ModeTag`): fitness
    into ``f`` (EUR/MW) and controller rates into ``z_rate`` at set points ``p`` (MW) and
    controller states ``z``; ``(congestion, residual)``. Compiled code only: the mode's kernel
    is chosen by the tag's class when numba types the call."""
    raise TypeError("payoff() runs in compiled code only; call the mode's own payoff")


@overload(payoff, inline="always")
def _payoff(mode, p, z, params, minute, work, f, z_rate):
    kernel = getattr(getattr(mode, "instance_class", None), "kernel", None)
    if kernel is None:
        return None

    def impl(mode, p, z, params, minute, work, f, z_rate):
        return kernel(p, z, params, minute, work, f, z_rate)

    return impl


class Stage(NamedTuple):
    """The field evaluated at one point: set points ``p`` (MW), fitness ``f`` (EUR/MW), the
    receiver weights ``w``, movable masses ``v`` and ``room`` (shares), the raw pairwise
    ``inflow``/``outflow`` (shares/s), the controllers' ``z_rate`` and the strategies'
    ``order`` by fitness (kept between evaluations: a nearly sorted order sorts in O(n)).
    ``v`` is the sender weight and ``mass`` the movable mass the flux limiter empties (the
    same values for the laws whose sender weight is their movable mass)."""

    p: np.ndarray
    f: np.ndarray
    w: np.ndarray
    v: np.ndarray
    room: np.ndarray
    mass: np.ndarray
    inflow: np.ndarray
    outflow: np.ndarray
    z_rate: np.ndarray
    order: np.ndarray

    @classmethod
    def empty(cls, n: int, n_states: int) -> Stage:
        vectors = (np.zeros(n) for _ in range(8))
        return cls(*vectors, np.zeros(n_states), np.arange(n, dtype=np.int64))


@nb.njit(cache=True, inline="always")
def evaluate(x, z, p, f, w, v, room, mass, inflow, outflow, z_rate, order, term, params, minute,
             work):  # fmt: skip
    """Fitness, weights and raw flows at ``(x, z)`` into the arrays of one
    :class:`Stage` (``p`` .. ``order``, its fields by name; the steppers take them out of the
    record once per iteration, since numba reference-counts every array of a record each time
    the record is handed to an inlined function).

    ``term``: :class:`Term`; ``params``: :class:`~popdispatch.game.parameters.GameParameters`;
    ``minute``: :class:`~popdispatch.game.parameters.MinuteInputs`; ``work``: the game's
    scratch (:class:`~popdispatch.game.parameters.GameWork`). Returns ``(congestion,
    residual)`` of the game.
    """
    demand = minute.demand
    for i in range(x.shape[0]):
        p[i] = x[i] * demand
    # the mode's payoff map, the law's weights and its sums on the graph, each chosen by its
    # record's class when numba compiles (Term): no branch, nothing else compiled, and each
    # inlined (overload inline="always"; called, each call would reference-count the
    # records' arrays, a large share of a paper-mode minute)
    congestion, residual = payoff(term.mode, p, z, params, minute, work, f, z_rate)
    field, graph = term.field, term.graph
    # the revision rates in force: the payoff's, where it sets them (GameWork.rate)
    rate = work.rate if work.rate.shape[0] else params.revision_rate
    weights(field, x, f, minute.lo, minute.hi, minute.active, rate, w, v, room, mass)
    local_weights(field, graph, rate, w, v, room, mass)
    order_for(field, graph, f, order)
    law_flows(field, graph, f, w, v, mass, room, order, inflow, outflow)
    return congestion, residual
