"""Exact mode's price laws on the ieee-elv days: the plain, tree and scaled laws
(docs/exact-mode.md, "Nested limits", "Per-line scaling") in one run, alternating, medians of
engine seconds.

Usage: python benchmarks/bench_price_law.py [--profiles DIR] [--repeat N]

Days: the official profiles without limits, and with the paper's congestion (505-666 at 28 kW);
then the congestion minute 566 from uniform shares. Each row: engine seconds (median of N after
one warm-up), minutes converged, iterations per minute (median, 95th percentile, max) and
game/field evaluations (``--profiles`` or ``$POPDISPATCH_PROFILES``; without them only the
minute).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
from dataclasses import replace
from datetime import date

import numpy as np

from popdispatch.game.parameters import PriceLaw
from popdispatch.online import RunSettings, run_day, run_snapshot
from popdispatch.readers import read_profiles
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem


def settings_of(law: PriceLaw) -> RunSettings:
    """Exact mode's default settings with price law ``law``."""
    settings = RunSettings(mode="exact")
    return replace(settings, exact=replace(settings.exact, price_law=law))


def alternate(problem, repeat: int) -> None:
    """Time the day with every law, alternating rounds, and print one row per law."""
    laws = list(PriceLaw)
    times: dict[PriceLaw, list[float]] = {law: [] for law in laws}
    for law in laws:
        run_day(problem, settings_of(law))  # warm-up
    for _ in range(repeat):
        for law in laws:
            times[law].append(run_day(problem, settings_of(law)).wall_seconds)
    for law in laws:
        day = run_day(problem, settings_of(law))
        it = day.iterations
        print(
            f"  {law.name.lower()}: {statistics.median(times[law]):.4f} s (median of {repeat}), "
            f"{int(day.converged.sum())}/{len(day.converged)} converged, iterations per minute "
            f"median {np.median(it):.0f}, p95 {np.percentile(it, 95):.0f}, max {it.max()}, "
            f"total {it.sum()}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(
        f"# exact-mode price laws, {date.today()}, {platform.processor() or platform.machine()}"
        f", {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    congested = elv_problem(limits=[CONGESTION_PATH])
    for law in PriceLaw:
        run = run_snapshot(congested, PEAK_MINUTE, settings_of(law))
        print(f"congestion minute 566, {law.name.lower()}: {run.iterations} iterations, "
              f"{run.status}")  # fmt: skip
    if not args.profiles:
        print("day benchmarks skipped: give --profiles or set POPDISPATCH_PROFILES")
        return
    profiles = read_profiles(args.profiles)
    for name, limits in (("official day", []), ("congested day", [CONGESTION_PATH])):
        print(f"{name}:")
        alternate(elv_problem(profiles, limits=limits), args.repeat)


if __name__ == "__main__":
    main()
