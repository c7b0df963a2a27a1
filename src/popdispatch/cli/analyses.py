"""``--ac``, ``--html``, ``--vmin``, ``--vmax`` and ``--ac-correct`` on ``snapshot`` and ``day``:
the AC check of the dispatch (:mod:`popdispatch.ac`), the interactive report
(:mod:`popdispatch.report.interactive`), the voltage limits (docs/voltage.md: the voltage
mode, its problem's voltage rows and the ``voltage`` JSON object) and the AC-corrected dispatch
(:mod:`popdispatch.ac.correct`, :mod:`popdispatch.ac.correct_day`).

They are checked before any work (the optional extra installed, the report's folder writable)
and run after the dynamics; the AC check's summary goes under the ``ac`` key of the command's
JSON, its per-step columns into ``day.csv``, its bus voltages onto the report's map. With
voltage limits every AC power flow says whether its voltages keep them and by how much they
miss (:mod:`popdispatch.ac.limits`: ``voltage_limits`` in the ``ac`` and ``ac_correct``
objects, ``below_vmin_pu``/``above_vmax_pu`` per step in ``day.csv``).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import NamedTuple

import click

from popdispatch.cli.clock import Failure
from popdispatch.progress import Progress

#: The optional extra each analysis needs: (importable module, extra's name).
EXTRAS = {"ac": ("power_grid_model", "ac"), "html": ("plotly", "html")}


class Analyses(NamedTuple):
    """What to do with a run's dispatch besides the DC-OPF comparison."""

    ac: bool = False
    vn_kv: float | None = None
    html: Path | None = None
    vmin: float | None = None
    vmax: float | None = None
    ac_correct: bool = False

    def settings(self, settings):
        """``settings`` with the voltage limits (exact mode becomes the voltage mode), checked
        by :class:`~popdispatch.online.RunSettings` (the one check of ``--vmin``/``--vmax``:
        :class:`~popdispatch.errors.OptionError`, exit 2, for bad limits or another mode)."""
        from dataclasses import replace

        return replace(settings, vmin_pu=self.vmin, vmax_pu=self.vmax)

    def problem(self, problem, profiles, settings):
        """The run's problem with its voltage rows (:func:`popdispatch.runs.with_voltage`)."""
        from popdispatch.runs import with_voltage

        if problem.meshed:
            self.refuse_mesh(problem)
        return with_voltage(problem, profiles, settings, self.vn_kv)

    def refuse_mesh(self, problem) -> None:
        """:class:`~popdispatch.errors.OptionError` naming the first analysis asked for that
        needs a radial feeder (the AC check, its corrections, voltage limits, the map)."""
        from popdispatch.errors import OptionError

        asked = [("--vmin", self.vmin is not None), ("--vmax", self.vmax is not None),
                 ("--ac-correct", self.ac_correct), ("--ac", self.ac),
                 ("--html", self.html is not None)]  # fmt: skip
        for option, on in asked:
            if on:
                raise OptionError(f"{option} needs a radial feeder; {problem.feeder.name} is "
                                  "meshed (its DC dispatch runs without it)", option)  # fmt: skip

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
    def command(*args, ac, vn_kv, html, vmin, vmax, ac_correct, **kwargs):
        if ac_correct and vmin is None and vmax is None:
            raise click.BadParameter("needs --vmin or --vmax", param_hint="'--ac-correct'")
        analyses = Analyses(ac or vn_kv is not None or ac_correct, vn_kv, html, vmin, vmax,
                            ac_correct)  # fmt: skip
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
        click.option(
            "--vmin",
            type=float,
            metavar="PU",
            help="Lowest bus voltage, p.u. (e.g. 0.95): exact mode adds LinDistFlow voltage "
            "prices at the key nodes; compared with the LinDistFlow OPF (docs/voltage.md).",
        ),
        click.option("--vmax", type=float, metavar="PU", help="Highest bus voltage, p.u."),
        click.option(
            "--ac-correct",
            is_flag=True,
            help="With --vmin/--vmax: rerun the voltage-aware dispatch (each step of a day, "
            "from the step before) with voltage offsets and loss factors from AC power flows "
            "until its model voltages equal the AC ones within 1e-5 p.u. (implies --ac; "
            "reported under ac_correct, per step in day.csv's ac_correct_* columns).",
        ),
    ]
    for decorate in reversed(decorators):
        command = decorate(command)
    return command


def check_analyses(analyses: Analyses) -> None:
    """Before any work: the extras installed (exit 1 naming the extra) and ``--html``'s folder
    there (exit 2) and writable (exit 1). The voltage limits are the run settings' to check
    (:class:`~popdispatch.online.RunSettings`, through :meth:`Analyses.settings`, which the
    commands call before loading anything): one rule for Python and the command line."""
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
        _limits(problem, ac.totals.to_frame().T, summary["ac"])
    if problem.n_voltage:
        run = result.run
        summary["voltage"] = _voltage(problem, [run.minute], run.setpoints_kw, [result.opf],
                                      ac and ac.buses["v_pu"].min(),
                                      run.voltage_price_eur_per_mwh)  # fmt: skip
    if analyses.ac_correct:
        summary["ac_correct"] = _corrected(analyses, problem, profiles, result, progress)
    if analyses.html is not None:
        from popdispatch.report.interactive import write_snapshot_html

        voltages = None if ac is None else ac.buses["v_pu"]
        with progress.step(f"writing {analyses.html}"):
            write_snapshot_html(analyses.html, result, problem, profiles, run_info=summary,
                                voltages_pu=voltages)  # fmt: skip


def day_analyses(analyses, problem, profiles, result, summary: dict, progress: Progress):
    """The AC check of every step (into ``summary['ac']``), the voltage object and the report
    of a day run. Returns the per-step columns for ``day.csv`` (index ``minute``): the AC
    check's and, with voltage limits, the LinDistFlow ``v_min_pu``/``v_max_pu`` of the
    monitored buses (:func:`popdispatch.ac.report.voltage_columns`); ``None`` without
    either."""
    ac = None
    if analyses.ac:
        from popdispatch.ac import check_day

        with progress.step(f"AC power flows of {len(result.run.minutes)} steps"):
            ac = check_day(problem, profiles, result, **analyses.model_options())
        summary["ac"] = ac.summary(_hours(profiles, ac.steps.index))
        _limits(problem, ac.steps, summary["ac"])
    if problem.n_voltage:
        run = result.run
        summary["voltage"] = _voltage(problem, run.minutes, run.setpoints_kw, result.opf,
                                      ac and float(ac.flows.v_pu.min()),
                                      run.voltage_price_eur_per_mwh)  # fmt: skip
    if analyses.html is not None:
        from popdispatch.report.interactive import write_day_html

        voltages = None if ac is None else ac.v_pu()
        with progress.step(f"writing {analyses.html}"):
            write_day_html(analyses.html, result, problem, profiles, run_info=summary,
                           voltages_pu=voltages)  # fmt: skip
    steps = None if ac is None else ac.steps.join(_misses(problem, ac.steps))
    if problem.n_voltage:
        from popdispatch.ac.report import voltage_columns

        columns = voltage_columns(problem, result.run.minutes, result.run.setpoints_kw)
        steps = columns if steps is None else steps.join(columns)
    if analyses.ac_correct:
        corrected = _corrected_day(analyses, problem, profiles, result, progress)
        summary["ac_correct"] = corrected.summary(_hours(profiles, corrected.steps.index))
        steps = steps.join(corrected.columns())
    return steps


def _hours(profiles, minutes):
    """Each step's duration, h (the series' timeline)."""
    return profiles.timeline.hours[minutes.to_numpy() - 1]


def _limits(problem, steps, ac: dict) -> None:
    """With voltage limits, the ``voltage_limits`` verdict of the AC voltages into ``ac``
    (:func:`popdispatch.ac.limits.limits_summary`)."""
    from popdispatch.ac.limits import has_bounds, limits_summary

    if has_bounds(problem.vmin_pu, problem.vmax_pu):
        ac["voltage_limits"] = limits_summary(steps, problem.vmin_pu, problem.vmax_pu)


def _misses(problem, steps):
    """Per step, the AC voltages' misses of the limits (none without limits)."""
    from popdispatch.ac.limits import has_bounds, miss_columns

    if not has_bounds(problem.vmin_pu, problem.vmax_pu):
        return steps[[]]
    return miss_columns(steps, problem.vmin_pu, problem.vmax_pu)


def _voltage(problem, minutes, p_kw, opf, ac_v_min_pu: float | None, prices=None) -> dict:
    """The ``voltage`` JSON object (:func:`popdispatch.ac.report.voltage_summary`; ``prices``:
    the run's voltage prices, EUR/MWh), with the linearization error where the AC check ran."""
    from popdispatch.ac.report import linearization_error, voltage_summary

    out = voltage_summary(problem, minutes, p_kw, opf, prices)
    if ac_v_min_pu is not None:
        out.update(linearization_error(out, ac_v_min_pu))
    return out


def _corrected(analyses, problem, profiles, result, progress: Progress) -> dict:
    """The ``ac_correct`` JSON object (:func:`popdispatch.ac.correct.ac_correct`)."""
    import numpy as np

    from popdispatch.ac.check import minute_loads
    from popdispatch.ac.correct import ac_correct

    run = result.run
    loads = minute_loads(problem.feeder.original, profiles, np.array([run.minute]))
    with progress.step("AC-corrected voltage-aware dispatch"):
        corrected = ac_correct(problem, loads, run.minute, run.settings,
                               **analyses.model_options())  # fmt: skip
    out = corrected.summary()
    if problem.vmin_pu > 0.0:
        out["below_vmin_pu"] = max(problem.vmin_pu - out["ac_v_min_pu"], 0.0)
    return out


def _corrected_day(analyses, problem, profiles, result, progress: Progress):
    """The AC-corrected dispatch of every step of a day run
    (:func:`popdispatch.ac.correct_day.ac_correct_day`)."""
    from popdispatch.ac.check import minute_loads
    from popdispatch.ac.correct_day import ac_correct_day

    run = result.run
    loads = minute_loads(problem.feeder.original, profiles, run.minutes)
    with progress.counter("AC-corrected day", len(run.minutes)) as advance:
        return ac_correct_day(problem, loads, run.minutes, run.settings, progress=advance,
                              **analyses.model_options())  # fmt: skip
