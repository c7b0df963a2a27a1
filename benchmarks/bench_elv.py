"""Benchmarks on ieee-elv: the online day (paper and exact mode), the congestion minute, the
same day solved minute by minute as a QP (the project's DC-OPF day and a lean Clarabel day),
the ratios between them measured in this one run, and the day's peak memory.

Usage: python benchmarks/bench_elv.py [--profiles DIR] [--repeat N] [--modes exact,paper]
    [--no-opf] [--old SRC] [--command]
Prints medians of N runs (after one warm-up run that compiles the kernels or loads them).

- ``--old SRC``: also time the day of each mode in another checkout's ``src`` folder (e.g.
  ``/tmp/oldtree/src``) in a child process, alternating rounds with this checkout's, and print
  the ratio of the medians (both after their own warm-up).
- ``--command``: also time the whole ``popdispatch day --mode exact`` command (a new process
  each, warm numba cache) and print the median.

The lean QP day is the yardstick issue 13 names: Clarabel, six variables, the balance row and
the bounds, a fresh solver object per minute, no line rows (the ELV day has no limits).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import time
import tracemalloc
from collections.abc import Callable
from datetime import date

import numpy as np

from popdispatch.online import RunSettings, run_day, run_snapshot
from popdispatch.opf import solve_opf_day
from popdispatch.readers import read_profiles
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

#: The child process of ``--old``: the exact-mode day of whatever ``popdispatch`` it imports,
#: ``rounds`` timings (engine seconds) after a warm-up, one per line.
CHILD = """
import sys
from popdispatch.online import RunSettings, run_day
from popdispatch.readers import read_profiles
from popdispatch.scenarios import elv_problem
problem = elv_problem(read_profiles(sys.argv[1]))
settings = RunSettings(mode=sys.argv[3])
run_day(problem, settings)
for _ in range(int(sys.argv[2])):
    print(run_day(problem, settings).wall_seconds, flush=True)
"""


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


def lean_qp_day(problem) -> None:
    """The day as 1440 small QPs, a fresh Clarabel solver each: min sum(b p + c p^2) (kW
    scaled as in :mod:`popdispatch.opf`) s.t. sum p = demand, bounds; no line rows."""
    import clarabel
    from scipy import sparse

    n = problem.n_generators
    P = sparse.csc_matrix(sparse.diags(2.0 * problem.c / 1000.0))
    q = problem.b.astype(float)
    eye = sparse.eye(n)
    A = sparse.vstack([sparse.csr_matrix(np.ones((1, n))), -eye, eye]).tocsc()
    cones = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(2 * n)]
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    for row in range(len(problem.demand)):
        online = problem.online[row]
        pmin = np.where(online, problem.pmin, 0.0) * 1000.0
        pmax = np.where(online, problem.pmax, 0.0) * 1000.0
        rhs = np.concatenate([[problem.demand[row] * 1000.0], -pmin, pmax])
        clarabel.DefaultSolver(P, q, A, rhs, cones, settings).solve()


def old_checkout_day(src: str, profiles: str, rounds: int, mode: str = "exact") -> list[float]:
    """Engine seconds of the ``mode`` day with ``src`` first on the path (child process)."""
    env = {**os.environ, "PYTHONPATH": src}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, profiles, str(rounds), mode],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return [float(line) for line in out.stdout.split()]


def command_seconds(profiles: str, repeat: int) -> float:
    """Median wall time of the whole ``popdispatch day --mode exact`` command (warm cache)."""
    argv = [sys.executable, "-m", "popdispatch.cli", "day", "--mode", "exact", "--profiles",
            profiles, "--json", "-q"]  # fmt: skip
    run = lambda: wall(lambda: subprocess.run(argv, capture_output=True, check=True))  # noqa: E731
    return median_seconds(run, repeat)


def distribution(values: np.ndarray) -> str:
    """Median, 95th percentile and maximum of per-minute iterations."""
    p50, p95 = np.percentile(values, [50, 95])
    return f"median {p50:.0f}, p95 {p95:.0f}, max {int(values.max())}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--modes", default="paper,exact", help="comma-separated modes to time")
    parser.add_argument("--no-opf", action="store_true", help="skip the QP days")
    parser.add_argument("--old", help="src folder of another checkout to compare exact days")
    parser.add_argument("--command", action="store_true", help="time the whole day command")
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
        run = run_snapshot(congested, PEAK_MINUTE, settings)
        print(
            f"congestion minute 566, {mode} mode: {minute * 1e3:.2f} ms (engine), "
            f"{run.iterations} iterations, {run.status}"
        )
    if day_problem is None:
        print("day benchmarks skipped: give --profiles or set POPDISPATCH_PROFILES")
        return
    qp_days = {}
    if not args.no_opf:
        qp_days["the project's DC-OPF day (Clarabel, built once, bounds updated)"] = median_seconds(
            lambda: wall(lambda: solve_opf_day(day_problem)), args.repeat
        )
        qp_days["a lean QP day (Clarabel, 6 variables, a fresh solver per minute)"] = (
            median_seconds(lambda: wall(lambda: lean_qp_day(day_problem)), args.repeat)
        )
        for name, seconds in qp_days.items():
            print(f"{name}: {seconds:.4f} s")
    # exact mode with its default warm start (the demand step in merit order: a central
    # incremental dispatch) and with the one that needs no central knowledge (setpoints)
    days = [(mode, None) for mode in reversed(modes)]
    if "exact" in modes:
        days.append(("exact", "setpoints"))
    for mode, warm in days:
        settings = RunSettings(mode=mode, warm_start=warm)
        repeat = args.repeat if mode == "exact" else 1
        day = median_seconds(lambda s=settings: run_day(day_problem, s).wall_seconds, repeat)
        result = run_day(day_problem, settings)
        print(
            f"population-dynamics day, {mode} mode, {settings.warm_start_policy} warm start: "
            f"{day:.4f} s (engine); {result.status}, "
            f"{int(result.converged.sum())}/{len(result.converged)} minutes converged, "
            f"iterations per minute {distribution(result.iterations)} "
            f"(mean {result.iterations.mean():.2f})"
        )
        for name, seconds in qp_days.items():
            print(f"  {seconds / day:.2f}x faster than {name}")
    if "exact" in modes:
        memory = peak_memory_mb(lambda: run_day(day_problem, RunSettings(mode="exact")))
        print(f"peak Python memory of the exact-mode day run: {memory:.1f} MiB (tracemalloc)")
    if args.old:
        for mode in modes:
            compare_old(day_problem, args.old, args.profiles, args.repeat, mode)
    if args.command:
        seconds = command_seconds(args.profiles, args.repeat)
        print(f"whole command popdispatch day --mode exact (warm cache): {seconds:.2f} s")


def compare_old(problem, old_src: str, profiles: str, repeat: int, mode: str = "exact") -> None:
    """Alternate rounds of this checkout's ``mode`` day and ``old_src``'s; print both
    medians."""
    settings = RunSettings(mode=mode)
    run_day(problem, settings)
    new: list[float] = []
    old: list[float] = []
    for _ in range(repeat):
        old += old_checkout_day(old_src, profiles, 3, mode)
        new += [run_day(problem, settings).wall_seconds for _ in range(3)]
    ratio = statistics.median(old) / statistics.median(new)
    print(
        f"{mode}-mode day, alternating {repeat} rounds of 3: this checkout "
        f"{statistics.median(new):.4f} s, {old_src} {statistics.median(old):.4f} s "
        f"({ratio:.2f}x faster here)"
    )


if __name__ == "__main__":
    main()
