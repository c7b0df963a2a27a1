"""What a dispatch mode is: a payoff mechanism (popgames' ``PayoffMechanism``) and its defaults.

A mode turns set points into fitness and its node controllers' state into a rate: the *payoff
map* ``(p, z) -> fitness`` and the *controller-state map* ``(p, z) -> z'``, with ``z`` of the
mode's dimension (:attr:`Mode.controller_states`). Both maps are one compiled kernel per mode,
``payoff(p, z, params, minute, work, fitness, z_rate) -> (congestion, residual)``, in the mode's
own module (:mod:`popdispatch.modes.paper`, :mod:`popdispatch.modes.exact`,
:mod:`popdispatch.modes.voltage`), which also defines the :class:`ModeTag` class that carries
it: the term (:func:`popdispatch.integrate.term.evaluate`) calls the kernel of the tag's
class, knowing no mode.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.mesh import smallest_factor_gap
from popdispatch.game.problem import DispatchProblem

if TYPE_CHECKING:
    from popdispatch.online.settings import RunSettings


def _paper_constants(problem: DispatchProblem, settings: RunSettings) -> FitnessParameters:
    return settings.fitness


def _unit_price_scale(problem: DispatchProblem) -> float:
    return 1.0


class ModeCode(IntEnum):
    """The compiled payoff map of a mode (its kernel in
    :func:`popdispatch.integrate.term.payoff`, by its :class:`ModeTag`)."""

    PAPER = 0
    EXACT = 1
    VOLTAGE = 2


class ModeTag(NamedTuple):
    """A mode as the compiled kernels take it: its :class:`ModeCode` value in ``code``. Each
    mode module subclasses it once per payoff kernel, the kernel in the class attribute
    ``kernel``: the *class* picks the kernel when numba compiles
    (:func:`popdispatch.integrate.term.payoff` reads ``kernel`` off the class, knowing no
    mode), so a run compiles its own mode's payoff only."""

    code: int


@dataclass(frozen=True)
class Mode:
    """A dispatch mode: its payoff mechanism and its defaults.

    ``code``: its payoff kernel. ``controller_states``: the dimension of ``z`` for a problem.
    ``bounded``: generator limits are kept by a capacity-constrained revision rule (the
    dynamics' ``bounded_field``) and warm starts respect the limits, instead of a barrier.
    ``integrator_options``: keyword arguments of the default
    :class:`~popdispatch.integrate.Integrator` (built by
    :meth:`popdispatch.online.RunSettings.stepping`).
    ``warm_start``: the default policy between minutes (:mod:`popdispatch.warm_start`).
    ``claims_dc_opf``: whether a run that comes to rest claims the DC-OPF optimum, so that its
    end state is checked against the DC-OPF's KKT conditions
    (:func:`popdispatch.online.kkt_violations`) and reported ``stalled`` where they fail.
    ``game_constants``: the game's EUR/MW constants for a problem and run settings (default:
    the settings' ``fitness``, the paper's constants). ``price_scale``: EUR/MW per unit of the
    integrator's ``price_atol`` (default 1).
    """

    name: str
    code: ModeCode
    controller_states: Callable[[DispatchProblem], int]
    bounded: bool
    integrator_options: dict = field(default_factory=dict)
    warm_start: str = "shares"
    claims_dc_opf: bool = False
    game_constants: Callable[[DispatchProblem, RunSettings], FitnessParameters] = _paper_constants
    price_scale: Callable[[DispatchProblem], float] = _unit_price_scale

    def held_relays(self, problem: DispatchProblem) -> np.ndarray:
        """Which generators relay always on a sparse communication graph (bool, one per
        generator; :func:`popdispatch.dynamics.pairwise.relay_flows`): in a mode that prices
        its lines (``bounded``) the generators below a limited line of a radial feeder. A line's
        price holds such a generator's output where the line binds, and mass crosses it only
        through its own trades, as fast as the price moves: relaying (while it also trades on
        its own) lets the others' mass pass it. None in paper mode and on a mesh (its
        generators are below no line). The engine relays them with adaptive steps only
        (:meth:`popdispatch.online.RunSettings.engine_held_relays`)."""
        if not self.bounded:
            return np.zeros(problem.n_generators, dtype=np.bool_)
        return np.asarray(problem.generator_line) >= 0

    def price_cap(self, problem: DispatchProblem) -> float:
        """Price (EUR/MW) beyond which congestion is deemed impossible to relieve: ten times
        the spread of marginal costs over the smallest difference two generators'
        coefficients make on a limited line (:func:`~popdispatch.game.mesh.smallest_factor_gap`;
        1 on a radial feeder, where an optimal line price never exceeds the spread). On a mesh
        a line price balances a marginal-cost gap through a difference of distribution
        factors that can be far below 1, and is larger by as much (docs/meshed.md)."""
        marginal = problem.b + 2.0 * problem.c * problem.pmax
        spread = float(marginal.max() - problem.b.min())
        gap = smallest_factor_gap(problem.factor) if problem.meshed else 1.0
        return 10.0 * spread / min(gap, 1.0) + 10.0
