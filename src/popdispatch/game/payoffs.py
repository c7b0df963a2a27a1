"""Payoff mechanisms of the dispatch modes, compiled: line flows -> signals -> fitness.

See :mod:`popdispatch.modes` for what each mode means. Every game writes into preallocated
arrays (no allocation on the hot path):
``game(code, p, z, params, work, fitness, z_rate) -> (congestion, residual)`` with ``p`` in MW,
``z`` the controllers' states, ``params`` the tuple of :func:`popdispatch.modes.game_parameters`
and ``work`` the scratch tuple of :func:`game_workspace`. ``congestion`` is the largest signal
magnitude (EUR/MW), ``residual`` how far the controllers are from done (MW).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.game.controllers import overflow_signal
from popdispatch.game.flows import broadcast, limited_line_flows


def game_workspace(n_lines: int) -> np.ndarray:
    """Scratch rows of one game evaluation: flows, parent- and child-side values, path sums."""
    return np.zeros((4, n_lines))


@nb.njit(cache=True, inline="always")
def _fitness(p, b, c, pmin, pmax, B, m, gain, signal, barrier, fitness):
    """Eqs. 5-7 (barrier if ``barrier``) plus signals, times ``gain``, into ``fitness``."""
    for i in range(p.shape[0]):
        f = B - (b[i] + 2.0 * c[i] * p[i]) + signal[i]
        if barrier:
            if p[i] < pmin[i]:
                f += m * p[i]
            elif p[i] > pmax[i]:
                f -= m * p[i]
        fitness[i] = gain * f


@nb.njit(cache=True, inline="always")
def paper_game(p, z, params, work, fitness, z_rate):
    """Paper mode: eqs. 5-8. ``z`` is unused (the paper's controllers have no memory)."""
    b, c, pmin, pmax, B, m, C, gain, price_rate, limit, gen_line, line_up, order, load_flow = params
    flow, parent_side, child_side, path = work[0], work[1], work[2], work[3]
    limited_line_flows(load_flow, p, gen_line, line_up, order, flow)
    for k in range(flow.shape[0]):
        parent_side[k] = overflow_signal(flow[k], limit[k], C)
        child_side[k] = overflow_signal(-flow[k], limit[k], C) if parent_side[k] != 0.0 else 0.0
    broadcast(parent_side, child_side, gen_line, line_up, order, path, fitness)
    congestion = 0.0
    for i in range(p.shape[0]):
        congestion = max(congestion, abs(fitness[i]))
    _fitness(p, b, c, pmin, pmax, B, m, 1.0, fitness, True, fitness)
    return congestion, 0.0


@nb.njit(cache=True, inline="always")
def _dual_residual(excess, price):
    """How far a line-direction is from complementary slackness, MW: any overflow, and any
    slack while its price is still positive."""
    return abs(excess) if price > 0.0 else max(excess, 0.0)


@nb.njit(cache=True, inline="always")
def exact_game(p, z, params, work, fitness, z_rate):
    """Exact mode: line prices with integral and proportional parts, no barrier.

    For limited line ``k`` the controllers keep prices ``z[k]`` (flow above ``+U``) and
    ``z[L + k]`` (flow below ``-U``), integrating the excess at ``price_rate``. The broadcast
    price is the augmented-Lagrangian multiplier ``mu = max(0, z + C * excess)``; the net price
    ``nu = mu_up - mu_down`` goes as ``+nu / 2`` to the generators below the line and ``-nu / 2``
    to those above (incentive to the receiving side, penalty to the sending side).
    """
    b, c, pmin, pmax, B, m, C, gain, price_rate, limit, gen_line, line_up, order, load_flow = params
    flow, parent_side, child_side, path = work[0], work[1], work[2], work[3]
    n_lines = limit.shape[0]
    limited_line_flows(load_flow, p, gen_line, line_up, order, flow)
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
    broadcast(parent_side, child_side, gen_line, line_up, order, path, fitness)
    _fitness(p, b, c, pmin, pmax, B, m, gain, fitness, False, fitness)
    return congestion, residual


PAPER, EXACT = range(2)


@nb.njit(cache=True, inline="always")
def game(code, p, z, params, work, fitness, z_rate):
    """Static dispatch to the mode ``code``'s game (cacheable, unlike a function argument)."""
    if code == PAPER:
        return paper_game(p, z, params, work, fitness, z_rate)
    return exact_game(p, z, params, work, fitness, z_rate)
