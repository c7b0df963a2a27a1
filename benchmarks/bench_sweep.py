"""Sweep benchmark: ELV scenario-days (official profiles randomly assigned, exact mode, with and
without the paper's 28 kW limit on 505-666) per minute in a plain in-process loop and on a Dask
LocalCluster of 1 and 2 workers, the Dask overhead against the loop, and the driver's peak
memory as the scenario count grows.

Usage:
  python benchmarks/bench_sweep.py --profiles DIR [--scenarios 24] [--repeat 3] [--steps day]
  python benchmarks/bench_sweep.py --profiles DIR --memory 100,1000 [--workers 2]

Throughput: medians of ``--repeat`` runs of the same scenarios, each into a fresh folder; the
cluster is started and every worker warmed up (kernels loaded from numba's disk cache) once,
before the timed runs (its start-up time is printed separately). Memory: the driver process's
resident set (it holds the scheduler of a LocalCluster), sampled every 50 ms during a whole
sweep, peak minus the level before the sweep.
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


def loop(todo: list, profiles: str, repeat: int) -> list[float]:
    """The same scenarios in a plain loop in this process (after a warm-up)."""
    warm_up()

    def run(out: Path) -> None:
        context = Context(str(out), profiles)
        for s in todo:
            run_and_store(s, context)

    return timed_runs(run, repeat)


def on_dask(todo: list, profiles: str, repeat: int, workers: int) -> tuple[list[float], float]:
    """The scenarios on a LocalCluster of ``workers``; returns the run times and the seconds
    to start the cluster and warm its workers."""
    start = time.perf_counter()
    with client_for(workers=workers) as client:
        client.run(warm_up)
        ready = time.perf_counter() - start

        def run(out: Path) -> None:
            submit_all(client, todo, Context(str(out), profiles), lambda outcome: None)

        return timed_runs(run, repeat), ready


def per_minute(count: int, seconds: float) -> float:
    return count / seconds * 60.0


def throughput(args) -> None:
    todo = scenarios(args.scenarios, args.steps)
    plain = statistics.median(loop(todo, args.profiles, args.repeat))
    print(f"plain loop, in process: {plain:.2f} s = {per_minute(len(todo), plain):.1f} "
          f"scenario-days/min")  # fmt: skip
    for workers in (1, 2):
        times, ready = on_dask(todo, args.profiles, args.repeat, workers)
        took = statistics.median(times)
        print(
            f"dask, {workers} worker(s): {took:.2f} s (runs {', '.join(f'{t:.2f}' for t in times)}"
            f") = {per_minute(len(todo), took):.1f} scenario-days/min; overhead vs loop "
            f"{(took / plain - 1) * 100:+.1f} % (x{workers} cores: "
            f"{(took * workers / plain - 1) * 100:+.1f} %); cluster start + warm-up {ready:.1f} s"
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
    else:
        throughput(args)


if __name__ == "__main__":
    main()
