"""One scenario run: its problem, its online day against the DC-OPF, and the two result tables
(the summary row and the per-step rows). Runs anywhere (a Dask worker or in process) and
never raises for a scenario's own problem: :func:`run_and_store` records it as failed."""

from __future__ import annotations

import json
import os
import socket
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.sweep.spec import Scenario
from popdispatch.sweep.store import FAILED, write_scenario

#: ``day`` summary keys not carried (deprecated, unit-less twins of ``*_eur`` keys) or
#: replaced by the scenario's own parameters (``limits``, ``events`` as text).
DROPPED_KEYS = {"cost", "opf_cost", "cost_unit", "cost_all_minutes", "limits", "events", "case"}
#: ``day`` summary keys always stored as JSON text (``*_json``): lists of objects, or null.
JSON_KEYS = {"limits_in_force", "infeasibility"}


@dataclass(frozen=True)
class Context:
    """What every scenario of a sweep shares: the output folder and the profile folder
    (official profiles for ieee-elv; ``None``: ``$POPDISPATCH_PROFILES`` or the default)."""

    out: str
    profiles: str | None = None


def scenario_profiles(scenario: Scenario, context: Context):
    """``(profiles, profile numbers or None)`` for an ieee-elv scenario, None for own loads."""
    from popdispatch.errors import ProfileError
    from popdispatch.sweep.assign import assigned_profiles, official_profiles

    if scenario.own_loads:
        return None, None
    if scenario.assignment.seed is None:
        if context.profiles is None:
            from popdispatch.runs import load_profiles

            return load_profiles(None), None
        return official_profiles(context.profiles), None
    if context.profiles is None:
        raise ProfileError(
            "random profile assignments need the official profiles: --profiles DIR or "
            "POPDISPATCH_PROFILES"
        )
    a = scenario.assignment
    return assigned_profiles(context.profiles, a.seed, a.draw)


def parameters(scenario: Scenario) -> dict:
    """The scenario's own columns of the summary row."""
    return {
        "scenario_index": scenario.index,
        "case": scenario.feeder_label,
        "steps": scenario.steps.label,
        "mode": scenario.mode,
        "dynamics": scenario.dynamics,
        "graph": scenario.graph,
        "x0": scenario.x0,
        "limits": scenario.limits_label,
        "events": scenario.events_label,
        "assignment": scenario.assignment.label,
    }


def summary_row(summary: dict, result) -> dict:
    """The ``day`` summary (:func:`popdispatch.report.summaries.day_summary`) as one flat row:
    nested objects as JSON text (``*_json``), plus the cost gap and iteration counts."""
    row = {}
    for key, value in summary.items():
        if key in DROPPED_KEYS:
            continue
        as_json = isinstance(value, dict) or key in JSON_KEYS
        row[f"{key}_json" if as_json else key] = json.dumps(value) if as_json else value
    if summary["cost_eur"] is not None and summary["opf_cost_eur"] is not None:
        row["cost_gap_eur"] = summary["cost_eur"] - summary["opf_cost_eur"]
    row["mean_iterations"] = float(np.mean(result.run.iterations))
    row["max_iterations"] = int(np.max(result.run.iterations))
    return row


def steps_table(result, problem) -> pd.DataFrame:
    """The day's per-minute table (:func:`popdispatch.report.summaries.day_table`) in long
    form: one row per minute and generator (minute-major, generators in the problem's order),
    with each minute's status."""
    from popdispatch.report.summaries import day_table, generator_buses

    wide = day_table(result, problem)
    run = result.run
    status = np.where(run.converged, "converged", "not_converged").astype(object)
    if run.stalled is not None:
        status[run.stalled] = "stalled"
    status[~result.feasible] = "infeasible"
    wide["status"] = status
    names = list(run.generators)
    own = [f"{g}_{kind}_kw" for kind in ("setpoint", "opf") for g in names]
    shared = wide.drop(columns=own)
    n = len(names)
    table = pd.DataFrame({c: np.repeat(shared[c].to_numpy(), n) for c in shared.columns})
    table["generator"] = np.tile(np.array(names, dtype=object), len(wide))
    table["bus"] = np.tile(generator_buses(problem), len(wide))
    table["setpoint_kw"] = run.setpoints_kw.ravel()  # minutes x generators, row-major
    table["opf_kw"] = result.opf_kw.ravel()
    table["abs_error_kw"] = result.abs_error_kw.ravel()
    return table


def run_scenario(scenario: Scenario, context: Context) -> tuple[dict, pd.DataFrame]:
    """``(summary row, steps table)`` of one scenario; raises whatever the run raises."""
    from popdispatch.events import event_label
    from popdispatch.report.summaries import day_summary
    from popdispatch.report.text import infeasible_day_message
    from popdispatch.runs import load_problem, run_day_vs_opf

    profiles, numbers = scenario_profiles(scenario, context)
    minutes = scenario.steps.minutes()
    problem = load_problem(profiles, scenario.limits, scenario.source(), scenario.events, minutes)
    result = run_day_vs_opf(problem, scenario.settings(), minutes)
    summary = day_summary(
        problem, result, scenario.limits, [event_label(e) for e in scenario.events]
    )
    row = summary_row(summary, result)
    row["profile_numbers"] = numbers
    if summary["infeasible_minutes"]:
        row["error"] = infeasible_day_message(summary)
    return row, steps_table(result, problem)


def _now() -> datetime:
    return datetime.now(UTC)


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def run_and_store(scenario: Scenario, context: Context) -> dict:
    """Run one scenario and write its results (:func:`popdispatch.sweep.store.write_scenario`);
    a scenario that raises is written as ``failed`` with its one-line message. Returns what
    the driver needs: ``{"id", "status", "error", "scenario_seconds"}``."""
    started, clock = _now(), time.perf_counter()
    steps = None
    try:
        row, steps = run_scenario(scenario, context)
    except Exception as exc:  # a scenario's problem never stops the sweep
        message = " ".join(str(exc).split()) or type(exc).__name__
        row = {"status": FAILED, "error": f"{type(exc).__name__}: {message}"}
    row.update(parameters(scenario))
    row.update(
        scenario_seconds=time.perf_counter() - clock,
        worker=worker_name(),
        started_at=started,
        finished_at=_now(),
    )
    write_scenario(Path(context.out), scenario.id, row, steps)
    return {key: row.get(key) for key in ("status", "error", "scenario_seconds")} | {
        "id": scenario.id
    }
