"""Dispatch modes: how node controllers turn line flows into fitness signals.

- ``paper``: the paper's rule. Barrier for generator limits (eq. 7) and a congestion signal
  proportional to the present overflow (eq. 8). Memoryless; leaves a residual overflow.

A mode bundles a compiled ``game(p, z, params) -> (fitness, z_rate, congestion)`` with the
parameters it needs, so the integrator and the dynamics never depend on the mode.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba as nb
import numpy as np

from popdispatch.game.controllers import broadcast_signals
from popdispatch.game.fitness import FitnessParameters, generator_fitness
from popdispatch.game.problem import DispatchProblem


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
    return fitness, np.zeros_like(z), np.abs(signal).max()


@dataclass(frozen=True)
class Mode:
    """A dispatch mode (see module docstring)."""

    name: str
    game: Callable
    controller_states: Callable[[DispatchProblem], int]
    parameters: Callable[[DispatchProblem, int, FitnessParameters], tuple]


def _paper_parameters(problem: DispatchProblem, minute: int, fp: FitnessParameters) -> tuple:
    return (
        problem.b,
        problem.c,
        problem.pmin,
        problem.pmax,
        float(fp.B),
        float(fp.m),
        float(fp.C),
        problem.limit,
        problem.down,
        problem.load_flow[minute - 1],
    )


MODES = {"paper": Mode("paper", paper_game, lambda problem: 0, _paper_parameters)}


def get_mode(name: str) -> Mode:
    try:
        return MODES[name]
    except KeyError:
        raise ValueError(f"unknown mode {name!r} (known: {', '.join(MODES)})") from None
