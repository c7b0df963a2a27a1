"""``popdispatch cosim``: the ELV in a mosaik co-simulation with an AC plant (docs/cosim.md)."""

from __future__ import annotations

from pathlib import Path

import click

from popdispatch.cli.clock import Failure, stamp
from popdispatch.cli.options import (
    check_out,
    json_option,
    limit_option,
    option,
    profiles_option,
    quiet_option,
)
from popdispatch.cli.render import announce_compile, emit
from popdispatch.notation import MinutesType
from popdispatch.progress import Progress


@click.command(short_help="The dispatcher in a mosaik co-simulation with an AC grid.")
@click.argument("case", type=click.Choice(["ieee-elv"]))
@profiles_option
@limit_option
@option("--minutes", type=MinutesType(), required=True,
        help="Minutes START-END of the day to simulate (1-based).")  # fmt: skip
@option("--out", type=click.Path(file_okay=False, path_type=Path), required=True,
        help="Folder for cosim.csv (mosaik's record), steps.csv and summary.json.")  # fmt: skip
@json_option
@quiet_option
def cosim(case, profiles, limits, minutes, out, as_json, quiet) -> int:
    """Run CASE's minutes in mosaik: the dispatcher (the online engine, exact mode) reads the
    loads' demand and the measured AC flows of the limited lines and sets the DGs; a pandapower
    grid solves the AC power flow each minute. Compared with the DC online day of the same
    minutes (set points, JSON key vs_dc_day)."""
    import numpy as np

    from popdispatch.cosim.report import cosim_summary, cosim_table, cosim_text
    from popdispatch.cosim.scenario import run_cosim
    from popdispatch.online import RunSettings
    from popdispatch.report.output import staged_folder
    from popdispatch.runs import FeederSource, load_run, run_day_vs_opf

    try:
        import mosaik  # noqa: F401
    except ImportError as exc:
        raise Failure(f'cosim needs mosaik: pip install "popdispatch[cosim]" ({exc})') from None
    progress = Progress(quiet)
    check_out(out)
    settings = RunSettings(mode="exact")
    announce_compile(progress, settings)
    problem, series = load_run(FeederSource(), profiles, limits=limits, progress=progress)
    steps = np.arange(minutes[0], minutes[1] + 1)
    with staged_folder(out) as folder:
        with progress.step("co-simulation (mosaik)"):
            result = run_cosim(problem, series, steps, settings, folder.path)
        day = run_day_vs_opf(problem, settings, steps, progress)
        summary = cosim_summary(result, day.run.setpoints_kw, settings.accuracy_kw)
        folder.write_csv("steps.csv", cosim_table(result))
        folder.write_json("summary.json", stamp(summary))
    emit(stamp(summary), as_json, cosim_text(summary))
    return 0
