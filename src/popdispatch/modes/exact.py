"""Exact mode: line prices that integrate the overflow (dual ascent), no barrier.

Capacity-constrained revision keeps the generator limits; a non-negative price per limited
line and direction integrates its overflow and is broadcast like the paper's signals. Its
equilibria are the KKT points of the DC-OPF (docs/exact-mode.md).
"""

from __future__ import annotations

import numba as nb

from popdispatch.game.fitness import fitness_into
from popdispatch.game.flows import broadcast, limited_line_flows
from popdispatch.modes.mechanism import Mode, ModeCode


@nb.njit(cache=True, inline="always")
def _dual_residual(excess, price):
    """How far a line-direction is from complementary slackness, MW: any overflow, and any
    slack while its price is still positive."""
    return abs(excess) if price > 0.0 else max(excess, 0.0)


@nb.njit(cache=True, inline="always")
def payoff(p, z, params, minute, work, fitness, z_rate):
    """Line prices with integral and proportional parts, no barrier.

    For limited line ``k`` the controllers keep prices ``z[k]`` (flow above ``+U``) and
    ``z[L + k]`` (flow below ``-U``), integrating the excess at ``price_rate`` (``z_rate``).
    The broadcast price is the augmented-Lagrangian multiplier ``mu = max(0, z + C * excess)``;
    the net price ``nu = mu_up - mu_down`` goes as ``+nu / 2`` to the generators below the line
    and ``-nu / 2`` to those above (incentive to the receiving side, penalty to the sending
    side). Returns ``(congestion, residual)``: the largest ``|nu|`` (EUR/MW) and the largest
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
        residual = max(residual, _dual_residual(excess_up, z[k]))
        residual = max(residual, _dual_residual(excess_down, z[n_lines + k]))
        nu = max(0.0, z[k] + C * excess_up) - max(0.0, z[n_lines + k] + C * excess_down)
        congestion = max(congestion, abs(nu))
        child_side[k] = 0.5 * nu
        parent_side[k] = -0.5 * nu
    broadcast(parent_side, child_side, params.generator_line, params.line_up,
              params.line_preorder, work.path, fitness)  # fmt: skip
    fitness_into(p, params.b, params.c, params.pmin, params.pmax, params.B, params.m,
                 params.gain, fitness, False, fitness)  # fmt: skip
    return congestion, residual


MODE = Mode(
    "exact",
    ModeCode.EXACT,
    lambda problem: 2 * len(problem.limit),
    bounded=True,
    integrator_options={"method": "heun", "tol_kw": 1e-5, "window": 5, "extrapolate": True},
    warm_start="setpoints",
    claims_dc_opf=True,
)
