"""Summaries of results as plain dicts (the CLI's ``--json`` objects) and time-series tables.

Powers are in kW, energies in kWh, costs in EUR (a day) or EUR/h (one minute's dispatch, Table
I's coefficients applied to MW). Key names carry their units. See README, "JSON output".
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from popdispatch.feeder.model import Feeder
from popdispatch.feeder.reduction import ReducedFeeder
from popdispatch.game.problem import DispatchProblem
from popdispatch.opf import OpfResult
from popdispatch.scenarios import DayComparison, SnapshotComparison

#: Set points closer than this to the DC-OPF count as "on the DC-OPF", kW.
MATCH_KW = 0.1


def _limits(limits: Sequence[tuple[int, int, float]]) -> list[dict]:
    return [{"from_bus": a, "to_bus": b, "limit_kw": kw} for a, b, kw in limits]


def feeder_summary(feeder: Feeder, reduced: ReducedFeeder) -> dict:
    """What the feeder is: sizes of the original and reduced networks, loads, fleet."""
    gens = reduced.generators
    return {
        "case": feeder.name,
        "buses": len(feeder.buses),
        "original_lines": len(feeder.lines),
        "source_bus": int(feeder.source_bus),
        "nodes": reduced.n_nodes,
        "key_node_buses": reduced.nodes.bus.tolist(),
        "lines": reduced.n_lines,
        "loads": len(feeder.loads),
        "generators": [
            {
                "name": name,
                "bus": int(row.bus),
                "node": int(row.node),
                "a_eur": float(row.a),
                "b_eur_per_mwh": float(row.b),
                "c_eur_per_mw2h": float(row.c),
                "pmin_kw": float(row.pmin_kw),
                "pmax_kw": float(row.pmax_kw),
            }
            for name, row in gens.iterrows()
        ],
        "capacity_kw": float(gens.pmax_kw.sum()),
    }


def generator_buses(problem: DispatchProblem) -> list[int]:
    """Original bus of every generator, in the problem's generator order."""
    return problem.feeder.generators.bus.astype(int).tolist()


def opf_summary(
    problem: DispatchProblem, opf: OpfResult, limits: Sequence[tuple[int, int, float]] = ()
) -> dict:
    """The DC-OPF of one minute."""
    buses = generator_buses(problem)
    return {
        "status": opf.status,
        "minute": opf.minute,
        "demand_kw": opf.demand_kw,
        "profile_source": problem.profile_source,
        "limits": _limits(limits),
        "generators": [
            {"name": name, "bus": bus, "p_kw": p}
            for name, bus, p in zip(problem.generators, buses, opf.p_kw, strict=True)
        ],
        "cost": opf.cost,
        "cost_unit": "EUR/h",
        "marginal_price_eur_per_mwh": opf.marginal_price,
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
) -> dict:
    """One minute of dynamics compared with the DC-OPF."""
    run, opf = result.run, result.opf
    settings = run.settings
    buses = generator_buses(problem)
    error = result.max_abs_error_kw if opf.status == "optimal" else None
    return {
        "status": snapshot_status(result),
        "minute": run.minute,
        "demand_kw": run.demand_kw,
        "mode": settings.mode,
        "dynamics": settings.dynamics,
        "x0": settings.x0_label(),
        "graph": settings.graph if isinstance(settings.graph, str) else "custom",
        "profile_source": run.profile_source,
        "limits": _limits(limits),
        "generators": [
            {"name": name, "bus": bus, "setpoint_kw": sp, "opf_kw": p}
            for name, bus, sp, p in zip(
                problem.generators, buses, run.setpoints_kw, opf.p_kw, strict=True
            )
        ],
        "iterations": run.iterations,
        "converged_iteration": run.converged_at,
        "first_congestion_iteration": run.first_congestion,
        "max_overflow_kw": float(run.overflow_kw.max()) if run.overflow_kw.size else 0.0,
        "max_abs_error_kw": error,
        "cost": float(_cost(problem, run.setpoints_kw)),
        "opf_cost": opf.cost,
        "cost_unit": "EUR/h",
        "wall_seconds": run.wall_seconds,
    }


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
) -> dict:
    """An online day compared minute by minute with the DC-OPF (energies kWh, costs EUR)."""
    run = result.run
    settings = run.settings
    buses = [str(b) for b in generator_buses(problem)]
    error = result.abs_error_kw
    worst = error.max(axis=1)
    opf_cost = np.array([o.cost for o in result.opf])
    return {
        "status": day_status(result),
        "minutes": len(run.minutes),
        "first_minute": int(run.minutes[0]),
        "last_minute": int(run.minutes[-1]),
        "profile_source": run.profile_source,
        "mode": settings.mode,
        "dynamics": settings.dynamics,
        "x0": settings.x0_label(),
        "warm_start": settings.warm_start_policy,
        "graph": settings.graph if isinstance(settings.graph, str) else "custom",
        "limits": _limits(limits),
        "events": list(events),
        "converged_minutes": int(run.converged.sum()),
        "minutes_within_0_1_kw": int((worst <= MATCH_KW).sum()),
        "max_abs_error_kw": float(np.nanmax(error)) if np.isfinite(error).any() else None,
        "mean_abs_error_kw": float(np.nanmean(error)) if np.isfinite(error).any() else None,
        "median_max_abs_error_kw": float(np.nanmedian(worst)) if np.isfinite(worst).any() else None,
        "energy_kwh": dict(zip(buses, run.setpoints_kw.sum(axis=0) / 60.0, strict=True)),
        "opf_energy_kwh": dict(zip(buses, np.nansum(result.opf_kw, axis=0) / 60.0, strict=True)),
        "cost": float(run.cost.sum() / 60.0),
        "opf_cost": float(opf_cost.sum() / 60.0),
        "cost_unit": "EUR",
        "max_overflow_kw": float(run.overflow_kw.max()) if run.overflow_kw.size else 0.0,
        "wall_seconds": run.wall_seconds,
    }


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


def day_table(result: DayComparison) -> pd.DataFrame:
    """One row per simulated minute: demand, set points, DC-OPF, iterations, costs, overflow."""
    run = result.run
    table = pd.DataFrame({"minute": run.minutes, "demand_kw": run.demand_kw})
    for k, name in enumerate(run.generators):
        table[f"{name}_setpoint_kw"] = run.setpoints_kw[:, k]
    for k, name in enumerate(run.generators):
        table[f"{name}_opf_kw"] = result.opf_kw[:, k]
    table["max_abs_error_kw"] = result.abs_error_kw.max(axis=1)
    table["iterations"] = run.iterations
    table["converged"] = run.converged
    table["cost_eur_per_h"] = run.cost
    table["opf_cost_eur_per_h"] = [o.cost for o in result.opf]
    overflow = run.overflow_kw
    table["max_overflow_kw"] = overflow.max(axis=1) if overflow.shape[1] else 0.0
    return table
