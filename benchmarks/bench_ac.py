"""AC check benchmark: the ieee-elv day, 1440 power flows on 906 buses (issue 14, part 1).

Usage: python benchmarks/bench_ac.py [--profiles DIR] [--repeat 7] [--threads 0] [--json]

Set points: the DC-OPF of every minute of the official day (profiles from ``--profiles``,
``$POPDISPATCH_PROFILES`` or ``../shared/ieee-elv``; solved once, not timed). Times
:func:`popdispatch.ac.check_day` as the CLI calls it (network built from the feeder's tables,
one power-grid-model batch of 1440 steps, per-step table), ``--repeat`` times, and prints the
median wall time (target under 0.5 s on the 2-core machine), the minimum, the median CPU time
of the process and the load average (other work on the machine shows in the wall time).
``--threads``: power-grid-model's batch threads (0, the default: one per core; -1: one
thread).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from popdispatch.ac import check_day
from popdispatch.opf import solve_opf_day
from popdispatch.readers import read_profiles
from popdispatch.scenarios import elv_problem

TARGET_S = 0.5


def profiles_folder(given: str | None) -> Path:
    """``--profiles``, else ``$POPDISPATCH_PROFILES``, else ``../shared/ieee-elv``."""
    env = os.environ.get("POPDISPATCH_PROFILES", "").strip()
    default = Path(__file__).resolve().parents[2] / "shared" / "ieee-elv"
    folder = Path(given or env or default)
    if not (folder / "Loads.txt").is_file():
        raise SystemExit(f"official ieee-elv profiles not found in {folder} (give --profiles)")
    return folder


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profiles", help="official ieee-elv folder (OpenDSS or CSV form)")
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--threads", type=int, default=0, help="0: one per core; -1: one")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args()

    profiles = read_profiles(profiles_folder(args.profiles))
    problem = elv_problem(profiles)
    opf = solve_opf_day(problem, range(1, 1441))
    run = SimpleNamespace(
        minutes=np.arange(1, 1441),
        generators=problem.generators,
        setpoints_kw=np.array([o.p_kw for o in opf]),
    )
    check_day(problem, profiles, run, threads=args.threads)  # warm-up: imports, allocation
    walls, cpus = [], []
    for _ in range(args.repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        day = check_day(problem, profiles, run, threads=args.threads)
        cpus.append(time.process_time() - cpu)
        walls.append(time.perf_counter() - wall)
    summary = day.summary()
    result = {
        "case": "ieee-elv official day, DC-OPF set points",
        "steps": len(day.steps),
        "buses": day.network.n_buses,
        "median_s": statistics.median(walls),
        "min_s": min(walls),
        "median_cpu_s": statistics.median(cpus),
        "per_step_ms": statistics.median(walls) / len(day.steps) * 1e3,
        "target_s": TARGET_S,
        "repeat": args.repeat,
        "threads": args.threads,
        "load_average": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        "machine": platform.machine(),
        "losses_kwh": summary["losses_kwh"],
        "v_min_pu": summary["v_min_pu"],
        "v_min_bus": summary["v_min_bus"],
        "v_min_minute": summary["v_min_minute"],
    }
    if args.json:
        print(json.dumps(result))
        return
    print(
        f"AC check of the ieee-elv day: {result['steps']} power flows on {result['buses']} "
        f"buses, median {result['median_s']:.3f} s (min {result['min_s']:.3f} s, CPU "
        f"{result['median_cpu_s']:.3f} s; {result['per_step_ms']:.3f} ms per step) over "
        f"{args.repeat} runs, threads {args.threads}; target < {TARGET_S} s; load average "
        f"{result['load_average']:.2f} on {result['cpus']} CPUs"
    )
    print(
        f"losses {result['losses_kwh']:.4f} kWh over the day; lowest voltage "
        f"{result['v_min_pu']:.5f} p.u. at bus {result['v_min_bus']}, minute "
        f"{result['v_min_minute']}"
    )


if __name__ == "__main__":
    main()
