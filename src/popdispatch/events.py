"""Generator availability events: ``BUS:off@MIN`` trips the generator at BUS at minute MIN,
``BUS:on@MIN`` brings it back. The CLI's ``--event`` and Python users share this validation."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from popdispatch.errors import FeederError, OptionError
from popdispatch.game.problem import DispatchProblem, check_online

#: One event: (generator bus as the source format names it: a number, or an OpenDSS name;
#: ``"off"`` or ``"on"``; 1-based minute).
Event = tuple[int | str, str, int]


def event_label(event: Event) -> str:
    """``BUS:state@MIN``, the form the CLI accepts."""
    bus, state, minute = event
    return f"{bus}:{state}@{minute}"


def apply_events(
    problem: DispatchProblem, events: Sequence[Event], minutes: np.ndarray | None = None
) -> DispatchProblem:
    """The problem with each event's generator outage applied.

    Raises :class:`OptionError` (option ``--event``) for a bus without a generator, a
    generator switched off twice, or one switched on that was not off. Once every outage is
    applied, raises :class:`~popdispatch.errors.InfeasibleError` if no generator is online at
    one of ``minutes`` (1-based, default every minute; the message names the first). Minutes
    whose demand exceeds the capacity left online are kept: a day runs them and their DC-OPF
    is infeasible (:func:`popdispatch.game.problem.check_capacity` is the strict check).
    """
    buses = dict(zip(problem.feeder.generators.bus.astype(int), problem.generators, strict=True))
    original = problem.feeder.original
    off_since: dict[str, int] = {}
    for event in sorted(events, key=lambda e: e[2]):
        given, state, minute = event
        text = event_label(event)
        try:
            bus = original.bus_id(given)  # a number, or a name where the network names buses
        except FeederError:
            bus = None
        if bus not in buses:
            known = ", ".join(str(b) for b in original.bus_labels(list(buses)))
            raise OptionError(
                f"no generator at bus {given} in {text} (generator buses: {known})", "--event"
            )
        name = buses[bus]
        if minute > len(problem.online):
            raise OptionError(
                f"{text}: step {minute} is outside the series' 1-{len(problem.online)}", "--event"
            )
        if state == "off":
            if name in off_since:
                raise OptionError(f"{name} is already off in {text}", "--event")
            off_since[name] = minute
        elif name not in off_since:
            raise OptionError(f"{name} is not off before {text}", "--event")
        else:
            problem = _outage(problem, name, off_since.pop(name), minute)
    for name, minute in off_since.items():
        problem = _outage(problem, name, minute, None)
    check_online(problem, minutes)
    return problem


def _outage(problem: DispatchProblem, name: str, off: int, on: int | None) -> DispatchProblem:
    """``name`` offline from step ``off`` until step ``on`` (excluded; ``None``: to the end);
    capacity is checked by the caller over the steps that run (:func:`check_online`)."""
    return problem.with_outage(name, off, on, check=False)
