"""Year benchmark: a SimBench LV grid's bundled year at 15 minutes in exact mode (issue 12).

Usage: python benchmarks/bench_year.py [--code 1-LV-rural1--0-sw] [--repeat 3] [--limit-kw 10]
       [--json]

Needs the optional ``simbench`` extra (``pip install "popdispatch[simbench]"``; its data is
bundled). The grid is read with ``--case simbench:<code>`` (its own line ratings) and runs on
its own year: 35,136 quarter hours of absolute load values (``simbench.get_absolute_values``).
SimBench has no cost data, so the fleet is made here: the substation (the transformer's LV
bus) imports at 60 EUR/MWh (c = 0.5 EUR/(MW^2 h), up to 400 kW) and every static generator
(PV) becomes a dispatchable DG at its bus, rated at its ``p_mw``, at 5-8 EUR/MWh. With
``--limit-kw`` every branch between the source and the cheapest DG is limited, so that DG's
export binds for much of the year and the next one takes over.

Prints, for the year run in exact mode from uniform shares (warm start from step to step):
engine seconds (``wall_seconds``: the compiled loop, no loading or DC-OPF; median of
``--repeat`` runs after a warm-up run that compiles or loads the kernels), steps converged,
mean iterations per step, and once: the time to load the grid and its year, the DC-OPF of every
step (Clarabel) and the largest set-point distance from it (kW).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
import warnings

import numpy as np
import pandas as pd

from popdispatch.cases.builtin import load_case, simbench_net, simbench_profiles
from popdispatch.feeder import make_fleet
from popdispatch.online import RunSettings, run_day
from popdispatch.scenarios import day_vs_opf, elv_problem


def bench_fleet(code: str) -> pd.DataFrame:
    """The substation import and one DG per static generator (see the module docstring)."""
    net = simbench_net(code)
    source = int(net.trafo.lv_bus.iloc[0])
    rows = [(source, 0.0, 60.0, 0.5, 0.0, 400.0)]
    names = ["grid"]
    for k, (index, sgen) in enumerate(net.sgen.iterrows()):
        rows.append((int(sgen.bus), 0.0, 5.0 + k % 4, 2.0, 0.0, float(sgen.p_mw) * 1000.0))
        names.append(f"sgen{index}")
    return make_fleet(rows, names)


def cheapest_dg_path(code: str) -> tuple[int, int]:
    """(source bus, bus of the cheapest DG, the first static generator): the path limited by
    ``--limit-kw``."""
    net = simbench_net(code)
    return int(net.trafo.lv_bus.iloc[0]), int(net.sgen.bus.iloc[0])


def year_problem(code: str, limit_kw: float | None):
    """The dispatch problem of the grid's year (and the seconds it took to build)."""
    start = time.perf_counter()
    feeder = load_case(f"simbench:{code}", fleet=bench_fleet(code))
    profiles = simbench_profiles(code, feeder)
    limits = [(*cheapest_dg_path(code), limit_kw)] if limit_kw is not None else []
    problem = elv_problem(profiles, limits, feeder, check=False)
    return problem, profiles, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--code", default="1-LV-rural1--0-sw", help="SimBench LV grid code")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--limit-kw", type=float, default=None, help="limit the largest PV's path")
    parser.add_argument("--steps", type=int, default=None, help="only the first STEPS steps")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args()
    warnings.simplefilter("ignore")  # pandapower's deprecation notes on SimBench nets
    problem, profiles, load_seconds = year_problem(args.code, args.limit_kw)
    if args.steps is not None:
        profiles = profiles.select(1, args.steps)
        problem = elv_problem(profiles, [], problem.feeder.original, check=False)
    settings = RunSettings(mode="exact")
    run_day(problem, settings, np.arange(1, 97))  # warm-up: compile or load the kernels
    runs = [run_day(problem, settings) for _ in range(args.repeat)]
    run = runs[-1]
    start = time.perf_counter()
    compared = day_vs_opf(problem, settings)
    opf_seconds = time.perf_counter() - start - compared.run.wall_seconds
    feasible = compared.feasible
    result = {
        "code": args.code,
        "steps": int(profiles.steps),
        "step_minutes": profiles.timeline.step_minutes,
        "first_time": profiles.timeline.label(1),
        "last_time": profiles.timeline.label(profiles.steps),
        "generators": int(problem.n_generators),
        "limited_lines": int(len(problem.lines)),
        "limit_kw": args.limit_kw,
        "engine_seconds_median": statistics.median(r.wall_seconds for r in runs),
        "engine_seconds": [round(r.wall_seconds, 4) for r in runs],
        "converged_steps": int(run.converged.sum()),
        "mean_iterations": float(run.iterations.mean()),
        "binding_steps": int(sum(bool(np.any(np.abs(o.line_price) > 1e-6)) for o in compared.opf)),
        "infeasible_steps": int((~feasible).sum()),
        "max_abs_error_kw": float(compared.abs_error_kw[feasible].max()),
        "load_seconds": load_seconds,
        "opf_year_seconds": opf_seconds,
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
    }
    if args.json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        print(f"{key:>24}: {value}")


if __name__ == "__main__":
    main()
