"""Benchmarks on ieee-elv: the online day (paper and exact mode), the congestion minute, the
same day solved minute by minute as a DC-OPF QP, and the day's peak memory.

Usage: python benchmarks/bench_elv.py [--profiles DIR] [--repeat N] [--modes exact,paper]
    [--no-opf]
Prints medians of N runs (after one warm-up run that compiles the kernels). For an A/B of the
engine against an older checkout, alternate ``PYTHONPATH=OLD/src python benchmarks/bench_elv.py
--modes exact --no-opf`` with the same command on this one, several rounds each.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
import tracemalloc
from collections.abc import Callable
from datetime import date

from popdispatch.online import RunSettings, run_day, run_snapshot
from popdispatch.opf import solve_opf_day
from popdispatch.readers import read_profiles
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem


def median_seconds(run: Callable[[], float], repeat: int) -> float:
    """Median of ``repeat`` timings; ``run`` returns its own time in seconds."""
    run()  # warm-up: JIT compilation and caches
    return statistics.median(run() for _ in range(repeat))


def wall(fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def peak_memory_mb(fn: Callable[[], object]) -> float:
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--modes", default="paper,exact", help="comma-separated modes to time")
    parser.add_argument("--no-opf", action="store_true", help="skip the DC-OPF day")
    args = parser.parse_args()
    modes = [m for m in ("paper", "exact") if m in args.modes.split(",")]
    profiles = read_profiles(args.profiles) if args.profiles else None
    day_problem = elv_problem(profiles) if profiles else None
    congested = elv_problem(limits=[CONGESTION_PATH])

    print(
        f"# popdispatch benchmarks, {date.today()}, {platform.processor() or platform.machine()}"
        f", {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    for mode in modes:
        settings = RunSettings(mode=mode)
        minute = median_seconds(
            lambda s=settings: run_snapshot(congested, PEAK_MINUTE, s).wall_seconds, args.repeat
        )
        print(f"congestion minute 566, {mode} mode: {minute * 1e3:.2f} ms (engine)")
    if day_problem is None:
        print("day benchmarks skipped: give --profiles or set POPDISPATCH_PROFILES")
        return
    opf_day = float("nan")
    if not args.no_opf:
        opf_day = median_seconds(lambda: wall(lambda: solve_opf_day(day_problem)), args.repeat)
        print(f"DC-OPF day, 1440 QPs (Clarabel, built once): {opf_day:.3f} s")
    for mode in reversed(modes):
        settings = RunSettings(mode=mode)
        repeat = args.repeat if mode == "exact" else 1
        day = median_seconds(lambda s=settings: run_day(day_problem, s).wall_seconds, repeat)
        result = run_day(day_problem, settings)
        speed = "" if args.no_opf else f", {opf_day / day:.2f}x the DC-OPF day's speed"
        print(
            f"population-dynamics day, {mode} mode: {day:.3f} s (engine){speed}; {result.status}, "
            f"{int(result.converged.sum())}/{len(result.converged)} minutes converged, "
            f"{result.iterations.mean():.1f} iterations per minute"
        )
    if "exact" not in modes:
        return
    memory = peak_memory_mb(lambda: run_day(day_problem, RunSettings(mode="exact")))
    print(f"peak Python memory of the exact-mode day run: {memory:.1f} MiB (tracemalloc)")


if __name__ == "__main__":
    main()
