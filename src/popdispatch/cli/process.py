"""The ``popdispatch`` command line (click): process plumbing (clock, signals, exit codes).

Commands: ``feeder``, ``opf``, ``snapshot``, ``day``, ``reproduce``, ``export``. With ``--json``
a command prints exactly one JSON object on stdout (see docs/cli.md, "JSON output"); progress and
notes go to stderr. Exit codes: 0 success, 1 a problem (bad data, infeasible dispatch, cannot
write), 2 bad usage (malformed or unknown option values, checked before any data is read),
130 interrupted. Every error is one line on stderr, without traceback (set
``POPDISPATCH_DEBUG=1`` to see one).

Infeasible minutes: ``opf``, ``snapshot`` and ``day`` run and report everything they can also
where the DC-OPF is infeasible (the line limits or the generators online cannot meet the
demand). A day runs every minute asked for and lists those in ``infeasible_minutes`` (their
DC-OPF values null, the dynamics' set points and overflow kept, comparisons over the other
minutes). The output is printed (and written to ``--out``) in full; then the command exits
with code 1 and one line on stderr naming how many minutes and the first of them. Code 1, not
0, because a script must not take such a result for a complete comparison with the DC-OPF;
the JSON on stdout is complete and parseable all the same.

Importing this module imports only click and the standard library: numpy, pandas, numba,
pandapower, scipy and matplotlib are imported by the commands that use them, so ``--help`` and
usage errors are quick and a command pays only for what it runs.

``day`` and ``snapshot`` report two times: ``wall_seconds``, the engine's own time (see
:class:`popdispatch.online.DayResult`), and ``command_seconds``, the whole command's time: from
the start of the process when run as the ``popdispatch`` program (read from ``/proc`` on Linux;
elsewhere, and when :func:`main` is called with arguments, from :func:`main`'s entry) until
the output is complete (files in ``--out`` written, before the JSON is printed). The
interpreter's exit after that is kept short (see :func:`_spare_the_exit`).
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Sequence

import click

from popdispatch.cli.clock import (
    EXIT_INTERRUPTED,
    EXIT_PROBLEM,
    EXIT_USAGE,
    CommandClock,
    Failure,
    process_age_seconds,
)
from popdispatch.errors import OptionError, PopdispatchError

# -- entry point --------------------------------------------------------------------------------


def _one_line(message: str) -> str:
    return " ".join(str(message).split())


class _Interrupt:
    """SIGINT handler that remembers it fired: compiled engine code may turn the
    KeyboardInterrupt into another exception (numba raises SystemError), which must still be
    reported as an interruption."""

    fired = False

    def __call__(self, signum, frame) -> None:
        self.fired = True
        raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0, 1 problem, 2 usage, 130 interrupted)."""
    entered = time.perf_counter()
    age = process_age_seconds() if argv is None else None
    CommandClock.start = entered - (age or 0.0)
    try:
        return _main(argv)
    finally:
        CommandClock.start = None
        if argv is None:  # run as the program: the interpreter exits next
            _spare_the_exit()


def _spare_the_exit() -> None:
    """Move every live object out of the cyclic garbage collector's reach before the
    interpreter exits: its final collections would otherwise scan all of numba's, pandas' and
    scipy's objects after the work is done. Nothing is skipped (atexit handlers
    and finalisers run as usual); only call this when the process is about to end, since frozen
    objects are never collected."""
    import gc

    gc.freeze()


def _main(argv: Sequence[str] | None) -> int:
    debug = bool(os.environ.get("POPDISPATCH_DEBUG"))
    interrupt = _Interrupt()
    signal.signal(signal.SIGINT, interrupt)
    from popdispatch.cli.commands import cli

    try:
        code = cli.main(args=argv, prog_name="popdispatch", standalone_mode=False)
    except (click.Abort, KeyboardInterrupt):
        _error("interrupted; no output written")
        return EXIT_INTERRUPTED
    except Exception as exc:
        if interrupt.fired and not debug:
            _error("interrupted; no output written")
            return EXIT_INTERRUPTED
        code, message = _problem(exc)
        if debug and code == EXIT_PROBLEM:
            raise
        _error(message)
        return code
    return code if isinstance(code, int) else 0


def _error(message: str) -> None:
    """The one line every error prints on stderr: ``popdispatch: error: <message>``."""
    click.echo(f"popdispatch: error: {_one_line(message)}", err=True)


def _problem(exc: Exception) -> tuple[int, str]:
    """``(exit code, message)`` of an exception: bad usage (exit 2) names the option; a
    problem (exit 1) says what failed; anything unforeseen says it is a bug."""
    if isinstance(exc, OptionError):
        where = f" {exc.option}" if exc.option else ""
        return EXIT_USAGE, f"invalid value for{where}: {exc}"
    if isinstance(exc, click.BadParameter) and not isinstance(exc, click.MissingParameter):
        return EXIT_USAGE, f"invalid value for {_option_of(exc)}: {exc.message}"
    if isinstance(exc, click.UsageError):
        return EXIT_USAGE, _lower_first(exc.format_message())
    if isinstance(exc, click.ClickException):
        return exc.exit_code, _lower_first(exc.format_message())
    if isinstance(exc, Failure | PopdispatchError | ValueError | OSError):
        return EXIT_PROBLEM, str(exc)
    if isinstance(exc, RuntimeError):  # a solver that gave up (Clarabel, HiGHS)
        return EXIT_PROBLEM, f"{exc} (a solver failed; check the numbers of the fleet and limits)"
    return EXIT_PROBLEM, (
        f"unexpected {type(exc).__name__}: {exc} (a bug in popdispatch: POPDISPATCH_DEBUG=1 "
        "shows the traceback)"
    )


def _option_of(exc: click.BadParameter) -> str:
    """The option a :class:`click.BadParameter` is about, as the user typed it (``--minute``)."""
    hint = exc.param_hint
    if isinstance(hint, list | tuple):
        hint = hint[0] if hint else None
    if hint is None and exc.param is not None:
        hint = " / ".join(getattr(exc.param, "opts", None) or [exc.param.name])
    return str(hint or "an option").replace("'", "").replace('"', "")


def _lower_first(text: str) -> str:
    return text[:1].lower() + text[1:]
