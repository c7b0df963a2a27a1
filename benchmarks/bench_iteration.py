"""Exact mode's cost per iteration on a large feeder, and its iterations on the congested day.

Usage: python benchmarks/bench_iteration.py [--buses 100000] [--generators 1000]
    [--iterations 200] [--repeat 3] [--profiles DIR]

- Per iteration: the synthetic feeder of ``benchmarks/scale_cases.py`` (every candidate line
  limited) in exact mode from uniform shares, ``--iterations`` iterations with the stopping
  rule's horizon at that count (so every run does the same iterations); engine seconds per
  iteration and per game/field evaluation, medians of ``--repeat`` runs after a warm-up.
- Iterations: the ELV day with the paper's congestion limit (``CONGESTION_PATH``) in exact mode
  (needs ``--profiles``): the per-minute distribution (median, 95th percentile, max) and the
  congestion minute 566 on its own from uniform shares.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from scale_cases import synthetic  # noqa: E402

from popdispatch.online import Engine, RunSettings, initial_shares, run_day, run_snapshot  # noqa: E402
from popdispatch.readers import read_profiles  # noqa: E402
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem  # noqa: E402


def per_iteration(buses: int, generators: int, iterations: int, repeat: int) -> None:
    """Engine seconds per iteration and per evaluation on the synthetic feeder."""
    problem = synthetic(buses, generators)
    base = RunSettings(mode="exact")
    settings = replace(
        base, integrator=replace(base.stepping, max_iterations=iterations, fixed_point=False)
    )
    x0 = initial_shares(problem, "uniform", 1)
    times, evaluations = [], []
    for k in range(repeat + 1):
        engine = Engine(problem, settings)
        start = time.perf_counter()
        run = engine.run_minute(x0, 1, record=False)
        seconds = time.perf_counter() - start
        if k > 0:  # the first run compiles or loads the kernels
            times.append(seconds / run.iterations)
            evaluations.append(engine.evaluations / run.iterations)
    per_it = statistics.median(times)
    per_eval = per_it / statistics.median(evaluations)
    print(
        f"synthetic {buses} buses, {generators} generators, {len(problem.limit)} limited lines: "
        f"{per_it * 1e3:.3f} ms per iteration ({statistics.median(evaluations):.1f} evaluations "
        f"per iteration, {per_eval * 1e6:.0f} us per evaluation), {iterations} iterations, "
        f"status {run.status.name.lower()}"
    )


def congested_day(profiles: str) -> None:
    """Iterations per minute of the exact-mode ELV day with the congestion limit."""
    problem = elv_problem(read_profiles(profiles), limits=[CONGESTION_PATH])
    settings = RunSettings(mode="exact")
    result = run_day(problem, settings)
    p50, p95 = np.percentile(result.iterations, [50, 95])
    minute = run_snapshot(elv_problem(limits=[CONGESTION_PATH]), PEAK_MINUTE, settings)
    row = PEAK_MINUTE - 1
    print(
        f"ELV day with the congestion limit, exact mode: {result.status}, "
        f"{int(result.converged.sum())}/{len(result.converged)} converged, iterations per minute "
        f"median {p50:.0f}, p95 {p95:.0f}, max {int(result.iterations.max())}; minute 566 in "
        f"the day {int(result.iterations[row])}, from uniform shares {minute.iterations} "
        f"({minute.status}); engine {result.wall_seconds:.3f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--buses", type=int, default=100_000)
    parser.add_argument("--generators", type=int, default=1000)
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    args = parser.parse_args()
    if args.profiles:
        congested_day(args.profiles)
    per_iteration(args.buses, args.generators, args.iterations, args.repeat)


if __name__ == "__main__":
    main()
