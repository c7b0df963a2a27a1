"""Voltage mode: exact mode's line prices plus voltage prices at the monitored buses.

LinDistFlow (:mod:`popdispatch.ac.lindistflow`) makes the squared voltage of a monitored bus
``j`` affine in the set points, ``v_j^2 = v0_j^2 + sum_i S_ji p_i`` with ``S_ji = 2
R_shared(j, i) / Z_base`` (p.u.^2 per MW) and ``v0_j^2`` the loads-only squared voltage. Each
bound is one more row of the OPF, ``vmin^2 - v_j^2 <= 0`` and ``v_j^2 - vmax^2 <= 0``. Divided
by the bus's scale ``s_j`` (the spread of ``S_j`` over the generators, p.u.^2 per MW), a row's
excess is in MW equivalents, like a line's overflow:

    e_lo_j = (vmin^2 - v0_j^2) / s_j - sum_i sens_ji p_i,
    e_hi_j = (v0_j^2 - vmax^2) / s_j + sum_i sens_ji p_i,   sens_ji = S_ji / s_j.

The bus's controller integrates each excess into a non-negative price exactly as a line's
controller does (:func:`popdispatch.modes.exact.line_price`: integral ``z`` at
``price_rate``, proportional part ``C e``, same dimensionless constants), and broadcasts the
net price ``m_j = mu_lo_j - mu_hi_j``; generator ``i`` adds ``m_j sens_ji`` to its signal (it
knows its own path resistance to ``j``). The fitness is exact mode's (paper eqs. 5-7 without
the barrier, docs/exact-mode.md) with these terms added to the line prices; at rest it is the
stationarity condition of the LinDistFlow OPF with ``mu / s_j`` the duals of the unscaled rows
(docs/voltage.md).

Controller states: ``z = [line up (L), line down (L), bus low (V), bus high (V)]``.
"""

from __future__ import annotations

from dataclasses import replace

import numba as nb

from popdispatch.game.problem import DispatchProblem
from popdispatch.modes import exact
from popdispatch.modes.exact import (
    dual_residual,
    line_price,
    line_signals,
    marginal_costs_into,
    tree_line_signals,
)
from popdispatch.modes.mechanism import ModeCode, ModeTag

#: Voltage mode's Heun error control, relative (exact mode: 1e-4). Measured (docs/voltage.md):
#: at 1e-4 the prices and set points hover at the error control's noise, 0.02 kW on the
#: voltage scenario, above the stopping tolerance in 133 of 321 ELV minutes with a binding
#: vmax; at 3e-6 every one converges (43 iterations on average) and the scenario in 34.
RTOL = 3e-6


@nb.njit(cache=True, inline="always")
def voltage_signals(p, z, params, minute, signal, z_rate):
    """Add the voltage prices' signal per generator to ``signal`` (EUR/MW) and write the bus
    controllers' rates into ``z_rate``; returns ``(congestion, residual)`` of the voltage rows
    (largest ``|m_j|``, EUR/MW; largest distance from complementary slackness, MW).

    Rows ``j`` of ``params.voltage_sens``; their loads-only excesses are
    ``minute.load_flow[L + j]`` (low) and ``minute.load_flow[L + V + j]`` (high), their
    states ``z[2 L + j]`` and ``z[2 L + V + j]``.
    """
    sens = params.voltage_sens
    n_rows = sens.shape[0]
    n_lines = params.limit.shape[0]
    C, price_rate = params.C, params.price_rate
    load, state = n_lines, 2 * n_lines
    congestion = 0.0
    residual = 0.0
    for j in range(n_rows):
        rise = 0.0
        for i in range(p.shape[0]):
            rise += sens[j, i] * p[i]
        excess_lo = minute.load_flow[load + j] - rise
        excess_hi = minute.load_flow[load + n_rows + j] + rise
        z_lo, z_hi = z[state + j], z[state + n_rows + j]
        z_rate[state + j] = price_rate * excess_lo
        z_rate[state + n_rows + j] = price_rate * excess_hi
        residual = max(residual, dual_residual(excess_lo, z_lo))
        residual = max(residual, dual_residual(excess_hi, z_hi))
        net = line_price(z_lo, z_hi, excess_lo, excess_hi, C)  # mu_lo - mu_hi
        congestion = max(congestion, abs(net))
        if net != 0.0:
            for i in range(p.shape[0]):
                signal[i] += net * sens[j, i]
    return congestion, residual


@nb.njit(cache=True)
def payoff(p, z, params, minute, work, fitness, z_rate):
    """Voltage mode's payoff map: exact mode's line prices (:func:`line_signals`, plain law),
    the voltage prices (:func:`voltage_signals`) and the marginal costs, no barrier
    (``fitness``, EUR/MW, and ``z_rate`` overwritten); returns ``(congestion, residual)``
    (EUR/MW, MW)."""
    congestion, residual = line_signals(p, z, params, minute, work, fitness, z_rate)
    return with_voltage_prices(p, z, params, minute, fitness, z_rate, congestion, residual)


@nb.njit(cache=True)
def tree_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`payoff` with the line prices moving by the tree law (:func:`tree_line_signals`)."""
    congestion, residual = tree_line_signals(p, z, params, minute, work, fitness, z_rate)
    return with_voltage_prices(p, z, params, minute, fitness, z_rate, congestion, residual)


@nb.njit(cache=True, inline="always")
def with_voltage_prices(p, z, params, minute, fitness, z_rate, congestion, residual):
    """The voltage prices added to the line signals in ``fitness``, then the marginal costs;
    the larger congestion and residual of lines and buses."""
    v_congestion, v_residual = voltage_signals(p, z, params, minute, fitness, z_rate)
    marginal_costs_into(p, params, fitness)
    return max(congestion, v_congestion), max(residual, v_residual)


def controller_states(problem: DispatchProblem) -> int:
    """Two prices per limited line and two per monitored bus."""
    return 2 * len(problem.limit) + 2 * problem.n_voltage


#: exact mode's record with its own name, payoff kernel, dimension and a tighter error control
MODE = replace(
    exact.MODE,
    name="voltage",
    code=ModeCode.VOLTAGE,
    controller_states=controller_states,
    integrator_options={**exact.MODE.integrator_options, "rtol": RTOL},
)


class VoltageTag(ModeTag):
    """Voltage mode's payoff, plain price law (:func:`payoff`)."""

    __slots__ = ()
    kernel = staticmethod(payoff)


class VoltageTreeTag(ModeTag):
    """Voltage mode's payoff with the tree price law (:func:`tree_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(tree_payoff)
