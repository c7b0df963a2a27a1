"""Summaries of results as plain dicts (the CLI's ``--json`` objects) and time-series tables.

Powers are in kW, energies in kWh, costs in EUR (a day) or EUR/h (one minute's dispatch, Table
I's coefficients applied to MW). Key names carry their units. See docs/cli.md, "JSON output".

Deprecated keys: ``cost``, ``opf_cost`` and ``cost_all_minutes`` meant EUR/h in a snapshot or
DC-OPF summary and EUR in a day summary (with ``cost_unit`` saying which). Their unit-named
twins carry the same values: ``cost_eur_per_h`` and ``opf_cost_eur_per_h`` (``opf``,
``snapshot``), ``cost_eur``, ``opf_cost_eur`` and ``cost_all_minutes_eur`` (``day``). The old
keys (and ``cost_unit``) stay for one release and will then be removed; new code should read
the unit-named keys.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from popdispatch.compare import DayComparison, SnapshotComparison
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import Timeline, day_timeline
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.opf import OpfResult
from popdispatch.report.infeasibility import diagnose

#: Set points closer than this to the DC-OPF count as "on the DC-OPF", kW.
MATCH_KW = 0.1


#: A set point further than this outside its limits is flagged (``outside_limits``), kW.
LIMIT_TOLERANCE_KW = 1e-3


def _limits(
    limits: Sequence[tuple[int, int, float]], problem: DispatchProblem | None = None
) -> list[dict]:
    """The ``--limit`` options as given, with the number of original lines each one limits."""
    rows = []
    for a, b, kw in limits:
        row = {"from_bus": a, "to_bus": b, "limit_kw": kw}
        if problem is not None:
            row["lines_on_path"] = len(problem.feeder.original.path_lines(a, b))
        rows.append(row)
    return rows


#: A limited line counts as binding where the DC-OPF's flow is within this of its limit, kW.
BINDING_KW = 1e-3


def limits_in_force(
    problem: DispatchProblem,
    limits: Sequence[tuple[int, int, float]] = (),
    opf_kw: np.ndarray | None = None,
    minutes: Sequence[int] = (),
) -> list[dict]:
    """Every line limit the run applies, one row per limited line of the reduced feeder (the
    problem's order): ``from_bus`` and ``to_bus`` (its key-node ends, as the source format
    names them), ``limit_kw``, ``source`` (``"--limit"``: one of ``limits``, the path limits
    given; ``"rating"``: the network's own rating of an original line, see the readers),
    ``element`` (the option as given, ``A:B=KW``, or the rated original line's name) and
    ``binding_minutes``: at how many of ``minutes`` (1-based) the DC-OPF set points
    ``opf_kw`` (kW, one row per minute; NaN where infeasible) carry the line within
    :data:`BINDING_KW` of its limit (null without them). A reduced line holds the tightest
    limit of the original lines it merges; a ``--limit`` equal to a rating is named as the
    ``--limit``."""
    original = problem.feeder.original
    rows = problem.feeder.lines.iloc[np.asarray(problem.lines, dtype=int)]
    option_of = _limit_options(original, limits)
    line_map = problem.feeder.line_map
    merged_into = pd.Series(line_map.index).groupby(line_map.to_numpy()).agg(list)
    original_kw = original.lines.limit_kw
    ends = source_bus_ids(original, np.concatenate([rows.from_bus, rows.to_bus]))
    binding = _binding_minutes(problem, opf_kw, minutes)
    out = []
    for k, (line, row) in enumerate(zip(problem.lines, rows.itertuples(), strict=True)):
        tightest = [name for name in merged_into[line] if original_kw[name] == row.limit_kw]
        options = [option_of[name] for name in tightest if name in option_of]
        out.append({
            "from_bus": ends[k], "to_bus": ends[len(rows) + k], "limit_kw": float(row.limit_kw),
            "source": "--limit" if options else "rating",
            "element": options[0] if options else str(tightest[0]),
            "binding_minutes": None if binding is None else int(binding[k]),
        })  # fmt: skip
    return out


def _binding_minutes(problem: DispatchProblem, opf_kw, minutes) -> np.ndarray | None:
    """Per limited line, the minutes where the DC-OPF holds it at its limit (None: no OPF)."""
    if opf_kw is None:
        return None
    p_mw = np.atleast_2d(np.asarray(opf_kw, dtype=float)) / KW_PER_MW
    rows = np.asarray(minutes, dtype=np.int64) - 1
    flows_kw = (problem.line_load_flow[rows] - p_mw @ problem.down.T) * KW_PER_MW
    with np.errstate(invalid="ignore"):
        at_limit = np.abs(flows_kw) >= problem.limit * KW_PER_MW - BINDING_KW
    return at_limit.sum(axis=0)


def _limit_options(original: Feeder, limits: Sequence[tuple[int, int, float]]) -> dict[str, str]:
    """Original line name -> the ``--limit`` (``A:B=KW``) that sets its limit (the tightest
    one where several cover it)."""
    set_by: dict[str, tuple[float, str]] = {}
    for a, b, kw in limits:
        for name in original.path_lines(a, b):
            if name not in set_by or kw < set_by[name][0]:
                set_by[name] = (kw, f"{a}:{b}={kw:g}")
    return {name: option for name, (_, option) in set_by.items()}


def _why(problem: DispatchProblem, minute: int, opf: OpfResult, in_force: list[dict]):
    """Why ``minute`` has no DC-OPF (:func:`~popdispatch.report.infeasibility.diagnose`);
    ``None`` where it has one."""
    return None if opf.status == "optimal" else diagnose(problem, minute, in_force)


def setpoint_bounds_kw(problem: DispatchProblem, online: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(lower, upper)`` limits (kW) of the set points given the online flags (offline: 0)."""
    lower = np.where(online, problem.pmin, 0.0) * KW_PER_MW
    return lower, np.where(online, problem.pmax, 0.0) * KW_PER_MW


def distance_outside_limits_kw(
    problem: DispatchProblem, p_kw: np.ndarray, online: np.ndarray
) -> np.ndarray:
    """How far (kW, >= 0) set points ``p_kw`` (kW, (..., generators)) lie outside their limits."""
    lower, upper = setpoint_bounds_kw(problem, online)
    return np.maximum(np.maximum(lower - p_kw, p_kw - upper), 0.0)


def outside_limits(problem: DispatchProblem, p_kw: np.ndarray, online: np.ndarray) -> np.ndarray:
    """Where set points ``p_kw`` (kW, (..., generators)) lie more than
    :data:`LIMIT_TOLERANCE_KW` outside their limits (the paper's barrier can be overpowered)."""
    return distance_outside_limits_kw(problem, p_kw, online) > LIMIT_TOLERANCE_KW


def _timeline(problem: DispatchProblem, timeline: Timeline | None) -> Timeline:
    """The run's timeline; default one-minute steps of an undated day (the ELV day)."""
    return timeline if timeline is not None else day_timeline(len(problem.demand))


def _per_hour(hours: np.ndarray) -> float | None:
    """Steps per hour when every step lasts the same (60 for one-minute steps), else None."""
    if len(hours) == 0 or not np.allclose(hours, hours[0], rtol=0, atol=1e-12):
        return None
    per_hour = 1.0 / float(hours[0])
    return float(round(per_hour)) if abs(per_hour - round(per_hour)) < 1e-9 else per_hour


def _energy(values: np.ndarray, hours: np.ndarray) -> np.ndarray:
    """Energy of per-step powers ``values`` (steps, ...) lasting ``hours`` each: kW -> kWh,
    EUR/h -> EUR (a regular series divides the sum by the steps per hour)."""
    per_hour = _per_hour(hours)
    if per_hour is not None:
        return values.sum(axis=0) / per_hour
    return np.tensordot(hours, values, axes=(0, 0))


def _time_keys(timeline: Timeline, step: int) -> dict:
    """``step`` and ``time`` (ISO 8601, the start of the step's interval) of one step."""
    return {"step": int(step), "time": timeline.label(step)}


def _finite(value) -> float | None:
    """A float, or None where it is NaN or infinite (JSON's null: unknown)."""
    return float(value) if value is not None and np.isfinite(value) else None


def fixed_injection_kw(problem: DispatchProblem, minutes) -> list[float]:
    """The fixed injections' total output (kW) at each 1-based step of ``minutes``: generators
    without cost data following their profiles (0 where the network has none)."""
    fixed = getattr(problem, "fixed_injection", np.zeros(0))
    rows = np.asarray(minutes, dtype=np.int64) - 1
    return (fixed[rows] * KW_PER_MW).tolist() if len(fixed) else [0.0] * len(rows)


def _fixed_energy_kwh(problem: DispatchProblem, minutes, timeline: Timeline) -> float:
    """Energy of the fixed injections over ``minutes`` (kWh; each step its own length)."""
    kw = np.array(fixed_injection_kw(problem, minutes))
    return float(_energy(kw, timeline.hours[np.asarray(minutes) - 1]))


def generator_buses(problem: DispatchProblem) -> list[int | str]:
    """Original bus of every generator, in the problem's generator order, as the source format
    names it (:func:`source_bus_ids`)."""
    return source_bus_ids(problem.feeder.original, problem.feeder.generators.bus)


def source_bus_ids(feeder: Feeder, buses) -> list[int | str]:
    """The source format's ids of ``feeder``'s ``buses``: the bus numbers, or, where the format
    names its buses (OpenDSS), every bus by its name (a string, ``"650"`` too: one JSON type
    per network)."""
    return feeder.bus_labels(buses)


def opf_summary(
    problem: DispatchProblem,
    opf: OpfResult,
    limits: Sequence[tuple[int, int, float]] = (),
    timeline: Timeline | None = None,
) -> dict:
    """The DC-OPF of one minute (``step``: the same 1-based step; ``time``: its start, ISO
    8601, from ``timeline``, default a day of minutes)."""
    buses = generator_buses(problem)
    online = problem.online[opf.minute - 1]
    in_force = limits_in_force(problem, limits, opf.p_kw, [opf.minute])
    return {
        "status": opf.status,
        "minute": opf.minute,
        **_time_keys(_timeline(problem, timeline), opf.minute),
        "demand_kw": opf.demand_kw,
        "fixed_injection_kw": fixed_injection_kw(problem, [opf.minute])[0],
        "capacity_kw": float(np.where(online, problem.pmax, 0.0).sum() * KW_PER_MW),
        "case": problem.feeder.original.name,
        "profile_source": problem.profile_source,
        "limits": _limits(limits, problem),
        "limits_in_force": in_force,
        "infeasibility": _why(problem, opf.minute, opf, in_force),
        "generators": [
            {"name": name, "bus": bus, "p_kw": _finite(p)}
            for name, bus, p in zip(problem.generators, buses, opf.p_kw, strict=True)
        ],
        "cost_eur_per_h": _finite(opf.cost),
        "cost": _finite(opf.cost),  # deprecated: cost_eur_per_h
        "cost_unit": "EUR/h",  # deprecated with cost
        "marginal_price_eur_per_mwh": _finite(opf.marginal_price),
    }


def snapshot_status(result: SnapshotComparison) -> str:
    """``infeasible`` (no DC-OPF exists), ``converged``, ``stalled`` (at rest at a state that
    fails the DC-OPF's KKT check, exact mode; see ``SnapshotResult``) or ``not_converged``."""
    if result.opf.status != "optimal":
        return "infeasible"
    status = result.run.status
    return status if status in ("converged", "stalled") else "not_converged"


def snapshot_summary(
    problem: DispatchProblem,
    result: SnapshotComparison,
    limits: Sequence[tuple[int, int, float]] = (),
    timeline: Timeline | None = None,
) -> dict:
    """One minute of dynamics compared with the DC-OPF (null where the DC-OPF is infeasible).
    ``step`` and ``time`` as in :func:`opf_summary`.

    ``status`` is the comparison's (``infeasible``: no DC-OPF exists); ``dynamics_status``
    the run's own (``infeasible`` there: exact mode's line prices ran away). A generator's
    ``outside_limits`` flags a set point more than :data:`LIMIT_TOLERANCE_KW` outside
    ``[pmin_kw, pmax_kw]`` (the limits in force at that minute; 0 when offline).
    """
    run, opf = result.run, result.opf
    settings = run.settings
    online = problem.online[run.minute - 1]
    outside = outside_limits(problem, run.setpoints_kw, online)
    error = result.max_abs_error_kw if opf.status == "optimal" else None
    cost = float(_cost(problem, run.setpoints_kw))
    in_force = limits_in_force(problem, limits, opf.p_kw, [run.minute])
    return {
        "status": snapshot_status(result),
        "dynamics_status": run.status,
        "minute": run.minute,
        **_time_keys(_timeline(problem, timeline), run.minute),
        "demand_kw": run.demand_kw,
        "fixed_injection_kw": fixed_injection_kw(problem, [run.minute])[0],
        "capacity_kw": float(setpoint_bounds_kw(problem, online)[1].sum()),
        "case": problem.feeder.original.name,
        "mode": settings.mode,
        "dynamics": settings.dynamics,
        "x0": settings.x0_label(),
        "graph": settings.graph if isinstance(settings.graph, str) else "custom",
        "profile_source": run.profile_source,
        "limits": _limits(limits, problem),
        "limits_in_force": in_force,
        "infeasibility": _why(problem, run.minute, opf, in_force),
        "generators": _snapshot_generators(problem, run.setpoints_kw, opf.p_kw, online),
        "generators_outside_limits": list(problem.generators[outside]),
        "iterations": run.iterations,
        "converged_iteration": run.converged_at,
        "rest_iteration": getattr(run, "rest_at", None),
        "stall_reason": getattr(run, "stall_reason", None),
        "distance_bound_kw": _finite(getattr(run, "distance_bound_kw", None)),
        "accuracy_kw": getattr(run, "accuracy_kw", None),
        "first_congestion_iteration": run.first_congestion,
        "max_overflow_kw": float(run.overflow_kw.max()) if run.overflow_kw.size else 0.0,
        **snapshot_prices(problem, run, opf),
        "max_abs_error_kw": _finite(error),
        "cost_eur_per_h": cost,
        "opf_cost_eur_per_h": _finite(opf.cost),
        "cost": cost,  # deprecated: cost_eur_per_h
        "opf_cost": _finite(opf.cost),  # deprecated: opf_cost_eur_per_h
        "cost_unit": "EUR/h",  # deprecated with cost
        "wall_seconds": run.wall_seconds,
    }


def limited_line_buses(problem: DispatchProblem) -> list[tuple[int | str, int | str]]:
    """``(from_bus, to_bus)`` of each limited line (the reduced feeder's, named as the source
    format names its buses, :func:`source_bus_ids`)."""
    lines = problem.feeder.lines.iloc[np.asarray(problem.lines, dtype=int)]
    original = problem.feeder.original
    ends = zip(original.bus_labels(lines.from_bus), original.bus_labels(lines.to_bus), strict=True)
    return list(ends)


def snapshot_prices(problem: DispatchProblem, run, opf: OpfResult) -> dict:
    """``line_prices`` (per limited line: ``from_bus``, ``to_bus``) and ``voltage_prices``
    (per monitored bus: ``bus``), each with ``price_eur_per_mwh``, the price the run's
    controllers broadcast at its end state, and ``opf_price_eur_per_mwh``, the DC-OPF's
    (LinDistFlow OPF's) dual of the same row (null where infeasible); EUR/MWh. A line's price
    is ``mu_up - mu_down`` (positive: the flow towards the leaves binds), a bus's ``mu_lo -
    mu_hi`` per MW equivalent (positive: vmin binds; docs/voltage.md). Both lists are null in
    a mode without price controllers (paper mode)."""
    line = getattr(run, "line_price_eur_per_mwh", None)
    voltage = getattr(run, "voltage_price_eur_per_mwh", None)
    if line is None:
        return {"line_prices": None, "voltage_prices": None}
    feasible = opf.status == "optimal"
    lines = [
        {"from_bus": a, "to_bus": b, "price_eur_per_mwh": float(price),
         "opf_price_eur_per_mwh": _finite(dual) if feasible else None}
        for (a, b), price, dual in zip(limited_line_buses(problem), line, opf.line_price,
                                       strict=True)
    ]  # fmt: skip
    buses = [
        {"bus": bus, "price_eur_per_mwh": float(price),
         "opf_price_eur_per_mwh": _finite(dual) if feasible else None}
        for bus, price, dual in zip(problem.feeder.original.bus_labels(problem.voltage_buses),
                                    voltage, opf.voltage_price, strict=True)
    ]  # fmt: skip
    return {"line_prices": lines, "voltage_prices": buses}


def _snapshot_generators(
    problem: DispatchProblem, setpoints_kw: np.ndarray, opf_kw: np.ndarray, online: np.ndarray
) -> list[dict]:
    """Per generator: set point, DC-OPF (null if none), limits in force, outside-limits flag."""
    lower, upper = setpoint_bounds_kw(problem, online)
    outside = outside_limits(problem, setpoints_kw, online)
    columns = zip(
        problem.generators, generator_buses(problem), setpoints_kw, opf_kw, lower, upper, outside,
        strict=True,
    )  # fmt: skip
    return [
        {
            "name": name,
            "bus": bus,
            "setpoint_kw": float(sp),
            "opf_kw": _finite(p),
            "pmin_kw": float(lo),
            "pmax_kw": float(hi),
            "outside_limits": bool(out),
        }
        for name, bus, sp, p, lo, hi, out in columns
    ]


def _cost(problem: DispatchProblem, p_kw: np.ndarray) -> float:
    p = np.asarray(p_kw) / 1000.0
    return float(np.sum(problem.a + problem.b * p + problem.c * p**2))


def day_status(result: DayComparison) -> str:
    """``infeasible`` if some minute has no DC-OPF, ``converged`` if every minute converged
    (a stalled minute never counts), ``stalled`` if some minute came to rest away from the
    DC-OPF (see ``DayResult``), else ``not_converged``."""
    if any(o.status != "optimal" for o in result.opf):
        return "infeasible"
    status = result.run.status
    return status if status in ("converged", "stalled") else "not_converged"


def day_summary(
    problem: DispatchProblem,
    result: DayComparison,
    limits: Sequence[tuple[int, int, float]] = (),
    events: Sequence[str] = (),
    timeline: Timeline | None = None,
) -> dict:
    """An online day compared minute by minute with the DC-OPF (energies kWh, costs EUR).

    A "minute" is a 1-based step of the series (``timeline``: when each starts and how long it
    lasts; default a day of one-minute steps): ``steps``, ``first_step`` and ``last_step``
    repeat ``minutes``, ``first_minute`` and ``last_minute``; ``first_time`` and ``last_time``
    are the starts of the first and last steps (ISO 8601), ``step_minutes`` the step length
    (null if the steps differ). Energies and costs weigh each step by its duration.

    Every simulated minute is reported. ``infeasible_minutes`` (1-based) are those whose DC-OPF
    is infeasible; errors, ``energy_kwh``/``opf_energy_kwh`` and ``cost_eur``/``opf_cost_eur``
    compare the dynamics with the DC-OPF over the other ``compared_minutes`` only (null when
    there are none); ``energy_all_minutes_kwh`` and ``cost_all_minutes_eur`` are the dynamics'
    own over every simulated minute (deprecated twins: see the module docstring).
    ``price_runaway_minutes``: where exact mode's own infeasibility signal fired (line prices
    past their cap); the DC-OPF's verdict is the one that counts.
    ``max_abs_price_gap_eur_per_mwh``: the largest difference between the run's own line and
    voltage prices and the DC-OPF's duals over the converged minutes with a DC-OPF (EUR/MWh;
    null in paper mode or without such minutes; per minute in ``day.csv``, see
    :func:`price_columns`).
    ``minutes_outside_limits`` (and ``..._by_generator``) count minutes with a set point more
    than :data:`LIMIT_TOLERANCE_KW` outside its limits, ``max_outside_limits_kw`` the worst.
    """
    run = result.run
    settings = run.settings
    timeline = _timeline(problem, timeline)
    first, last = int(run.minutes[0]), int(run.minutes[-1])
    in_force = limits_in_force(problem, limits, result.opf_kw, run.minutes)
    bad = result.infeasible_minutes
    return {
        "status": day_status(result),
        "minutes": len(run.minutes),
        "first_minute": first,
        "last_minute": last,
        "steps": len(run.minutes),
        "first_step": first,
        "last_step": last,
        "first_time": timeline.label(first),
        "last_time": timeline.label(last),
        "step_minutes": timeline.step_minutes,
        "case": problem.feeder.original.name,
        "profile_source": run.profile_source,
        "fixed_injection_kwh": _fixed_energy_kwh(problem, run.minutes, timeline),
        "mode": settings.mode,
        "dynamics": settings.dynamics,
        "x0": settings.x0_label(),
        "warm_start": settings.warm_start_policy,
        "graph": settings.graph if isinstance(settings.graph, str) else "custom",
        "limits": _limits(limits, problem),
        "limits_in_force": in_force,
        "events": list(events),
        "infeasible_minutes": bad,
        "infeasibility": diagnose(problem, bad[0], in_force) if bad else None,
        "price_runaway_minutes": _runaway_minutes(run),
        "stalled_minutes": sorted(int(m) for m in getattr(run, "stall_reasons", {})),
        "converged_minutes": int(run.converged.sum()),
        **_certificate_keys(run),
        "max_abs_price_gap_eur_per_mwh": max_price_gap(result),
        **_day_comparison(problem, result, timeline.hours[run.minutes - 1]),
        "max_overflow_kw": float(run.overflow_kw.max()) if run.overflow_kw.size else 0.0,
        "wall_seconds": run.wall_seconds,
    }


def _certificate_keys(run) -> dict:
    """The day's distance certificate: the largest bound any minute proves on its distance to
    the DC-OPF (``max_distance_bound_kw``; null where a minute proves nothing, or in paper
    mode) and the smallest accuracy a minute had to prove (``accuracy_kw``)."""
    bound = getattr(run, "distance_bound_kw", None)
    if bound is None:
        return {"max_distance_bound_kw": None, "accuracy_kw": None}
    return {"max_distance_bound_kw": _finite(float(np.max(bound))),
            "accuracy_kw": float(np.min(run.accuracy_kw))}  # fmt: skip


def max_price_gap(result: DayComparison) -> float | None:
    """Largest ``|engine price - OPF dual|`` (EUR/MWh) over the converged minutes with a
    DC-OPF, limited lines and monitored buses together; None in paper mode or without such
    minutes (or without priced rows)."""
    run = result.run
    line = getattr(run, "line_price_eur_per_mwh", None)
    if line is None:
        return None
    rows = np.flatnonzero(np.asarray(run.converged, bool) & np.asarray(result.feasible, bool))
    engine = np.concatenate([line, run.voltage_price_eur_per_mwh], axis=1)[rows]
    opf = np.array([np.concatenate([result.opf[r].line_price, result.opf[r].voltage_price])
                    for r in rows]).reshape(engine.shape)  # fmt: skip
    return float(np.max(np.abs(engine - opf))) if engine.size else None


def _runaway_minutes(run) -> list[int]:
    flags = run.infeasible if run.infeasible is not None else np.zeros(len(run.minutes), bool)
    return [int(m) for m in run.minutes[flags]]


def _day_comparison(problem: DispatchProblem, result: DayComparison, hours: np.ndarray) -> dict:
    """Errors, energies and costs of the dynamics and the DC-OPF over the same minutes (each
    lasting ``hours``, h)."""
    run, feasible = result.run, result.feasible
    buses = [str(b) for b in generator_buses(problem)]
    error = result.abs_error_kw[feasible]
    worst = error.max(axis=1) if len(error) else error
    some = bool(feasible.any())
    opf_cost = np.array([o.cost for o in result.opf])[feasible]
    distance = distance_outside_limits_kw(problem, run.setpoints_kw, run.online)
    outside = distance > LIMIT_TOLERANCE_KW
    counts = outside.sum(axis=0)
    kept = hours[feasible]
    cost = float(_energy(run.cost[feasible], kept))
    total_opf_cost = float(_energy(opf_cost, kept)) if some else None
    cost_all = float(_energy(run.cost, hours))
    return {
        "compared_minutes": int(feasible.sum()),
        "minutes_within_0_1_kw": int((worst <= MATCH_KW).sum()),
        "max_abs_error_kw": float(error.max()) if some else None,
        "mean_abs_error_kw": float(error.mean()) if some else None,
        "median_max_abs_error_kw": float(np.median(worst)) if some else None,
        "energy_kwh": _by_bus(buses, _energy(run.setpoints_kw[feasible], kept)),
        "opf_energy_kwh": _by_bus(buses, _energy(result.opf_kw[feasible], kept), some),
        "cost_eur": cost,
        "opf_cost_eur": total_opf_cost,
        "cost": cost,  # deprecated: cost_eur
        "opf_cost": total_opf_cost,  # deprecated: opf_cost_eur
        "cost_unit": "EUR",  # deprecated with cost
        "energy_all_minutes_kwh": _by_bus(buses, _energy(run.setpoints_kw, hours)),
        "cost_all_minutes_eur": cost_all,
        "cost_all_minutes": cost_all,  # deprecated: cost_all_minutes_eur
        "minutes_outside_limits": int(outside.any(axis=1).sum()),
        "max_outside_limits_kw": float(distance.max()) if distance.size else 0.0,
        "minutes_outside_limits_by_generator": {
            name: int(n) for name, n in zip(problem.generators, counts, strict=True) if n
        },
    }


def _by_bus(buses: list[str], values: np.ndarray, known: bool = True) -> dict:
    return {bus: (float(v) if known else None) for bus, v in zip(buses, values, strict=True)}


def iteration_seconds(settings) -> float:
    """Length of one iteration (s): the integrator in force (a mode may bring its own)."""
    integrator = getattr(settings, "stepping", None) or settings.integrator
    return float(integrator.dt)


def trajectory_table(result: SnapshotComparison) -> pd.DataFrame:
    """Set points per iteration (kW) with the DC-OPF as constant columns; time in seconds."""
    run = result.run
    dt = iteration_seconds(run.settings)
    table = pd.DataFrame({"iteration": np.arange(run.iterations + 1)})
    table["time_s"] = table.iteration * dt
    for k, name in enumerate(run.generators):
        table[f"{name}_setpoint_kw"] = run.trajectory_kw[:, k]
    for k, name in enumerate(run.generators):
        table[f"{name}_opf_kw"] = result.opf.p_kw[k]
    return table


def day_table(
    result: DayComparison, problem: DispatchProblem | None = None, timeline: Timeline | None = None
) -> pd.DataFrame:
    """One row per simulated minute: the step (``minute`` and ``step``, 1-based) and its start
    ``time`` (ISO 8601, from ``timeline``; default a day of minutes), demand, set points, DC-OPF
    (empty where infeasible: ``opf_feasible`` false), iterations, costs, overflow; with
    ``problem``, ``outside_limits`` (some set point more than :data:`LIMIT_TOLERANCE_KW` outside
    its limits)."""
    run = result.run
    timeline = timeline if timeline is not None else day_timeline(int(run.minutes.max()))
    table = pd.DataFrame(
        {
            "minute": run.minutes,
            "step": run.minutes,
            "time": timeline.labels(run.minutes),
            "demand_kw": run.demand_kw,
        }
    )
    if problem is not None:
        table["fixed_injection_kw"] = fixed_injection_kw(problem, run.minutes)
    for k, name in enumerate(run.generators):
        table[f"{name}_setpoint_kw"] = run.setpoints_kw[:, k]
    for k, name in enumerate(run.generators):
        table[f"{name}_opf_kw"] = result.opf_kw[:, k]
    table["max_abs_error_kw"] = result.abs_error_kw.max(axis=1)
    table["opf_feasible"] = result.feasible
    if problem is not None:
        table["outside_limits"] = outside_limits(problem, run.setpoints_kw, run.online).any(1)
    table["iterations"] = run.iterations
    table["converged"] = run.converged
    table["cost_eur_per_h"] = run.cost
    table["opf_cost_eur_per_h"] = [o.cost for o in result.opf]
    overflow = run.overflow_kw
    table["max_overflow_kw"] = overflow.max(axis=1) if overflow.shape[1] else 0.0
    if problem is not None:
        table = pd.concat([table, price_columns(problem, result)], axis=1)
    return table


def price_columns(problem: DispatchProblem, result: DayComparison) -> pd.DataFrame:
    """Per minute, the run's broadcast prices and the DC-OPF's duals (EUR/MWh, as in
    :func:`snapshot_prices`): ``line_{from}_{to}_price_eur_per_mwh`` and
    ``line_{from}_{to}_opf_price_eur_per_mwh`` per limited line, ``bus_{j}_price_eur_per_mwh``
    and ``bus_{j}_opf_price_eur_per_mwh`` per monitored bus (OPF empty where infeasible). No
    columns in a mode without price controllers (paper mode)."""
    run = result.run
    line = getattr(run, "line_price_eur_per_mwh", None)
    if line is None:
        return pd.DataFrame(index=range(len(run.minutes)))
    voltage = run.voltage_price_eur_per_mwh
    opf_line = np.array([o.line_price for o in result.opf]).reshape(line.shape)
    opf_voltage = np.array([o.voltage_price for o in result.opf]).reshape(voltage.shape)
    columns = {}
    for k, (a, b) in enumerate(limited_line_buses(problem)):
        columns[f"line_{a}_{b}_price_eur_per_mwh"] = line[:, k]
        columns[f"line_{a}_{b}_opf_price_eur_per_mwh"] = opf_line[:, k]
    for j, bus in enumerate(problem.voltage_buses):
        columns[f"bus_{int(bus)}_price_eur_per_mwh"] = voltage[:, j]
        columns[f"bus_{int(bus)}_opf_price_eur_per_mwh"] = opf_voltage[:, j]
    return pd.DataFrame(columns, index=range(len(run.minutes)))
