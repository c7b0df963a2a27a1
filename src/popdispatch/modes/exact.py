"""Exact mode: line prices that integrate the overflow (dual ascent), no barrier.

A capacity-constrained revision (by default scaled by each generator's own cost curvature)
keeps the generator limits; a non-negative price per limited line and direction integrates
its overflow and is broadcast like the paper's signals. Its equilibria are the KKT points of
the DC-OPF (docs/exact-mode.md).

Exact mode is dimensionless: fitness is counted in units of the marginal-cost spread ``S``
(EUR/MW) and powers in units of the reference demand ``P`` (MW) (:func:`scales`),
so its constants (:class:`ExactConstants`) are pure rates and the same feeder scaled by 100
takes the same iterations. :func:`game_constants` turns them into the engine's EUR/MW units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from popdispatch.game.fitness import FitnessParameters, fitness_into
from popdispatch.game.flows import (
    broadcast,
    limited_line_flows,
    mesh_broadcast,
    mesh_line_flows,
)
from popdispatch.game.mesh import lever_scale
from popdispatch.game.parameters import PriceLaw
from popdispatch.game.problem import DispatchProblem
from popdispatch.modes.mechanism import Mode, ModeCode, ModeTag

#: Default dimensionless constants (:class:`ExactConstants`), measured on every case of
#: benchmarks/bench_scale.py (docs/exact-mode.md, "Every scale").
GAIN, WEIGHT, PRICE_RATE = 1000.0, 2.5, 1500.0
#: The curvature-scaled revision's constants (dynamics/newton.py): its gain (1/s: each marginal
#: cost relaxes at this rate), its price rate (1/s) and the cap of a flat generator's revision
#: rate, measured on random fleets, the ieee-elv day and the synthetic feeders
#: (docs/exact-mode.md, "Revision rates").
NEWTON_GAIN, NEWTON_PRICE_RATE, NEWTON_RATE_CAP = 300.0, 3000.0, 10.0
#: The cap of the revision rate of a quadratic generator whose output moves no priced row, in
#: the adaptive engine (dynamics/newton.py): measured on the random
#: fleets and the ELV congestion minute (docs/exact-mode.md, "Revision").
NEWTON_FREE_RATE_CAP = 1000.0
#: Pinned lines (docs/exact-mode.md, "Pinned lines"): with adaptive steps, under the plain
#: and tree laws, a line with no generator below it inside its limits (and a nested pair of
#: lines with none between them inside) moves its prices at least at ``pinned_speed`` (the
#: marginal-cost spread ``S`` per s, :class:`ExactConstants`), by at most ``PINNED_BOOST``
#: times their plain rate; a generator within ``PINNED_MARGIN`` of its range from a limit is
#: at it.
PINNED_SPEED, PINNED_BOOST, PINNED_MARGIN = 1000.0, 1000.0, 1e-12
#: A generator within this fraction of its range from a limit (and not within
#: ``PINNED_MARGIN``) is *near* it: a line with no generator below it further inside is pinned
#: in part, its gain weighed by ``1 - sum(d_i / PINNED_FADE)`` over the near ones (``d_i``
#: each one's distance from its nearer limit as a fraction of its range), so the gain fades
#: continuously as a generator leaves its limit instead of switching off (docs/exact-mode.md,
#: "Pinned lines").
PINNED_FADE = 1e-6
#: A pinned pair's gain empties the price it lowers no faster than with this time constant
#: (s): the gain fades with that price instead of stopping where it reaches zero.
PINNED_SETTLE = 1e-3
#: A stuck line's gain closes its gap no faster than with this time constant (s), one
#: iteration of the default steps: a line none of whose trades can move its flow the way its
#: excess asks, gaining on its price at most its gap over this time, reaches the price where
#: a trade opens within about an iteration, and the gain fades with the gap (docs/exact-mode.md,
#: "Stuck lines").
STUCK_SETTLE = 1e-2
#: A limited line is idle, and the generators below it revise at their idle rates
#: (:func:`rates_in_force`), once its augmented term ``z + C e`` is below ``-C`` times this
#: fraction of its limit in both directions: no price and this much slack.
IDLE_MARGIN = 0.1
#: Exact mode's revision protocols: each generator's revision scaled by its own curvature
#: (dynamics/newton.py), or capacity-constrained Smith (dynamics/capacity.py).
REVISIONS = ("newton", "capacity")
#: Generators a region of the active tree without any counts as (see :func:`region_weight`).
EMPTY_REGION = 1e-4


@dataclass(frozen=True)
class ExactConstants:
    """Exact mode's constants, dimensionless: fitness in units of the marginal-cost spread
    ``S`` and powers in units of the reference demand ``P`` (:func:`scales`); see
    :func:`game_constants` for the EUR/MW values they give.

    Attributes
    ----------
    gain : revision rate per unit of fitness difference, 1/s.
    C : augmented-Lagrangian weight, ``S`` per unit of overflow.
    price_rate : how fast a price (units of ``S``) integrates its overflow (units of ``P``), 1/s.
    price_law : how the line prices move (:class:`~popdispatch.game.parameters.PriceLaw`, or
        its name): ``PLAIN`` (each line its own overflow), ``TREE`` (preconditioned by the
        tree of active lines; docs/exact-mode.md, "Nested limits") or ``SCALED`` (each line's
        rate and weight scaled by its share of the tradable generators, "Per-line scaling").
    revision : ``"newton"`` (each generator's revision scaled by its own curvature) or
        ``"capacity"`` (:data:`REVISIONS`).
    rate_cap, free_rate_cap : the largest revision rate of a flat generator, and of an
        unpriced quadratic one with adaptive steps (dimensionless, dynamics/newton.py).
    pinned_speed : with adaptive steps, the least speed of a pinned line's prices (no
        generator below it inside its limits), ``S`` per s (docs/exact-mode.md, "Pinned lines").
    """

    gain: float | None = None
    C: float = WEIGHT
    price_rate: float | None = None
    price_law: PriceLaw = PriceLaw.PLAIN
    revision: str = "newton"
    rate_cap: float = NEWTON_RATE_CAP
    free_rate_cap: float = NEWTON_FREE_RATE_CAP
    pinned_speed: float = PINNED_SPEED

    def __post_init__(self) -> None:
        if self.revision not in REVISIONS:
            raise ValueError(f"unknown revision {self.revision!r} (known: {', '.join(REVISIONS)})")
        newton = self.revision == "newton"
        if self.gain is None:
            object.__setattr__(self, "gain", NEWTON_GAIN if newton else GAIN)
        if self.price_rate is None:
            object.__setattr__(self, "price_rate", NEWTON_PRICE_RATE if newton else PRICE_RATE)
        for name in ("gain", "C", "price_rate", "rate_cap", "free_rate_cap", "pinned_speed"):
            value = getattr(self, name)
            if not (value > 0 and value < float("inf")):
                raise ValueError(f"exact-mode constant {name} must be finite and > 0, got {value}")
        object.__setattr__(self, "price_law", PriceLaw.parse(self.price_law))


def scales(problem: DispatchProblem) -> tuple[float, float]:
    """``(S, P)``: the spread of marginal costs over the generators' ranges, ``max(b + 2 c
    Pmax) - min(b + 2 c Pmin)`` (EUR/MW; if zero, the largest marginal cost, at least 1), and
    the reference demand, the problem's largest (MW)."""
    top = problem.b + 2.0 * problem.c * problem.pmax
    spread = float(top.max() - (problem.b + 2.0 * problem.c * problem.pmin).min())
    if not spread > 0.0:
        spread = max(float(np.abs(top).max()), 1.0)
    return spread, float(np.max(problem.demand))


def game_constants(problem: DispatchProblem, constants: ExactConstants) -> FitnessParameters:
    """The EUR/MW constants of the game for ``problem``: ``gain = gain / S`` (fitness per unit
    of spread), ``C = C S / P``, ``price_rate = price_rate S / P`` (:func:`scales`), ``B = 0``
    (a common shift of fitness, which no pairwise comparison sees) and no barrier. (The price
    law is not a constant of the kernels but a choice of kernel: the mode's compile-time
    record, :func:`popdispatch.modes.mode_tag`.)"""
    spread, demand = scales(problem)
    return FitnessParameters(
        B=0.0, m=0.0, C=constants.C * spread / demand, gain=constants.gain / spread,
        price_rate=constants.price_rate * spread / demand,
    )  # fmt: skip


def scaled_weights(problem: DispatchProblem, rows: np.ndarray, C: float) -> np.ndarray:
    """The scaled law's augmented-Lagrangian weight of every limited line, ``sqrt(s_k) C``
    (EUR/MW per MW; minutes ``rows``, 0-based, x limited lines), for the KKT check of its end states
    (:func:`popdispatch.online.kkt_violations` takes ``C`` per minute and line): ``s_k = N /
    N_k`` from the online generators with ``Pmax > Pmin`` (:func:`line_scale`)."""
    tradable = problem.online[np.asarray(rows)] & (problem.pmax > problem.pmin)[None, :]
    tradable = tradable.astype(float)
    below = tradable @ problem.down.T
    total = tradable.sum(axis=1, keepdims=True)
    scale = np.where(below > 0, total / np.where(below > 0, below, 1.0), 1.0)
    return C * np.sqrt(scale)


def price_weights(
    problem: DispatchProblem, price_law: PriceLaw, C: float, rows: np.ndarray
) -> float | np.ndarray:
    """The augmented-Lagrangian weight the controllers broadcast their prices with, EUR/MW per
    MW: ``C`` under the plain and tree laws, one per minute (``rows``, 0-based) and limited
    line under the scaled law (:func:`scaled_weights`), on a mesh ``C`` times each line's
    lever scale (:func:`popdispatch.game.mesh.lever_scale`, one per minute and line). For
    reading a run's prices back (its KKT check, the reported prices)."""
    if PriceLaw(price_law) == PriceLaw.SCALED:
        return scaled_weights(problem, rows, C)
    if problem.meshed:
        return np.tile(C * lever_scale(problem.factor), (len(np.atleast_1d(rows)), 1))
    return C


def price_rates(
    problem: DispatchProblem, price_law: PriceLaw, price_rate: float, rows: np.ndarray
) -> np.ndarray:
    """Each limited line's price rate at the minutes ``rows`` (0-based; minutes x lines), 1/s
    in the units of ``price_rate``: ``price_rate`` under the plain and tree laws, times the
    scaled law's ``s_k`` (:func:`scaled_weights` squared over ``C^2``), on a mesh times the
    line's lever scale (:func:`popdispatch.game.mesh.lever_scale`): the controllers' own
    constants, for the agents and the message runtime."""
    shape = (len(np.atleast_1d(rows)), len(problem.limit))
    if PriceLaw(price_law) == PriceLaw.SCALED:
        return price_rate * scaled_weights(problem, rows, 1.0) ** 2
    if problem.meshed:
        return np.broadcast_to(price_rate * lever_scale(problem.factor), shape).copy()
    return np.full(shape, float(price_rate))


def controller_constants(
    problem: DispatchProblem, price_law: PriceLaw, C: float, price_rate: float, minute: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each limited line's proportional weight ``C_k`` (EUR/MW per MW) and price rate
    ``alpha_k`` (1/s in the units of ``price_rate``) at ``minute`` (1-based), as the engine's
    kernels have them (:func:`price_weights`, :func:`price_rates`): what each node controller
    is configured with in the agents and the message runtime, and what bounds the price loop's
    stiffness."""
    row = np.array([minute - 1])
    rates = price_rates(problem, price_law, float(price_rate), row)[0]
    weight = np.broadcast_to(price_weights(problem, price_law, float(C), row), (1, rates.size))
    return weight[0].copy(), rates


@nb.njit(cache=True, inline="always")
def dual_residual(excess, price):
    """How far a line-direction is from complementary slackness, MW: any overflow, and any
    slack while its price is still positive."""
    return abs(excess) if price > 0.0 else max(excess, 0.0)


@nb.njit(cache=True, inline="always")
def multiplier(z, excess, C):
    """The augmented-Lagrangian multiplier of one line direction, ``mu = max(0, z + C *
    excess)``, EUR/MW (``z``: its integral part, EUR/MW; ``excess``: flow beyond the limit,
    MW; ``C``: EUR/MW per MW)."""
    return max(0.0, z + C * excess)


@nb.njit(cache=True, inline="always")
def line_price(z_up, z_down, excess_up, excess_down, C):
    """The net price of one limited line, EUR/MW: ``nu = mu_up - mu_down`` with the
    :func:`multiplier` of its two directions."""
    return multiplier(z_up, excess_up, C) - multiplier(z_down, excess_down, C)


@nb.njit(cache=True, inline="always")
def line_signals(p, z, params, minute, work, signal, z_rate):
    """The line prices under the plain law: their signal per generator into ``signal``
    (EUR/MW, overwritten) and the controllers' rates into ``z_rate``; returns ``(congestion,
    residual)``.

    For limited line ``k`` the controllers keep prices ``z[k]`` (flow above ``+U``) and
    ``z[L + k]`` (flow below ``-U``), each integrating its own excess at ``price_rate``
    (:func:`plain_rates`; :func:`tree_line_signals` for the tree law); the broadcast is
    :func:`broadcast_prices`.
    """
    limited_line_flows(minute.load_flow, p, params.generator_line, params.line_up,
                       params.line_preorder, work.flow)  # fmt: skip
    plain_rates(work.flow, params.limit, params.price_rate, z_rate)
    return broadcast_prices(z, params, work, signal)


@nb.njit(cache=True, inline="always")
def tree_line_signals(p, z, params, minute, work, signal, z_rate):
    """:func:`line_signals` with the prices moving by the tree law (:func:`tree_rates`)."""
    limited_line_flows(minute.load_flow, p, params.generator_line, params.line_up,
                       params.line_preorder, work.flow)  # fmt: skip
    tree_rates(z, params, minute, work, z_rate)
    return broadcast_prices(z, params, work, signal)


@nb.njit(cache=True, inline="always")
def broadcast_prices(z, params, work, signal):
    """Each line's broadcast price :func:`line_price` at the flows in ``work.flow``: the net
    price ``nu`` goes as ``+nu / 2`` to the generators below the line and ``-nu / 2`` to those
    above (incentive to the receiving side, penalty to the sending side), into ``signal``
    (EUR/MW). Returns the largest ``|nu|`` (EUR/MW) and the largest distance from
    complementary slackness (MW)."""
    congestion, residual = price_sides(z, params, work)
    broadcast(work.parent_side, work.child_side, params.generator_line, params.line_up,
              params.line_preorder, work.path, signal)  # fmt: skip
    return congestion, residual


@nb.njit(cache=True, inline="always")
def price_sides(z, params, work):
    """Each line's :func:`line_price` ``nu`` at the flows in ``work.flow``, as the values its
    controllers send: ``+nu / 2`` to the child side (``work.child_side``) and ``-nu / 2`` to
    the parent side (``work.parent_side``), each line's ``C`` times its ``params.line_scale``
    on a mesh. Returns the largest ``|nu|`` (EUR/MW) and the largest distance from
    complementary slackness (MW)."""
    flow, parent_side, child_side = work.flow, work.parent_side, work.child_side
    limit, scale = params.limit, params.line_scale
    n_lines = limit.shape[0]
    congestion = 0.0
    residual = 0.0
    for k in range(n_lines):
        C = params.C * scale[k] if scale.shape[0] else params.C
        excess_up = flow[k] - limit[k]
        excess_down = -flow[k] - limit[k]
        residual = max(residual, dual_residual(excess_up, z[k]))
        residual = max(residual, dual_residual(excess_down, z[n_lines + k]))
        nu = line_price(z[k], z[n_lines + k], excess_up, excess_down, C)
        congestion = max(congestion, abs(nu))
        child_side[k] = 0.5 * nu
        parent_side[k] = -0.5 * nu
    return congestion, residual


@nb.njit(cache=True, inline="always")
def mesh_line_signals(p, z, params, minute, work, signal, z_rate):
    """:func:`line_signals` on a meshed network: flows ``load_flow - D p`` and each line's
    price weighed by every generator's own distribution factor, ``signal_i = sum_k nu_k (D_ki
    - 1/2)`` (:func:`~popdispatch.game.flows.mesh_broadcast`; ``params.factor`` = ``D``),
    prices moving by the plain law with each line's rate and ``C`` times its lever scale
    (``params.line_scale``, :func:`popdispatch.game.mesh.lever_scale`)."""
    mesh_line_flows(minute.load_flow, p, params.factor, work.flow)
    plain_rates(work.flow, params.limit, params.price_rate, z_rate)
    n_lines = params.limit.shape[0]
    for k in range(n_lines):
        z_rate[k] *= params.line_scale[k]
        z_rate[n_lines + k] *= params.line_scale[k]
    congestion, residual = price_sides(z, params, work)
    mesh_broadcast(work.parent_side, work.child_side, params.factor, signal)
    return congestion, residual


@nb.njit(cache=True)
def mesh_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`payoff` on a meshed network (:func:`mesh_line_signals`)."""
    congestion, residual = mesh_line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    return congestion, residual


@nb.njit(cache=True, inline="always")
def plain_rates(flow, limit, price_rate, z_rate):
    """The plain law (dual ascent): ``z' = price_rate * excess`` per line and direction
    (EUR/MW per s; ``flow``, ``limit`` MW)."""
    n_lines = limit.shape[0]
    for k in range(n_lines):
        z_rate[k] = price_rate * (flow[k] - limit[k])
        z_rate[n_lines + k] = price_rate * (-flow[k] - limit[k])


@nb.njit(cache=True, inline="always")
def active_direction(z_up, z_down, excess_up, excess_down):
    """Which direction of a line its price acts in: +1 (flow above ``+U``: priced or
    overflowing), -1 (below ``-U``), 0 (neither, or both at once)."""
    up = z_up > 0.0 or excess_up > 0.0
    down = z_down > 0.0 or excess_down > 0.0
    if up and not down:
        return 1.0
    if down and not up:
        return -1.0
    return 0.0


@nb.njit(cache=True, inline="always")
def inside_by(p, low, high, fraction):
    """Is ``p`` strictly inside ``[low, high]``, more than ``fraction`` of the range from
    either end?"""
    margin = fraction * (high - low)
    return low + margin < p < high - margin


@nb.njit(cache=True, inline="always")
def inside_limits(p, low, high):
    """Is ``p`` strictly inside ``[low, high]``, more than :data:`PINNED_MARGIN` of the range
    from either end?"""
    return inside_by(p, low, high, PINNED_MARGIN)


@nb.njit(cache=True, inline="always")
def limit_state(p, low, high):
    """Where ``p`` is in ``[low, high]`` (MW): 0 inside, more than :data:`PINNED_FADE` of the
    range from both ends; -1 at the lower limit, +1 at the upper (not :func:`inside_limits`,
    the nearer one); -2 and +2 near them (between)."""
    if inside_by(p, low, high, PINNED_FADE):
        return 0.0
    side = -1.0 if p - low < high - p else 1.0
    return 2.0 * side if inside_limits(p, low, high) else side


@nb.njit(cache=True, inline="always")
def count_on_path(state, k, line_up, at_low, at_high, near, step):
    """Add ``step`` to the count of the limit ``state`` (:func:`limit_state`; 0 counts
    nowhere) of every limited line from ``k`` up to the source: ``at_low``, ``at_high`` or
    ``near`` (one branch per array, so that numba counts no references in the loop that
    calls it)."""
    if state == 0.0:
        return
    while k >= 0:
        if state == -1.0:
            at_low[k] += step
        elif state == 1.0:
            at_high[k] += step
        else:
            near[k] += step
        k = line_up[k]


@nb.njit(cache=True, inline="always")
def count_at_limits(p, params, minute, work):
    """Per limited line, its generators below that can trade (``hi > lo``) at their lower
    limit, at their upper limit and near either (:func:`limit_state`), in ``work.at_low``,
    ``work.at_high`` and ``work.near``, at set points ``p`` (MW). Kept from the evaluation
    before (``work.limit_state``): only a generator whose state changed walks its path up the
    tree of limited lines, so an evaluation costs one pass over the generators. Returns how
    many generators below a line are at a limit and how many near one. ``work`` must hold a
    limit state per generator (``GameWork.empty``'s ``n_generators``; not checked here, on
    the hot path)."""
    state = work.limit_state
    lo, hi, demand = minute.lo, minute.hi, minute.demand
    held, near = 0, 0
    for i in range(p.shape[0]):
        k = params.generator_line[i]
        if k < 0:  # below no limited line: never counted
            continue
        new = limit_state(p[i], lo[i] * demand, hi[i] * demand) if hi[i] > lo[i] else 0.0
        held += abs(new) == 1.0
        near += abs(new) == 2.0
        old = state[i]
        if new != old:
            state[i] = new
            count_on_path(old, k, params.line_up, work.at_low, work.at_high, work.near, -1.0)
            count_on_path(new, k, params.line_up, work.at_low, work.at_high, work.near, 1.0)
    return held, near


@nb.njit(cache=True, inline="always")
def fade_sums(p, params, minute, work):
    """Per limited line with generators near a limit below it (``work.near`` > 0), the sum of
    their distances from their nearer limits, each as a fraction of its range over
    :data:`PINNED_FADE`, into ``work.path`` (other lines' values are left as they were)."""
    lo, hi, demand, line_up = minute.lo, minute.hi, minute.demand, params.line_up
    for sweep in range(2):  # zero the paths of the near generators, then add along them
        for i in range(p.shape[0]):
            if abs(work.limit_state[i]) != 2.0:
                continue
            share = 0.0
            if sweep == 1:
                low, high = lo[i] * demand, hi[i] * demand
                share = min(p[i] - low, high - p[i]) / ((high - low) * PINNED_FADE)
            k = params.generator_line[i]
            while k >= 0:
                work.path[k] = 0.0 if sweep == 0 else work.path[k] + share
                k = line_up[k]


@nb.njit(cache=True, inline="always")
def pinned_weight(held, near, below, fade_sum):
    """How pinned a line is, 0 to 1: 0 unless every one of the ``below`` generators below it
    that can trade is ``held`` at a limit or ``near`` one (:func:`limit_state`), then ``1 -
    fade_sum`` (:func:`fade_sums`, read only with near ones), at least 0."""
    if below == 0.0 or held + near != below:
        return 0.0
    return 1.0 if near == 0.0 else max(0.0, 1.0 - fade_sum)


@nb.njit(cache=True, inline="always")
def hastened(rate, speed):
    """``rate`` (EUR/MW per s) raised to ``speed`` in magnitude, by at most
    :data:`PINNED_BOOST` times (unchanged if already faster, or zero)."""
    size = abs(rate)
    if size == 0.0 or size >= speed:
        return rate
    return rate * min(PINNED_BOOST, speed / size)


@nb.njit(cache=True, inline="always")
def pair_gain(gap, sign, lows, highs, lowered, speed):
    """What a pinned pair adds to its upper price's rate and takes from its lower one's
    (EUR/MW per s) at the rate ``gap`` of their difference: :func:`hastened` to ``speed``, at
    most ``lowered / PINNED_SETTLE`` (``lowered``: the price the gain lowers, EUR/MW), and 0
    unless that price is positive and every generator between (``lows`` at their lower
    limit, ``highs`` at their upper, none inside) stays at the limit the gain pushes it into.
    ``sign``: +1 for the up prices, whose gain raises those generators' fitness; -1 for the
    down prices, whose gain lowers it."""
    raised = gap * sign > 0.0
    held = lows + highs > 0.0 and (lows == 0.0 if raised else highs == 0.0)
    if not held or not lowered > 0.0:
        return 0.0
    cap = lowered / PINNED_SETTLE
    return max(-cap, min(cap, hastened(gap, speed) - gap))


@nb.njit(cache=True, inline="always")
def trade_ends(p, f, low, high):
    """``(as a receiver, as a sender)``: a generator's fitness ``f`` if it can rise (else
    ``-inf``) and if it can fall (else ``+inf``), at ``p`` in ``[low, high]`` (MW); neither if
    it cannot trade (``high <= low``)."""
    if not high > low:
        return -np.inf, np.inf
    state = limit_state(p, low, high)
    return (-np.inf if state == 1.0 else f), (np.inf if state == -1.0 else f)


@nb.njit(cache=True, inline="always")
def stuck_gaps(p, z, fitness, params, minute, work):
    """Per limited line, how far (EUR/MW of price) its flow is from moving the way each of its
    prices asks, into ``work.line_ends[k, 2]`` (the up price) and ``[k, 3]`` (the down price);
    returns whether any price waits (a gap above 0).

    The flow falls when a generator below the line that can rise is fitter than one elsewhere
    that can fall (a trade of the field), so its gap to falling is ``max(0, min f_out,fall -
    max f_below,rise) / gain``, and to rising the same the other way; 0 where such a trade is
    open (:func:`stuck_gap` picks the one each price asks for). A line's price moves the
    fitness of the generators below it against those elsewhere one for one, so the gap is what
    its price must still move. One pass over the generators in the order
    ``params.stuck_order`` (those below each line a run, ``params.stuck_span``) with prefix
    and suffix extremes for the generators outside each run, and one up the tree of limited
    lines: O(generators + lines)."""
    order, span = params.stuck_order, params.stuck_span
    ends, line_ends = work.order_ends, work.line_ends
    n, n_lines = p.shape[0], params.limit.shape[0]
    lo, hi, demand, line_up = minute.lo, minute.hi, minute.demand, params.line_up
    for k in range(n_lines):
        line_ends[k, 0], line_ends[k, 1] = -np.inf, np.inf
    # ends[r, 0:2]: the best that can rise and the worst that can fall before position r;
    # ends[r, 2:4]: first the generator at r's own, then (second loop) from r on
    ends[0, 0], ends[0, 1] = -np.inf, np.inf
    for r in range(n):
        i = order[r]
        rise, fall = trade_ends(p[i], fitness[i], lo[i] * demand, hi[i] * demand)
        ends[r, 2], ends[r, 3] = rise, fall
        ends[r + 1, 0], ends[r + 1, 1] = max(ends[r, 0], rise), min(ends[r, 1], fall)
        k = params.generator_line[i]
        if k >= 0:
            line_ends[k, 0] = max(line_ends[k, 0], rise)
            line_ends[k, 1] = min(line_ends[k, 1], fall)
    ends[n, 2], ends[n, 3] = -np.inf, np.inf
    for r in range(n - 1, -1, -1):
        ends[r, 2], ends[r, 3] = max(ends[r, 2], ends[r + 1, 2]), min(ends[r, 3], ends[r + 1, 3])
    for r in range(params.line_preorder.shape[0] - 1, -1, -1):  # children before parents
        k = params.line_preorder[r]
        up = line_up[k]
        if up >= 0:
            line_ends[up, 0] = max(line_ends[up, 0], line_ends[k, 0])
            line_ends[up, 1] = min(line_ends[up, 1], line_ends[k, 1])
    waiting = False
    for k in range(n_lines):
        start, stop = span[k, 0], span[k, 1]
        rise_out = max(ends[start, 0], ends[stop, 2])
        fall_out = min(ends[start, 1], ends[stop, 3])
        lowering = max(0.0, fall_out - line_ends[k, 0]) / params.gain
        raising = max(0.0, line_ends[k, 1] - rise_out) / params.gain
        up = stuck_gap(lowering, raising, 1.0, work.flow[k] - params.limit[k], z[k])
        down = stuck_gap(lowering, raising, -1.0, -work.flow[k] - params.limit[k],
                         z[n_lines + k])  # fmt: skip
        line_ends[k, 2], line_ends[k, 3] = up, down
        waiting = waiting or up > 0.0 or down > 0.0
    return waiting


@nb.njit(cache=True, inline="always")
def crawling(z, params, work, below, total, speed):
    """Could a line's price be stuck (:func:`stuck_gaps`)? Only one that moves slower than
    ``speed`` (EUR/MW per s), with an excess or a price: elsewhere the stuck gain is zero. A
    test over the lines that spares most evaluations the pass over the generators."""
    n_lines = params.limit.shape[0]
    for k in range(n_lines):
        rate = line_rate(params.price_rate, below[k], total)
        for side, sign in ((0, 1.0), (n_lines, -1.0)):
            excess = sign * work.flow[k] - params.limit[k]
            own = abs(rate * excess)
            if 0.0 < own < speed and (excess > 0.0 or z[side + k] > 0.0):
                return True
    return False


@nb.njit(cache=True, inline="always")
def stuck_gap(lowering, raising, sign, excess, price):
    """The gap (EUR/MW) of the trade a line's price of direction ``sign`` (+1 up, -1 down)
    waits for, of its line's ``lowering`` and ``raising`` gaps (:func:`stuck_gaps`): its flow
    must fall where the up price's excess is positive (the down price's negative), else rise;
    0 where that price cannot move (no excess and no price to give back)."""
    if not (excess > 0.0 or price > 0.0):
        return 0.0
    return lowering if (sign > 0.0) == (excess > 0.0) else raising


@nb.njit(cache=True, inline="always")
def hasten_pinned(p, z, params, minute, work, z_rate, fitness, scaled=False):
    """The pinned and stuck lines' and the pinned pairs' prices hastened (docs/exact-mode.md,
    "Pinned lines", "Stuck lines"), ``z_rate`` in place at prices ``z`` (EUR/MW), the flows in
    ``work.flow`` and the ``fitness`` the field reads (with the revision gain); the counts
    at the limits in ``work`` (:func:`count_at_limits`); ``params.pinned_speed`` the least
    speed (EUR/MW per s; 0: never), each gain at most :data:`PINNED_BOOST` times the rate it
    raises (:func:`hastened`).

    - A *pinned line* (generators below it that can trade, none inside its limits): its
      overflow cannot fall until its price crosses one's marginal cost, so each of its prices
      gains what raises its own plain rate ``alpha e`` to the speed. The gain has the sign of
      the line's own excess and is zero with it; the tree law's rates from the other lines'
      excesses are not hastened. It is weighed by :func:`pinned_weight`: 1 with every
      generator below at a limit, fading to 0 as one leaves it by :data:`PINNED_FADE` of its
      range, so the field stays continuous where a generator leaves its limit.
    - A *stuck line* (where ``params.stuck_order`` is given: a field that trades in pairs):
      its flow waits for a trade that the fitness order closes (:func:`stuck_gaps`), so its
      price alone moves, at its rate times an overflow that can be a few watts. Each of its
      prices that has an excess or a value gains the same as a pinned line's, but at most the
      gap over :data:`STUCK_SETTLE`: the price reaches the trade within about that time, and
      the gain fades with the gap. Where a line is pinned as well, the larger gain counts.
    - A *pinned pair*: a line with generators below it inside their limits and the nearest
      limited line above it, the generators between them able to trade, none inside, each
      at the limit the pair's gain pushes it into. The generators below the lower line answer
      the sum of the two prices, those between do not move, so the prices' difference moves
      at half the gap of the lines' rates, ``(alpha_up e_up - alpha_low e_low) / 2``, and
      nothing answers it: that rate is raised to the speed, added to the upper price and
      taken from the lower one (the sum's rate unchanged), while the price it lowers is
      positive.

    ``scaled``: the scaled law, each line's rate ``alpha s_k`` (:func:`line_rate`).

    No gain moves a rest point of the plain or scaled law: at one, a pinned or stuck line's
    excess is zero where its price is positive (a price at zero is held there by the
    projection), and of a pair's prices the one a nonzero gap lowers is zero (its line is below
    its limit); nor makes one: with both prices still ``alpha_up e_up + g = 0 = alpha_low
    e_low - g`` would need ``g = -gap``, against the gain's sign (docs/exact-mode.md, "Pinned
    pairs")."""
    speed = params.pinned_speed
    n_lines = params.limit.shape[0]
    if speed == 0.0 or n_lines == 0:
        return
    at_low, at_high, near, below = work.at_low, work.at_high, work.near, minute.below
    path, line_ends = work.path, work.line_ends
    held_any, near_any = count_at_limits(p, params, minute, work)
    total = minute.tradable if scaled else 0.0
    waiting = (params.stuck_order.shape[0] > 0 and crawling(z, params, work, below, total, speed)
               and stuck_gaps(p, z, fitness, params, minute, work))  # fmt: skip
    if held_any + near_any == 0 and not waiting:
        return
    if near_any > 0:
        fade_sums(p, params, minute, work)
    for k in range(n_lines):
        up = params.line_up[k]
        held = at_low[k] + at_high[k]
        inside = below[k] - held
        weight = pinned_weight(held, near[k], below[k], path[k])
        pinned = weight > 0.0
        # a pair: a positive price to lower, generators below inside, none between inside,
        # some between at a limit
        pair = (up >= 0 and max(z[k], z[n_lines + k], z[up], z[n_lines + up]) > 0.0
                and inside > 0.0 and at_low[up] + at_high[up] > held
                and below[up] - at_low[up] - at_high[up] == inside)  # fmt: skip
        if not (pinned or pair or waiting):
            continue
        rate = line_rate(params.price_rate, below[k], total)
        rate_up = line_rate(params.price_rate, below[up], total) if pair else 0.0
        for side, sign in ((0, 1.0), (n_lines, -1.0)):  # the up and down prices
            excess = sign * work.flow[k] - params.limit[k]
            waits = line_ends[k, 2 if sign > 0.0 else 3] if waiting else 0.0
            if pinned or waits > 0.0:
                own = rate * excess
                full = hastened(own, speed) - own
                size = max(weight * abs(full), min(abs(full), waits / STUCK_SETTLE))
                z_rate[side + k] += size if full > 0.0 else -size
            if not pair:
                continue
            gap = 0.5 * (rate_up * (sign * work.flow[up] - params.limit[up]) - rate * excess)
            gain = pair_gain(gap, sign, at_low[up] - at_low[k], at_high[up] - at_high[k],
                             z[side + k] if gap > 0.0 else z[side + up], speed)  # fmt: skip
            z_rate[side + up] += gain
            z_rate[side + k] -= gain


@nb.njit(cache=True, inline="always")
def line_activity(z_up, z_down, excess_up, excess_down, C, limit):
    """How active a limited line is, 0 (idle) to 1: its larger augmented term ``a = z + C e``
    over both directions (EUR/MW) from ``-C m`` (``m`` :data:`IDLE_MARGIN` times the
    ``limit``, MW: no price and that much slack) to 0 (priced or at its limit), linearly; 1
    for a line without a positive limit."""
    margin = C * IDLE_MARGIN * limit
    if not margin > 0.0:
        return 1.0
    a = max(z_up + C * excess_up, z_down + C * excess_down)
    return min(1.0, max(0.0, 1.0 + a / margin))


@nb.njit(cache=True, inline="always")
def rates_in_force(z, params, work):
    """The revision rates of this evaluation into ``work.rate`` (docs/exact-mode.md,
    "Revision"), at prices ``z`` (EUR/MW) and the flows in ``work.flow``; scratch
    ``work.path`` (the broadcast is done). A generator below limited lines revises at its
    priced rate ``params.revision_rate`` under an active line and at ``params.idle_rate``
    while every line above it is idle, geometrically between by the most active line above
    it (:func:`line_activity`): the cap of the priced rate is there for the stiffness of an
    active line's augmented term, which an idle line does not have. Continuous in the state;
    the rates stay positive, so the rest points are unchanged."""
    rate = work.rate
    if rate.shape[0] == 0:
        return
    n_lines = params.limit.shape[0]
    activity = work.path
    for r in range(n_lines):  # pre-order: the most active line on the path from the root
        k = params.line_preorder[r]
        a = line_activity(z[k], z[n_lines + k], work.flow[k] - params.limit[k],
                          -work.flow[k] - params.limit[k], params.C, params.limit[k])  # fmt: skip
        up = params.line_up[k]
        activity[k] = a if up < 0 else max(a, activity[up])
    for i in range(rate.shape[0]):
        k = params.generator_line[i]
        h = activity[k] if k >= 0 else 1.0
        if h >= 1.0:
            rate[i] = params.revision_rate[i]
        elif h <= 0.0:
            rate[i] = params.idle_rate[i]
        else:
            rate[i] = params.revision_rate[i] ** h * params.idle_rate[i] ** (1.0 - h)


@nb.njit(cache=True, inline="always")
def region_weight(own, below):
    """Inverse weight ``1 / w`` of a region of the active tree: generators below its line over
    those in the region itself (1 for a line without active lines below it)."""
    return (below + EMPTY_REGION) / (own + EMPTY_REGION)


@nb.njit(cache=True, inline="always")
def tree_rates(z, params, minute, work, z_rate):
    """The tree law: the rates of the active lines' prices preconditioned by the tree of
    active lines, ``nu' = price_rate * (M eps)``, ``M = L^-T W^-1 L^-1`` (docs/exact-mode.md,
    "Nested limits"), into ``z_rate`` (EUR/MW per s). Reads the flows in ``work.flow`` (MW).

    ``eps``: each active line's excess in its active direction (MW); ``L^-1 eps`` leaves
    ``g_k = eps_k - sum eps_c`` over the nearest active lines ``c`` below ``k``; ``L^-T``
    subtracts the value of the nearest active line ``a`` above: ``(M eps)_k = g_k / w_k -
    g_a / w_a``. Lines neither priced nor overflowing keep ``z' = price_rate * excess``.
    Scratch: ``work.parent_side`` (direction), ``child_side`` (``g``), ``path`` (nearest
    active ancestor) and ``z_rate`` itself (generators in each line's region; those below
    it are the minute's ``below``).
    """
    flow, sign, g, above = work.flow, work.parent_side, work.child_side, work.path
    limit, price_rate = params.limit, params.price_rate
    line_up, preorder = params.line_up, params.line_preorder
    n_lines = limit.shape[0]
    own, below = z_rate[:n_lines], minute.below
    for r in range(n_lines):  # pre-order: direction, excess, nearest active ancestor
        k = preorder[r]
        s = active_direction(z[k], z[n_lines + k], flow[k] - limit[k], -flow[k] - limit[k])
        sign[k] = s
        g[k] = flow[k] - s * limit[k] if s != 0.0 else 0.0
        own[k] = below[k]
        up = line_up[k]
        above[k] = -1.0 if up < 0 else (float(up) if sign[up] != 0.0 else above[up])
    for k in range(n_lines):  # g = L^-1 eps; own: generators in each line's own region
        a = int(above[k])
        if sign[k] != 0.0 and a >= 0:
            g[a] -= flow[k] - sign[k] * limit[k]
            own[a] -= below[k]
    # post-order: a line reads its ancestor's g, own and below before they are overwritten
    for r in range(n_lines - 1, -1, -1):
        k = preorder[r]
        s = sign[k]
        step = 0.0
        if s != 0.0:
            a = int(above[k])
            step = g[k] * region_weight(own[k], below[k])
            if a >= 0:
                step -= g[a] * region_weight(own[a], below[a])
        z_rate[k] = price_rate * (flow[k] - limit[k])
        z_rate[n_lines + k] = price_rate * (-flow[k] - limit[k])
        if s > 0.0:
            z_rate[k] = price_rate * step
        elif s < 0.0:
            z_rate[n_lines + k] = -price_rate * step


@nb.njit(cache=True, inline="always")
def line_scale(below, total):
    """The scaled law's factor of one line, ``N / N_k``: the online tradable generators of the
    fleet over those below the line (1 for a line with none below, whose price moves nothing).
    """
    return total / below if below > 0.0 else 1.0


@nb.njit(cache=True, inline="always")
def line_rate(price_rate, below, total):
    """A line's price rate (1/s): ``price_rate`` times the scaled law's :func:`line_scale` of
    its ``below`` tradable generators out of ``total`` (0: the plain and tree laws, no
    scale)."""
    return price_rate * line_scale(below, total) if total > 0.0 else price_rate


@nb.njit(cache=True, inline="always")
def scaled_line_signals(p, z, params, minute, work, signal, z_rate):
    """:func:`line_signals` with each line's price rate and augmented-Lagrangian weight
    multiplied by its :func:`line_scale` ``s_k`` and its square root (the scaled law,
    docs/exact-mode.md "Per-line scaling"): ``z' = s_k price_rate excess`` and ``nu = max(0, z+
    + sqrt(s_k) C e+) - max(0, z- + sqrt(s_k) C e-)``, ``s_k`` from the minute's tradable
    generators below each line (``minute.below``)."""
    limited_line_flows(minute.load_flow, p, params.generator_line, params.line_up,
                       params.line_preorder, work.flow)  # fmt: skip
    flow, parent_side, child_side = work.flow, work.parent_side, work.child_side
    limit, C, price_rate = params.limit, params.C, params.price_rate
    n_lines = limit.shape[0]
    below = minute.below
    total = minute.tradable
    congestion = 0.0
    residual = 0.0
    for k in range(n_lines):
        scale = line_scale(below[k], total)
        excess_up = flow[k] - limit[k]
        excess_down = -flow[k] - limit[k]
        z_rate[k] = price_rate * scale * excess_up
        z_rate[n_lines + k] = price_rate * scale * excess_down
        residual = max(residual, dual_residual(excess_up, z[k]))
        residual = max(residual, dual_residual(excess_down, z[n_lines + k]))
        nu = line_price(z[k], z[n_lines + k], excess_up, excess_down, C * np.sqrt(scale))
        congestion = max(congestion, abs(nu))
        child_side[k] = 0.5 * nu
        parent_side[k] = -0.5 * nu
    broadcast(parent_side, child_side, params.generator_line, params.line_up,
              params.line_preorder, work.path, signal)  # fmt: skip
    return congestion, residual


@nb.njit(cache=True)
def scaled_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`payoff` with the scaled price law (:func:`scaled_line_signals`) and, where the
    engine gives idle rates, the revision rates following the lines (:func:`rates_in_force`)."""
    congestion, residual = scaled_line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    rates_in_force(z, params, work)
    return congestion, residual


@nb.njit(cache=True)
def pinned_scaled_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`scaled_payoff` with the pinned lines' and pairs' prices hastened
    (:func:`hasten_pinned`, ``scaled``)."""
    congestion, residual = scaled_line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    rates_in_force(z, params, work)
    hasten_pinned(p, z, params, minute, work, z_rate, fitness, True)
    return congestion, residual


@nb.njit(cache=True)
def payoff(p, z, params, minute, work, fitness, z_rate):
    """Exact mode's payoff map: the line prices (:func:`line_signals`, plain law) and the
    marginal costs, no barrier (``fitness``, EUR/MW, and ``z_rate`` overwritten); returns
    ``(congestion, residual)`` (EUR/MW, MW)."""
    congestion, residual = line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    return congestion, residual


@nb.njit(cache=True)
def tree_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`payoff` with the tree price law (:func:`tree_line_signals`)."""
    congestion, residual = tree_line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    return congestion, residual


@nb.njit(cache=True)
def pinned_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`payoff` with the pinned lines' prices hastened (:func:`hasten_pinned`) and the
    revision rates following the lines (:func:`rates_in_force`): the engine's kernel with
    adaptive steps on a feeder with limited lines."""
    congestion, residual = line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    rates_in_force(z, params, work)
    hasten_pinned(p, z, params, minute, work, z_rate, fitness)
    return congestion, residual


@nb.njit(cache=True)
def pinned_tree_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`tree_payoff` with the pinned lines' prices hastened (:func:`hasten_pinned`) and
    the revision rates following the lines (:func:`rates_in_force`)."""
    congestion, residual = tree_line_signals(p, z, params, minute, work, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    rates_in_force(z, params, work)
    hasten_pinned(p, z, params, minute, work, z_rate, fitness)
    return congestion, residual


@nb.njit(cache=True, inline="always")
def marginal_costs_into(p, params, fitness):
    """Exact mode's fitness from the signals already in ``fitness`` (EUR/MW): paper eqs. 5-6
    without the barrier (``fitness_into`` with the barrier off)."""
    fitness_into(p, params.b, params.c, params.pmin, params.pmax, params.B, params.m,
                 params.gain, fitness, False, fitness)  # fmt: skip


MODE = Mode(
    "exact",
    ModeCode.EXACT,
    lambda problem: 2 * len(problem.limit),
    bounded=True,
    # the adaptive Heun pair's error control (docs/exact-mode.md, "Choosing the constants");
    # the stopping tolerances follow the run's accuracy (RunSettings.stepping)
    integrator_options={
        "method": "heun",
        "rtol": 1e-4,
        "tol_kw": 1e-6,
        "tol_rel": 1e-6,
        "window": 5,
        "extrapolate": True,
        "price_atol": 2.5e-5,
    },  # fmt: skip
    warm_start="merit",
    claims_dc_opf=True,
    game_constants=lambda problem, settings: game_constants(problem, settings.exact),
    price_scale=lambda problem: scales(problem)[0],
)


class ExactTag(ModeTag):
    """Exact mode's payoff, plain price law (:func:`payoff`)."""

    __slots__ = ()
    kernel = staticmethod(payoff)


class ExactTreeTag(ModeTag):
    """Exact mode's payoff with the tree price law (:func:`tree_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(tree_payoff)


class ExactScaledTag(ModeTag):
    """Exact mode's payoff with the scaled price law (:func:`scaled_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(scaled_payoff)


class ExactMeshTag(ModeTag):
    """Exact mode's payoff on a meshed network, plain price law (:func:`mesh_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(mesh_payoff)


class ExactPinnedTag(ModeTag):
    """Exact mode's payoff, plain price law, pinned lines hastened (:func:`pinned_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(pinned_payoff)


class ExactTreePinnedTag(ModeTag):
    """Exact mode's payoff, tree price law, pinned lines hastened
    (:func:`pinned_tree_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(pinned_tree_payoff)


class ExactScaledPinnedTag(ModeTag):
    """Exact mode's payoff with the scaled price law and the pinned lines and pairs hastened
    (:func:`pinned_scaled_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(pinned_scaled_payoff)
