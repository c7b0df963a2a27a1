"""Payoff mechanisms of the dispatch modes, compiled: line flows -> signals -> fitness.

See :mod:`popdispatch.modes` for what each mode means. Every game has the signature
``(p, z, params) -> (fitness, z_rate, congestion, residual)`` with ``p`` in MW, ``z`` the
controllers' states and ``params`` the tuple of :func:`popdispatch.modes.game_parameters`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.game.controllers import broadcast_signals
from popdispatch.game.fitness import generator_fitness


@nb.njit(cache=True)
def limited_line_flows(load_flow, down, p):
    """Flows (MW) on the limited lines: loads' flow minus generators below each line."""
    flow = load_flow.copy()
    for k in range(down.shape[0]):
        for i in range(down.shape[1]):
            flow[k] -= down[k, i] * p[i]
    return flow


@nb.njit(cache=True)
def paper_game(p, z, params):
    """Paper mode: eqs. 5-8. ``z`` is unused (the paper's controllers have no memory)."""
    b, c, pmin, pmax, B, m, C, gain, price_rate, limit, down, load_flow = params
    flow = limited_line_flows(load_flow, down, p)
    signal = broadcast_signals(flow, limit, down, C)
    fitness = generator_fitness(p, b, c, pmin, pmax, B, m, signal)
    return fitness, np.zeros_like(z), np.abs(signal).max(), 0.0


@nb.njit(cache=True)
def _dual_residual(excess, price):
    """How far a line-direction is from complementary slackness, MW: any overflow, and any
    slack while its price is still positive."""
    return abs(excess) if price > 0.0 else max(excess, 0.0)


@nb.njit(cache=True)
def exact_game(p, z, params):
    """Exact mode: line prices with integral and proportional parts, no barrier.

    For limited line ``k`` the controllers keep prices ``z[k]`` (flow above ``+U``) and
    ``z[L + k]`` (flow below ``-U``), integrating the excess at ``price_rate``. The broadcast
    price is the augmented-Lagrangian multiplier ``mu = max(0, z + C * excess)``; the net price
    ``nu = mu_up - mu_down`` goes as ``+nu / 2`` to the generators below the line and ``-nu / 2``
    to those above (incentive to the receiving side, penalty to the sending side).
    """
    b, c, pmin, pmax, B, m, C, gain, price_rate, limit, down, load_flow = params
    n_lines = limit.shape[0]
    flow = limited_line_flows(load_flow, down, p)
    signal = np.zeros_like(p)
    z_rate = np.zeros_like(z)
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
        if nu != 0.0:
            congestion = max(congestion, abs(nu))
            for i in range(p.shape[0]):
                signal[i] += nu * (down[k, i] - 0.5)
    return gain * (B - (b + 2.0 * c * p) + signal), z_rate, congestion, residual


PAPER, EXACT = range(2)


@nb.njit(cache=True)
def game(code, p, z, params):
    """Static dispatch to the mode ``code``'s game (cacheable, unlike a function argument)."""
    if code == PAPER:
        return paper_game(p, z, params)
    return exact_game(p, z, params)
