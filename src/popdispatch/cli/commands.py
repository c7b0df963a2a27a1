"""The ``popdispatch`` commands: parse the options, call the library, render the result.

See :mod:`popdispatch.cli.process` for exit codes, errors and times; heavy libraries are
imported inside the commands that use them.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import click

from popdispatch.cli.analyses import Analyses, analysis_options
from popdispatch.cli.clock import Failure, stamp, start_clock
from popdispatch.cli.options import (
    MODE_CHOICE,
    WARM_START_CHOICE,
    MinutesType,
    accuracy_options,
    build,
    check_out,
    check_shares,
    feeder_options,
    json_option,
    limit_option,
    minute_option,
    option,
    out_option,
    profiles_option,
    quiet_option,
    refuse_opendss,
    run_options,
    series_options,
    settings_from,
    steps_options,
)
from popdispatch.cli.render import (
    announce_compile,
    emit,
    minute_loads,
    write_day,
    write_snapshot,
)
from popdispatch.notation import EventType
from popdispatch.progress import Progress
from popdispatch.report.output import json_text, staged_folder
from popdispatch.report.text import (
    cases_summary,
    cases_text,
    day_text,
    infeasible_day_message,
    infeasible_minute_message,
    opf_text,
    reproduce_text,
    snapshot_text,
)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="popdispatch")
@click.pass_context
def cli(ctx: click.Context) -> None:
    """Online, distributed, network-constrained dispatch of distributed generators
    with population dynamics, compared with an exact DC-OPF (IEEE European LV feeder)."""
    start_clock(ctx)
    warnings.showwarning = _note  # a reader's remark: one line, no source location


def _note(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as the CLI prints it: ``popdispatch: note: ...`` on one line of stderr."""
    click.echo(f"popdispatch: note: {' '.join(str(message).split())}", err=True)


@cli.command(short_help="The built-in cases: size and source.")
@json_option
@quiet_option
def cases(as_json: bool, quiet: bool) -> None:
    """The built-in cases (--case NAME): buses, lines, loads, total load, source."""
    from popdispatch.cases.builtin import list_cases

    with Progress(quiet).step("listing the built-in cases"):
        table = list_cases()
    emit(cases_summary(table), as_json, cases_text(table))


@cli.command(short_help="Any network: buses, source, loads, lines, ratings, fleet.")
@feeder_options
@json_option
@quiet_option
def feeder(source, as_json: bool, quiet: bool) -> None:
    """What the feeder is: buses, the source, key nodes, loads (names, kW), fixed injections,
    lines (ratings, impedances), load shapes, generators. Any network, with or without a
    fleet (a dispatch needs one)."""
    from popdispatch.cases.sources import load_network
    from popdispatch.feeder import reduce_feeder
    from popdispatch.report.describe import (
        feeder_summary,
        feeder_text,
        network_summary,
        network_text,
    )

    progress = Progress(quiet)
    with progress.step(f"loading {source.label}"):
        net, note = load_network(source)
    if note:
        progress.note(note)
        summary = network_summary(net, source.ratings)
        return emit(summary, as_json, network_text(summary))
    summary = feeder_summary(net, reduce_feeder(net), source.ratings)
    emit(summary, as_json, feeder_text(summary))


@cli.command(short_help="The exact DC-OPF of one minute (paper eq. 1).")
@minute_option
@limit_option
@series_options
@feeder_options
@json_option
@quiet_option
def opf(minute: int, limits, profiles, source, as_json: bool, quiet: bool) -> int:
    """The exact DC-OPF of one minute (paper eq. 1): the cheapest dispatch meeting the
    demand within the generator limits and the line limits. Exit code 1 (after the output)
    when no such dispatch exists."""
    from popdispatch.opf import solve_opf
    from popdispatch.report.summaries import opf_summary

    progress = Progress(quiet)
    problem, series = build(source, profiles, minute, limits, progress)
    summary = opf_summary(problem, solve_opf(problem, minute), limits, series.timeline)
    emit(summary, as_json, opf_text(summary))
    if summary["status"] != "optimal":
        raise Failure(infeasible_minute_message(summary))
    return 0


@cli.command(short_help="One minute of dynamics against the DC-OPF.")
@minute_option
@limit_option
@run_options
@accuracy_options
@series_options
@feeder_options
@out_option
@analysis_options
@json_option
@quiet_option
def snapshot(
    minute, limits, dynamics, eta, mode, x0, graph, constants, price_law, accuracy, profiles,
    source, out, analyses, as_json, quiet,
) -> int:  # fmt: skip
    """One minute of dynamics: trajectory, convergence, comparison with the DC-OPF.

    A minute whose DC-OPF is infeasible is still run and reported (set points, overflow,
    set points outside their limits flagged; DC-OPF values null), then exit code 1.
    """
    from popdispatch.report.summaries import snapshot_summary, trajectory_table
    from popdispatch.runs import run_snapshot_vs_opf

    progress = Progress(quiet)
    check_out(out)
    settings = analyses.settings(settings_from(dynamics, mode, x0, graph, None, constants,
                                                price_law, accuracy, eta))  # fmt: skip
    check_shares(x0, progress, source)
    announce_compile(progress, settings)
    problem, series = build(source, profiles, minute, limits, progress)
    problem = analyses.problem(problem, series, settings)
    with progress.step(f"minute {minute}: {dynamics} dynamics and DC-OPF"):
        result = run_snapshot_vs_opf(problem, minute, settings)
    summary = snapshot_summary(problem, result, limits, series.timeline)
    analyses.snapshot(problem, series, result, summary, progress)
    if out is not None:
        write_snapshot(out, summary, trajectory_table(result), result, progress)
    emit(stamp(summary), as_json, snapshot_text(summary))
    if summary["status"] == "infeasible":
        raise Failure(infeasible_minute_message(summary))
    return 0


@cli.command(short_help="The online day, minute by minute, against the DC-OPF.")
@limit_option
@run_options
@accuracy_options
@option(
    "--event",
    "events",
    type=EventType(),
    multiple=True,
    help="Generator availability: BUS:off@MIN trips the generator at BUS at minute MIN, "
    "BUS:on@MIN brings it back (repeatable).",
)
@steps_options
@option(
    "--warm-start",
    type=WARM_START_CHOICE,
    help="How a minute starts from the last: shares (the paper's rule, p = x * new demand; "
    "paper mode's default), setpoints (set points kept, the demand step taken by the "
    "generators inside their limits) or merit (set points kept, the step placed in merit "
    "order of marginal cost: a central incremental dispatch; exact mode's default).",
)
@series_options
@feeder_options
@out_option
@analysis_options
@json_option
@quiet_option
def day(
    limits, dynamics, eta, mode, x0, graph, constants, price_law, accuracy, events, minutes,
    warm_start, profiles, source, out, analyses, as_json, quiet,
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
    from popdispatch.events import event_label
    from popdispatch.report.summaries import day_summary, day_table
    from popdispatch.runs import run_day_vs_opf

    progress = Progress(quiet)
    check_out(out)
    settings = analyses.settings(settings_from(dynamics, mode, x0, graph, warm_start,
                                                constants, price_law, accuracy, eta))  # fmt: skip
    check_shares(x0, progress, source)
    announce_compile(progress, settings)
    problem, series = build(source, profiles, None, limits, progress, events, minutes)
    problem = analyses.problem(problem, series, settings)
    result = run_day_vs_opf(problem, settings, minutes.of(series), progress)
    labels = [event_label(event) for event in events]
    summary = day_summary(problem, result, limits, labels, series.timeline)
    ac_steps = analyses.day(problem, series, result, summary, progress)
    if out is not None:
        table = day_table(result, problem, series.timeline)
        table = table if ac_steps is None else table.join(ac_steps, on="minute")
        write_day(out, summary, table, result, problem, progress, series.timeline)
    emit(stamp(summary), as_json, day_text(summary))
    if summary["infeasible_minutes"]:
        raise Failure(infeasible_day_message(summary))
    return 0


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
@option("--html", is_flag=True, help="Also the interactive reports base_day.html and "
        "congestion.html (needs the html extra).")  # fmt: skip
@json_option
@quiet_option
def reproduce(profiles, out, mode, minutes, html, as_json, quiet) -> None:
    """The paper's three experiments end to end: figures, summary.json, report.md."""
    import numpy as np

    from popdispatch import runs
    from popdispatch.reproduce import run_reproduction, write_reproduction

    progress = Progress(quiet)
    check_out(out)
    Analyses(html=out if html else None).check()  # the extra; out itself checked above
    settings = settings_from("smith", mode, "uniform", "complete")
    announce_compile(progress, settings)
    day_profiles = runs.load_profiles(profiles, None, progress)
    span = np.arange(minutes[0], minutes[1] + 1) if minutes else None
    rep = run_reproduction(day_profiles, settings, span, progress)
    with staged_folder(out) as folder:
        summary = write_reproduction(rep, folder, progress, day_profiles if html else None)
    click.echo(json_text(summary) if as_json else reproduce_text(out, html), nl=not as_json)


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
@series_options
@feeder_options
@quiet_option
def export(minute, fmt, out, limits, profiles, source, quiet) -> None:
    """The reduced feeder at one minute as a MATPOWER or pandapower case (DC-OPF cross-check)."""
    from popdispatch.export import write_case

    progress = Progress(quiet)
    check_out(out)
    problem, day_profiles = build(source, profiles, minute, limits, progress)
    if problem.meshed:
        from popdispatch.errors import OptionError

        name = problem.feeder.name
        raise OptionError(f"export writes a radial feeder's reduced case; {name} is meshed "
                          "and its own file is the case to cross-check", "--net")  # fmt: skip
    loads = minute_loads(problem, day_profiles, minute)
    write_case(out, fmt, problem, minute, loads)
    progress.note(f"wrote {out} ({fmt}, minute {minute})")
