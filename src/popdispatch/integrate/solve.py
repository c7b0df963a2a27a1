"""One run of the dynamics at fixed inputs: stepper after stepper until the stopping rule."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb

from popdispatch.integrate.steppers import advance, copy_into, evaluate_stage
from popdispatch.integrate.stopping import Status, at_rest, check, tolerance


class Outcome(NamedTuple):
    """How a run ended: ``iterations`` run, :class:`Status`, ``converged_at`` (the first
    iteration of the last window if converged, else -1), ``first_congestion`` (first iteration
    with a non-zero signal, -1 if none) and the step size to try next (``h_try``, s)."""

    iterations: int
    status: Status
    converged_at: int
    first_congestion: int
    h_try: float


@nb.njit(cache=True, inline="always")
def equal(a, b):
    """Are the vectors ``a`` and ``b`` (same length) equal element by element?"""
    for i in range(a.shape[0]):  # noqa: SIM110 (numba compiles no generator expression)
        if a[i] != b[i]:
            return False
    return True


@nb.njit(cache=True, inline="always")
def final_residual(x, z, term, params, minute, ws):
    """The mode's residual (MW) at the state ``(x, z)`` itself, evaluated into the first
    stage of the workspace ``ws`` (which the next step evaluates afresh anyway)."""
    one = ws.first
    ws.counters.evaluations[0] += 1
    _, residual = evaluate_stage(x, z, one.p, one.f, one.w, one.v, one.room, one.mass,
                                 one.inflow, one.outflow, one.z_rate, one.order, term, params,
                                 minute, ws.game)  # fmt: skip
    return residual


@nb.njit(cache=True, inline="always")
def integrate(x, z, term, params, minute, ws, stepper, rule, h_try, history):
    """Run the dynamics from shares ``x`` (and controller states ``z``, both updated in place)
    at fixed ``minute`` inputs until converged, infeasible or the horizon; an :class:`Outcome`.

    ``term``: :class:`~popdispatch.integrate.term.Term`; ``params``/``minute``: the game's
    :class:`~popdispatch.game.parameters.GameParameters` and
    :class:`~popdispatch.game.parameters.MinuteInputs`; ``ws``:
    :func:`~popdispatch.integrate.steppers.workspace`; ``stepper``/``rule``: from
    :class:`~popdispatch.integrate.Integrator`. ``history`` (rows ``max_iterations + 1`` or 0)
    receives the set points (MW) of every iteration when it has rows.
    """
    ring = ws.ring
    size = ring.shape[0]
    record = history.shape[0] > 0
    demand = minute.demand
    for i in range(x.shape[0]):
        ring[0, i] = x[i] * demand
        if record:
            history[0, i] = ring[0, i]
    first_congestion = -1
    last_x, last_z = ws.last_x, ws.last_z
    stationary = False
    residual = 0.0
    calm = 0  # iterations in a row with the residual within tol_mw
    congested = 0.0
    for k in range(1, rule.max_iterations + 1):
        # A state that an iteration left exactly unchanged is a fixed point of the scheme:
        # later iterations would repeat it, so they are recorded without being recomputed.
        still = stationary
        if not stationary:
            copy_into(x, last_x)
            copy_into(z, last_z)
            congested, residual, h_try = advance(stepper.method, x, z, term, params, minute, ws,
                                                 stepper, h_try)  # fmt: skip
            stationary = equal(x, last_x) and equal(z, last_z)
            still = at_rest(x, last_x, z, last_z)
        row = k % size
        for i in range(x.shape[0]):
            ring[row, i] = x[i] * demand
            if record:
                history[k, i] = ring[row, i]
        if first_congestion < 0 and congested > 0.0:
            first_congestion = k
        status, calm, converged_at = check(rule, ring, k, z, residual, calm, demand, still)
        # (without controller states the residual is 0 everywhere: nothing to read again)
        reread = status == Status.CONVERGED and z.shape[0] > 0
        if reread and final_residual(x, z, term, params, minute, ws) > tolerance(rule, demand):
            # the steppers' residual is read where each step starts, so the last step's end
            # state (the one reported, and checked against the KKT conditions) is read here
            status, calm = Status.NOT_CONVERGED, 0
        if status == Status.CONVERGED:
            return Outcome(k, status, converged_at, first_congestion, h_try)
        if status == Status.INFEASIBLE:
            return Outcome(k, status, -1, first_congestion, h_try)
    return Outcome(rule.max_iterations, Status.NOT_CONVERGED, -1, first_congestion, h_try)
