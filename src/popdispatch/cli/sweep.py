"""``popdispatch sweep SPEC.toml --out DIR`` and ``popdispatch sweep-report DIR`` (the
``sweep`` extra: Dask and pyarrow). See docs/sweeps.md and :mod:`popdispatch.sweep`.

Exit codes as for every command: 2 for a bad spec or option (checked before any work), 1 when
some scenario failed (every other scenario is still run and written), 130 when interrupted
(finished scenarios stay written; rerun the same command to resume).
"""

from __future__ import annotations

from pathlib import Path

import click

from popdispatch.cli.clock import EXIT_INTERRUPTED, Failure
from popdispatch.cli.options import option, profiles_option, quiet_option

#: Columns of ``--dry-run``'s listing.
LISTED = ("id", "case", "steps", "mode", "dynamics", "graph", "limits", "events", "assignment")


def scenario_line(scenario, done: bool) -> str:
    """One scenario as a tab-separated line of :data:`LISTED` values and whether it is done."""
    values = [
        scenario.id, scenario.feeder_label, scenario.steps.label, scenario.mode,
        scenario.dynamics, scenario.graph, scenario.limits_label, scenario.events_label,
        scenario.assignment.label, "done" if done else "to-run",
    ]  # fmt: skip
    return "\t".join(values)


@click.command(short_help="Many online days from one TOML spec, on Dask; Parquet results.")
@click.argument("spec", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Results folder: summary.parquet and steps.parquet (rerun with it to resume).",
)
@option("--dry-run", is_flag=True, help="List the scenarios (id, parameters, done?) and stop.")
@option("--scheduler", metavar="ADDRESS", help="An existing Dask scheduler (tcp://host:8786).")
@option(
    "--workers",
    type=click.IntRange(min=1),
    help="Worker processes of the local cluster (default: one per core).",
)
@profiles_option
@quiet_option
def sweep(spec, out, dry_run, scheduler, workers, profiles, quiet) -> int:
    """Run every scenario of SPEC (a product of cases, steps, modes, dynamics, graphs, limits,
    events and profile assignments) as an online day against the DC-OPF, on a Dask cluster.

    Each scenario is written to OUT as soon as it finishes; scenarios already there are
    skipped, so rerunning after Ctrl-C or a lost worker completes the sweep. A scenario that
    raises is recorded as failed with its message (status, error) and the rest still run.
    """
    from popdispatch.errors import OptionError
    from popdispatch.sweep import load_spec
    from popdispatch.sweep.store import finished_ids

    if scheduler is not None and workers is not None:
        raise OptionError("--workers sizes the local cluster; not with --scheduler", "--workers")
    parsed = load_spec(spec)
    done = finished_ids(out) if out.is_dir() else set()
    count = len(parsed.scenarios)
    left = sum(s.id not in done for s in parsed.scenarios)
    sampled = f" (sampled from {parsed.product_size})" if count != parsed.product_size else ""
    click.echo(
        f"{count} scenarios{sampled}: {count - left} already in {out}, {left} to run", err=True
    )
    if dry_run:
        click.echo("\t".join((*LISTED, "state")))
        for s in parsed.scenarios:
            click.echo(scenario_line(s, s.id in done))
        return 0
    return _run(parsed, out, profiles, scheduler, workers, quiet)


def _run(parsed, out, profiles, scheduler, workers, quiet) -> int:
    from popdispatch.sweep.execute import run_sweep

    try:
        result = run_sweep(parsed.scenarios, out, profiles, scheduler, workers, quiet)
    except KeyboardInterrupt:
        click.echo(
            f"popdispatch: sweep interrupted; every finished scenario is in {out}: rerun the "
            "same command to run the rest",
            err=True,
        )
        raise click.exceptions.Exit(EXIT_INTERRUPTED) from None
    if not result.ran:
        click.echo(f"nothing to run: every scenario is already in {out}", err=True)
        return 0
    days_per_min = result.ran / result.seconds * 60 if result.seconds else float("nan")
    click.echo(
        f"ran {result.ran} scenarios in {result.seconds:.1f} s on {result.workers} workers "
        f"({days_per_min:.1f} scenario-days per minute); {result.skipped} skipped as done; "
        f"results in {out}",
        err=True,
    )
    if result.failed:
        first, message = next(iter(result.failed.items()))
        raise Failure(
            f"{len(result.failed)} of {result.ran} scenarios failed (first: {first}: {message}); "
            f"their rows in {out}/summary.parquet have status failed"
        )
    return 0


@click.command("sweep-report", short_help="A sweep's summary: table and figures.")
@click.argument(
    "sweep_dir", metavar="DIR", type=click.Path(exists=True, file_okay=False, path_type=Path)
)
@option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Where to write report.txt, groups.csv and sweep.png/.pdf (default DIR/report).",
)
def sweep_report(sweep_dir, out) -> int:
    """Print the sweep in DIR grouped by case, steps, mode, dynamics, graph and limits
    (statuses, worst and median error in kW, cost gap in EUR, iterations) and write figures
    of their distributions."""
    from popdispatch.sweep.report import write_report

    text, folder = write_report(sweep_dir, out)
    click.echo(text, nl=False)
    click.echo(f"report written to {folder}", err=True)
    return 0
