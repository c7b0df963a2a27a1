"""Dispatch modes: how node controllers turn line flows into fitness signals.

- ``paper``: the paper's rule. Barrier for generator limits (eq. 7) and a congestion signal
  proportional to the present overflow (eq. 8). Memoryless; leaves a residual overflow, and its
  discontinuous barrier has rest points away from the DC-OPF (docs/paper-mode.md).
- ``exact``: capacity-constrained revision (no barrier) and a non-negative price per limited
  line and direction that integrates the overflow (dual ascent), broadcast like the paper's
  signals. Its equilibria are the KKT points of the DC-OPF (docs/exact-mode.md).

A mode bundles a compiled ``game(p, z, params) -> (fitness, z_rate, congestion, residual)``
with the parameters it needs, so the integrator and the dynamics never depend on the mode.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba as nb
import numpy as np

from popdispatch.game.controllers import broadcast_signals
from popdispatch.game.fitness import FitnessParameters, generator_fitness
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import Integrator


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
    b, c, pmin, pmax, B, m, C, limit, down, load_flow = params
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
    b, c, B, gain, C, price_rate, limit, down, load_flow = params
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


@dataclass(frozen=True)
class Mode:
    """A dispatch mode (see module docstring).

    ``bounded``: generator limits are kept by a capacity-constrained revision rule (the dynamics'
    ``bounded_rates``) and warm starts are projected onto the limits, instead of a barrier.
    """

    name: str
    game: Callable
    controller_states: Callable[[DispatchProblem], int]
    parameters: Callable[[DispatchProblem, int, FitnessParameters], tuple]
    bounded: bool
    integrator: Integrator

    def price_cap(self, problem: DispatchProblem) -> float:
        """Price (EUR/MW) beyond which congestion is deemed impossible to relieve: ten times
        the spread of marginal costs; an optimal line price never exceeds that spread."""
        marginal = problem.b + 2.0 * problem.c * problem.pmax
        return 10.0 * float(marginal.max() - problem.b.min()) + 10.0


def _paper_parameters(problem: DispatchProblem, minute: int, fp: FitnessParameters) -> tuple:
    return (
        problem.b, problem.c, problem.pmin, problem.pmax, float(fp.B), float(fp.m), float(fp.C),
        problem.limit, problem.down, problem.load_flow[minute - 1],
    )  # fmt: skip


def _exact_parameters(problem: DispatchProblem, minute: int, fp: FitnessParameters) -> tuple:
    return (
        problem.b, problem.c, float(fp.B), float(fp.gain), float(fp.C), float(fp.price_rate),
        problem.limit, problem.down, problem.load_flow[minute - 1],
    )  # fmt: skip


MODES = {
    "paper": Mode("paper", paper_game, lambda problem: 0, _paper_parameters, False, Integrator()),
    "exact": Mode(
        "exact",
        exact_game,
        lambda problem: 2 * len(problem.limit),
        _exact_parameters,
        True,
        Integrator(method="heun", tol_kw=1e-5, window=5),
    ),
}


def get_mode(name: str) -> Mode:
    try:
        return MODES[name]
    except KeyError:
        raise ValueError(f"unknown mode {name!r} (known: {', '.join(MODES)})") from None
