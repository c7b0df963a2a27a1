"""Benchmark: the first run after install (numba's disk cache empty), per command.

Usage: python benchmarks/bench_first_run.py [--old SRC] [--repeat N] [--profiles DIR]
    [--commands day-exact,day-paper,snapshot-exact,reproduce,cases] [--new-user]

Each run is a new ``python -m popdispatch.cli ...`` process with an empty ``NUMBA_CACHE_DIR``
(a fresh temporary folder: nothing in the checkout is deleted), so numba compiles every kernel
the command uses; the next run in the same folder is timed too (the warm cache). With
``--new-user`` popdispatch's own cache (``POPDISPATCH_CACHE_DIR``: the ieee-elv tables, the
built-in cases' sizes, built problems) starts empty too, as on a new user's first run. Prints, per
command, the medians of ``N`` rounds of the child's CPU seconds (user + system, from
``getrusage``: on a shared machine it moves less with the load than the wall clock) and wall
seconds (CPU of the command's process and of the processes it waited for: ``reproduce`` runs
its voltage scenario in a second process, so its wall time can be less than its CPU time).
With ``--old SRC`` (e.g. a ``git archive main`` unpacked in ``/tmp/kbase``: its ``src``)
every round also runs that checkout, alternating, and the ratio of the CPU medians is printed
(issue 13: first run under 20 s).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")

COMMANDS = {
    "day-exact": ["day", "--mode", "exact"],
    "day-paper": ["day"],
    "snapshot-exact": ["snapshot", "--minute", "566", "--limit", "505:666=28", "--mode", "exact"],
    # the paper's experiments and the voltage scenario, into a fresh folder ({out}) each run
    "reproduce": ["reproduce", "--out", "{out}"],
    "cases": ["cases"],
}


def run_once(
    src: str, args: list[str], cache: str, profiles: str | None, own_cache: str | None = None
) -> tuple[float, float]:
    """``(CPU s, wall s)`` of one ``popdispatch`` command importing ``src``, numba's cache in
    ``cache`` (and popdispatch's in ``own_cache``, if given)."""
    env = {**os.environ, "PYTHONPATH": src, "NUMBA_CACHE_DIR": cache}
    if own_cache is not None:
        env["POPDISPATCH_CACHE_DIR"] = own_cache
    if profiles:
        env["POPDISPATCH_PROFILES"] = profiles
    out = tempfile.mkdtemp(prefix="popdispatch-first-run-out-")
    args = [arg.replace("{out}", os.path.join(out, "results")) for arg in args]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", *args, "-q", "--json"],
        env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    shutil.rmtree(out, ignore_errors=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(args)} failed ({src}): {done.stderr.strip()[-400:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def cold_and_warm(
    src: str, args: list[str], profiles: str | None, new_user: bool = False
) -> dict[str, tuple]:
    """The command on an empty cache, then again on the cache it left."""
    with (
        tempfile.TemporaryDirectory(prefix="popdispatch-first-run-") as cache,
        tempfile.TemporaryDirectory(prefix="popdispatch-first-run-own-") as own,
    ):
        own_cache = own if new_user else None
        return {"cold": run_once(src, args, cache, profiles, own_cache),
                "warm": run_once(src, args, cache, profiles, own_cache)}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", help="src folder of another checkout to time alternately")
    parser.add_argument("--repeat", type=int, default=1, help="rounds (each compiles afresh)")
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    parser.add_argument("--commands", default="day-exact,day-paper,snapshot-exact")
    parser.add_argument(
        "--new-user", action="store_true", help="popdispatch's own cache empty too (first use)"
    )
    options = parser.parse_args()
    trees = {"this": SRC} | ({"old": options.old} if options.old else {})
    print(f"{date.today()} {platform.node()} {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
          + (", new user (both caches empty)" if options.new_user else ""))  # fmt: skip
    for name in options.commands.split(","):
        args = COMMANDS[name]
        runs: dict[str, list[dict]] = {tree: [] for tree in trees}
        for _ in range(options.repeat):
            for tree, src in trees.items():  # alternating: the load drifts alike for both
                runs[tree].append(cold_and_warm(src, args, options.profiles, options.new_user))
        medians = {}
        for tree, rounds in runs.items():
            cpu = statistics.median(r["cold"][0] for r in rounds)
            wall = statistics.median(r["cold"][1] for r in rounds)
            warm = statistics.median(r["warm"][1] for r in rounds)
            medians[tree] = cpu
            print(f"{name:15s} {tree:5s} first run {cpu:6.1f} s CPU, {wall:6.1f} s wall; "
                  f"warm cache {warm:5.2f} s wall  (popdispatch {' '.join(args)})")  # fmt: skip
        if "old" in medians:
            print(f"{name:15s} first-run CPU this/old = {medians['this'] / medians['old']:.2f}")


if __name__ == "__main__":
    main()
