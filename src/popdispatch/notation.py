"""The text forms of a run's limits, events and minute ranges (``A:B=KW``, ``BUS:off@MIN``,
``START-END``) as click parameter types, shared by the command line and the sweep specs: each
form is checked when it is parsed (a usage error naming the value)."""

from __future__ import annotations

import re

import click

from popdispatch.constants import MINUTES_PER_DAY

Limit = tuple[int | str, int | str, float]


def bus_token(text: str) -> int | str:
    """A bus as an option gives it: its number, or its name (OpenDSS: ``sourcebus``)."""
    return int(text) if text.isdigit() else text

#: The largest line limit ``--limit`` takes, kW (10 GW, as a fleet's powers: ``runs.
#: FLEET_RANGES``, cases/sources.py); an unlimited line is one without a ``--limit``.
MAX_LIMIT_KW = 1e7


class LimitType(click.ParamType):
    """``A:B=KW``: every line on the path between original buses A and B (numbers, or names
    where the network names its buses) limited to KW kW."""

    name = "A:B=KW"
    pattern = re.compile(r"^\s*([^\s:=]+)\s*:\s*([^\s:=]+)\s*=\s*([^\s]+)\s*$")

    def convert(self, value, param, ctx) -> Limit:
        if isinstance(value, tuple):
            return value
        match = self.pattern.match(str(value))
        if match is None:
            self.fail(f"{value!r} is not of the form A:B=KW (e.g. 505:666=28)", param, ctx)
        a, b, kw = bus_token(match[1]), bus_token(match[2]), number_or_none(match[3])
        if kw is None or kw < 0:
            self.fail(f"{value!r}: limit {match[3]!r} is not a finite number >= 0 kW", param, ctx)
        if kw > MAX_LIMIT_KW:
            self.fail(f"{value!r}: limit {kw:g} kW is above {MAX_LIMIT_KW:g} kW (10 GW); leave "
                      "a line unlimited by giving no --limit for it", param, ctx)  # fmt: skip
        if str(a).lower() == str(b).lower():
            self.fail(f"{value!r}: buses A and B are the same; no line between them", param, ctx)
        return a, b, kw


def number_or_none(text: str) -> float | None:
    """``text`` as a finite float, else ``None``."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if value == value and abs(value) != float("inf") else None


class EventType(click.ParamType):
    """``BUS:off@MIN`` or ``BUS:on@MIN``: the generator at BUS trips or returns at minute MIN."""

    name = "BUS:off|on@MIN"
    pattern = re.compile(r"^\s*([^\s:@]+)\s*:\s*(off|on)\s*@\s*(\d+)\s*$", re.IGNORECASE)

    def convert(self, value, param, ctx) -> tuple[int, str, int]:
        if isinstance(value, tuple):
            return value
        match = self.pattern.match(str(value))
        if match is None:
            self.fail(f"{value!r} is not of the form BUS:off@MIN or BUS:on@MIN", param, ctx)
        minute = int(match[3])
        if minute < 1:
            self.fail(f"{value!r}: minute {minute} is not a 1-based step", param, ctx)
        return bus_token(match[1]), match[2].lower(), minute


class MinutesType(click.ParamType):
    """``START-END``: a range of 1-based minutes, both included (``upper``: the last allowed;
    ``None``: any, checked against the series once it is read)."""

    name = "START-END"

    def __init__(self, upper: int | None = MINUTES_PER_DAY) -> None:
        self.upper = upper

    def convert(self, value, param, ctx) -> tuple[int, int]:
        if isinstance(value, tuple):
            return value
        match = re.fullmatch(r"\s*(\d+)\s*-\s*(\d+)\s*", str(value))
        if match is None:
            self.fail(f"{value!r} is not of the form START-END (e.g. 540-600)", param, ctx)
        start, end = int(match[1]), int(match[2])
        if self.upper is None and not 1 <= start <= end:
            self.fail(f"{value!r}: need 1 <= START <= END", param, ctx)
        if self.upper is not None and not 1 <= start <= end <= self.upper:
            self.fail(f"{value!r}: need 1 <= START <= END <= {self.upper}", param, ctx)
        return start, end


__all__ = [
    "MAX_LIMIT_KW", "EventType", "Limit", "LimitType", "MinutesType", "bus_token",
    "number_or_none",
]  # fmt: skip
