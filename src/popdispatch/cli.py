"""The ``popdispatch`` command line (click).

Commands: ``feeder``, ``opf``, ``snapshot``, ``day``, ``reproduce``, ``export``. With ``--json``
a command prints exactly one JSON object on stdout (see README, "JSON output"); progress and
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

import importlib
import os
import re
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import click

from popdispatch.errors import OptionError, PopdispatchError
from popdispatch.report.output import check_writable, json_text, staged_folder
from popdispatch.report.progress import Progress
from popdispatch.report.text import day_text, feeder_text, opf_text, snapshot_text

Limit = tuple[int, int, float]
EXIT_PROBLEM, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130
#: Minutes in a day; equals :data:`popdispatch.feeder.profiles.MINUTES_PER_DAY` (a test checks),
#: not imported from there because that imports pandas.
MINUTES_PER_DAY = 1440


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


class _Clock:
    """``perf_counter()`` value at which the running command started (None: not running)."""

    start: float | None = None


def command_seconds() -> float:
    """Seconds since the command started (see the module docstring)."""
    if _Clock.start is None:
        _Clock.start = time.perf_counter()
    return time.perf_counter() - _Clock.start


def stamp(summary: dict) -> dict:
    """Add ``command_seconds`` to a summary once, when its output is complete."""
    if summary.get("command_seconds") is None:
        summary["command_seconds"] = command_seconds()
    return summary


# -- option types -------------------------------------------------------------------------------


class LimitType(click.ParamType):
    """``A:B=KW``: every line on the path between original buses A and B limited to KW kW."""

    name = "A:B=KW"
    pattern = re.compile(r"^\s*(\d+)\s*:\s*(\d+)\s*=\s*([^\s]+)\s*$")

    def convert(self, value, param, ctx) -> Limit:
        if isinstance(value, tuple):
            return value
        match = self.pattern.match(str(value))
        if match is None:
            self.fail(f"{value!r} is not of the form A:B=KW (e.g. 505:666=28)", param, ctx)
        a, b, kw = int(match[1]), int(match[2]), _float(match[3])
        if kw is None or kw < 0:
            self.fail(f"{value!r}: limit {match[3]!r} is not a finite number >= 0 kW", param, ctx)
        if a == b:
            self.fail(f"{value!r}: buses A and B are the same; no line between them", param, ctx)
        return a, b, kw


def _float(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if value == value and abs(value) != float("inf") else None


class EventType(click.ParamType):
    """``BUS:off@MIN`` or ``BUS:on@MIN``: the generator at BUS trips or returns at minute MIN."""

    name = "BUS:off|on@MIN"
    pattern = re.compile(r"^\s*(\d+)\s*:\s*(off|on)\s*@\s*(\d+)\s*$", re.IGNORECASE)

    def convert(self, value, param, ctx) -> tuple[int, str, int]:
        if isinstance(value, tuple):
            return value
        match = self.pattern.match(str(value))
        if match is None:
            self.fail(f"{value!r} is not of the form BUS:off@MIN or BUS:on@MIN", param, ctx)
        minute = int(match[3])
        if not 1 <= minute <= MINUTES_PER_DAY:
            self.fail(f"{value!r}: minute {minute} is outside 1..{MINUTES_PER_DAY}", param, ctx)
        return int(match[1]), match[2].lower(), minute


class X0Type(click.ParamType):
    """``uniform``, ``capacity`` or ``NAME=SHARE,...`` (names ``G114`` or buses ``114``).

    Only the form is checked here; the names are checked against the problem's own fleet once
    it is built (:func:`check_x0`), still a usage error.
    """

    name = "uniform|capacity|G=SHARE,..."

    def convert(self, value, param, ctx) -> str | dict[str, float]:
        if isinstance(value, dict) or value in ("uniform", "capacity"):
            return value
        shares: dict[str, float] = {}
        for item in str(value).split(","):
            key, sep, share = item.partition("=")
            key, number = key.strip(), _float(share)
            name = f"G{key}" if key.isdigit() else key
            if not sep or not key or number is None or number < 0:
                self.fail(
                    f"{item!r} is not NAME=SHARE with a share >= 0 (in {value!r})", param, ctx
                )
            shares[name] = number
        if sum(shares.values()) <= 0:
            self.fail(f"{value!r}: the shares sum to zero", param, ctx)
        return shares


class MinutesType(click.ParamType):
    """``START-END``: a range of 1-based minutes, both included."""

    name = "START-END"

    def convert(self, value, param, ctx) -> tuple[int, int]:
        if isinstance(value, tuple):
            return value
        match = re.fullmatch(r"\s*(\d+)\s*-\s*(\d+)\s*", str(value))
        if match is None:
            self.fail(f"{value!r} is not of the form START-END (e.g. 540-600)", param, ctx)
        start, end = int(match[1]), int(match[2])
        if not 1 <= start <= end <= MINUTES_PER_DAY:
            self.fail(f"{value!r}: need 1 <= START <= END <= {MINUTES_PER_DAY}", param, ctx)
        return start, end


# -- shared options -----------------------------------------------------------------------------

FOLDER = click.Path(exists=True, file_okay=False, dir_okay=True, readable=True, path_type=Path)


class EngineChoice(click.Choice):
    """A choice among names the engine defines (``"module:ATTRIBUTE"``), looked up only when
    click needs them (parsing, help): importing the CLI must not import the engine (numba)."""

    def __init__(self, source: str, case_sensitive: bool = True) -> None:
        self.source = source
        self.case_sensitive = case_sensitive

    @property
    def choices(self) -> tuple[str, ...]:
        module, _, attribute = self.source.partition(":")
        return tuple(getattr(importlib.import_module(module), attribute))


DYNAMICS_CHOICE = EngineChoice("popdispatch.dynamics:DYNAMICS")
MODE_CHOICE = EngineChoice("popdispatch.modes:MODES")
GRAPH_CHOICE = EngineChoice("popdispatch.dynamics.graph:GRAPHS")


option = click.option


json_option = option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
quiet_option = option("-q", "--quiet", is_flag=True, help="No progress bars or notes on stderr.")
minute_option = option(
    "--minute",
    type=click.IntRange(1, MINUTES_PER_DAY),
    required=True,
    help="1-based minute of the day (566 = the peak).",
)
limit_option = option(
    "--limit",
    "limits",
    type=LimitType(),
    multiple=True,
    help="Limit every line on the path between original buses A and B to KW kilowatts "
    "(repeatable), e.g. 505:666=28.",
)
profiles_option = option(
    "--profiles",
    type=FOLDER,
    help="Folder with the official load profiles (else $POPDISPATCH_PROFILES, else the shipped "
    "synthetic default; minute 566 alone uses the official loads shipped by pandapower).",
)
out_option = option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Also write time series (CSV, units in column names), summary.json and a figure here.",
)


def run_options(func):
    """``--dynamics``, ``--mode``, ``--x0`` and ``--graph``."""
    decorators = [
        option(
            "--dynamics",
            type=DYNAMICS_CHOICE,
            default="smith",
            show_default=True,
            help="Population dynamics (paper eqs. 9-14).",
        ),
        option(
            "--mode",
            type=MODE_CHOICE,
            default="paper",
            show_default=True,
            help="How node controllers turn flows into fitness signals.",
        ),
        option(
            "--x0",
            type=X0Type(),
            default="uniform",
            show_default=True,
            help="Initial shares: uniform, capacity or e.g. G114=0,G1=1,G578=1 (generators "
            "not named start at zero; a note on stderr names them).",
        ),
        option(
            "--graph",
            type=GRAPH_CHOICE,
            default="complete",
            show_default=True,
            help="Communication graph (local-replicator and distributed-smith only).",
        ),
    ]
    for decorate in reversed(decorators):
        func = decorate(func)
    return func


def settings_from(dynamics: str, mode: str, x0, graph: str, warm_start: str | None = None):
    from popdispatch.online import RunSettings

    return RunSettings(dynamics=dynamics, mode=mode, graph=graph, x0=x0, warm_start=warm_start)


# -- loading inputs -----------------------------------------------------------------------------


def check_limits(limits: Sequence[Limit], feeder=None) -> None:
    """Usage error (exit 2) for a limit naming a bus the feeder (default ieee-elv) lacks."""
    if feeder is None:
        from popdispatch.feeder.cases import ieee_elv

        feeder = ieee_elv()
    buses = feeder.buses.index
    for a, b, kw in limits:
        for bus in (a, b):
            if bus not in buses:
                raise click.BadParameter(
                    f"unknown bus {bus} in {a}:{b}={kw:g} (feeder {feeder.name} has buses "
                    f"{buses.min()}..{buses.max()})",
                    param_hint="'--limit'",
                )


def fleet_names() -> list[str]:
    """Names of the generators of the feeders the CLI loads (the paper's fleet, Table I, on
    the built-in case and on a feeder read with ``--opendss``)."""
    from popdispatch.feeder.generators import paper_fleet

    return list(paper_fleet().index)


def check_x0(x0, names: Sequence[str], progress: Progress) -> None:
    """Usage error (exit 2) for ``--x0`` shares naming a generator not in ``names``; a note
    naming the generators ``--x0`` leaves out (they start at zero share)."""
    if not isinstance(x0, dict):
        return
    unknown = [name for name in x0 if name not in names]
    if unknown:
        raise OptionError(
            f"unknown generator {unknown[0]!r} in {x0_text(x0)} (known: {', '.join(names)})",
            "--x0",
        )
    zeroed = [name for name in names if not x0.get(name)]
    if zeroed:
        progress.note(
            f"--x0 gives no share to {', '.join(zeroed)}: they start at 0 kW (imitative "
            "dynamics such as replicator then keep them there)"
        )


def x0_text(x0: dict[str, float]) -> str:
    return ",".join(f"{name}={share:g}" for name, share in x0.items())


def announce_compile(progress: Progress) -> None:
    """Say on stderr (unless quiet) that the engine's kernels compile now, when they must."""
    from popdispatch.compile_notice import COMPILE_NOTICE, kernels_cached

    if kernels_cached() is False:
        progress.note(COMPILE_NOTICE)


def load_profiles(folder: Path | None, minute: int | None, progress: Progress):
    """Profiles for a run: ``--profiles``, else minute 566's official loads, else the default."""
    from popdispatch.readers import PROFILES_ENV, read_profiles, resolve_profiles
    from popdispatch.scenarios import PEAK_MINUTE, peak_profiles

    if folder is not None:
        with progress.step("reading load profiles"):
            return read_profiles(folder)
    if minute == PEAK_MINUTE:
        return peak_profiles()
    profiles = resolve_profiles(None)
    if not os.environ.get(PROFILES_ENV, "").strip():
        progress.note(f"no --profiles given: using the offline default, {profiles.source}")
    return profiles


def load_feeder(opendss: Path | None):
    """The built-in ieee-elv feeder, or the one in the OpenDSS files of folder ``opendss``."""
    if opendss is not None:
        from popdispatch.readers import read_opendss_feeder

        return read_opendss_feeder(opendss)
    from popdispatch.feeder.cases import ieee_elv

    return ieee_elv()


def build(profiles, limits: Sequence[Limit], progress: Progress, opendss: Path | None = None):
    """The dispatch problem with path limits (seconds if the feeder is not cached).

    Nothing is checked about minutes here: the commands check only the minutes they run.
    """
    from popdispatch.scenarios import elv_problem

    what = f"the feeder in {opendss}" if opendss else "the ieee-elv feeder"
    with progress.step(f"loading {what}"):
        feeder = load_feeder(opendss)
        check_limits(limits, feeder)
        return elv_problem(profiles, limits, feeder, check=False)


def check_out(out: Path | None) -> None:
    """Usage error (exit 2) before any work if ``--out`` cannot be created where it is asked."""
    if out is not None and not out.absolute().parent.is_dir():
        raise click.BadParameter(
            f"cannot write {out}: folder {out.absolute().parent} does not exist",
            param_hint="'--out'",
        )
    if out is not None:
        check_writable(out)  # read-only or forbidden: one line, exit 1, before any work


def emit(summary: dict, as_json: bool, text: str) -> None:
    """Print the summary as JSON or the human-readable text on stdout."""
    click.echo(json_text(summary) if as_json else text, nl=not as_json)


# -- commands -----------------------------------------------------------------------------------


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="popdispatch")
@click.pass_context
def cli(ctx: click.Context) -> None:
    """Online, distributed, network-constrained dispatch of distributed generators
    with population dynamics, compared with an exact DC-OPF (IEEE European LV feeder)."""
    if _Clock.start is None:  # invoked without main() (e.g. click's test runner)
        _Clock.start = time.perf_counter()
        ctx.call_on_close(lambda: setattr(_Clock, "start", None))


@cli.command(short_help="The feeder: buses, key nodes, lines, loads, generators.")
@click.option("--case", type=click.Choice(["ieee-elv"]), help="Built-in case (default).")
@click.option("--opendss", type=FOLDER, help="Read the feeder from its OpenDSS files instead.")
@json_option
@quiet_option
def feeder(case: str | None, opendss: Path | None, as_json: bool, quiet: bool) -> None:
    """What the feeder is: buses, key nodes, lines, loads, generators, capacity."""
    from popdispatch.feeder import load_case, reduce_feeder
    from popdispatch.readers import read_opendss_feeder
    from popdispatch.report.summaries import feeder_summary

    if case and opendss:
        raise click.UsageError("give either --case or --opendss, not both")
    with Progress(quiet).step("loading the feeder"):
        net = read_opendss_feeder(opendss) if opendss else load_case(case or "ieee-elv")
        summary = feeder_summary(net, reduce_feeder(net))
    emit(summary, as_json, feeder_text(summary))


opendss_option = option(
    "--opendss",
    type=FOLDER,
    help="Read the feeder from its OpenDSS files in this folder instead of the built-in "
    "ieee-elv case (the paper's six generators on the same buses).",
)


@cli.command(short_help="The exact DC-OPF of one minute (paper eq. 1).")
@minute_option
@limit_option
@profiles_option
@opendss_option
@json_option
@quiet_option
def opf(minute: int, limits, profiles: Path | None, opendss, as_json: bool, quiet: bool) -> int:
    """The exact DC-OPF of one minute (paper eq. 1): the cheapest dispatch meeting the
    demand within the generator limits and the line limits. Exit code 1 (after the output)
    when no such dispatch exists."""
    from popdispatch.opf import solve_opf
    from popdispatch.report.summaries import opf_summary

    progress = Progress(quiet)
    problem = build(load_profiles(profiles, minute, progress), limits, progress, opendss)
    summary = opf_summary(problem, solve_opf(problem, minute), limits)
    emit(summary, as_json, opf_text(summary))
    if summary["status"] != "optimal":
        raise Failure(infeasible_minute_message(summary))
    return 0


def infeasible_minute_message(summary: dict) -> str:
    """One line: the DC-OPF of a minute is infeasible, with its demand and online capacity."""
    return (
        f"the DC-OPF of minute {summary['minute']} is infeasible: no dispatch meets the demand "
        f"{summary['demand_kw']:.3f} kW within the generator limits (online capacity "
        f"{summary['capacity_kw']:.3f} kW) and the given line limits"
    )


@cli.command(short_help="One minute of dynamics against the DC-OPF.")
@minute_option
@limit_option
@run_options
@profiles_option
@opendss_option
@out_option
@json_option
@quiet_option
def snapshot(
    minute, limits, dynamics, mode, x0, graph, profiles, opendss, out, as_json, quiet
) -> int:
    """One minute of dynamics: trajectory, convergence, comparison with the DC-OPF.

    A minute whose DC-OPF is infeasible is still run and reported (set points, overflow,
    set points outside their limits flagged; DC-OPF values null), then exit code 1.
    """
    from popdispatch.game.problem import check_online
    from popdispatch.report.summaries import snapshot_summary, trajectory_table
    from popdispatch.scenarios import snapshot_vs_opf

    progress = Progress(quiet)
    check_out(out)
    settings = settings_from(dynamics, mode, x0, graph)
    check_x0(x0, fleet_names(), progress)
    announce_compile(progress)
    problem = build(load_profiles(profiles, minute, progress), limits, progress, opendss)
    check_online(problem, [minute])
    with progress.step(f"minute {minute}: {dynamics} dynamics and DC-OPF"):
        result = snapshot_vs_opf(problem, minute, settings)
    summary = snapshot_summary(problem, result, limits)
    if out is not None:
        write_snapshot(out, summary, trajectory_table(result), result, progress)
    emit(stamp(summary), as_json, snapshot_text(summary))
    if summary["status"] == "infeasible":
        raise Failure(infeasible_minute_message(summary))
    return 0


def write_snapshot(out: Path, summary: dict, table, result, progress: Progress) -> None:
    from popdispatch.report import figures

    with progress.step(f"writing {out}"), staged_folder(out) as folder:
        folder.write_csv("trajectory.csv", table)
        figures.save_figure(figures.congestion_figure(result), folder.file("setpoints"))
        folder.write_json("summary.json", stamp(summary))


@cli.command(short_help="The online day, minute by minute, against the DC-OPF.")
@limit_option
@run_options
@option(
    "--event",
    "events",
    type=EventType(),
    multiple=True,
    help="Generator availability: BUS:off@MIN trips the generator at BUS at minute MIN, "
    "BUS:on@MIN brings it back (repeatable).",
)
@option("--minutes", type=MinutesType(), help="Simulate only minutes START-END (default 1-1440).")
@option(
    "--warm-start",
    type=EngineChoice("popdispatch.warm_start:WARM_STARTS"),
    help="How a minute starts from the last: shares (the paper's rule, p = x * new demand; "
    "paper mode's default) or setpoints (set points kept, the demand step taken by the "
    "generators inside their limits; exact mode's default).",
)
@profiles_option
@opendss_option
@out_option
@json_option
@quiet_option
def day(
    limits, dynamics, mode, x0, graph, events, minutes, warm_start, profiles, opendss, out,
    as_json, quiet,
) -> int:  # fmt: skip
    """The online day: every minute continues from the last (warm start), against the DC-OPF.

    Every minute asked for is run, also where the DC-OPF is infeasible (the line limits or
    the generators online cannot meet the demand): those minutes are listed in
    infeasible_minutes, their DC-OPF values are null, the dynamics' set points and overflow
    are still reported, and the comparisons (errors, energy, cost) use the other minutes
    only. Such a day is printed and written in full and then exits with code 1, naming the
    infeasible minutes on stderr. Minutes with no generator online at all are an error
    (exit 1, nothing run).

    Times: wall_seconds is the engine's own (no start-up, imports, data loading or DC-OPF),
    command_seconds the whole command's, from the process start.
    """
    import numpy as np

    from popdispatch.events import apply_events, event_label
    from popdispatch.report.reproduce import run_day_with_opf
    from popdispatch.report.summaries import day_summary, day_table

    progress = Progress(quiet)
    check_out(out)
    settings = settings_from(dynamics, mode, x0, graph, warm_start)
    check_x0(x0, fleet_names(), progress)
    announce_compile(progress)
    span = np.arange(minutes[0], minutes[1] + 1) if minutes else None
    problem = build(load_profiles(profiles, None, progress), limits, progress, opendss)
    problem = apply_events(problem, events, span)
    result = run_day_with_opf(problem, settings, span, progress)
    labels = [event_label(event) for event in events]
    summary = day_summary(problem, result, limits, labels)
    if out is not None:
        write_day(out, summary, day_table(result, problem), result, problem, progress)
    emit(stamp(summary), as_json, day_text(summary))
    if summary["infeasible_minutes"]:
        raise Failure(infeasible_day_message(summary))
    return 0


def infeasible_day_message(summary: dict, shown: int = 5) -> str:
    """One line naming how many minutes, and which first, have no feasible DC-OPF."""
    from popdispatch.report.text import minute_ranges

    bad = summary["infeasible_minutes"]
    ranges = minute_ranges(bad).split(", ")
    listed = ", ".join(ranges[:shown]) + (", ..." if len(ranges) > shown else "")
    return (
        f"the DC-OPF is infeasible at {len(bad)} of {summary['minutes']} minutes ({listed}) "
        "with the given limits and events; every minute was run and reported "
        "(infeasible_minutes)"
    )


def write_day(out: Path, summary: dict, table, result, problem, progress: Progress) -> None:
    from popdispatch.report import figures
    from popdispatch.report.summaries import generator_buses

    with progress.step(f"writing {out}"), staged_folder(out) as folder:
        folder.write_csv("day.csv", table)
        fig = figures.base_day_figure(result, generator_buses(problem))
        figures.save_figure(fig, folder.file("setpoints"))
        folder.write_json("summary.json", stamp(summary))


def refuse_opendss(ctx: click.Context, param: click.Parameter, value) -> None:
    """``reproduce --opendss``: a usage error saying which commands read OpenDSS files."""
    if value is not None:
        raise click.BadParameter(
            "reproduce runs the paper's experiments on the built-in ieee-elv case; --opendss "
            "is accepted by feeder, opf, snapshot, day and export",
            ctx,
            param,
        )


@cli.command(short_help="The paper's three experiments: figures and report.md.")
@profiles_option
@option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for figures, time series, summary.json and report.md.",
)
@option("--opendss", hidden=True, callback=refuse_opendss, expose_value=False, is_eager=True)
@option(
    "--mode",
    type=MODE_CHOICE,
    default="paper",
    show_default=True,
    help="Dispatch mode of every experiment.",
)
@option("--minutes", type=MinutesType(), help="Base day over minutes START-END only (quick look).")
@json_option
@quiet_option
def reproduce(profiles, out, mode, minutes, as_json, quiet) -> None:
    """The paper's three experiments end to end: figures, summary.json, report.md."""
    import numpy as np

    from popdispatch.report.reproduce import run_reproduction, write_reproduction

    progress = Progress(quiet)
    check_out(out)
    settings = settings_from("smith", mode, "uniform", "complete")
    announce_compile(progress)
    day_profiles = load_profiles(profiles, None, progress)
    span = np.arange(minutes[0], minutes[1] + 1) if minutes else None
    rep = run_reproduction(day_profiles, settings, span, progress)
    with staged_folder(out) as folder:
        summary = write_reproduction(rep, folder, progress)
    progress.note(f"wrote {out}/report.md, summary.json and figures/")
    if as_json:
        click.echo(json_text(summary), nl=False)


@cli.command(short_help="One minute as a MATPOWER or pandapower case.")
@minute_option
@option(
    "--format",
    "fmt",
    type=click.Choice(["matpower", "pandapower"]),
    required=True,
    help="MATPOWER case file (.m) or pandapower JSON net.",
)
@option(
    "--out", type=click.Path(dir_okay=False, path_type=Path), required=True, help="File to write."
)
@limit_option
@profiles_option
@opendss_option
@quiet_option
def export(minute, fmt, out, limits, profiles, opendss, quiet) -> None:
    """The reduced feeder at one minute as a MATPOWER or pandapower case (DC-OPF cross-check)."""
    from popdispatch.export import write_case

    progress = Progress(quiet)
    check_out(out)
    day_profiles = load_profiles(profiles, minute, progress)
    problem = build(day_profiles, limits, progress, opendss)
    loads = minute_loads(problem, day_profiles, minute)
    write_case(out, fmt, problem, minute, loads)
    progress.note(f"wrote {out} ({fmt}, minute {minute})")


def minute_loads(problem, profiles, minute: int):
    """Per-load demand (kW) at ``minute`` in the order of the feeder's loads."""
    return profiles.for_loads(problem.feeder.original.loads.index).at(minute).to_numpy(float)


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
    _Clock.start = entered - (age or 0.0)
    try:
        return _main(argv)
    finally:
        _Clock.start = None
        if argv is None:  # run as the program: the interpreter exits next
            _spare_the_exit()


def _spare_the_exit() -> None:
    """Move every live object out of the cyclic garbage collector's reach before the
    interpreter exits: its final collections would otherwise scan all of numba's, pandas' and
    scipy's objects, about 0.3-0.6 s after the work is done. Nothing is skipped (atexit handlers
    and finalisers run as usual); only call this when the process is about to end, since frozen
    objects are never collected."""
    import gc

    gc.freeze()


def _main(argv: Sequence[str] | None) -> int:
    debug = bool(os.environ.get("POPDISPATCH_DEBUG"))
    interrupt = _Interrupt()
    signal.signal(signal.SIGINT, interrupt)
    try:
        code = cli.main(args=argv, prog_name="popdispatch", standalone_mode=False)
    except OptionError as exc:
        where = f" {exc.option}" if exc.option else ""
        click.echo(f"popdispatch: error: invalid value for{where}: {_one_line(str(exc))}", err=True)
        return EXIT_USAGE
    except click.UsageError as exc:
        where = exc.ctx.command_path if exc.ctx else "popdispatch"
        click.echo(f"{where}: error: {_one_line(exc.format_message())}", err=True)
        return EXIT_USAGE
    except click.ClickException as exc:
        click.echo(f"popdispatch: error: {_one_line(exc.format_message())}", err=True)
        return exc.exit_code
    except (click.Abort, KeyboardInterrupt):
        click.echo("popdispatch: interrupted; no output written", err=True)
        return EXIT_INTERRUPTED
    except (Failure, PopdispatchError, ValueError, OSError) as exc:
        if debug:
            raise
        click.echo(f"popdispatch: error: {_one_line(str(exc))}", err=True)
        return EXIT_PROBLEM
    except Exception:
        if not interrupt.fired or debug:
            raise
        click.echo("popdispatch: interrupted; no output written", err=True)
        return EXIT_INTERRUPTED
    return code if isinstance(code, int) else 0


if __name__ == "__main__":
    sys.exit(main())
