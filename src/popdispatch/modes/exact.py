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
def dual_residual(excess, price):
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
def line_signals(p, z, params, minute, work, signal, z_rate):
    """The line prices: their signal per generator into ``signal`` (EUR/MW, overwritten) and
    the controllers' rates into ``z_rate``; returns ``(congestion, residual)``.

    For limited line ``k`` the controllers keep prices ``z[k]`` (flow above ``+U``) and
    ``z[L + k]`` (flow below ``-U``), integrating the excess at ``price_rate`` (``z_rate``).
    The broadcast price is :func:`line_price`; the net price ``nu`` goes as ``+nu / 2`` to the
    generators below the line and ``-nu / 2`` to those above (incentive to the receiving side,
    penalty to the sending side). Returns the largest ``|nu|`` (EUR/MW) and the largest
    distance from complementary slackness (MW).
    """
    flow, parent_side, child_side = work.flow, work.parent_side, work.child_side
    limit, C, price_rate = params.limit, params.C, params.price_rate
    n_lines = limit.shape[0]
    limited_line_flows(minute.load_flow, p, params.generator_line, params.line_up,
                       params.line_preorder, flow)  # fmt: skip
    congestion = 0.0
    residual = 0.0
    for k in range(n_lines):
        excess_up = flow[k] - limit[k]
        excess_down = -flow[k] - limit[k]
        z_rate[k] = price_rate * excess_up
        z_rate[n_lines + k] = price_rate * excess_down
        residual = max(residual, dual_residual(excess_up, z[k]))
        residual = max(residual, dual_residual(excess_down, z[n_lines + k]))
        nu = line_price(z[k], z[n_lines + k], excess_up, excess_down, C)
        congestion = max(congestion, abs(nu))
        child_side[k] = 0.5 * nu
        parent_side[k] = -0.5 * nu
    broadcast(parent_side, child_side, params.generator_line, params.line_up,
              params.line_preorder, work.path, signal)  # fmt: skip
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
    # rtol 1e-5 (Integrator's 1e-4 otherwise): measured after issue 13's warm start, the
    # congestion minute 566 takes 19 iterations instead of 71 and the congested ELV day at most
    # 48 per minute instead of 104, for 0-20 % more engine time on the day (docs/exact-mode.md)
    integrator_options={
        "method": "heun",
        "rtol": 1e-5,
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
