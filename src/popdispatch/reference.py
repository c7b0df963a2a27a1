"""Plain-numpy reference of one minute of dynamics (the compiled engine's yardstick).

Written for clarity, not speed, and deliberately naive where the engine is clever: the dense
``(lines x generators)`` matrix ``D`` for flows and signals (the engine: one pass each way over
the tree of limited lines), the full ``(n x n)`` matrix of pairwise flows (the engine: sorted
running sums), Python loops over steps. It follows the same equations and the same numerical
scheme as the compiled kernels (:mod:`popdispatch.integrate`, :mod:`popdispatch.modes`,
:mod:`popdispatch.dynamics.pairwise`), so both must give the same trajectories; the tests
check that they do. The fitness (eqs. 5-7) and the share bounds are not re-derived: they are
the engine's own (:func:`popdispatch.game.fitness.generator_fitness`,
:class:`popdispatch.game.parameters.MinuteInputs`), one implementation for both. Powers in MW,
shares dimensionless.
"""

from __future__ import annotations

import networkx as nx
import numpy as np

from popdispatch.dynamics import Kernel, communication_graph
from popdispatch.dynamics.fields import field_tag, law_of
from popdispatch.dynamics.pairwise import NEAR_LIMIT, RELAY_MASS, SLOW_RELAY
from popdispatch.game.fitness import FitnessParameters, generator_fitness
from popdispatch.game.mesh import lever_scale
from popdispatch.game.parameters import MinuteInputs
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import ROUND_OFF, Status
from popdispatch.integrate.steppers import next_step
from popdispatch.modes import ModeCode, get_mode
from popdispatch.modes.exact import (
    IDLE_MARGIN,
    PINNED_BOOST,
    PINNED_FADE,
    PINNED_MARGIN,
    PINNED_SETTLE,
    STUCK_SETTLE,
)


def at_rest(x, last_x, z, last_z) -> bool:
    """The fixed-point test: every share within ``ROUND_OFF`` of where it was, every
    controller state within ``ROUND_OFF`` of its size."""
    return bool(
        np.all(np.abs(x - last_x) <= ROUND_OFF)
        and np.all(np.abs(z - last_z) <= ROUND_OFF * np.abs(z))
    )


def overflow_signals(flow: np.ndarray, limit: np.ndarray, C: float) -> np.ndarray:
    """Eq. 8 for controllers measuring ``flow`` (MW, + leaving their node): EUR/MW."""
    below = np.where(flow < -limit, -(flow + limit) * C, 0.0)
    return np.where(flow > limit, -(flow - limit) * C, below)


def fitness(problem: DispatchProblem, p, signal, fp: FitnessParameters, gain: float, barrier):
    """Eqs. 5-7 plus ``signal`` by the engine's own fitness kernel."""
    return generator_fitness(p, problem.b, problem.c, problem.pmin, problem.pmax, float(fp.B),
                             float(fp.m), signal, float(gain), bool(barrier))  # fmt: skip


def voltage_rows(problem: DispatchProblem, p, minute: int) -> tuple[np.ndarray, np.ndarray]:
    """``(excess, dexcess_dp)`` of the voltage rows from the unscaled LinDistFlow model
    (docs/voltage.md): ``v^2 = v0^2 + S p`` (p.u.^2; ``S = d(v^2)/dp``, p.u.^2 per MW), the
    rows ``vmin^2 - v^2 <= 0`` and ``v^2 - vmax^2 <= 0``, each divided by its bus's scale
    ``s_j`` (p.u.^2 per MW) into MW equivalents: ``(2 V,)`` and ``(2 V, generators)``, low
    rows then high rows. (The engine instead reads pre-scaled loads-only excesses from
    ``load_flow`` and the scaled ``voltage_sens``.)"""
    if not problem.n_voltage:
        return np.zeros(0), np.zeros((0, problem.n_generators))
    scale = problem.voltage_scale
    S = problem.voltage_sens * scale[:, None]  # unscaled d(v^2)/dp
    v_sq = problem.voltage_base[minute - 1] + S @ p
    excess = np.concatenate([(problem.vmin_pu**2 - v_sq) / scale,
                             (v_sq - problem.vmax_pu**2) / scale])  # fmt: skip
    return excess, np.concatenate([-S / scale[:, None], S / scale[:, None]])


def game(mode: ModeCode, p, z, problem: DispatchProblem, minute: int, fp: FitnessParameters,
         pinned_speed: float = 0.0, stuck: bool = False):  # fmt: skip
    """``(fitness, z_rate, congestion, residual)`` of a mode at set points ``p`` (MW).

    Exact and voltage modes: every row ``r`` (a limited line's direction, a monitored bus's
    bound) has an excess ``e_r`` (MW or MW equivalents) and a price ``mu_r = max(0, z_r + C
    e_r)`` that integrates at ``price_rate e_r`` (a mesh line's ``C`` and ``price_rate`` times
    its lever scale, :func:`popdispatch.game.mesh.lever_scale`; a pinned line's, and a pinned
    pair's gap, raised to ``pinned_speed``, EUR/MW per s, and with ``stuck`` a stuck line's,
    :func:`pinned_rates`); generator
    ``i``'s signal is ``-sum_r mu_r de_r/dp_i`` weighed as the paper splits a line's (half to
    each side, eq. 8's sides) and in full for a bus (the Lagrangian's gradient of the voltage
    rows)."""
    down = problem.down
    flow = problem.line_load_flow[minute - 1] - down @ p
    if mode == ModeCode.PAPER:
        parent = overflow_signals(flow, problem.limit, fp.C)
        child = np.where(parent != 0.0, overflow_signals(-flow, problem.limit, fp.C), 0.0)
        signal = (1.0 - down).T @ parent + down.T @ child
        congestion = np.abs(signal).max() if len(signal) else 0.0
        return fitness(problem, p, signal, fp, 1.0, True), np.zeros_like(z), congestion, 0.0
    excess = np.concatenate([flow - problem.limit, -flow - problem.limit])
    if mode == ModeCode.VOLTAGE:
        v_excess, v_gradient = voltage_rows(problem, p, minute)
        excess = np.concatenate([excess, v_excess])
    lines = len(flow)
    scale = np.ones(len(excess))  # a mesh line's lever scale multiplies its C and rate
    if problem.meshed:
        scale[: 2 * lines] = np.tile(lever_scale(problem.factor), 2)
    z_rate = fp.price_rate * scale * excess
    slack = np.where(z > 0.0, np.abs(excess), np.maximum(excess, 0.0))
    mu = np.maximum(0.0, z + fp.C * scale * excess)
    nu = mu[:lines] - mu[lines : 2 * lines]
    signal = down.T @ (0.5 * nu) - (1.0 - down).T @ (0.5 * nu)
    prices = np.abs(nu)
    if mode == ModeCode.VOLTAGE:
        signal = signal - mu[2 * lines :] @ v_gradient
        n_v = problem.n_voltage
        prices = np.concatenate([prices, np.abs(mu[2 * lines : 2 * lines + n_v]
                                                - mu[2 * lines + n_v :])])  # fmt: skip
    congestion = prices.max() if len(prices) else 0.0
    residual = slack.max() if len(slack) else 0.0
    f = fitness(problem, p, signal, fp, fp.gain, False)
    if pinned_speed > 0.0 and lines:
        z_rate[: 2 * lines] = pinned_rates(problem, minute, p, z[: 2 * lines],
                                           excess[: 2 * lines], z_rate[: 2 * lines],
                                           fp.price_rate, pinned_speed,
                                           f / fp.gain if stuck else None)  # fmt: skip
    return f, z_rate, congestion, residual


def rates_in_force(problem: DispatchProblem, minute: int, p, z, C: float, rate, idle_rate):
    """The revision rates at set points ``p`` (MW) and prices ``z`` (EUR/MW; ``C`` EUR/MW per
    MW): a generator's priced ``rate`` under an active limited line, its ``idle_rate`` while
    every line above it has no price and more than ``IDLE_MARGIN`` of its limit in slack,
    geometrically between by ``h = clip(1 + max(z + C e) / (C m U), 0, 1)`` of the most
    active line above it (:func:`popdispatch.modes.exact.rates_in_force`)."""
    lines = len(problem.limit)
    flow = problem.line_load_flow[minute - 1] - problem.down @ p
    augmented = np.maximum(z[:lines] + C * (flow - problem.limit),
                           z[lines : 2 * lines] + C * (-flow - problem.limit))  # fmt: skip
    margin = C * IDLE_MARGIN * problem.limit
    with np.errstate(divide="ignore", invalid="ignore"):
        activity = np.where(margin > 0, np.clip(1.0 + augmented / margin, 0.0, 1.0), 1.0)
    below = problem.down != 0.0  # lines x generators
    hot = np.where(below, activity[:, None], 0.0).max(axis=0, initial=0.0)
    return np.where(below.any(axis=0), rate**hot * idle_rate ** (1.0 - hot), rate)


def pinned_rates(problem: DispatchProblem, minute: int, p, z, excess, z_rate, price_rate,
                 speed: float, price_fitness=None):  # fmt: skip
    """The line prices' rates ``z_rate`` (both directions, EUR/MW per s, at prices ``z``) plus
    the gains of the pinned lines and pairs: a line with generators below it that can trade,
    none more than ``PINNED_FADE`` of its range inside its limits, gains on each price what
    raises its own plain rate ``price_rate * excess`` to ``speed`` in magnitude, times ``1 -
    sum(d_i / PINNED_FADE)`` (at least 0) over the generators below it more than
    ``PINNED_MARGIN`` of their range from their limits, ``d_i`` the fraction of its range from
    the nearer one; a line and the nearest limited line above it, with some
    generators below the lower one inside and those between able to trade, none inside, each
    at the limit the gain pushes it into (an up price's gain raises their fitness, a down
    price's lowers it), gain the same on half the gap of their rates ``price_rate * excess``,
    added to the upper price and taken from the lower while the price it lowers is positive,
    by at most that price over ``PINNED_SETTLE``; each gain by at most ``PINNED_BOOST`` times.
    A *stuck* price (``price_fitness`` given: the fitness over the revision gain, EUR/MW) with
    an excess or a price: none of the trades that would move its line's flow the way it asks
    is open (the flow must fall where the up price's excess is positive: a generator below
    that can rise fitter than one elsewhere that can fall), its gap being how much the worst
    sender is fitter than the best receiver; it gains the same, by at most its gap over
    ``STUCK_SETTLE``, where that is more than the pinned gain.
    ``price_rate``: one value, or one per price (the scaled law's ``alpha s_k``)."""
    inputs = MinuteInputs.of(problem, minute)
    low, high = inputs.lo * inputs.demand, inputs.hi * inputs.demand
    margin = PINNED_MARGIN * (high - low)
    tradable = high > low
    is_inside = (p > low + margin) & (p < high - margin)
    fade = PINNED_FADE * (high - low)
    deep = (p > low + fade) & (p < high - fade)
    near = tradable & is_inside & ~deep
    distance = np.minimum(p - low, high - p) / np.where(tradable, (high - low) * PINNED_FADE, 1.0)
    at_limit = tradable & ~is_inside
    nearer_low = p - low < high - p
    inside = problem.down @ is_inside
    at_low = problem.down @ (at_limit & nearer_low)
    at_high = problem.down @ (at_limit & ~nearer_low)
    lines = len(inside)

    def gain(rate):
        size = np.abs(rate)
        with np.errstate(divide="ignore"):
            factor = np.where((size > 0) & (size < speed), np.minimum(PINNED_BOOST, speed / size),
                              1.0)  # fmt: skip
        return rate * (factor - 1.0)

    weight = np.maximum(0.0, 1.0 - problem.down @ np.where(near, distance, 0.0))
    pinned = (problem.down @ (tradable & deep) == 0) & (problem.down @ tradable > 0)
    own = np.broadcast_to(price_rate, excess.shape) * excess
    full = gain(own)
    size = np.tile(np.where(pinned, weight, 0.0), 2) * np.abs(full)
    if price_fitness is not None:
        rises = tradable & ~(at_limit & ~nearer_low)
        falls = tradable & ~(at_limit & nearer_low)
        waits = stuck_gaps(problem.down != 0.0, price_fitness, rises, falls, excess, z)
        size = np.maximum(size, np.minimum(np.abs(full), waits / STUCK_SETTLE))
    z_rate = z_rate + np.sign(full) * size
    lower = np.flatnonzero(problem.line_up >= 0)
    upper = problem.line_up[lower]
    pair = (inside[lower] >= 1) & (inside[upper] == inside[lower])
    lows, highs = (at_low[upper] - at_low[lower])[pair], (at_high[upper] - at_high[lower])[pair]
    for side, sign in ((0, 1.0), (lines, -1.0)):
        low_row, up_row = side + lower[pair], side + upper[pair]
        gap = 0.5 * (own[up_row] - own[low_row])
        held = (lows + highs > 0) & np.where(gap * sign > 0, lows == 0, highs == 0)
        lowered = np.where(gap > 0, z[low_row], z[up_row])
        cap = lowered / PINNED_SETTLE
        pair_gain = np.where(held & (lowered > 0), np.clip(gain(gap), -cap, cap), 0.0)
        np.add.at(z_rate, up_row, pair_gain)
        np.add.at(z_rate, low_row, -pair_gain)
    return z_rate


def stuck_gaps(below, f, rises, falls, excess, z):
    """Per price (up prices, then down): the gap (EUR/MW) of the trade its line's flow waits
    for (:func:`pinned_rates`); 0 where such a trade is open, and where the price has neither
    an excess nor a value. ``below``: lines x generators; ``f``: fitness over the gain."""

    def extreme(mask, values, worst, pick):
        return pick(np.where(mask, values[None, :], worst), axis=1, initial=worst)

    rise_below = extreme(below & rises, f, -np.inf, np.max)
    fall_below = extreme(below & falls, f, np.inf, np.min)
    rise_out = extreme(~below & rises, f, -np.inf, np.max)
    fall_out = extreme(~below & falls, f, np.inf, np.min)
    lowering = np.maximum(0.0, fall_out - rise_below)
    raising = np.maximum(0.0, fall_below - rise_out)
    lines = below.shape[0]
    up = np.arange(2 * lines) < lines
    waits = np.where(up == (excess > 0.0), np.tile(lowering, 2), np.tile(raising, 2))
    return np.where((excess > 0.0) | (z > 0.0), waits, 0.0)


def weights(field, x, f, lo, hi, active, rate=None):
    """Receiver weight, sender weight, room and movable mass of a field (a
    :class:`~popdispatch.dynamics.fields.Field` whose law takes no parameters, or its record)
    at shares ``x`` and fitness ``f``: the plain-numpy statement in the law's own module
    (:attr:`~popdispatch.dynamics.law.FlowLaw.reference`; ``rate``: the revision rates of the
    curvature-scaled field)."""
    tag = field_tag(field)
    rate = np.ones(len(x)) if rate is None else rate
    return law_of(tag).reference(tag, x, f, lo, hi, active, rate)


def pair_flows(f, w, v, graph, mass=None, room=None, kernel=Kernel.COMPARISON, slow=None):
    """``(inflow, outflow)``: ``T[i, j] = g_ij w_i v_j K(f_i, f_j)`` summed over j / over i,
    with ``K = [f_i - f_j]_+`` (a comparison ``kernel``, plus the relay:
    :func:`relay_matrix`; ``mass``, ``room``: the movable masses and rooms that say who is
    blocked, default the sender weights and no upper limits; ``slow``: who relays by rate,
    default nobody) or ``K = 1`` (a target)."""
    if kernel == Kernel.TARGET:
        T = graph * w[:, None] * v[None, :]
        return T.sum(axis=1), T.sum(axis=0)
    T = graph * w[:, None] * v[None, :] * np.maximum(f[:, None] - f[None, :], 0.0)
    mass = v if mass is None else mass
    room = np.full(len(f), np.inf) if room is None else room
    T = T + relay_matrix(f, w, v, graph, mass, room, slow)
    return T.sum(axis=1), T.sum(axis=0)


def slow_members(rate: np.ndarray, graph: np.ndarray) -> np.ndarray:
    """Who relays by rate (dynamics/pairwise.py ``slow_relays``): a rate below ``SLOW_RELAY``
    times the largest of its neighbours' on the dense 0/1 ``graph``."""
    if len(rate) != len(graph):
        return np.zeros(len(graph), dtype=bool)
    fastest = np.where(graph > 0, rate[None, :], 0.0).max(axis=1)
    return rate < SLOW_RELAY * fastest


def relay_matrix(f, w, v, graph, mass, room, slow=None) -> np.ndarray:
    """The relay of distributed Smith on a graph (dynamics/pairwise.py ``relay_flows``),
    written from its definition with networkx: each connected set of relaying strategies
    (offline, room or movable mass within ``NEAR_LIMIT`` of its range, at least
    ``RELAY_MASS``; or ``slow``: :func:`slow_members`) together with its neighbours is a
    group; within it every member sends to every member that can receive (``w > 0``, room
    above ``RELAY_MASS``) at ``w_b v_a [f_b - f_a]_+``. Nothing on the complete graph."""
    n = len(f)
    relay = np.zeros((n, n))
    if (graph + np.eye(n) > 0).all():
        return relay
    span = np.where(np.isinf(room), 0.0, mass + room)  # unbounded room: no range
    margin = np.maximum(RELAY_MASS, NEAR_LIMIT * span)
    blocked = ~((w > 0) & (mass > margin) & (room > margin))
    if slow is not None:
        blocked = blocked | slow
    g = nx.from_numpy_array(graph)
    for members in nx.connected_components(g.subgraph(np.flatnonzero(blocked).tolist())):
        group = sorted(set(members) | {b for k in members for b in g.neighbors(k)})
        for b in group:
            if w[b] > 0 and room[b] > RELAY_MASS:
                for a in group:
                    relay[b, a] += w[b] * v[a] * max(f[b] - f[a], 0.0)
    return relay


class ReferenceMinute:
    """One minute of a run configuration (problem, settings) in plain numpy."""

    def __init__(self, problem: DispatchProblem, settings, minute: int):
        self.problem, self.minute = problem, minute
        self.fp = settings.game_constants(problem)  # EUR/MW (exact mode: scaled)
        self.price_scale = settings.price_scale(problem)
        self.mode = get_mode(settings.mode)
        self.tag = settings.field_tag(problem)
        self.law = law_of(self.tag)
        self.graph = communication_graph(settings.trading_graph, list(problem.generators))
        self.sparse = not (self.graph + np.eye(len(problem.generators)) > 0).all()
        inputs = MinuteInputs.of(problem, minute)
        self.active, self.demand, self.lo, self.hi = (
            inputs.active,
            inputs.demand,
            inputs.lo,
            inputs.hi,
        )
        self.integrator = settings.stepping
        self.rate = settings.engine_revision_rates(problem)
        self.idle_rate = settings.engine_idle_rates(problem)
        self.slow = slow_members(self.rate, self.graph) | settings.engine_held_relays(problem)
        if len(self.idle_rate):  # slow by either rate relays (dynamics/pairwise.py graph_of)
            self.slow |= slow_members(self.idle_rate, self.graph)
        self.z_cap = self.mode.price_cap(problem) if self.mode.bounded else np.inf
        self.pinned_speed = settings.engine_pinned_speed(problem)
        self.stuck = settings.engine_hastens_stuck_lines(problem)

    def evaluate(self, x, z):
        f, z_rate, congestion, residual = game(
            self.mode.code, x * self.demand, z, self.problem, self.minute, self.fp,
            self.pinned_speed, self.stuck,
        )
        law = self.law
        rate = self.rate
        if len(self.idle_rate):
            rate = rates_in_force(self.problem, self.minute, x * self.demand, z, self.fp.C,
                                  self.rate, self.idle_rate)  # fmt: skip
        w, v, room, mass = law.reference(self.tag, x, f, self.lo, self.hi, self.active, rate)
        if law.reference_local is not None and self.sparse:
            w, v = law.reference_local(self.graph, rate, w, v, room, mass)
        inflow, outflow = self.flows(f, w, v, mass, room)
        return (f, w, v, room, mass, inflow, outflow, z_rate), congestion, residual

    def flows(self, f, w, v, mass, room):
        """``(inflow, outflow)`` of the law's kernel on the run's graph (:func:`pair_flows`)."""
        return pair_flows(f, w, v, self.graph, mass, room, self.law.kernel, self.slow)

    def limited_stage(self, h, x, z, point):
        f, w, v, room, mass, inflow, outflow, z_rate = point
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            alpha = np.where(h * outflow > mass, mass / (h * outflow), 1.0)
            # the receivers from the flows of the limited senders
            limited = (alpha < 1.0).any()
            into = self.flows(f, w, alpha * v, mass, room)[0] if limited else inflow
            beta = np.where(h * into > room, room / (h * into), 1.0)
        if (alpha < 1.0).any() or (beta < 1.0).any():
            inflow, outflow = self.flows(f, beta * w, alpha * v, mass, room)
        return x + h * (inflow - outflow), np.maximum(z + h * z_rate, 0.0)

    def heun_combination(self, h, x, z, one, two):
        f1, w1, v1, room1, mass1, in1, out1, zr1 = one
        f2, w2, v2, room2, mass2, in2, out2, zr2 = two
        half = 0.5 * h
        out, into = half * (out1 + out2), half * (in1 + in2)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            alpha = np.where(out > mass1, mass1 / out, 1.0)
            if (alpha < 1.0).any():  # the receivers from the flows of the limited senders
                into = half * (
                    self.flows(f1, w1, alpha * v1, mass1, room1)[0]
                    + self.flows(f2, w2, alpha * v2, mass2, room2)[0]
                )
            beta = np.where(into > room1, room1 / into, 1.0)
        if (alpha < 1.0).any() or (beta < 1.0).any():
            in1, out1 = self.flows(f1, beta * w1, alpha * v1, mass1, room1)
            in2, out2 = self.flows(f2, beta * w2, alpha * v2, mass2, room2)
        return x + half * (in1 - out1 + in2 - out2), np.maximum(z + half * (zr1 + zr2), 0.0)

    def advance(self, x, z, h_try):
        """One iteration (``dt`` seconds): ``(x, z, congested, residual, h_try)``."""
        it = self.integrator
        congested = residual = 0.0
        if it.method == "euler":
            h = it.dt / it.substeps
            for _ in range(it.substeps):
                point, congestion, residual = self.evaluate(x, z)
                congested = max(congested, congestion)
                x, z = self.limited_stage(h, x, z, point)
            return x, z, congested, residual, h_try
        remaining, point, switches = it.dt, None, 0
        while remaining > 1e-12 * it.dt:
            if point is None:
                point, congestion, step_residual = self.evaluate(x, z)
                congested = max(congested, congestion)
                residual = max(residual, step_residual)
            h = min(h_try, remaining)
            x1, z1 = self.limited_stage(h, x, z, point)
            second, _, _ = self.evaluate(x1, z1)
            x2, z2 = self.heun_combination(h, x, z, point, second)
            scale_x = it.atol + it.rtol * np.abs(x2)
            scale_z = it.price_atol * self.price_scale + it.rtol * np.abs(z2)
            err = max(
                np.max(np.abs(x2 - x1) / scale_x), np.max(np.abs(z2 - z1) / scale_z, initial=0.0)
            )
            rate = self.stiffness(h, x, z, point, second)
            if err <= 1.0:
                x, z, remaining, point = x2, z2, remaining - h, None
            h_try, switches = next_step(h, err, rate, switches, it.dt)
        return x, z, congested, residual, min(h_try, it.dt)

    def stiffness(self, h, x, z, one, two) -> float:
        """``||k2 - k1|| / ||x1 - x||`` over components the limiter left alone (1/s)."""
        it = self.integrator
        (_, _, _, room1, mass1, in1, out1, zr1), (_, _, _, _, _, in2, out2, zr2) = one, two
        free = ~((h * out1 > mass1) | (h * in1 > room1))
        scale = it.atol + it.rtol * np.abs(x)
        k1, k2 = (in1 - out1)[free] / scale[free], (in2 - out2)[free] / scale[free]
        open_ = z + h * zr1 >= 0.0
        zscale = it.price_atol * self.price_scale + it.rtol * np.abs(z)
        q1, q2 = zr1[open_] / zscale[open_], zr2[open_] / zscale[open_]
        moved = np.sum(k1**2) + np.sum(q1**2)
        turned = np.sum((k2 - k1) ** 2) + np.sum((q2 - q1) ** 2)
        return float(np.sqrt(turned / moved) / h) if moved > 0.0 else 0.0

    def run(self, x, z=None, max_iterations: int | None = None):
        """``(setpoints per iteration (MW), x, z, status, converged_at)`` from shares ``x``
        (``converged_at`` -1 unless converged)."""
        it = self.integrator
        horizon = max_iterations or it.max_iterations
        z = np.zeros(self.mode.controller_states(self.problem)) if z is None else z
        tol = it.tol_mw(self.demand)
        need = (3 if it.extrapolate else 2) * it.window
        samples = [x * self.demand]
        h_try = it.dt
        calm = 0  # iterations in a row with the residual within tol
        for k in range(1, horizon + 1):
            last_x, last_z = x, z
            x, z, _, residual, h_try = self.advance(x, z, h_try)
            samples.append(x * self.demand)
            if len(z) and z.max() > self.z_cap:
                return np.array(samples), x, z, Status.INFEASIBLE, -1
            calm = calm + 1 if residual <= tol else 0
            if k >= need and calm >= it.window and self._windows_agree(samples, tol):
                converged_at = k - it.window
            elif it.fixed_point and residual <= tol and at_rest(x, last_x, z, last_z):
                converged_at = k - 1  # the fixed-point stop
            else:
                continue
            if self.evaluate(x, z)[2] > tol:  # the end state's own residual
                calm = 0
                continue
            return np.array(samples), x, z, Status.CONVERGED, converged_at
        return np.array(samples), x, z, Status.NOT_CONVERGED, -1

    def _windows_agree(self, samples, tol) -> bool:
        window = self.integrator.window
        means = [
            np.mean(samples[len(samples) - (j + 1) * window :][:window], axis=0) for j in range(3)
        ]
        step = means[0] - means[1]
        if np.abs(step).max() > tol:
            return False
        if self.integrator.extrapolate:
            previous = means[1] - means[2]
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(previous != 0.0, step / previous, 0.0)
            tail = np.where((ratio > 0) & (ratio < 1), np.abs(step) * ratio / (1 - ratio), 0.0)
            return bool(tail.max() <= tol)
        return True
