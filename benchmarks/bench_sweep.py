"""Sweep benchmark: ELV scenario-days (official profiles randomly assigned, exact mode, with and
without the paper's 28 kW limit on 505-666) per minute in a plain in-process loop and on a Dask
LocalCluster of 1 and 2 workers, the Dask overhead against the loop, and the driver's peak
memory as the scenario count grows.

Usage:
  python benchmarks/bench_sweep.py --profiles DIR [--scenarios 24] [--repeat 3] [--steps day]
  python benchmarks/bench_sweep.py --profiles DIR --memory 100,1000 [--workers 2]
  python benchmarks/bench_sweep.py --profiles DIR --scaling [--scenarios 24] [--repeat 3]

Throughput: ``--repeat`` A/B pairs of the same scenarios, a plain in-process loop then Dask,
each run into a fresh folder (alternated so both see the same load on a shared machine); the
cluster is started and every worker warmed up (kernels loaded from numba's disk cache) once,
before the timed runs (its start-up time is printed separately). Overhead: the median of the
pairs' Dask/loop time ratios, times the workers (core-seconds), minus one. Memory: the
driver process's resident set (it holds the scheduler of a LocalCluster), sampled every 50 ms
during a whole sweep, peak minus the level before the sweep.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import tempfile
import threading
import time
from datetime import date
from pathlib import Path

from popdispatch.sweep import parse_spec
from popdispatch.sweep.execute import client_for, run_sweep, submit_all, warm_up
from popdispatch.sweep.scenario import Context, run_and_store


def scenarios(count: int, steps: str) -> list:
    """``count`` ELV scenarios: half without limits, half with 505:666=28 (count even)."""
    spec = {
        "steps": steps,
        "mode": "exact",
        "limits": [[], ["505:666=28"]],
        "profile_assignments": {"count": max(1, count // 2), "seed": 1},
    }
    return parse_spec(spec).scenarios[:count]


def timed_runs(run, repeat: int) -> list[float]:
    """Seconds of ``repeat`` calls of ``run(out)``, each into a fresh folder."""
    times = []
    for _ in range(repeat):
        out = Path(tempfile.mkdtemp(prefix="bench-sweep-"))
        start = time.perf_counter()
        run(out)
        times.append(time.perf_counter() - start)
        shutil.rmtree(out, ignore_errors=True)
    return times


def loop_run(todo: list, profiles: str):
    """A run of the scenarios in a plain loop in this process (``run(out)``)."""

    def run(out: Path) -> None:
        context = Context(str(out), profiles)
        for s in todo:
            run_and_store(s, context)

    return run


def per_minute(count: int, seconds: float) -> float:
    return count / seconds * 60.0


def throughput(args) -> None:
    """Plain loop and Dask runs alternated (A/B pairs), so both see the same machine load
    (it is shared); the overhead is the median of the pairs' ratios."""
    todo = scenarios(args.scenarios, args.steps)
    warm_up()
    plain = loop_run(todo, args.profiles)
    for workers in (1, 2):
        start = time.perf_counter()
        with client_for(workers=workers) as client:
            client.run(warm_up)
            ready = time.perf_counter() - start

            def dask_run(out: Path, client=client) -> None:
                submit_all(client, todo, Context(str(out), args.profiles), lambda _: None)

            pairs = [
                (timed_runs(plain, 1)[0], timed_runs(dask_run, 1)[0]) for _ in range(args.repeat)
            ]
        loops, dasks = zip(*pairs, strict=True)
        ratio = statistics.median(d / p for p, d in pairs)
        print(
            f"{workers} worker(s), {len(todo)} scenarios, {args.repeat} A/B pairs: loop "
            f"{', '.join(f'{t:.1f}' for t in loops)} s, dask {', '.join(f'{t:.1f}' for t in dasks)}"
            f" s; medians {per_minute(len(todo), statistics.median(loops)):.1f} vs "
            f"{per_minute(len(todo), statistics.median(dasks)):.1f} scenario-days/min; dask/loop "
            f"time ratio (median of pairs) {ratio:.3f}: overhead "
            f"{(ratio * workers - 1) * 100:+.1f} % of the loop's core-seconds; cluster start + "
            f"warm-up {ready:.1f} s"
        )


def _ignore(outcome: dict) -> None:
    """Outcomes are not needed: every scenario's results are on disk."""


def scaling(args) -> None:
    """1 and 2 workers alternated (two LocalClusters alive at once), so both see the same
    machine load: scenario-days per minute and the speed-up, medians of the pairs."""
    todo = scenarios(args.scenarios, args.steps)
    with client_for(workers=1) as one, client_for(workers=2) as two:
        for client in (one, two):
            client.run(warm_up)

        def on(client):
            return lambda out: submit_all(client, todo, Context(str(out), args.profiles), _ignore)

        pairs = [(timed_runs(on(one), 1)[0], timed_runs(on(two), 1)[0]) for _ in range(args.repeat)]
    ones, twos = zip(*pairs, strict=True)
    print(
        f"{len(todo)} scenarios, {args.repeat} pairs: 1 worker "
        f"{', '.join(f'{t:.1f}' for t in ones)} s, 2 workers "
        f"{', '.join(f'{t:.1f}' for t in twos)} s; medians "
        f"{per_minute(len(todo), statistics.median(ones)):.1f} and "
        f"{per_minute(len(todo), statistics.median(twos)):.1f} scenario-days/min; speed-up "
        f"(median of pairs) {statistics.median(a / b for a, b in pairs):.2f}"
    )


def peak_rss_mb(run) -> tuple[float, float]:
    """``(peak - before, seconds)`` of this process's resident set while ``run()`` runs."""
    import psutil

    process = psutil.Process()
    before = process.memory_info().rss
    peak = [before]
    done = threading.Event()

    def sample() -> None:
        while not done.wait(0.05):
            peak[0] = max(peak[0], process.memory_info().rss)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    start = time.perf_counter()
    run()
    seconds = time.perf_counter() - start
    done.set()
    sampler.join()
    return (max(peak[0], process.memory_info().rss) - before) / 2**20, seconds


def memory(args) -> None:
    for count in (int(c) for c in args.memory.split(",")):
        todo = scenarios(count, args.steps)
        out = Path(tempfile.mkdtemp(prefix="bench-sweep-mem-"))
        grown, seconds = peak_rss_mb(
            lambda: run_sweep(todo, out, args.profiles, workers=args.workers, quiet=True)  # noqa: B023
        )
        print(
            f"{count} scenarios on {args.workers} workers: driver peak RSS +{grown:.1f} MiB over "
            f"its start, whole sweep {seconds:.0f} s ({per_minute(count, seconds):.1f} "
            "scenario-days/min incl. cluster start)"
        )
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    parser.add_argument("--scenarios", type=int, default=24)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--steps", default="day", help="minutes START-END or day (default)")
    parser.add_argument(
        "--memory", help="scenario counts for the driver-memory runs, e.g. 100,1000"
    )
    parser.add_argument("--workers", type=int, default=2, help="workers of the memory runs")
    parser.add_argument("--scaling", action="store_true", help="1 vs 2 workers, alternated")
    args = parser.parse_args()
    if not args.profiles:
        parser.error("the official profiles are needed: --profiles DIR or POPDISPATCH_PROFILES")
    args.profiles = str(Path(args.profiles).resolve())
    print(
        f"# sweep benchmark, {date.today()}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, steps {args.steps}"
    )
    if args.memory:
        memory(args)
    elif args.scaling:
        scaling(args)
    else:
        throughput(args)


if __name__ == "__main__":
    main()
