"""The online day as one compiled loop over minutes: warm start, then run until converged.

Per minute the demand and the online set change, the state warm-starts
(:mod:`popdispatch.warm_start`) and the dynamics run (:func:`popdispatch.integrate.integrate`)
until the stopping rule says; one row per minute is written to :class:`DayOutputs`. A minute
whose prices ran past their cap (infeasible) is reported at its end state, and the next minute
continues from the state it started from.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

from popdispatch.game.parameters import MinuteInputs, minute_bounds
from popdispatch.integrate import Status, integrate
from popdispatch.integrate.steppers import copy_into
from popdispatch.jit import BORROWING
from popdispatch.warm_start import warm_start


class DayInputs(NamedTuple):
    """The minutes of a day (or a chunk of it), one row each: demand (MW), loads-only flows of
    the limited lines (MW), online generators; the warm start (the
    :class:`~popdispatch.warm_start.WarmStart` policy as an integer, and whether the mode keeps
    generator limits: plain values, every policy runs the same compiled loop) and the demand of
    the minute before the first (MW, 0 if none)."""

    demand: np.ndarray
    load_flow: np.ndarray
    online: np.ndarray
    warm_start: int
    bounded: bool
    previous_demand: float


class DayOutputs(NamedTuple):
    """One row per minute: set points (MW), iterations, :class:`~popdispatch.integrate.Status`
    (as integers), iteration of convergence (-1 if none), the controller states at the
    minute's end (for the KKT check) and the first iteration with congestion (-1 if none);
    ``history`` (rows ``max_iterations + 1``, or none) receives the set points (MW) of every
    iteration of a one-minute run."""

    setpoints: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    converged_at: np.ndarray
    states: np.ndarray
    first_congestion: np.ndarray
    history: np.ndarray


class DayScratch(NamedTuple):
    """Scratch of the day loop, overwritten every minute: the minute's share bounds ``lo``,
    ``hi`` and the warm start's ``weight`` (one per generator), the generators that can trade
    ``below`` each limited line, and the state the minute started from, ``x_start`` (shares)
    and ``z_start`` (controller states). Allocated by the caller: the loop borrows it."""

    lo: np.ndarray
    hi: np.ndarray
    weight: np.ndarray
    below: np.ndarray
    x_start: np.ndarray
    z_start: np.ndarray

    @classmethod
    def empty(cls, n: int, n_lines: int, n_states: int) -> DayScratch:
        """Scratch for ``n`` generators, ``n_lines`` limited lines and ``n_states`` controller
        states."""
        return cls(np.empty(n), np.empty(n), np.empty(n), np.empty(n_lines), np.empty(n),
                   np.empty(n_states))  # fmt: skip


@nb.njit(cache=True, **BORROWING)
def integrate_day(x, z, term, params, day, ws, stepper, rule, h_try, out, scratch):
    """The minutes of ``day`` (:class:`DayInputs`) in order from shares ``x`` and controller
    states ``z`` (both updated in place), into ``out`` (:class:`DayOutputs`), with the
    caller's ``scratch`` (:class:`DayScratch`). Returns ``(h_try, demand of the last minute)``.

    The engine's one compiled entry point (a single minute is a day of one row): each entry
    point links the game and field again and LLVM optimises all it links once more, so one
    instead of two saves a full optimisation of the engine on the first run. Compiled without
    reference counting (:data:`~popdispatch.jit.BORROWING`): it allocates nothing, its scratch
    comes from the caller."""
    n = x.shape[0]
    lo, hi, weight, below = scratch.lo, scratch.hi, scratch.weight, scratch.below
    x_start, z_start = scratch.x_start, scratch.z_start
    old_demand = day.previous_demand
    pmin, pmax = params.pmin, params.pmax
    for row in range(day.demand.shape[0]):
        active = day.online[row]
        demand = day.demand[row]
        # the demand step in merit order (docs/exact-mode.md, "Warm start between minutes")
        warm_start(day.warm_start, day.bounded, x, old_demand, demand, pmin, pmax, active, weight,
                   params.b, params.c)  # fmt: skip
        tradable = minute_bounds(pmin, pmax, active, demand, params.generator_line,
                                 params.line_up, params.line_preorder, lo, hi, below)  # fmt: skip
        minute = MinuteInputs(demand, day.load_flow[row], lo, hi, active, below, tradable)
        copy_into(x, x_start)
        copy_into(z, z_start)
        outcome = integrate(x, z, term, params, minute, ws, stepper, rule, h_try, out.history)
        h_try = outcome.h_try
        for i in range(n):
            out.setpoints[row, i] = x[i] * demand
        for k in range(z.shape[0]):
            out.states[row, k] = z[k]
        out.iterations[row] = outcome.iterations
        out.status[row] = outcome.status
        out.converged_at[row] = outcome.converged_at
        out.first_congestion[row] = outcome.first_congestion
        if outcome.status == Status.INFEASIBLE:
            # prices past their cap say nothing of the next minute's: it continues from the
            # state this minute started from, not from the runaway
            copy_into(x_start, x)
            copy_into(z_start, z)
        old_demand = demand
    return h_try, old_demand


@dataclass
class DayArrays:
    """Per-minute outputs of the day loop, filled chunk by chunk."""

    setpoints: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    converged_at: np.ndarray
    states: np.ndarray  # controller states at each minute's end (exact mode's prices)
    first_congestion: np.ndarray
    history: np.ndarray  # set points per iteration of a one-minute run (MW), else no rows
    last_demand: float = 0.0

    @classmethod
    def empty(cls, minutes: int, n: int, n_states: int, history_rows: int = 0) -> DayArrays:
        """Outputs of ``minutes`` minutes; ``history_rows`` rows of per-iteration set points
        (for a one-minute run)."""
        return cls(
            np.zeros((minutes, n)), np.zeros(minutes, np.int64), np.zeros(minutes, np.int64),
            np.zeros(minutes, np.int64), np.zeros((minutes, n_states)),
            np.zeros(minutes, np.int64), np.empty((history_rows, n)),
        )  # fmt: skip

    def chunk(self, part: slice) -> DayArrays:
        """Views of the rows ``part`` (the last demand carried over)."""
        return DayArrays(self.setpoints[part], self.iterations[part], self.status[part],
                         self.converged_at[part], self.states[part], self.first_congestion[part],
                         self.history, self.last_demand)  # fmt: skip

    def outputs(self) -> DayOutputs:
        return DayOutputs(self.setpoints, self.iterations, self.status, self.converged_at,
                          self.states, self.first_congestion, self.history)  # fmt: skip

    def statuses(self) -> np.ndarray:
        """Each minute's :class:`~popdispatch.integrate.Status`."""
        return np.array([Status(s) for s in self.status], dtype=object)
