"""Dispatch modes: how node controllers turn line flows into fitness signals.

- ``paper`` (:mod:`popdispatch.modes.paper`): the paper's barrier and overflow signal.
- ``exact`` (:mod:`popdispatch.modes.exact`): capacity-constrained revision and integrating
  line prices; its equilibria are the KKT points of the DC-OPF.

Each mode is a payoff mechanism (:class:`Mode`, :mod:`popdispatch.modes.mechanism`) in its own
module: the compiled payoff kernel and the mode's record with its defaults. All modes take the
same arguments (:class:`~popdispatch.game.parameters.GameParameters`, one minute's
:class:`~popdispatch.game.parameters.MinuteInputs`), so the integrator and the dynamics never
depend on the mode.

Adding a mode: a module here with ``payoff`` and ``MODE``, a :class:`ModeCode` member, a branch
in :func:`payoff` and an entry in :data:`MODES`. The branch is the static dispatch numba needs
to cache the engine on disk (a kernel taking a function argument recompiles in every process).
"""

from __future__ import annotations

import numba as nb

from popdispatch.modes import exact, paper
from popdispatch.modes.exact import payoff as exact_payoff
from popdispatch.modes.mechanism import Mode, ModeCode
from popdispatch.modes.paper import payoff as paper_payoff

MODES = {mode.name: mode for mode in (paper.MODE, exact.MODE)}


def get_mode(name: str) -> Mode:
    try:
        return MODES[name]
    except KeyError:
        raise ValueError(f"unknown mode {name!r} (known: {', '.join(MODES)})") from None


@nb.njit(cache=True, inline="always")
def payoff(code, p, z, params, minute, work, fitness, z_rate):
    """The payoff kernel of the mode ``code`` (a :class:`ModeCode`): fitness and controller-
    state rates at set points ``p`` (MW) and states ``z``; ``(congestion, residual)``."""
    # module-level names, not ``paper.payoff``: numba inlines only calls of global functions
    if code == ModeCode.PAPER:
        return paper_payoff(p, z, params, minute, work, fitness, z_rate)
    return exact_payoff(p, z, params, minute, work, fitness, z_rate)


__all__ = ["MODES", "Mode", "ModeCode", "get_mode", "payoff"]
