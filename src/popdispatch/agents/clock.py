"""The agents' clock, the same for every algorithm: rounds of phases, each phase whole ticks.

An algorithm declares its round as an :class:`~enum.IntEnum` of phases (the population
dynamics': :class:`popdispatch.agents.schedule.Phase`); a round lasts one tick per phase, or
``phase_ticks`` ticks per phase when rounds are paced to a slow network. Agents act on whole
ticks; a message takes half a tick (plus any simulated delay), so what is sent at one tick is
in the receiver's inbox at the next.
"""

from __future__ import annotations

#: Transit time of every message, ticks: delivered before the receiver's next tick.
HOP_TICKS = 0.5


def tick_of(time_s: float, ticks_per_round: int, phase_ticks: int = 1) -> tuple[int, int]:
    """``(round, phase)`` of the clock time ``time_s`` (ticks) in rounds of
    ``ticks_per_round`` phases, each lasting ``phase_ticks`` ticks."""
    tick = int(round(time_s)) // phase_ticks
    return tick // ticks_per_round, tick % ticks_per_round
