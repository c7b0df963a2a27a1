"""Integration of the mean dynamics on the paper's 0.01 s grid.

The paper ran the MATLAB population-dynamics toolbox: an adaptive ODE solver whose state is
sampled every 0.01 s; one sample is one *iteration*. :class:`Integrator` separates the solver
and its step control from the vector field (:mod:`popdispatch.dynamics`) and the game
(:mod:`popdispatch.modes`):

- ``method="euler"``: ``substeps`` explicit Euler steps per iteration. Paper mode uses it: its
  barrier (eq. 7) is discontinuous, generators slide along their limits, and an explicit step
  chatters around a limit with an amplitude proportional to the step (0.01 s: kW; 1e-4 s,
  the default: tens of W), so small fixed steps resolve the sliding motion.
- ``method="heun"``: adaptive Heun-Euler pair (second order, SSP) with error control
  ``rtol``/``atol`` on the shares and ``price_atol`` on the controller states, steps up to one
  iteration. Exact mode uses it.

Domain, by flux limiting: every dynamic moves mass along pairs (:mod:`popdispatch.dynamics.
pairwise`). An Euler stage of length ``h`` would move ``h * outflow_j`` out of strategy ``j``
and ``h * inflow_i`` into ``i``; where that exceeds the movable mass of ``j`` (or the room
left below the upper limit of ``i``), the sender's (receiver's) weight is scaled down so that
it exactly empties (fills), and the flows are summed again. Mass is conserved pair by pair and
every stage stays in its domain for any ``h``; Heun is a convex combination of two such stages,
so it does too. A stage that needs no limiting is the plain Euler stage, so away from the
limits this is the textbook scheme. (Shortening the step instead, to ``1 / rate``, cost exact
mode 10-17 steps per iteration even at rest, since the rate of a strategy sitting at its limit
stays large.)

Controller states ``z`` (exact mode's line prices) are integrated alongside and kept
non-negative. A state above ``z_cap`` means the controllers cannot relieve the congestion: the
run stops and reports the problem infeasible.

Convergence (documented criterion): the mean set point of every generator over the last
``window`` iterations differs by at most ``tol_kw`` kilowatts from its mean over the ``window``
iterations before, and the controllers' residual (exact mode: overflow, or slack under a
positive price) is at most ``tol_kw`` at every iteration of the last window; with
``extrapolate`` (exact mode) the geometric tail of the window means must be within ``tol_kw``
as well. Means, not samples, because a generator sliding along its limit chatters on the
scale of the internal step. The iteration of
convergence is the first iteration of the last window; the run stops when the criterion first
holds. Only the last ``3 * window`` samples are kept, unless a history is asked for.

Everything below is compiled and allocation-free per stage; the online day runs as one compiled
loop over minutes (:func:`integrate_day`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from popdispatch.dynamics.fields import field_weights
from popdispatch.dynamics.pairwise import pairwise_flows, sort_by_fitness
from popdispatch.game.payoffs import game
from popdispatch.warm_start import warm_start

METHODS = {"euler": 0, "heun": 1}

#: ``converged_at`` value of a run stopped because a controller state exceeded ``z_cap``.
INFEASIBLE = -2

#: Largest ``h * rate`` a Heun step may take (its stability interval on the real axis is 2).
STABLE_STEP = 1.5


@dataclass(frozen=True)
class Integrator:
    """Solver, step-size control and stopping rule.

    Attributes
    ----------
    dt : sampling interval, s (one iteration; paper: 0.01 s).
    method : ``"euler"`` (fixed substeps) or ``"heun"`` (adaptive), see the module docstring.
    substeps : Euler steps per iteration (internal step ``dt / substeps``, s).
    rtol, atol : Heun error control: relative, and absolute on the shares (dimensionless).
    price_atol : Heun error control: absolute on controller states, EUR/MW.
    tol_kw : convergence tolerance on window means of the set points and on the residual, kW.
    window : iterations per averaging window.
    max_iterations : horizon per run (per minute in the day loop); 6000 = one minute.
    extrapolate : also require the geometrically projected remaining motion to be within
        ``tol_kw`` (for smooth, slowly converging runs; chatter in paper mode defeats it).
    """

    dt: float = 0.01
    method: str = "euler"
    substeps: int = 100
    rtol: float = 1e-4
    atol: float = 1e-8
    price_atol: float = 1e-4
    tol_kw: float = 0.01
    window: int = 20
    max_iterations: int = 6000
    extrapolate: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown integration method {self.method!r} (euler or heun)")
        for name in ("dt", "tol_kw", "rtol", "atol", "price_atol"):
            if not getattr(self, name) > 0:
                raise ValueError(f"integrator {name} must be positive, got {getattr(self, name)}")
        for name in ("substeps", "window", "max_iterations"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"integrator {name} must be >= 1, got {getattr(self, name)}")

    @property
    def method_code(self) -> int:
        return METHODS[self.method]

    def settings(self, tol_mw: float, z_cap: float) -> tuple:
        """The numbers the compiled kernels take (``tol_mw``: ``tol_kw`` in MW)."""
        return (
            float(self.dt), int(self.method_code), int(self.substeps), float(self.rtol),
            float(self.atol), float(self.price_atol), float(tol_mw), int(self.window),
            int(self.max_iterations), float(z_cap), bool(self.extrapolate),
        )  # fmt: skip


def workspace(n: int, n_lines: int, n_prices: int, window: int) -> tuple:
    """Scratch arrays for the kernels: two evaluation points, limiter, stages, samples, and
    counters (evaluations, rejected steps)."""
    vectors = np.zeros((25, n))
    prices = np.zeros((5, n_prices))
    lines = np.zeros((4, n_lines))
    order = np.zeros((2, n), dtype=np.int64) + np.arange(n)
    ring = np.zeros((3 * window, n))
    counters = np.zeros(2, dtype=np.int64)  # evaluations of the game and field, rejected steps
    return vectors, prices, lines, order, ring, counters


@nb.njit(cache=True, inline="always")
def _evaluate(point, x, z, demand, rules, problem, ws):
    """Fitness, weights and raw pairwise flows at ``(x, z)`` into evaluation ``point`` (0/1).

    Returns ``(congestion, residual)`` of the game.
    """
    field, mode, complete, indptr, indices = rules
    params, lo, hi, active = problem
    vectors, prices, lines, order, _, counters = ws
    counters[0] += 1
    base = 7 * point
    p, f, w, v = vectors[base], vectors[base + 1], vectors[base + 2], vectors[base + 3]
    room, inflow, outflow = vectors[base + 4], vectors[base + 5], vectors[base + 6]
    z_rate = prices[point]
    for i in range(x.shape[0]):
        p[i] = x[i] * demand
    congestion, residual = game(mode, p, z, params, lines, f, z_rate)
    field_weights(field, x, lo, hi, active, w, v, room)
    if complete:
        sort_by_fitness(f, order[point])
    pairwise_flows(f, w, v, complete, indptr, indices, order[point], inflow, outflow)
    return congestion, residual


@nb.njit(cache=True, inline="always")
def _limited_stage(point, h, x, z, rules, ws, x_out, z_out):
    """``x_out = x + h * (inflow - outflow)`` with the flux limiter; ``z_out`` projected >= 0."""
    _, _, complete, indptr, indices = rules
    vectors, prices, _, order, _, _ = ws
    base = 7 * point
    f, w, v = vectors[base + 1], vectors[base + 2], vectors[base + 3]
    room, inflow, outflow = vectors[base + 4], vectors[base + 5], vectors[base + 6]
    w2, v2, in2, out2 = vectors[14], vectors[15], vectors[16], vectors[17]
    z_rate = prices[point]
    limited = False
    for i in range(x.shape[0]):
        w2[i] = w[i]
        v2[i] = v[i]
        if h * outflow[i] > v[i]:
            v2[i] = v[i] * (v[i] / (h * outflow[i]))
            limited = True
        if h * inflow[i] > room[i]:
            w2[i] = w[i] * (room[i] / (h * inflow[i]))
            limited = True
    if limited:
        pairwise_flows(f, w2, v2, complete, indptr, indices, order[point], in2, out2)
        for i in range(x.shape[0]):
            x_out[i] = x[i] + h * (in2[i] - out2[i])
    else:
        for i in range(x.shape[0]):
            x_out[i] = x[i] + h * (inflow[i] - outflow[i])
    for k in range(z.shape[0]):
        z_out[k] = max(z[k] + h * z_rate[k], 0.0)


@nb.njit(cache=True, inline="always")
def _error_norm(x_high, x_low, z_high, z_low, rtol, atol, price_atol):
    err = 0.0
    for i in range(x_high.shape[0]):
        err = max(err, abs(x_high[i] - x_low[i]) / (atol + rtol * abs(x_high[i])))
    for k in range(z_high.shape[0]):
        err = max(err, abs(z_high[k] - z_low[k]) / (price_atol + rtol * abs(z_high[k])))
    return err


@nb.njit(cache=True)
def _advance_euler(x, z, demand, rules, problem, ws, dt, substeps):
    """One iteration of ``substeps`` limited Euler steps; ``(congested, residual)``."""
    congested = 0.0
    residual = 0.0
    h = dt / substeps
    for _ in range(substeps):
        congestion, residual = _evaluate(0, x, z, demand, rules, problem, ws)
        congested = max(congested, congestion)
        _limited_stage(0, h, x, z, rules, ws, x, z)
    return congested, residual


@nb.njit(cache=True, inline="always")
def _heun_combination(h, x, z, rules, ws, x_out, z_out):
    """``x_out = x + h/2 (k1 + k2)`` from the raw flows at both points, flux-limited as one step.

    Where the combined step would carry a strategy past its movable mass or its room, the
    senders' (receivers') weights at both points are scaled down together so that it lands
    exactly on its limit; a strategy driven into a limit thus reaches it, instead of halving
    its distance each step as a convex combination of limited stages would.
    """
    _, _, complete, indptr, indices = rules
    vectors, prices, _, order, _, _ = ws
    f1, w1, v1, room1 = vectors[1], vectors[2], vectors[3], vectors[4]
    in1, out1 = vectors[5], vectors[6]
    f2, w2, v2, in2, out2 = vectors[8], vectors[9], vectors[10], vectors[12], vectors[13]
    sw1, sv1, sin1, sout1 = vectors[14], vectors[15], vectors[16], vectors[17]
    sw2, sv2, sin2, sout2 = vectors[20], vectors[21], vectors[22], vectors[23]
    half = 0.5 * h
    limited = False
    for i in range(x.shape[0]):
        alpha = 1.0
        beta = 1.0
        out = half * (out1[i] + out2[i])
        into = half * (in1[i] + in2[i])
        if out > v1[i]:
            alpha = v1[i] / out
            limited = True
        if into > room1[i]:
            beta = room1[i] / into
            limited = True
        sw1[i], sv1[i], sw2[i], sv2[i] = beta * w1[i], alpha * v1[i], beta * w2[i], alpha * v2[i]
    if limited:
        pairwise_flows(f1, sw1, sv1, complete, indptr, indices, order[0], sin1, sout1)
        pairwise_flows(f2, sw2, sv2, complete, indptr, indices, order[1], sin2, sout2)
        for i in range(x.shape[0]):
            x_out[i] = x[i] + half * (sin1[i] - sout1[i] + sin2[i] - sout2[i])
    else:
        for i in range(x.shape[0]):
            x_out[i] = x[i] + half * (in1[i] - out1[i] + in2[i] - out2[i])
    for k in range(z.shape[0]):
        z_out[k] = max(z[k] + half * (prices[0][k] + prices[1][k]), 0.0)


@nb.njit(cache=True, inline="always")
def _stiffness(h, x, z, ws, rtol, atol, price_atol):
    """Largest rate the last step saw, ``||k2 - k1|| / ||x1 - x||`` (1/s), in the error norm's
    scaling, over the components the limiter left alone.

    Error control alone lets the step grow near a rest point (where the error vanishes) until
    it meets the stability boundary of the price loop, and then hovers there with an
    oscillation of the size of the error tolerance, far above the convergence tolerance.
    Capping the step by this estimate keeps Heun inside its stability region. Strategies that
    the limiter stopped at a limit are left out: their fast approach is absorbed exactly.
    """
    vectors, prices, _, _, _, _ = ws
    v1, room1, in1, out1 = vectors[3], vectors[4], vectors[5], vectors[6]
    in2, out2 = vectors[12], vectors[13]
    moved = 0.0
    turned = 0.0
    for i in range(x.shape[0]):
        if h * out1[i] > v1[i] or h * in1[i] > room1[i]:
            continue
        scale = atol + rtol * abs(x[i])
        k1 = (in1[i] - out1[i]) / scale
        k2 = (in2[i] - out2[i]) / scale
        moved += k1 * k1
        turned += (k2 - k1) * (k2 - k1)
    for k in range(z.shape[0]):
        if z[k] + h * prices[0][k] < 0.0:
            continue
        scale = price_atol + rtol * abs(z[k])
        k1 = prices[0][k] / scale
        k2 = prices[1][k] / scale
        moved += k1 * k1
        turned += (k2 - k1) * (k2 - k1)
    if moved <= 0.0:
        return 0.0
    return np.sqrt(turned / moved) / h


@nb.njit(cache=True)
def _advance_heun(x, z, demand, rules, problem, ws, dt, h_try, tol):
    """One iteration of adaptive Heun steps; ``(congested, largest residual, next h_try)``."""
    rtol, atol, price_atol = tol
    vectors, prices, _, _, _, counters = ws
    x1, x2 = vectors[18], vectors[19]
    z1, z2 = prices[2], prices[3]
    remaining = dt
    congested = 0.0
    residual = 0.0
    fresh = False
    while remaining > 1e-12 * dt:
        if not fresh:
            # residual: the largest at the start of any step, the iteration's first sample
            # included (the last step's alone missed a period-3 price oscillation)
            congestion, step_residual = _evaluate(0, x, z, demand, rules, problem, ws)
            congested = max(congested, congestion)
            residual = max(residual, step_residual)
            fresh = True
        h = min(h_try, remaining)
        _limited_stage(0, h, x, z, rules, ws, x1, z1)
        _evaluate(1, x1, z1, demand, rules, problem, ws)
        _heun_combination(h, x, z, rules, ws, x2, z2)
        err = _error_norm(x2, x1, z2, z1, rtol, atol, price_atol)
        rate = _stiffness(h, x, z, ws, rtol, atol, price_atol)
        if err <= 1.0:
            x[:] = x2
            z[:] = z2
            remaining -= h
            fresh = False
        else:
            counters[1] += 1
        h_try = h * min(5.0, max(0.2, 0.9 / np.sqrt(err))) if err > 0.0 else 5.0 * h
        if rate * h_try > STABLE_STEP:
            h_try = STABLE_STEP / rate
    return congested, residual, min(h_try, dt)


@nb.njit(cache=True)
def _window_mean(ring, last, window, i):
    """Mean of sample column ``i`` over the ``window`` samples ending at iteration ``last``."""
    size = ring.shape[0]
    total = 0.0
    for k in range(window):
        total += ring[(last - k) % size, i]
    return total / window


@nb.njit(cache=True)
def _windows_agree(ring, last, window, tol, extrapolate):
    """Do the means of the last two windows of set points differ by at most ``tol``?

    With ``extrapolate`` (needs three windows), a geometric tail is also projected: if the
    window means keep moving the same way with ratio ``r < 1``, the distance still to go,
    ``|d| r / (1 - r)``, must be within ``tol`` too. Slow exponential tails (several generators
    inside their limits, whose split is set by tiny quadratic costs) otherwise look converged.
    """
    for i in range(ring.shape[1]):
        recent = _window_mean(ring, last, window, i)
        middle = _window_mean(ring, last - window, window, i)
        step = recent - middle
        if abs(step) > tol:
            return False
        if extrapolate:
            previous = middle - _window_mean(ring, last - 2 * window, window, i)
            ratio = step / previous if previous != 0.0 else 0.0
            if 0.0 < ratio < 1.0 and abs(step) * ratio / (1.0 - ratio) > tol:
                return False
    return True


@nb.njit(cache=True)
def integrate(x, z, demand, rules, problem, ws, settings, h_try, history):
    """Run the dynamics from shares ``x`` (and controller state ``z``, both updated in place) at
    fixed ``demand`` (MW) until converged, infeasible or the horizon.

    ``rules = (field code, game code, complete graph?, CSR indptr, CSR indices)``;
    ``problem = (game parameters, lo, hi, active)``; ``ws``: :func:`workspace`;
    ``settings``: :meth:`Integrator.settings`. ``history`` (rows ``max_iterations + 1`` or 0)
    receives the set points (MW) of every iteration when it has rows.

    Returns ``(iterations, converged_at, first_congestion, h_try)``: ``converged_at`` is -1 if
    the run did not converge and :data:`INFEASIBLE` if a price passed ``z_cap``;
    ``first_congestion`` the first iteration with a non-zero signal (-1 if none).
    """
    dt, method, substeps, rtol, atol, price_atol, tol_mw, window, horizon, z_cap, extra = settings
    ring = ws[4]
    size = ring.shape[0]
    record = history.shape[0] > 0
    for i in range(x.shape[0]):
        ring[0, i] = x[i] * demand
        if record:
            history[0, i] = ring[0, i]
    converged_at = -1
    first_congestion = -1
    need = (3 if extra else 2) * window
    last_x = ws[0][24]
    last_z = ws[1][4]
    stationary = False
    residual = 0.0
    calm = 0  # iterations in a row with the residual within tol_mw
    congested = 0.0
    for k in range(1, horizon + 1):
        # A state that an iteration left exactly unchanged is a fixed point of the scheme:
        # later iterations would repeat it, so they are recorded without being recomputed.
        if not stationary:
            last_x[:] = x
            last_z[:] = z
            if method == 0:
                congested, residual = _advance_euler(
                    x, z, demand, rules, problem, ws, dt, substeps
                )
            else:
                congested, residual, h_try = _advance_heun(
                    x, z, demand, rules, problem, ws, dt, h_try, (rtol, atol, price_atol)
                )
            stationary = np.array_equal(x, last_x) and np.array_equal(z, last_z)
        row = k % size
        for i in range(x.shape[0]):
            ring[row, i] = x[i] * demand
            if record:
                history[k, i] = ring[row, i]
        if first_congestion < 0 and congested > 0.0:
            first_congestion = k
        if z.shape[0] > 0 and z.max() > z_cap:
            return k, INFEASIBLE, first_congestion, h_try
        # the residual within tolerance over the whole last window, not at one sample: the
        # price loop can oscillate with a period of 2-3 iterations whose window means agree
        # while every other sample overflows (issue 10: 1e-4 kW on random feeders)
        calm = calm + 1 if residual <= tol_mw else 0
        if k >= need and calm >= window and _windows_agree(ring, k, window, tol_mw, extra):
            converged_at = k - window
            return k, converged_at, first_congestion, h_try
    return horizon, converged_at, first_congestion, h_try


@nb.njit(cache=True)
def integrate_day(x, z, rules, day, ws, settings, h_try, first, last, out):
    """The online day, minutes ``first..last - 1`` (row indices of ``day``), in one loop.

    ``day = (base game parameters, demand (MW), load_flow (MW), online, pmin, pmax (MW),
    bounded?, warm-start policy, previous demand (MW))``: per minute the demand and online set
    change, the state warm-starts (:mod:`popdispatch.warm_start`) and the dynamics run until
    converged. ``out = (setpoints (MW), iterations, converged_at, controller states)`` receive
    one row per minute (the states for the KKT check at each minute's end).
    Returns ``(h_try, demand of the last minute)``.
    """
    base, demand, load_flow, online, pmin, pmax, bounded, policy, old_demand = day
    b, c, gmin, gmax, B, m, C, gain, rate, limit, gen_line, line_up, order, _ = base
    setpoints, iterations, converged_at, states = out
    n = x.shape[0]
    lo = np.empty(n)
    hi = np.empty(n)
    weight = np.empty(n)
    no_history = np.empty((0, n))
    for row in range(first, last):
        active = online[row]
        warm_start(policy, bounded, x, old_demand, demand[row], pmin, pmax, active, weight)
        for i in range(n):
            lo[i] = pmin[i] / demand[row] if active[i] else 0.0
            hi[i] = pmax[i] / demand[row] if active[i] else 0.0
        params = (b, c, gmin, gmax, B, m, C, gain, rate, limit, gen_line, line_up, order,
                  load_flow[row])  # fmt: skip
        steps, done_at, _, h_try = integrate(
            x, z, demand[row], rules, (params, lo, hi, active), ws, settings, h_try, no_history
        )
        for i in range(n):
            setpoints[row, i] = x[i] * demand[row]
        for k in range(z.shape[0]):
            states[row, k] = z[k]
        iterations[row] = steps
        converged_at[row] = done_at
        old_demand = demand[row]
    return h_try, old_demand
