"""``--ac`` and ``--html`` on ``snapshot`` and ``day``: the AC check of the dispatch
(:mod:`popdispatch.ac`) and the interactive report (:mod:`popdispatch.report.interactive`).

Both are checked before any work (the optional extra installed, the report's folder writable)
and run after the dynamics; the AC check's summary goes under the ``ac`` key of the command's
JSON, its per-step columns into ``day.csv``, its bus voltages onto the report's map.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple

import click

from popdispatch.cli.process import Failure
from popdispatch.report.progress import Progress

#: The optional extra each analysis needs: (importable module, extra's name).
EXTRAS = {"ac": ("power_grid_model", "ac"), "html": ("plotly", "html")}


class Analyses(NamedTuple):
    """What to do with a run's dispatch besides the DC-OPF comparison."""

    ac: bool = False
    vn_kv: float | None = None
    html: Path | None = None

    def check(self) -> None:
        """Before any work (see :func:`check_analyses`)."""
        check_analyses(self)

    def snapshot(self, problem, profiles, result, summary: dict, progress: Progress) -> None:
        """See :func:`snapshot_analyses`."""
        snapshot_analyses(self, problem, profiles, result, summary, progress)

    def day(self, problem, profiles, result, summary: dict, progress: Progress):
        """See :func:`day_analyses`."""
        return day_analyses(self, problem, profiles, result, summary, progress)

    def model_options(self) -> dict:
        """Keyword arguments of :func:`popdispatch.ac.check_setpoints`."""
        return {} if self.vn_kv is None else {"vn_kv": self.vn_kv}


def analysis_options(func):
    """``--ac``, ``--vn-kv`` and ``--html``, handed to the command as one ``analyses``
    (:class:`Analyses`), checked before the command runs."""

    @functools.wraps(func)
    def command(*args, ac, vn_kv, html, **kwargs):
        analyses = Analyses(ac or vn_kv is not None, vn_kv, html)
        check_analyses(analyses)
        return func(*args, analyses=analyses, **kwargs)

    decorators = [
        click.option(
            "--ac",
            is_flag=True,
            help="AC power flow of the dispatched full feeder (power-grid-model): losses (kW), "
            "lowest and highest voltage (p.u.), line loading (%), the source's extra supply.",
        ),
        click.option(
            "--vn-kv",
            type=click.FloatRange(min=0, min_open=True),
            help="Nominal line-to-line voltage of the feeder (kV) for --ac, where the network "
            "does not say (implies --ac).",
        ),
        click.option(
            "--html",
            type=click.Path(dir_okay=False, path_type=Path),
            help="Write an interactive, self-contained HTML report (the feeder map over time "
            "and linked panels) to this file.",
        ),
    ]
    for decorate in reversed(decorators):
        command = decorate(command)
    return command


def check_analyses(analyses: Analyses) -> None:
    """Before any work: the extras installed (exit 1 naming the extra) and ``--html``'s folder
    there (exit 2) and writable (exit 1)."""
    from importlib.util import find_spec

    from popdispatch.cli.options import check_out

    wanted = [name for name, on in (("ac", analyses.ac), ("html", analyses.html)) if on]
    for name in wanted:
        module, extra = EXTRAS[name]
        if find_spec(module) is None:
            raise Failure(f"--{name} needs the optional extra {extra!r}: "
                          f'pip install "popdispatch[{extra}]"')  # fmt: skip
    if analyses.html is not None:
        try:
            check_out(analyses.html)
        except click.BadParameter as exc:
            exc.param_hint = "'--html'"
            raise


def snapshot_analyses(analyses, problem, profiles, result, summary: dict, progress: Progress):
    """The AC check (into ``summary['ac']``) and the report of a snapshot run."""
    from popdispatch.ac import check_snapshot

    ac = None
    if analyses.ac:
        with progress.step("AC power flow of the dispatch"):
            ac = check_snapshot(problem, profiles, result, **analyses.model_options())
        summary["ac"] = ac.summary()
    if analyses.html is not None:
        from popdispatch.report.interactive import write_snapshot_html

        voltages = None if ac is None else ac.buses["v_pu"]
        with progress.step(f"writing {analyses.html}"):
            write_snapshot_html(analyses.html, result, problem, profiles, run_info=summary,
                                voltages_pu=voltages)  # fmt: skip


def day_analyses(analyses, problem, profiles, result, summary: dict, progress: Progress):
    """The AC check of every step (into ``summary['ac']``) and the report of a day run.
    Returns the AC check's per-step columns (index ``minute``) or ``None``."""
    from popdispatch.ac import check_day

    ac = None
    if analyses.ac:
        with progress.step(f"AC power flows of {len(result.run.minutes)} steps"):
            ac = check_day(problem, profiles, result, **analyses.model_options())
        hours = profiles.timeline.hours[ac.steps.index.to_numpy() - 1]
        summary["ac"] = ac.summary(hours)
    if analyses.html is not None:
        from popdispatch.report.interactive import write_day_html

        voltages = None if ac is None else ac.v_pu()
        with progress.step(f"writing {analyses.html}"):
            write_day_html(analyses.html, result, problem, profiles, run_info=summary,
                           voltages_pu=voltages)  # fmt: skip
    return None if ac is None else ac.steps
