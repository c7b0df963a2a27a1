"""Dispatch modes: how node controllers turn line flows into fitness signals.

- ``paper`` (:mod:`popdispatch.modes.paper`): the paper's barrier and overflow signal.
- ``exact`` (:mod:`popdispatch.modes.exact`): capacity-constrained revision and integrating
  line prices; its equilibria are the KKT points of the DC-OPF.
- ``voltage`` (:mod:`popdispatch.modes.voltage`): exact mode plus voltage prices at the
  monitored buses (LinDistFlow); its equilibria are the KKT points of the LinDistFlow OPF.

Each mode is a payoff mechanism (:class:`Mode`, :mod:`popdispatch.modes.mechanism`) in its own
module: the compiled payoff kernel ``payoff`` and the mode's record ``MODE`` with its
defaults. All modes take the same arguments
(:class:`~popdispatch.game.parameters.GameParameters`, one minute's
:class:`~popdispatch.game.parameters.MinuteInputs`), so the integrator and the dynamics never
depend on the mode.

Adding a mode: a module here with ``payoff`` and ``MODE``, a :class:`ModeCode` member, an entry
in :data:`MODES`, a :class:`~popdispatch.modes.mechanism.ModeTag` class and its kernel in
:data:`popdispatch.integrate.term._PAYOFFS`. The tag's class picks the kernel when numba
compiles: a static dispatch that numba caches on disk (a kernel taking a function argument
recompiles in every process) and that compiles a run's own mode only.
"""

from __future__ import annotations

from popdispatch.modes import exact, paper, voltage
from popdispatch.modes.mechanism import Mode, ModeCode

MODES = {mode.name: mode for mode in (paper.MODE, exact.MODE, voltage.MODE)}


def get_mode(name: str) -> Mode:
    try:
        return MODES[name]
    except KeyError:
        raise ValueError(f"unknown mode {name!r} (known: {', '.join(MODES)})") from None


__all__ = ["MODES", "Mode", "ModeCode", "get_mode"]
