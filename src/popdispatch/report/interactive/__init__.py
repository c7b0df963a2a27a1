"""Interactive HTML reports of a day or a snapshot: one self-contained offline file (plotly.js
embedded) with the feeder map over time and linked panels (needs the ``html`` extra).

- :func:`write_day_html` / :func:`day_report_html`: an online day against the DC-OPF, a map
  frame per kept minute (a time slider and a play button), panels over every minute;
- :func:`write_snapshot_html` / :func:`snapshot_report_html`: one minute, a map frame per kept
  iteration of its trajectory.

Powers in kW, prices in EUR/MWh, voltages in p.u. See docs/report.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.compare import DayComparison, SnapshotComparison
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import DispatchProblem
from popdispatch.report.interactive.page import EXTRA, require_plotly  # noqa: F401 (EXTRA re-exported)
from popdispatch.report.interactive.steps import (
    Steps,
    day_steps,
    default_every,
    frame_rows,
    snapshot_steps,
    step_name,
)

#: About this many regular map frames (a full day: every 5th minute, 288 frames).
TARGET_FRAMES = 288
#: The map's frames take at most about this much of the page (plotly.js itself is ~4.8 MB).
FRAMES_BUDGET_BYTES = 4_000_000
#: At most this many map frames (a slider of more steps is not usable anyway).
MAX_FRAMES = 1000
def within_budget(steps: Steps, problem: DispatchProblem, every: int) -> tuple[np.ndarray, int]:
    """``(rows, every)``: the map frames of :func:`frame_rows`, with ``every`` doubled until
    they fit :data:`FRAMES_BUDGET_BYTES` and :data:`MAX_FRAMES`; if the changes alone are too
    many, all frames are thinned evenly (``every`` is then 0)."""
    from popdispatch.report.interactive.feeder_map import frame_bytes

    n = len(steps.values)
    limit = max(min(int(FRAMES_BUDGET_BYTES // frame_bytes(problem, steps)), MAX_FRAMES), 2)
    rows = frame_rows(steps, problem, every)
    while len(rows) > limit and every < n:
        every = min(every * 2, n)
        rows = frame_rows(steps, problem, every)
    if len(rows) > limit:
        return np.unique(np.linspace(0, n - 1, limit).round().astype(np.int64)), 0
    return rows, every


def _run_info(run_info: Mapping | None, problem: DispatchProblem, steps: Steps, comparison):
    """The header's data: the run's summary as given, else the little the results say."""
    if run_info is not None:
        return dict(run_info)
    run = comparison.run
    info = {"case": problem.feeder.original.name, "mode": run.settings.mode,
            "dynamics": run.settings.dynamics, "profile_source": run.profile_source}  # fmt: skip
    if steps.kind == "minute":
        info.update(first_minute=int(steps.values[0]), last_minute=int(steps.values[-1]))
    else:
        info.update(minute=run.minute, demand_kw=run.demand_kw, iterations=run.iterations)
    return info


def day_report_html(
    comparison: DayComparison,
    problem: DispatchProblem,
    profiles: LoadProfiles,
    *,
    run_info: Mapping | None = None,
    voltages_pu: pd.DataFrame | None = None,
    every_minutes: int | None = None,
) -> str:
    """The day report as HTML text.

    ``comparison``: the day and its DC-OPFs; ``problem`` and ``profiles``: the ones it ran on
    (the loads of each minute give the flows of every line); ``run_info``: the run's summary
    (the ``day`` command's ``--json`` object; header); ``voltages_pu``: optional bus voltages
    (index minute, columns original bus ids, p.u.), e.g. from an AC check; ``every_minutes``:
    minutes between regular map frames (default: about :data:`TARGET_FRAMES` frames).
    """
    from popdispatch.report.interactive.feeder_map import map_figure
    from popdispatch.report.interactive.page import (
        frame_count_note,
        header_html,
        page_html,
    )
    from popdispatch.report.interactive.panels import panel_figure, panel_rows

    require_plotly()
    steps = day_steps(comparison, problem, profiles, voltages_pu)
    every = every_minutes or default_every(steps, TARGET_FRAMES)
    rows, every = within_budget(steps, problem, every)
    states = steps.line_states(problem)
    error = steps.abs_error_kw
    titles = [
        f"{steps.step_name} {m} ({steps.times[r]}): demand {steps.demand_kw[r]:.2f} kW, max "
        f"|error| to the "
        f"DC-OPF {_kw(error[r])}, {_at_limit(states[r])}"
        for r, m in ((int(r), int(steps.values[r])) for r in rows)
    ]
    info = _run_info(run_info, problem, steps, comparison)
    title = f"popdispatch day: {info.get('case')}, {info.get('mode')} mode"
    notes = [frame_count_note(steps.step_name, rows, len(steps.values), every), *NOTES]
    drawn = panel_rows(steps, rows)
    if len(drawn) < len(steps.values):
        notes.append(f"Panels: {len(drawn)} of {len(steps.values)} {steps.step_name}s, evenly "
                     "spaced, plus every step with a map frame.")  # fmt: skip
    return page_html(
        title,
        header_html(title, info, notes, steps.step_name),
        map_figure(problem, steps, rows, titles),
        panel_figure(problem, steps.take(drawn), int(steps.values[rows[-1]])),
    )


def snapshot_report_html(
    comparison: SnapshotComparison,
    problem: DispatchProblem,
    profiles: LoadProfiles,
    *,
    run_info: Mapping | None = None,
    voltages_pu: pd.Series | None = None,
    max_frames: int = 200,
) -> str:
    """The snapshot report as HTML text: map frames over the iterations of the trajectory
    (about ``max_frames``, plus the iterations of detection, convergence or rest and of every
    change of a limited line's state). ``voltages_pu``: bus -> p.u. at the final set points.
    Other arguments as in :func:`day_report_html` (``run_info``: the ``snapshot`` summary)."""
    from popdispatch.report.interactive.feeder_map import map_figure
    from popdispatch.report.interactive.page import frame_count_note, header_html, page_html
    from popdispatch.report.interactive.panels import panel_figure, panel_rows

    require_plotly()
    run = comparison.run
    steps = snapshot_steps(comparison, problem, profiles, voltages_pu)
    rows, every = within_budget(steps, problem, default_every(steps, max_frames))
    marks = [i for i in (run.first_congestion, run.converged_at, run.rest_at) if i is not None]
    rows = np.union1d(rows, np.asarray(marks, dtype=np.int64))
    states = steps.line_states(problem)
    error = steps.abs_error_kw
    dt = run.settings.stepping.dt
    series_step = step_name(profiles)
    titles = [
        f"{series_step} {run.minute} ({steps.times[r]}), iteration {r} ({r * dt:.2f} s): max "
        "|error| "
        f"to the DC-OPF "
        f"{_kw(error[r])}, {_at_limit(states[r])}"
        for r in (int(r) for r in rows)
    ]
    info = _run_info(run_info, problem, steps, comparison)
    mode = run.settings.mode
    title = f"popdispatch snapshot: {info.get('case')}, {series_step} {run.minute}, {mode} mode"
    notes = [frame_count_note("iteration", rows, len(steps.values), every), *NOTES]
    if voltages_pu is not None:
        notes.append("Bus voltages are those of the final set points.")
    return page_html(
        title,
        header_html(title, info, notes, series_step),
        map_figure(problem, steps, rows, titles),
        panel_figure(problem, steps.take(panel_rows(steps, rows)), int(rows[-1])),
    )


NOTES = [
    "Map: lines coloured and widened by |flow| (kW, radial DC flows of the set points and the "
    "loads); limited lines under a grey band, their node controllers as squares (white: idle, "
    "orange: at the limit, red: overloaded); generators sized by set point (grey: offline). "
    "Hover for values. Line prices: the DC-OPF's duals, and the eq.-8 signal the dynamics' "
    "flows would make a paper-mode controller send (exact mode's own integrated prices are "
    "not kept by the engine)."
]


def _at_limit(states: np.ndarray) -> str:
    if not len(states):
        return "no line limits"
    n = int((states > 0).sum())
    return f"{n} limited line{'' if n == 1 else 's'} at {'its' if n == 1 else 'their'} limit"


def _kw(value: float) -> str:
    return f"{value:.3g} kW" if np.isfinite(value) else "n/a (no DC-OPF)"


def write_html(
    path: str | Path,
    comparison: DayComparison | SnapshotComparison,
    problem: DispatchProblem,
    profiles: LoadProfiles,
    **options,
) -> Path:
    """Write the report of ``comparison`` to ``path`` atomically (never a partial file):
    :func:`day_report_html` for a day, :func:`snapshot_report_html` for a snapshot;
    ``options`` go to that function."""
    from popdispatch.report.output import atomic_write_text

    render = day_report_html if isinstance(comparison, DayComparison) else snapshot_report_html
    return atomic_write_text(path, render(comparison, problem, profiles, **options))


#: The day's and the snapshot's writers: :func:`write_html` under the names of what they write.
write_day_html = write_snapshot_html = write_html


__all__ = [
    "day_report_html", "require_plotly", "snapshot_report_html", "write_day_html", "write_html",
    "write_snapshot_html",
]  # fmt: skip
