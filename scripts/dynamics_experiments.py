"""The paper's extinction and base-day experiments for every dynamic, BNN and logit included
(docs/dynamics.md, "Results").

Usage: python scripts/dynamics_experiments.py [--profiles DIR] [--etas 0.01,0.1,1]
    [--skip-day] [--json FILE]

- Extinction (:func:`popdispatch.scenarios.extinction`'s start): minute 566 (official loads),
  no line limits, Generator 2 (``G114``, bus 114, the cheapest) at zero share and the others
  equal; each dynamic from that state (exact mode too: the ``shares`` warm start, not its
  default merit order, which would place the demand itself), against the DC-OPF (Clarabel).
- Base day (:func:`popdispatch.scenarios.base_day`): the ieee-elv day of 1440 minutes with
  the official profiles (``--profiles``, else ``$POPDISPATCH_PROFILES``, else
  ``../shared/ieee-elv``), no line limits, each minute warm-started from the last, against the
  DC-OPF of every minute.

Runs paper mode with smith, bnn and logit (each ``--etas`` value, EUR/MWh) and the replicator
(extinction only), and exact mode with smith and logit. Prints two Markdown tables (kW, EUR)
and, with ``--json``, writes the numbers. Wall times are the engine's own, on whatever
machine runs this: the tables are for accuracy, not speed.
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.readers import read_profiles
from popdispatch.scenarios import EXTINCT_GENERATOR, PEAK_MINUTE, base_day, elv_problem

ROOT = Path(__file__).resolve().parents[1]
#: A set point this far outside its limits counts as outside (paper mode's barrier lets
#: generators past Pmax), kW.
OUTSIDE_KW = 1e-3


def configurations(etas: list[float], extinction: bool) -> list[tuple[str, RunSettings]]:
    """``(label, settings)`` of every run: paper smith, (replicator), bnn, logit per eta;
    exact smith and logit per eta."""
    runs = [("paper smith", RunSettings())]
    if extinction:
        runs.append(("paper replicator", RunSettings(dynamics="replicator")))
    runs.append(("paper bnn", RunSettings(dynamics="bnn")))
    runs += [(f"paper logit eta={eta:g}", RunSettings(dynamics="logit", eta=eta)) for eta in etas]
    runs.append(("exact smith", RunSettings(mode="exact")))
    runs += [(f"exact logit eta={eta:g}", RunSettings(dynamics="logit", mode="exact", eta=eta))
             for eta in etas]  # fmt: skip
    return runs


def extinction_rows(etas: list[float]) -> list[dict]:
    """Each dynamic from the extinction start (see the module docstring)."""
    problem = elv_problem()
    opf = solve_opf(problem, PEAK_MINUTE).p_kw
    k = list(problem.generators).index(EXTINCT_GENERATOR)
    x0 = {g: (0.0 if g == EXTINCT_GENERATOR else 1.0) for g in problem.generators}
    rows = []
    for label, settings in configurations(etas, extinction=True):
        # from the start itself (exact mode's default, merit order, would place the demand)
        run = run_snapshot(problem, PEAK_MINUTE, replace(settings, x0=x0, warm_start="shares"))
        rows.append({
            "run": label, "status": run.status, "iterations": run.iterations,
            "g114_kw": float(run.setpoints_kw[k]), "g114_opf_kw": float(opf[k]),
            "max_abs_error_kw": float(np.abs(run.setpoints_kw - opf).max()),
            "distance_bound_kw": run.distance_bound_kw,
        })  # fmt: skip
    return rows


def day_rows(etas: list[float], folder: Path) -> list[dict]:
    """Each dynamic over the official base day (see the module docstring)."""
    profiles = read_profiles(folder)
    problem = elv_problem(profiles)
    rows = []
    for label, settings in configurations(etas, extinction=False):
        result = base_day(profiles, settings)
        run, feasible = result.run, result.feasible
        worst = result.abs_error_kw[feasible].max(axis=1)
        opf_cost = np.array([o.cost for o in result.opf])[feasible]
        above = run.setpoints_kw - problem.pmax * 1000 > OUTSIDE_KW
        below = problem.pmin * 1000 - run.setpoints_kw > OUTSIDE_KW
        stalled = 0 if run.stalled is None else int(run.stalled.sum())
        rows.append({
            "run": label, "minutes": len(run.minutes), "converged": int(run.converged.sum()),
            "stalled": stalled, "max_abs_error_kw": float(worst.max()),
            "median_abs_error_kw": float(np.median(worst)),
            "cost_gap_eur": float((run.cost[feasible] - opf_cost).sum() / 60.0),
            "opf_cost_eur": float(opf_cost.sum() / 60.0),
            "minutes_outside_limits": int((above | below).any(axis=1).sum()),
            "max_outside_limits_kw": float(max(0.0, np.max(run.setpoints_kw - problem.pmax * 1000),
                                               np.max(problem.pmin * 1000 - run.setpoints_kw))),
            "mean_iterations": float(run.iterations.mean()),
            "max_distance_bound_kw": (None if run.distance_bound_kw is None
                                      else float(np.max(run.distance_bound_kw))),
            "wall_seconds": run.wall_seconds,
        })  # fmt: skip
    return rows


def table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """A Markdown table of ``rows``: ``(key, heading, format)`` per column."""

    def cell(value, fmt: str) -> str:
        return "-" if value is None else format(value, fmt)

    head = "| " + " | ".join(h for _, h, _ in columns) + " |"
    rule = "|" + "|".join("---" for _ in columns) + "|"
    body = ["| " + " | ".join(cell(r[k], f) for k, _, f in columns) + " |" for r in rows]
    return "\n".join([head, rule, *body])


EXTINCTION_COLUMNS = [
    ("run", "run", "s"), ("status", "status", "s"), ("iterations", "iterations", "d"),
    ("g114_kw", "G114 kW", ".3f"), ("g114_opf_kw", "DC-OPF kW", ".3f"),
    ("max_abs_error_kw", "max abs error kW", ".4f"),
    ("distance_bound_kw", "certified bound kW", ".3g"),
]  # fmt: skip
DAY_COLUMNS = [
    ("run", "run", "s"), ("converged", "converged", "d"), ("stalled", "stalled", "d"),
    ("max_abs_error_kw", "max abs error kW", ".4f"),
    ("median_abs_error_kw", "median abs error kW", ".4f"),
    ("cost_gap_eur", "cost - DC-OPF EUR", ".2e"),
    ("minutes_outside_limits", "minutes outside limits", "d"),
    ("max_outside_limits_kw", "max outside kW", ".4f"),
    ("mean_iterations", "iterations / minute", ".1f"),
    ("max_distance_bound_kw", "largest bound kW", ".3g"),
]  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = os.environ.get("POPDISPATCH_PROFILES") or str(ROOT.parent / "shared" / "ieee-elv")
    parser.add_argument("--profiles", type=Path, default=Path(default))
    parser.add_argument("--etas", default="0.01,0.1,1", help="logit noise levels, EUR/MWh")
    parser.add_argument("--skip-day", action="store_true")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    etas = [float(e) for e in args.etas.split(",")]
    results = {"extinction": extinction_rows(etas)}
    print("Extinction (minute 566, G114 starts at zero share)\n")
    print(table(results["extinction"], EXTINCTION_COLUMNS))
    if not args.skip_day:
        results["day"] = day_rows(etas, args.profiles)
        print("\nBase day (1440 minutes, official profiles, no line limits)\n")
        print(table(results["day"], DAY_COLUMNS))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
