"""The ODE term: evaluation of the vector field at a state (game + weights + pairwise flows).

``x' = inflow - outflow`` of the pairwise flows (:mod:`popdispatch.dynamics.pairwise`) whose
fitness is the mode's payoff map (``payoff`` of the mode's module in :mod:`popdispatch.modes`,
reached by its :class:`~popdispatch.modes.ModeCode`) and whose weights are the dynamic's
(:func:`popdispatch.dynamics.fields.field_weights`); ``z' = z_rate``, the mode's
controller-state map. One evaluation fills a :class:`Stage`; the steppers combine stages.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from popdispatch.dynamics.fields import Field, field_weights
from popdispatch.dynamics.pairwise import pairwise_flows, sort_by_fitness
from popdispatch.modes import ModeCode
from popdispatch.modes.exact import payoff as exact_payoff
from popdispatch.modes.paper import payoff as paper_payoff
from popdispatch.modes.voltage import payoff as voltage_payoff


class Term(NamedTuple):
    """Which field and game: the dynamic's :class:`~popdispatch.dynamics.fields.Field`, the
    mode's :class:`~popdispatch.modes.ModeCode` and the communication graph (complete, else
    its symmetric adjacency in CSR form).

    Build it with :meth:`of`: the enums cross into the kernels as their integer values
    (compared there with the enum members), because numba types an ``IntEnum`` member passed
    from Python slowly (about 40-70 us per call, as much as a whole exact-mode minute).
    """

    field: Field
    mode: ModeCode
    complete: bool
    indptr: np.ndarray
    indices: np.ndarray

    @classmethod
    def of(cls, field: Field, mode: ModeCode, complete: bool, indptr, indices) -> Term:
        return cls(int(field), int(mode), bool(complete), indptr, indices)


class Stage(NamedTuple):
    """The field evaluated at one point: set points ``p`` (MW), fitness ``f`` (EUR/MW), the
    receiver weights ``w``, movable masses ``v`` and ``room`` (shares), the raw pairwise
    ``inflow``/``outflow`` (shares/s), the controllers' ``z_rate`` and the strategies'
    ``order`` by fitness (kept between evaluations: a nearly sorted order sorts in O(n))."""

    p: np.ndarray
    f: np.ndarray
    w: np.ndarray
    v: np.ndarray
    room: np.ndarray
    inflow: np.ndarray
    outflow: np.ndarray
    z_rate: np.ndarray
    order: np.ndarray

    @classmethod
    def empty(cls, n: int, n_states: int) -> Stage:
        vectors = (np.zeros(n) for _ in range(7))
        return cls(*vectors, np.zeros(n_states), np.arange(n, dtype=np.int64))


@nb.njit(cache=True, inline="always")
def evaluate(x, z, p, f, w, v, room, inflow, outflow, z_rate, order, term, params, minute, work):
    """Fitness, weights and raw pairwise flows at ``(x, z)`` into the arrays of one
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
    # the mode's payoff map by static dispatch (numba caches it on disk, unlike a function
    # argument), straight to the mode's kernel: a dispatching layer between would hand the
    # records on once more, and numba reference-counts their arrays at every inlined call
    if term.mode == ModeCode.PAPER:
        congestion, residual = paper_payoff(p, z, params, minute, work, f, z_rate)
    elif term.mode == ModeCode.EXACT:
        congestion, residual = exact_payoff(p, z, params, minute, work, f, z_rate)
    else:
        congestion, residual = voltage_payoff(p, z, params, minute, work, f, z_rate)
    field_weights(term.field, x, minute.lo, minute.hi, minute.active, w, v, room)
    complete = term.complete
    if complete:
        sort_by_fitness(f, order)
    pairwise_flows(f, w, v, complete, term.indptr, term.indices, order, inflow, outflow)
    return congestion, residual
