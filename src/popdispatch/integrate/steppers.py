"""Steppers: one iteration (``dt`` seconds) of the flux-limited Euler or Heun scheme.

Domain, by flux limiting: every dynamic moves mass along pairs (its flow law,
:mod:`popdispatch.dynamics.law`: ``T_ij = g_ij w_i v_j K(f_i, f_j)``). An Euler stage of
length ``h`` would move ``h * outflow_j`` out of strategy ``j`` and ``h * inflow_i`` into
``i``; where that exceeds the movable mass of ``j`` (or the room left below the upper limit of
``i``), the sender's (receiver's) weight is scaled down so that it exactly empties (fills),
and the flows are summed again by the law's own sums. Mass is conserved pair by pair and
every stage stays in its domain for any ``h``; Heun is a convex combination of two such
stages, so it does too. A stage that needs no limiting is the plain Euler stage, so away from
the limits this is the textbook scheme. (Shortening the step instead, to ``1 / rate``, cost
exact mode 10-17 steps per iteration even at rest, since the rate of a strategy sitting at its
limit stays large.)

- :attr:`Method.EULER`: ``substeps`` limited Euler steps per iteration (paper mode: its barrier
  is discontinuous, generators slide along their limits and an explicit step chatters around
  a limit with an amplitude proportional to the step, so small fixed steps resolve it).
- :attr:`Method.HEUN`: adaptive Heun-Euler pair (second order, SSP) with error control
  ``rtol``/``atol`` on the shares and ``price_atol`` on the controller states, steps up to one
  iteration, capped by a stiffness estimate (exact mode).

Controller states ``z`` are integrated alongside and kept non-negative. Everything here is
compiled and allocation-free, and runs inside the day loop, which is compiled without
reference counting (:mod:`popdispatch.jit`). The records (:class:`Workspace`, :class:`Stage`,
...) are taken apart once per iteration and the per-substep kernels take their arrays: that
is also what keeps the code short where a record would be handed down.

Compilation: the game and field (:func:`evaluate_stage`) and the limiter's flows
(:func:`limited_flows`) are compiled once each and called; inlined, numba typed and LLVM
optimised a copy at every call site, which multiplies the first run's compilation, and the
calls cost nothing measurable per step. The steppers themselves
(:func:`advance_euler`, :func:`advance_heun`) are the implementations numba compiles for
:func:`advance`, with :func:`euler_steps` inlined: numba inlines a function by copying its
IR, at a cost that grows with the square of its size, and every compiled level below the
day loop is optimised again by LLVM in each level above it, so the fewest levels with the
fewest copies compile fastest (``benchmarks/bench_first_run.py`` measures it; docs/performance.md).
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba as nb
import numpy as np
from numba.extending import overload

from popdispatch.dynamics.fields import law_flows
from popdispatch.game.parameters import GameWork
from popdispatch.integrate.term import Stage, evaluate
from popdispatch.jit import BORROWING


class Method(IntEnum):
    """Integration methods (see the module docstring)."""

    EULER = 0
    HEUN = 1


class MethodTag(NamedTuple):
    """A method as the compiled kernels take it: its :class:`Method` value in ``code``; the
    *class* picks the stepper when numba compiles (:func:`advance`), so a run compiles one."""

    code: int


class EulerTag(MethodTag):
    """Fixed limited Euler substeps (:func:`advance_euler`)."""

    __slots__ = ()


class HeunTag(MethodTag):
    """Adaptive Heun with the stiffness cap (:func:`advance_heun`)."""

    __slots__ = ()


def method_tag(method: Method) -> MethodTag:
    """The compile-time record of ``method``."""
    return (EulerTag if Method(method) == Method.EULER else HeunTag)(int(method))


#: Largest ``h * rate`` of an explicit step on a real rate (Heun's and Euler's stability
#: interval on the real axis is 2): the agents' Euler rounds (online/stiffness.py).
STABLE_STEP = 1.5
#: Largest ``h * rate`` an adaptive Heun step takes on the rate it measures
#: (:func:`stiffness`), whose direction in the complex plane it does not know. The price
#: loops are complex pairs: Heun's factor ``|1 + z + z^2 / 2|`` at ``|z| = 1.5`` is 0.99 at 76
#: degrees from the negative real axis and above 1 beyond, where at ``|z| = 1`` it is 0.80 at
#: 76 degrees and below 1 up to 85. A cap of 1.5 lets the steps hover at the edge of a weakly
#: damped loop, where the set points chatter with the error tolerance's amplitude, above the
#: stopping tolerance (docs/exact-mode.md, "Step size and stopping").
HEUN_STEP = 1.0
#: A step that moves the state by less than this, in the error norm's scaling (``h ||k1||``),
#: measures no rate (:func:`stiffness`): at rest the field is round-off, whose ``||k2 - k1|| /
#: ||k1||`` is of order one at any step, a rate of ``1 / h`` that would hold the steps where
#: they are. The oscillations the cap is for move the state by about the error tolerance a
#: step (docs/exact-mode.md, "Step size and stopping").
QUIET_MOTION = 1e-9
#: A measured ``h * rate`` beyond this is a switch of the field between the two stages of a
#: step (a limiter, or distributed Smith's relay, turning on or off), not a linear rate: it
#: stays about the same whatever ``h`` (beyond Heun's real stability limit, 2, a step the error
#: control accepts holds no unstable linear mode above the tolerances).
SWITCH_TURN = 3.0
#: Switches per iteration the stiffness cap may shrink the step for; after them a switch only
#: holds the step. A state sliding along a switch sees it at every step, and capping each time
#: shrank the steps by the same factor without end (measured: to 1e-16 s on a random connected
#: graph, an iteration that never ended).
SWITCH_CAPS = 64
#: The smallest Heun step once a switch has been seen more than :data:`SWITCH_CAPS` times in
#: an iteration, in units of the iteration's ``dt``. Holding the step does not always stop the
#: collapse: a state sliding along a switch can still be driven to steps of 5e-15 s by the
#: error control's rejections (measured: MATPOWER's case300 on a ring, two million steps an
#: iteration). A step at the floor is taken whatever its error estimate, if its result is finite
#: (else the iteration ends where it is): what the run reports rests on the end state's
#: certificate, not on the steps' error. Iterations with fewer switches have no floor.
STEP_FLOOR = 1e-6


class StepperSettings(NamedTuple):
    """What a stepper takes (from :meth:`popdispatch.integrate.Integrator.stepper`): method
    (a :class:`MethodTag`, see :func:`advance`), iteration ``dt`` (s),
    Euler ``substeps``, Heun error control ``rtol``, ``atol`` (shares) and ``price_atol``
    (EUR/MW)."""

    method: MethodTag
    dt: float
    substeps: int
    rtol: float
    atol: float
    price_atol: float


class Limited(NamedTuple):
    """Flux-limited weights and their pairwise flows for one stage."""

    w: np.ndarray
    v: np.ndarray
    inflow: np.ndarray
    outflow: np.ndarray


class Counters(NamedTuple):
    """Evaluations of the game and field, and rejected Heun steps (one-element arrays, since
    the kernels count in place)."""

    evaluations: np.ndarray
    rejected: np.ndarray


class Workspace(NamedTuple):
    """Scratch of the kernels: the two evaluation points of a step and their limited flows,
    Euler and Heun results, the state before the last iteration, the game's scratch, the ring
    of the last ``3 * window`` samples of the stopping rule, and the counters."""

    first: Stage
    second: Stage
    first_limited: Limited
    second_limited: Limited
    x_euler: np.ndarray
    x_heun: np.ndarray
    z_euler: np.ndarray
    z_heun: np.ndarray
    last_x: np.ndarray
    last_z: np.ndarray
    game: GameWork
    ring: np.ndarray
    counters: Counters


def workspace(n: int, n_lines: int, n_states: int, window: int, live_rates: bool = False
              ) -> Workspace:  # fmt: skip
    """Workspace for ``n`` generators, ``n_lines`` limited lines, ``n_states`` controller
    states and a stopping window of ``window`` iterations (``live_rates``: the game writes the
    revision rates in force at each evaluation, :class:`~popdispatch.game.parameters.GameWork`)."""

    def limited() -> Limited:
        return Limited(*(np.zeros(n) for _ in range(4)))

    game = GameWork.empty(n_lines, n if live_rates else 0, n_generators=n)
    return Workspace(
        Stage.empty(n, n_states), Stage.empty(n, n_states), limited(), limited(),
        np.zeros(n), np.zeros(n), np.zeros(n_states), np.zeros(n_states), np.zeros(n),
        np.zeros(n_states), game, np.zeros((3 * window, n)),
        Counters(np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)),
    )  # fmt: skip


@nb.njit(cache=True, inline="always")
def copy_into(source, target):
    """``target[:] = source`` as a loop (same length): numba compiles an array assignment
    with its broadcasting checks, which adds to the first run's compilation."""
    for i in range(source.shape[0]):
        target[i] = source[i]


@nb.njit(cache=True, **BORROWING)
def evaluate_stage(x, z, p, f, w, v, room, mass, inflow, outflow, z_rate, order, term, params,
                   minute, work):  # fmt: skip
    """:func:`~popdispatch.integrate.term.evaluate` as one compiled function, called (not
    inlined) by every stage of the steppers and by the stopping rule's end-state check.

    Inlined, the game and field (every mode's payoff, every field's weights, both pairwise
    sums) were copied into each of four call sites, and LLVM optimised every copy again in
    each function that links them, the bulk of the first run's compilation. Called, they are
    compiled once. Compiled without reference counting (:data:`~popdispatch.jit.BORROWING`):
    the records it takes hold dozens of arrays, and counting each of them at every inlined
    call cost more than the evaluation's arithmetic.
    """
    return evaluate(x, z, p, f, w, v, room, mass, inflow, outflow, z_rate, order, term, params,
                    minute, work)  # fmt: skip


@nb.njit(cache=True)
def limited_flows(field, graph, f, w, v, mass, room, order, inflow, outflow):
    """:func:`~popdispatch.dynamics.fields.law_flows` of limited weights: the flows of the law
    of ``field`` (its record) on ``graph``, compiled once and called by the limiter's four
    sites (inlined, numba typed and LLVM optimised a copy at each)."""
    law_flows(field, graph, f, w, v, mass, room, order, inflow, outflow)


@nb.njit(cache=True, inline="always")
def euler_steps(steps, evaluate_first, h, x, z, term, params, minute, p, f, w, v, room, mass,
                inflow, outflow, z_rate, order, lim, work, evaluations, x_out, z_out):  # fmt: skip
    """``steps`` limited Euler steps of length ``h`` from ``(x, z)`` to ``(x_out, z_out)``
    (which may be ``x``, ``z``), each evaluating the field into the arrays ``p`` .. ``order``
    of one :class:`Stage` first (the first one only with ``evaluate_first``: else they hold
    the field at ``x`` already); ``(largest congestion, last residual)`` of the evaluations
    (0 without any). The caller takes the stage apart once per iteration: Heun calls this in
    its step loop, where numba reference-counts every array of a record handed on.

    A step: ``x_out = x + h * (inflow - outflow)`` with the flux limiter (scratch: the
    :class:`Limited` ``lim``), ``z_out = max(z + h z_rate, 0)``. The records are taken apart
    here, once per call, and the limiter is written in the loop: numba reference-counts every
    array handed to an inlined function at each call, which cost paper mode (its minute is
    about 1400 steps on 6 generators) a quarter of its time when the limiter was a function.
    """
    lim_w, lim_v, lim_in, lim_out = lim.w, lim.v, lim.inflow, lim.outflow
    field, graph = term.field, term.graph
    congested = 0.0
    residual = 0.0
    for step in range(steps):
        if step > 0 or evaluate_first:
            evaluations[0] += 1
            congestion, residual = evaluate_stage(x, z, p, f, w, v, room, mass, inflow, outflow,
                                                  z_rate, order, term, params, minute,
                                                  work)  # fmt: skip
            congested = max(congested, congestion)
        # senders first; the receivers' factors from the flows of the limited senders, so a
        # pair limited at both ends is scaled once (from the unlimited flows it was scaled
        # twice and moved less than either limit allows)
        senders = False
        for i in range(x.shape[0]):
            lim_v[i] = v[i]
            if h * outflow[i] > mass[i]:
                lim_v[i] = v[i] * (mass[i] / (h * outflow[i]))
                senders = True
        into = inflow
        if senders:
            limited_flows(field, graph, f, w, lim_v, mass, room, order, lim_in, lim_out)
            into = lim_in
        limited_any = senders
        for i in range(x.shape[0]):
            lim_w[i] = w[i]
            if h * into[i] > room[i]:
                lim_w[i] = w[i] * (room[i] / (h * into[i]))
                limited_any = True
        if limited_any:
            limited_flows(field, graph, f, lim_w, lim_v, mass, room, order, lim_in, lim_out)
            for i in range(x.shape[0]):
                x_out[i] = x[i] + h * (lim_in[i] - lim_out[i])
        else:
            for i in range(x.shape[0]):
                x_out[i] = x[i] + h * (inflow[i] - outflow[i])
        for k in range(z.shape[0]):
            z_out[k] = max(z[k] + h * z_rate[k], 0.0)
        x, z = x_out, z_out
    return congested, residual


@nb.njit(cache=True, inline="always")
def largest_scaled_difference(high, low, atol, rtol):
    """``max |high - low| / (atol + rtol |high|)`` over the entries; infinite where either
    value is not finite (the quotient is then NaN: inf / inf, inf - inf, or NaN itself)."""
    err = 0.0
    for i in range(high.shape[0]):
        scaled = abs(high[i] - low[i]) / (atol + rtol * abs(high[i]))
        if scaled != scaled:
            return np.inf
        err = max(err, scaled)
    return err


@nb.njit(cache=True, inline="always")
def error_norm(x_high, x_low, z_high, z_low, rtol, atol, price_atol):
    """Largest scaled difference of the Heun and Euler results (accept the step if <= 1);
    infinite where either result is not finite (a step too long for a stiff field can
    overflow: rejected and shortened, never taken)."""
    return max(largest_scaled_difference(x_high, x_low, atol, rtol),
               largest_scaled_difference(z_high, z_low, price_atol, rtol))  # fmt: skip


def advance_euler(method, x, z, term, params, minute, ws, stepper, h_try):
    """One iteration of ``substeps`` limited Euler steps; ``(congested, residual, h_try)``
    (``h_try`` unchanged). Compiled by numba as :func:`advance` for an :class:`EulerTag`."""
    one = ws.first
    congested, residual = euler_steps(stepper.substeps, True, stepper.dt / stepper.substeps, x,
                                      z, term, params, minute, one.p, one.f, one.w, one.v,
                                      one.room, one.mass, one.inflow, one.outflow, one.z_rate,
                                      one.order, ws.first_limited, ws.game,
                                      ws.counters.evaluations, x, z)  # fmt: skip
    return congested, residual, h_try


@nb.njit(cache=True, inline="always")
def heun_combination(h, x, z, f1, w1, v1, room1, mass1, in1, out1, zr1, order1, f2, w2, v2,
                     room2, mass2, in2, out2, zr2, order2, lim1, lim2, field, graph, x_out,
                     z_out):  # fmt: skip
    """``x_out = x + h/2 (k1 + k2)`` from the raw flows at both points, flux-limited as one step.

    Where the combined step would carry a strategy past its movable mass or its room, the
    senders' (receivers') weights at both points are scaled down together so that it lands
    exactly on its limit; a strategy driven into a limit thus reaches it, instead of halving
    its distance each step as a convex combination of limited stages would. ``f1`` ..
    ``order1``, ``f2`` .. ``order2``: the arrays of the :class:`Stage` of each point that are
    read (taken apart once per iteration by :func:`advance_heun`: numba reference-counts
    every array of a record handed to an inlined function, at every step); ``lim1``,
    ``lim2``: scratch :class:`Limited`; ``field``, ``graph``: the
    :class:`~popdispatch.integrate.term.Term`'s field record and graph.
    """
    sw1, sv1, sin1, sout1 = lim1.w, lim1.v, lim1.inflow, lim1.outflow
    sw2, sv2, sin2, sout2 = lim2.w, lim2.v, lim2.inflow, lim2.outflow
    half = 0.5 * h
    # senders first, then the receivers from the flows of the limited senders (see
    # euler_steps)
    senders = False
    for i in range(x.shape[0]):
        alpha = 1.0
        out = half * (out1[i] + out2[i])
        if out > mass1[i]:
            alpha = mass1[i] / out
            senders = True
        sv1[i], sv2[i] = alpha * v1[i], alpha * v2[i]
    if senders:
        limited_flows(field, graph, f1, w1, sv1, mass1, room1, order1, sin1, sout1)
        limited_flows(field, graph, f2, w2, sv2, mass2, room2, order2, sin2, sout2)
    limited = senders
    for i in range(x.shape[0]):
        beta = 1.0
        into = half * (sin1[i] + sin2[i]) if senders else half * (in1[i] + in2[i])
        if into > room1[i]:
            beta = room1[i] / into
            limited = True
        sw1[i], sw2[i] = beta * w1[i], beta * w2[i]
    if limited:
        limited_flows(field, graph, f1, sw1, sv1, mass1, room1, order1, sin1, sout1)
        limited_flows(field, graph, f2, sw2, sv2, mass2, room2, order2, sin2, sout2)
        for i in range(x.shape[0]):
            x_out[i] = x[i] + half * (sin1[i] - sout1[i] + sin2[i] - sout2[i])
    else:
        for i in range(x.shape[0]):
            x_out[i] = x[i] + half * (in1[i] - out1[i] + in2[i] - out2[i])
    for k in range(z.shape[0]):
        z_out[k] = max(z[k] + half * (zr1[k] + zr2[k]), 0.0)


@nb.njit(cache=True, inline="always")
def stiffness(h, x, z, mass1, room1, in1, out1, zr1, in2, out2, zr2, rtol, atol, price_atol):
    """Largest rate the last step saw, ``||k2 - k1|| / ||x1 - x||`` (1/s), in the error norm's
    scaling, over the components the limiter left alone.

    Error control alone lets the step grow near a rest point (where the error vanishes) until
    it meets the stability boundary of the price loop, and then hovers there with an
    oscillation of the size of the error tolerance, far above the convergence tolerance.
    Capping the step by this estimate keeps Heun inside its stability region. Strategies that
    the limiter stopped at a limit are left out: their fast approach is absorbed exactly.
    A step that moved the state by at most :data:`QUIET_MOTION` measures no rate (0).
    Takes the arrays of the two stages it reads (``1``: first point, ``2``: second).
    """
    moved = 0.0
    turned = 0.0
    for i in range(x.shape[0]):
        if h * out1[i] > mass1[i] or h * in1[i] > room1[i]:
            continue
        scale = atol + rtol * abs(x[i])
        k1 = (in1[i] - out1[i]) / scale
        k2 = (in2[i] - out2[i]) / scale
        moved += k1 * k1
        turned += (k2 - k1) * (k2 - k1)
    for k in range(z.shape[0]):
        if z[k] + h * zr1[k] < 0.0:
            continue
        scale = price_atol + rtol * abs(z[k])
        k1 = zr1[k] / scale
        k2 = zr2[k] / scale
        moved += k1 * k1
        turned += (k2 - k1) * (k2 - k1)
    if h * h * moved <= QUIET_MOTION * QUIET_MOTION:
        return 0.0
    return np.sqrt(turned / moved) / h


@nb.njit(cache=True)
def next_step(h, err, rate, switches, dt):
    """``(next h, switches)`` after a Heun step of ``h`` (s) with error norm ``err`` and
    measured rate ``rate`` (1/s, :func:`stiffness`), ``switches`` seen so far this iteration
    of ``dt`` (s): the error control's step, capped at ``HEUN_STEP / rate`` (:data:`HEUN_STEP`)
    where that is smaller, except for a switch seen more than :data:`SWITCH_CAPS` times, which
    only holds the step (a state sliding along it). A switch is a measured ``h * rate`` beyond
    :data:`SWITCH_TURN`, or a cap below the step floor (:data:`STEP_FLOOR` of ``dt``): a rate
    measured across a jump of the field grows as the step shrinks, so each cap shrinks the
    next step by the same factor, and a jump smaller than :data:`SWITCH_TURN` times the
    field drove the steps to 1e-20 s, an iteration that never ended."""
    h_try = h * min(5.0, max(0.2, 0.9 / np.sqrt(err))) if err > 0.0 else 5.0 * h
    if rate * h_try > HEUN_STEP:
        switch = rate * h > SWITCH_TURN or rate * STEP_FLOOR * dt > HEUN_STEP
        switches += 1 if switch else 0
        h_try = min(h_try, h) if switch and switches > SWITCH_CAPS else HEUN_STEP / rate
    return h_try, switches


def advance_heun(method, x, z, term, params, minute, ws, stepper, h_try):
    """One iteration of adaptive Heun steps; ``(congested, largest residual, next h_try)``.
    Compiled by numba as :func:`advance` for a :class:`HeunTag`."""
    rtol, atol, price_atol, dt = stepper.rtol, stepper.atol, stepper.price_atol, stepper.dt
    one, two, lim1, lim2 = ws.first, ws.second, ws.first_limited, ws.second_limited
    work, counters = ws.game, ws.counters
    x1, x2, z1, z2 = ws.x_euler, ws.x_heun, ws.z_euler, ws.z_heun
    p1, f1, w1, v1, room1, in1, out1 = one.p, one.f, one.w, one.v, one.room, one.inflow, one.outflow
    mass1, zr1, order1 = one.mass, one.z_rate, one.order
    p2, f2, w2, v2, room2, mass2 = two.p, two.f, two.w, two.v, two.room, two.mass
    in2, out2, zr2, order2 = two.inflow, two.outflow, two.z_rate, two.order
    field, graph = term.field, term.graph
    remaining = dt
    congested = 0.0
    residual = 0.0
    fresh = False
    switches = 0
    while remaining > 1e-12 * dt:
        floor = STEP_FLOOR * dt if switches > SWITCH_CAPS else 0.0
        h = min(max(h_try, floor), remaining)
        # residual: the largest at the start of any step, the iteration's first sample
        # included (the last step's alone missed a period-3 price oscillation); a rejected
        # step's first evaluation is reused
        congestion, step_residual = euler_steps(1, not fresh, h, x, z, term, params, minute,
                                                p1, f1, w1, v1, room1, mass1, in1, out1, zr1,
                                                order1,
                                                lim1, work, counters.evaluations, x1,
                                                z1)  # fmt: skip
        congested = max(congested, congestion)
        residual = max(residual, step_residual)
        fresh = True
        counters.evaluations[0] += 1
        evaluate_stage(x1, z1, p2, f2, w2, v2, room2, mass2, in2, out2, zr2, order2, term, params,
                       minute, work)  # fmt: skip
        heun_combination(h, x, z, f1, w1, v1, room1, mass1, in1, out1, zr1, order1, f2, w2, v2,
                         room2, mass2, in2, out2, zr2, order2, lim1, lim2, field, graph, x2,
                         z2)  # fmt: skip
        err = error_norm(x2, x1, z2, z1, rtol, atol, price_atol)
        rate = stiffness(h, x, z, mass1, room1, in1, out1, zr1, in2, out2, zr2, rtol, atol,
                         price_atol)  # fmt: skip
        at_floor = h <= floor
        if err <= 1.0 or (at_floor and err < np.inf):  # a finite step at the floor is taken
            copy_into(x2, x)
            copy_into(z2, z)
            remaining -= h
            fresh = False
        else:
            counters.rejected[0] += 1
            if at_floor:  # not finite even at the floor: the iteration ends where it is
                remaining = 0.0
        h_try, switches = next_step(h, err, rate, switches, dt)
    return congested, residual, min(h_try, dt)


def advance(method, x, z, term, params, minute, ws, stepper, h_try):
    """One iteration by the stepper ``method`` (a :class:`MethodTag`, the stepper's own);
    ``(congested, residual, next h_try)`` (Euler leaves ``h_try`` as it is). Compiled code
    only: the stepper is chosen by the tag's class when numba types the call."""
    raise TypeError("advance() runs in compiled code only")


@overload(advance)
def _advance(method, x, z, term, params, minute, ws, stepper, h_try):
    cls = getattr(method, "instance_class", None)
    # the steppers are the implementations themselves (not a closure that inlines them: an
    # inlined function is copied IR, see the module docstring)
    return {EulerTag: advance_euler, HeunTag: advance_heun}.get(cls)
