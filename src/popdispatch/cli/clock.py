"""The command line's leaf: exit codes, the one-line :class:`Failure` and the command's own
clock (``command_seconds``: from the start of the process when run as the ``popdispatch``
program, read from ``/proc`` on Linux, else from :func:`popdispatch.cli.process.main`'s entry,
until the output is complete). Every command module imports these; this module imports no
command (only click and the standard library).
"""

from __future__ import annotations

import os
import time

import click

EXIT_PROBLEM, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130


class Failure(Exception):
    """A problem to report on one line with exit code 1 (after any ``--json`` output)."""


# -- the command's own clock --------------------------------------------------------------------


def process_age_seconds() -> float | None:
    """Seconds since this process started (Linux ``/proc/self/stat``), None where unknown."""
    try:
        with open("/proc/self/stat", "rb") as handle:
            stat = handle.read()
        start_ticks = int(stat[stat.rindex(b")") + 2 :].split()[19])  # field 22, starttime
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, AttributeError):
        return None
    return age if 0.0 <= age < 3600.0 else None  # anything else is not this command's start


class CommandClock:
    """``perf_counter()`` value at which the running command started (None: not running)."""

    start: float | None = None


def command_seconds() -> float:
    """Seconds since the command started (see the module docstring)."""
    if CommandClock.start is None:
        CommandClock.start = time.perf_counter()
    return time.perf_counter() - CommandClock.start


def start_clock(ctx: click.Context) -> None:
    """Start the clock of a command invoked without :func:`main` (e.g. click's test runner)."""
    if CommandClock.start is None:
        CommandClock.start = time.perf_counter()
        ctx.call_on_close(lambda: setattr(CommandClock, "start", None))


def stamp(summary: dict) -> dict:
    """Add ``command_seconds`` to a summary once, when its output is complete."""
    if summary.get("command_seconds") is None:
        summary["command_seconds"] = command_seconds()
    return summary
