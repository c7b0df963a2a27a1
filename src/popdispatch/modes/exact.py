"""Exact mode: line prices that integrate the overflow (dual ascent), no barrier.

Capacity-constrained revision keeps the generator limits; a non-negative price per limited
line and direction integrates its overflow and is broadcast like the paper's signals. Its
equilibria are the KKT points of the DC-OPF (docs/exact-mode.md).

Exact mode is dimensionless (issue 12): fitness is counted in units of the marginal-cost
spread ``S`` (EUR/MW) and powers in units of the reference demand ``P`` (MW) (:func:`scales`),
so its constants (:class:`ExactConstants`) are pure rates and the same feeder scaled by 100
takes the same iterations. :func:`game_constants` turns them into the engine's EUR/MW units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from popdispatch.game.fitness import FitnessParameters, fitness_into
from popdispatch.game.flows import broadcast, limited_line_flows
from popdispatch.game.problem import DispatchProblem
from popdispatch.modes.mechanism import Mode, ModeCode

#: Default dimensionless constants (:class:`ExactConstants`), measured on every case of
#: benchmarks/bench_scale.py (docs/exact-mode.md, "Every scale").
GAIN, WEIGHT, PRICE_RATE = 1000.0, 2.5, 1500.0


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
    """

    gain: float = GAIN
    C: float = WEIGHT
    price_rate: float = PRICE_RATE

    def __post_init__(self) -> None:
        for name in ("gain", "C", "price_rate"):
            value = getattr(self, name)
            if not (value > 0 and value < float("inf")):
                raise ValueError(f"exact-mode constant {name} must be finite and > 0, got {value}")


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
    (a common shift of fitness, which no pairwise comparison sees) and no barrier."""
    spread, demand = scales(problem)
    return FitnessParameters(
        B=0.0, m=0.0, C=constants.C * spread / demand, gain=constants.gain / spread,
        price_rate=constants.price_rate * spread / demand,
    )  # fmt: skip


@nb.njit(cache=True, inline="always")
def _dual_residual(excess, price):
    """How far a line-direction is from complementary slackness, MW: any overflow, and any
    slack while its price is still positive."""
    return abs(excess) if price > 0.0 else max(excess, 0.0)


@nb.njit(cache=True, inline="always")
def line_price(z_up, z_down, excess_up, excess_down, C):
    """The net price of one limited line, EUR/MW: ``nu = mu_up - mu_down`` with the
    augmented-Lagrangian multipliers ``mu = max(0, z + C * excess)`` of its two directions
    (``z``: the integral parts, EUR/MW; ``excess``: flow beyond the limit, MW; ``C``: EUR/MW
    per MW)."""
    return max(0.0, z_up + C * excess_up) - max(0.0, z_down + C * excess_down)


@nb.njit(cache=True, inline="always")
def _direction(z_up, z_down, excess_up, excess_down):
    """Which direction of a line its price currently acts in: +1 (flow above ``+U``: priced
    or overflowing), -1 (below ``-U``), 0 (neither, or both at once)."""
    up = z_up > 0.0 or excess_up > 0.0
    down = z_down > 0.0 or excess_down > 0.0
    if up and not down:
        return 1.0
    if down and not up:
        return -1.0
    return 0.0


#: Generators a region without any counts as, against the ones below its line (see _share).
EMPTY_REGION = 1e-4


@nb.njit(cache=True, inline="always")
def _share(own, below):
    """Inverse weight of a region of the active tree: generators below its line over those in
    the region itself (1 for a line without active lines below it)."""
    return (below + EMPTY_REGION) / (own + EMPTY_REGION)


@nb.njit(cache=True, inline="always")
def line_signals(p, z, params, minute, work, signal, z_rate):
    """The line prices: their signal per generator into ``signal`` (EUR/MW, overwritten) and
    the controllers' rates into ``z_rate``; returns ``(congestion, residual)``.

    For limited line ``k`` the controllers keep prices ``z[k]`` (flow above ``+U``) and
    ``z[L + k]`` (flow below ``-U``). The broadcast price is :func:`line_price`; the net price
    ``nu`` goes as ``+nu / 2`` to the generators below the line and ``-nu / 2`` to those above
    (incentive to the receiving side, penalty to the sending side). Returns the largest
    ``|nu|`` (EUR/MW) and the largest distance from complementary slackness (MW).

    Rates (``z_rate``, EUR/MW per s): a line whose price is zero and whose flow is within its
    limit integrates its excess at ``price_rate`` (and so stays at zero). The *active* lines
    (priced or overflowing) integrate their excesses preconditioned by the tree of active
    lines, ``nu' = price_rate * (g_k - g_a)``, with ``g_k = eps_k - sum eps_c`` over the
    nearest active lines ``c`` below ``k`` and ``a`` the nearest active line above ``k``
    (``eps``: flow minus the limit in the active direction, MW): dual ascent in the path sums
    of prices that the generators see (docs/exact-mode.md, "Nested limits").
    """
    flow, sign, g, above = work.flow, work.parent_side, work.child_side, work.path
    limit, C, price_rate = params.limit, params.C, params.price_rate
    line_up, preorder, generator_line = params.line_up, params.line_preorder, params.generator_line
    n_lines = limit.shape[0]
    limited_line_flows(minute.load_flow, p, generator_line, line_up, preorder, flow)
    # generators below each line (z_rate[L + k]; z_rate[k]: those in its own region)
    own, below = z_rate[:n_lines], z_rate[n_lines:]
    below[:] = 0.0
    for i in range(p.shape[0]):
        k = generator_line[i]
        if k >= 0 and minute.hi[i] > minute.lo[i]:
            below[k] += 1.0
    for r in range(n_lines - 1, -1, -1):
        k = preorder[r]
        if line_up[k] >= 0:
            below[line_up[k]] += below[k]
    # pre-order: each line's active direction, its excess there, its nearest active ancestor
    for r in range(n_lines):
        k = preorder[r]
        s = _direction(z[k], z[n_lines + k], flow[k] - limit[k], -flow[k] - limit[k])
        sign[k] = s
        g[k] = flow[k] - s * limit[k] if s != 0.0 else 0.0
        own[k] = below[k]
        up = line_up[k]
        above[k] = -1.0 if up < 0 else (float(up) if sign[up] != 0.0 else above[up])
    # g = L^-1 eps: every active line's excess (and generators) leave its nearest active
    # ancestor's own part
    for k in range(n_lines):
        a = int(above[k])
        if sign[k] != 0.0 and a >= 0:
            g[a] -= flow[k] - sign[k] * limit[k]
            own[a] -= below[k]
    congestion = 0.0
    residual = 0.0
    # post-order, so that a line reads its ancestor's values before they are overwritten
    for r in range(n_lines - 1, -1, -1):
        k = preorder[r]
        s = sign[k]
        step = 0.0
        if s != 0.0:
            # the active direction's excess, preconditioned: (M eps)_k, M = L^-T W^-1 L^-1
            # (read before z_rate[k], z_rate[L + k], which hold the counts, are written)
            a = int(above[k])
            step = g[k] * _share(own[k], below[k])
            if a >= 0:
                step -= g[a] * _share(own[a], below[a])
        excess_up = flow[k] - limit[k]
        excess_down = -flow[k] - limit[k]
        z_rate[k] = price_rate * excess_up
        z_rate[n_lines + k] = price_rate * excess_down
        if s != 0.0:
            if s > 0.0:
                z_rate[k] = price_rate * step
            else:
                z_rate[n_lines + k] = -price_rate * step
        residual = max(residual, _dual_residual(excess_up, z[k]))
        residual = max(residual, _dual_residual(excess_down, z[n_lines + k]))
        nu = line_price(z[k], z[n_lines + k], excess_up, excess_down, C)
        congestion = max(congestion, abs(nu))
        g[k] = 0.5 * nu  # the child side's value from here on
        sign[k] = -0.5 * nu  # the parent side's
    broadcast(sign, g, generator_line, line_up, preorder, above, signal)
    return congestion, residual


@nb.njit(cache=True, inline="always")
def payoff(p, z, params, minute, work, fitness, z_rate):
    """Exact mode's payoff map: the line prices (:func:`line_signals`) and the marginal
    costs, no barrier (``fitness``, EUR/MW, and ``z_rate`` overwritten); returns
    ``(congestion, residual)`` (EUR/MW, MW)."""
    congestion, residual = line_signals(p, z, params, minute, work, fitness, z_rate)
    fitness_into(p, params.b, params.c, params.pmin, params.pmax, params.B, params.m,
                 params.gain, fitness, False, fitness)  # fmt: skip
    return congestion, residual


MODE = Mode(
    "exact",
    ModeCode.EXACT,
    lambda problem: 2 * len(problem.limit),
    bounded=True,
    integrator_options={
        "method": "heun",
        "tol_kw": 1e-6,
        "tol_rel": 1e-6,
        "window": 5,
        "extrapolate": True,
        "price_atol": 2.5e-5,
    },  # fmt: skip
    warm_start="setpoints",
    claims_dc_opf=True,
    game_constants=lambda problem, settings: game_constants(problem, settings.exact),
    price_scale=lambda problem: scales(problem)[0],
)
