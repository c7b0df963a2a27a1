"""What a dispatch mode is: a payoff mechanism (popgames' ``PayoffMechanism``) and its defaults.

A mode turns set points into fitness and its node controllers' state into a rate: the *payoff
map* ``(p, z) -> fitness`` and the *controller-state map* ``(p, z) -> z'``, with ``z`` of the
mode's dimension (:attr:`Mode.controller_states`). Both maps are one compiled kernel per mode,
``payoff(p, z, params, minute, work, fitness, z_rate) -> (congestion, residual)``, in the mode's
own module (:mod:`popdispatch.modes.paper`, :mod:`popdispatch.modes.exact`,
:mod:`popdispatch.modes.voltage`), reached by the mode's :class:`ModeTag` in
:func:`popdispatch.integrate.term.evaluate`: the tag's class picks the kernel when numba
compiles, so a run compiles its own mode's payoff only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import TYPE_CHECKING, NamedTuple

from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.parameters import PriceLaw
from popdispatch.game.problem import DispatchProblem

if TYPE_CHECKING:
    from popdispatch.integrate import Integrator
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
    """A mode as the compiled kernels take it: its :class:`ModeCode` value in ``code``; the
    *class* (one per mode) picks the payoff kernel when numba compiles
    (:func:`popdispatch.integrate.term.payoff`)."""

    code: int


class PaperTag(ModeTag):
    """Paper mode's payoff (:mod:`popdispatch.modes.paper`)."""

    __slots__ = ()


class ExactTag(ModeTag):
    """Exact mode's payoff (:mod:`popdispatch.modes.exact`)."""

    __slots__ = ()


class VoltageTag(ModeTag):
    """Voltage mode's payoff (:mod:`popdispatch.modes.voltage`)."""

    __slots__ = ()


class ExactTreeTag(ModeTag):
    """Exact mode's payoff with the tree price law (:func:`popdispatch.modes.exact.tree_payoff`)."""

    __slots__ = ()


class VoltageTreeTag(ModeTag):
    """Voltage mode's payoff with the tree price law
    (:func:`popdispatch.modes.voltage.tree_payoff`)."""

    __slots__ = ()


class ExactScaledTag(ModeTag):
    """Exact mode's payoff with the scaled price law
    (:func:`popdispatch.modes.exact.scaled_payoff`)."""

    __slots__ = ()


_TAGS = {ModeCode.PAPER: PaperTag, ModeCode.EXACT: ExactTag, ModeCode.VOLTAGE: VoltageTag}
_TREE_TAGS = {ModeCode.EXACT: ExactTreeTag, ModeCode.VOLTAGE: VoltageTreeTag}
_SCALED_TAGS = {ModeCode.EXACT: ExactScaledTag}
_LAW_TAGS = {PriceLaw.TREE: _TREE_TAGS, PriceLaw.SCALED: _SCALED_TAGS}


def mode_tag(code: ModeCode, price_law: PriceLaw = PriceLaw.PLAIN) -> ModeTag:
    """The compile-time record of the mode ``code`` with exact mode's line-price law (a
    choice of kernel, so a run compiles only its own law; paper mode has no line prices).
    The scaled law exists for exact mode only: voltage mode with it raises
    :class:`~popdispatch.errors.OptionError`."""
    law = PriceLaw(price_law)
    if law == PriceLaw.SCALED and ModeCode(code) == ModeCode.VOLTAGE:
        from popdispatch.errors import OptionError

        raise OptionError("the scaled price law is for exact mode only (voltage mode: plain or "
                          "tree)", "--price-law")  # fmt: skip
    tags = _LAW_TAGS.get(law, _TAGS)
    return tags.get(ModeCode(code), _TAGS[ModeCode(code)])(int(code))


@dataclass(frozen=True)
class Mode:
    """A dispatch mode: its payoff mechanism and its defaults.

    ``code``: its payoff kernel. ``controller_states``: the dimension of ``z`` for a problem.
    ``bounded``: generator limits are kept by a capacity-constrained revision rule (the
    dynamics' ``bounded_field``) and warm starts respect the limits, instead of a barrier.
    ``integrator``: keyword arguments of the default :class:`~popdispatch.integrate.Integrator`.
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

    @property
    def integrator(self) -> Integrator:
        """The mode's default integrator."""
        from popdispatch.integrate import Integrator

        return Integrator(**self.integrator_options)

    def price_cap(self, problem: DispatchProblem) -> float:
        """Price (EUR/MW) beyond which congestion is deemed impossible to relieve: ten times
        the spread of marginal costs; an optimal line price never exceeds that spread."""
        marginal = problem.b + 2.0 * problem.c * problem.pmax
        return 10.0 * float(marginal.max() - problem.b.min()) + 10.0
