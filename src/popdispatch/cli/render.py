"""What the commands print and write: stdout (JSON or text), ``--out`` folders, the one-line
messages of infeasible minutes (:mod:`popdispatch.report.text`)."""

from __future__ import annotations

from pathlib import Path

import click

from popdispatch.cli.clock import stamp
from popdispatch.progress import Progress
from popdispatch.report.output import json_text, staged_folder


def emit(summary: dict, as_json: bool, text: str) -> None:
    """Print the summary as JSON or the human-readable text on stdout."""
    click.echo(json_text(summary) if as_json else text, nl=not as_json)


def announce_compile(progress: Progress, settings=None) -> None:
    """Say on stderr (unless quiet) that the engine's kernels compile now, when they must
    (for the run configuration of ``settings``, a RunSettings, if given)."""
    from popdispatch.compile_notice import COMPILE_NOTICE, kernels_cached

    if kernels_cached(settings) is False:
        progress.note(COMPILE_NOTICE)


def write_snapshot(out: Path, summary: dict, table, result, progress: Progress) -> None:
    from popdispatch.report import figures

    with progress.step(f"writing {out}"), staged_folder(out) as folder:
        folder.write_csv("trajectory.csv", table)
        figures.save_figure(figures.congestion_figure(result), folder.file("setpoints"))
        folder.write_json("summary.json", stamp(summary))


def write_day(out: Path, summary: dict, table, result, problem, progress: Progress,
              timeline=None) -> None:  # fmt: skip
    """``day.csv``, the set-point figure (on ``timeline``'s own time axis, if given) and
    ``summary.json`` into ``out``, staged and renamed into place."""
    from popdispatch.report import figures
    from popdispatch.report.summaries import generator_buses

    with progress.step(f"writing {out}"), staged_folder(out) as folder:
        folder.write_csv("day.csv", table)
        fig = figures.base_day_figure(result, generator_buses(problem), timeline=timeline)
        figures.save_figure(fig, folder.file("setpoints"))
        folder.write_json("summary.json", stamp(summary))


def minute_loads(problem, profiles, minute: int):
    """Per-load demand (kW) at ``minute`` in the order of the feeder's loads."""
    return profiles.for_loads(problem.feeder.original.loads.index).at(minute).to_numpy(float)
