"""``day --ac-correct``: the AC-corrected voltage-aware dispatch at every step of a series.

Each step runs the outer loop of :mod:`popdispatch.ac.correct` (rounds of the voltage mode,
each followed by one batch of AC power flows that measures the voltage offsets, the losses
and the loss penalty factors at its dispatch) until the corrected model's voltages at the
dispatch equal the AC ones and the AC voltages keep the limits, both within ``tol_pu``
(:func:`popdispatch.ac.correct.settled`). A step starts from the step before, as an
online controller would:

- its first round uses the corrections measured at the previous step's final dispatch (the
  offsets, losses and penalty factors of a minute ago), so where the loads move slowly the
  first round's dispatch already keeps the AC limits and the step needs one round;
- the dynamics continue from the previous round's shares and controller prices, with the
  day's warm start (:mod:`popdispatch.warm_start`) placing the demand step, as in the day loop.

The penalty factors change every generator's cost at every step, which the compiled day loop
holds fixed for a day, so each round runs one step on an :class:`~popdispatch.online.Engine`
of its corrected problem (cheap to build; its kernels are the day's, compiled once). Each
step's status is the distance certificate's verdict against its corrected problem's
LinDistFlow OPF, as for a minute of a day.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from popdispatch.ac.correct import (
    ROUNDS,
    TOL_PU,
    Corrections,
    Meter,
    Rows,
    ac_miss_pu,
    settled,
    true_cost,
)
from popdispatch.ac.limits import limits_summary, miss_columns
from popdispatch.constants import KW_PER_MW
from popdispatch.errors import OptionError
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import Status
from popdispatch.online import Engine, RunSettings, initial_shares, verdicts
from popdispatch.online.day import DayArrays

#: Per-step columns of :attr:`CorrectedDay.steps` besides the AC check's (units in the names).
STEP_COLUMNS = [
    "status", "rounds", "power_flows", "iterations", "seconds", "model_error_pu", "settled",
    "distance_bound_kw", "accuracy_kw", "cost_eur_per_h",
]  # fmt: skip
#: The AC check's per-step columns kept for the corrected dispatch.
AC_COLUMNS = [
    "losses_kw", "source_extra_kw", "v_min_pu", "v_min_bus", "v_max_pu", "v_max_bus",
]  # fmt: skip


@dataclass(frozen=True)
class CorrectedDay:
    """The AC-corrected dispatch of every step (:func:`ac_correct_day`).

    Attributes
    ----------
    generators : names, the order of ``setpoints_kw``'s columns.
    setpoints_kw : (steps, generators) the final dispatch of each step, kW.
    steps : index ``minute``; :data:`STEP_COLUMNS` (``status`` as a string; ``rounds``:
        voltage-mode runs; ``power_flows``: AC power flows; ``iterations``: of the dynamics,
        over the rounds; ``seconds``: wall time of the step, runs and power flows;
        ``model_error_pu``: the corrected model's error at the final dispatch, p.u.;
        ``settled``: the loop's test passed, :func:`popdispatch.ac.correct.settled`;
        ``distance_bound_kw``/``accuracy_kw``: the certificate against the corrected problem;
        ``cost_eur_per_h``: original costs, the source's AC supply included) and the AC
        check's :data:`AC_COLUMNS` at the final dispatch, then ``below_vmin_pu`` /
        ``above_vmax_pu`` (:func:`popdispatch.ac.limits.miss_columns`).
    stall_reasons : 1-based step -> why its final run came to rest without the proof.
    vmin_pu, vmax_pu : the limits (0 / 2: no bound); ``tolerance_pu``, ``max_rounds``: the
        loop's.
    """

    generators: pd.Index
    setpoints_kw: np.ndarray
    steps: pd.DataFrame
    vmin_pu: float
    vmax_pu: float
    tolerance_pu: float
    max_rounds: int
    stall_reasons: dict[int, str] = field(default_factory=dict)

    @property
    def status(self) -> str:
        """As a day's: ``infeasible`` if any step was, ``converged`` if every step converged,
        ``stalled`` if some step came to rest unproved, else ``not_converged``."""
        status = self.steps["status"]
        if (status == "infeasible").any():
            return "infeasible"
        if (status == "converged").all():
            return "converged"
        return "stalled" if (status == "stalled").any() else "not_converged"

    def summary(self, step_hours: np.ndarray | None = None) -> dict:
        """The day's ``ac_correct`` JSON object: the status and step counts (the steps whose
        corrected problem is infeasible in ``infeasible_minutes``), the cost of the
        loop per step (rounds, AC power flows, seconds: median and largest), the worst model
        error and certificate bound, the AC extremes, losses and source supply (kWh) and cost
        (EUR; ``step_hours``: each step's duration, h, default one minute) of the corrected
        dispatch, and the ``voltage_limits`` verdict of its AC voltages."""
        s = self.steps
        hours = np.full(len(s), 1 / 60) if step_hours is None else np.asarray(step_hours, float)
        low, high = s["v_min_pu"].astype(float).idxmin(), s["v_max_pu"].astype(float).idxmax()
        bound = s["distance_bound_kw"].astype(float)
        return {
            "status": self.status,
            "steps": len(s),
            "converged_steps": int((s["status"] == "converged").sum()),
            "infeasible_minutes": [int(m) for m in s.index[s["status"] == "infeasible"]],
            "settled_steps": int(s["settled"].sum()),
            "tolerance_pu": self.tolerance_pu,
            "max_rounds": self.max_rounds,
            "rounds": int(s["rounds"].sum()),
            "rounds_per_step_median": float(s["rounds"].median()),
            "rounds_per_step_max": int(s["rounds"].max()),
            "power_flows": int(s["power_flows"].sum()),
            "power_flows_per_step_median": float(s["power_flows"].median()),
            "seconds": float(s["seconds"].sum()),
            "seconds_per_step_median": float(s["seconds"].median()),
            "max_model_error_pu": float(s["model_error_pu"].max()),
            "max_distance_bound_kw": None if bound.isna().any() else float(bound.max()),
            "ac_v_min_pu": float(s.at[low, "v_min_pu"]),
            "ac_v_min_bus": _plain(s.at[low, "v_min_bus"]),
            "ac_v_min_minute": int(low),
            "ac_v_max_pu": float(s.at[high, "v_max_pu"]),
            "ac_v_max_bus": _plain(s.at[high, "v_max_bus"]),
            "ac_v_max_minute": int(high),
            "losses_kwh": float(s["losses_kw"].to_numpy(float) @ hours),
            "source_extra_kwh": float(s["source_extra_kw"].to_numpy(float) @ hours),
            "cost_eur": float(s["cost_eur_per_h"].to_numpy(float) @ hours),
            "stall_reasons": {str(m): r for m, r in self.stall_reasons.items()},
            "voltage_limits": limits_summary(s, self.vmin_pu, self.vmax_pu, self.tolerance_pu),
        }

    def columns(self) -> pd.DataFrame:
        """Per step for ``day.csv`` (index ``minute``), every column prefixed ``ac_correct_``:
        the set points (``ac_correct_<generator>_setpoint_kw``) and :attr:`steps`."""
        points = pd.DataFrame(
            self.setpoints_kw,
            index=self.steps.index,
            columns=[f"{g}_setpoint_kw" for g in self.generators],
        )
        return pd.concat([points, self.steps], axis=1).add_prefix("ac_correct_")


def ac_correct_day(
    problem: DispatchProblem,
    load_kw: np.ndarray,
    minutes: Sequence[int] | None = None,
    settings: RunSettings | None = None,
    *,
    rounds: int = ROUNDS,
    tol_pu: float = TOL_PU,
    progress: Callable[[int], None] | None = None,
    **model_options,
) -> CorrectedDay:
    """The AC-corrected voltage-aware dispatch of every step of ``minutes`` (module docstring).

    ``problem``: with voltage rows (:func:`popdispatch.runs.with_voltage`) and ``settings``
    with the same limits (the voltage mode); ``load_kw``: (steps, loads) per-load demand of
    the steps, kW, feeder order; ``minutes``: 1-based steps in order (default all);
    ``rounds``: at most this many voltage-mode runs per step; ``tol_pu``: a step is settled
    when the corrected model's voltages at its dispatch are within this of the AC ones and
    the AC voltages within this of the limits (p.u., :func:`popdispatch.ac.correct.settled`);
    ``progress``: called with each step once done; ``model_options``: of the AC model
    (:func:`popdispatch.ac.check_setpoints`)."""
    from popdispatch.compare import check_voltage

    settings = settings or RunSettings()
    check_voltage(problem, settings)
    if rounds < 1 or not tol_pu > 0.0:
        raise OptionError(f"the AC correction needs rounds >= 1 and tol_pu > 0 (got {rounds}, "
                          f"{tol_pu})", "--ac-correct")  # fmt: skip
    minutes = np.arange(1, len(problem.demand) + 1) if minutes is None else np.asarray(minutes)
    minutes = minutes.astype(np.int64)
    loads = np.atleast_2d(np.asarray(load_kw, dtype=float))
    stepper = _Stepper(problem, settings, int(minutes[0]), rounds, tol_pu, model_options)
    points, rows, reasons = [], [], {}
    for minute, step_loads in zip(minutes, loads, strict=True):
        p_kw, row, reason = stepper.step(int(minute), step_loads)
        points.append(p_kw)
        rows.append(row)
        if reason:
            reasons[int(minute)] = reason
        if progress is not None:
            progress(int(minute))
    steps = pd.DataFrame(rows, index=pd.Index(minutes, name="minute"))
    steps = steps.join(miss_columns(steps, problem.vmin_pu, problem.vmax_pu))
    return CorrectedDay(problem.generators, np.array(points), steps, problem.vmin_pu,
                        problem.vmax_pu, tol_pu, rounds, reasons)  # fmt: skip


class _Stepper:
    """The state one step hands the next: shares, controller states, the integrator's step,
    the last demand run and the corrections measured at the last dispatch."""

    def __init__(self, problem, settings, first_minute, rounds, tol_pu, model_options):
        self.problem, self.settings = problem, settings
        self.rounds, self.tol_pu = rounds, tol_pu
        self.meter, self.rows = Meter(problem, **model_options), Rows(problem)
        self.corrections = Corrections.none(problem)
        self.x = initial_shares(problem, settings.x0, first_minute)
        engine = Engine(problem, settings)
        engine.warm_up(self.x, first_minute)  # compile outside the timed steps
        self.z, self.h_try, self.last_demand = engine.z, engine.h_try, 0.0

    def step(self, minute: int, load_kw: np.ndarray) -> tuple[np.ndarray, dict, str | None]:
        """One step's rounds: its final set points (kW), its row of :attr:`CorrectedDay.steps`
        and why it stalled (None)."""
        start = time.perf_counter()
        iterations = 0
        for done in range(1, self.rounds + 1):
            engine, status, p_mw, ran = self._run(minute)
            iterations += ran
            measured = self.meter.measure(load_kw, p_mw * KW_PER_MW, minute)
            self.corrections, error = self.corrections.updated(
                engine.problem, minute, p_mw, measured
            )
            miss = ac_miss_pu(measured.v_sq, self.problem.vmin_pu, self.problem.vmax_pu)
            done_now = settled(error, miss, self.tol_pu)
            if done_now or done == self.rounds or status == Status.INFEASIBLE:
                break
        verdict = verdicts(engine, np.array([minute]), p_mw[None], self.z[None],
                            np.array([status == Status.CONVERGED]),
                            np.array([status == Status.INFEASIBLE]))  # fmt: skip
        p_kw = p_mw * KW_PER_MW
        ac = measured.day().steps.iloc[0]
        reason = verdict.reasons[0]
        row = {
            "status": verdict.status(0, status),
            "rounds": done,
            "power_flows": done * len(measured.generator_kw),
            "iterations": iterations,
            "seconds": time.perf_counter() - start,
            "model_error_pu": error,
            "settled": done_now,
            "distance_bound_kw": float(verdict.bound_kw[0]),
            "accuracy_kw": float(verdict.accuracy_kw[0]),
            "cost_eur_per_h": true_cost(self.problem, p_kw, float(ac["source_extra_kw"])),
            **{column: ac[column] for column in AC_COLUMNS},
        }
        return p_kw, row, reason

    def _run(self, minute: int) -> tuple[Engine, Status, np.ndarray, int]:
        """One voltage-mode run of ``minute`` on its problem corrected as measured last,
        continuing the shares and prices: ``(engine, status, set points MW, iterations)``."""
        current = self.rows.problem(minute, self.corrections)
        engine = Engine(current, self.settings)
        engine.z, engine.h_try = self.z, self.h_try
        out = DayArrays.empty(1, current.n_generators, len(self.z))
        out.last_demand = self.last_demand
        engine.run_day_chunk(self.x, np.array([minute]), out)
        self.z, self.h_try = engine.z, engine.h_try
        self.last_demand = float(current.demand[minute - 1])
        status = Status(int(out.status[0]))
        return engine, status, out.setpoints[0].copy(), int(out.iterations[0])


def _plain(value):
    """A bus id as JSON (numpy integers as int)."""
    return value.item() if isinstance(value, np.generic) else value
