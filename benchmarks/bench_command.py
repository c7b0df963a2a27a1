"""Whole-command benchmark (issue 13): the wall time of ``popdispatch day --mode exact`` and of
the quick commands, each a fresh process, on a warm cache (numba's and popdispatch's).

Usage: python benchmarks/bench_command.py [--repeat 7] [--profiles FOLDER]
       [--src LABEL=PATH ...] [--json]

Each ``--src`` names a source tree (``PYTHONPATH``) to time, e.g. ``--src before=/work/main/src
--src after=src``; the trees are timed in turns (tree A run 1, tree B run 1, ...) so that the
machine's load falls on each alike, and the ratio of their medians is printed. Every command
runs once unmeasured first (warming numba's cache and popdispatch's on-disk cache, which lives
in a fresh temporary ``POPDISPATCH_CACHE_DIR`` shared by the runs). Reported per tree and
command: the median wall time of ``--repeat`` runs (s) and the median CPU time of the child
process (user + system, s), which the other processes on a shared machine disturb less.
Last, the floor under any of them that runs a kernel: a process importing numba and calling
one five-line function from numba's disk cache (:data:`NUMBA_FLOOR`).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = {
    "day --mode exact": ["day", "--mode", "exact", "--quiet"],
    "--help": ["--help"],
    "day --help": ["day", "--help"],
    "cases": ["cases", "--quiet"],
}


#: The floor under any command that runs a compiled kernel: a process that imports numba and
#: calls one five-line function from numba's disk cache (numba's import and its one-time set-up
#: at the first call; the second run of the same script, as for the commands).
NUMBA_FLOOR = """
import numba, numpy
@numba.njit(cache=True)
def total(a):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i]
    return s
total(numpy.ones(3))
"""


def run_argv(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """``(wall s, child CPU s)`` of one process ``argv``; raises if it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(argv, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed: {done.stderr.strip()[-500:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def run_once(src: Path, args: list[str], env: dict[str, str]) -> tuple[float, float]:
    """``(wall s, child CPU s)`` of one ``python -m popdispatch.cli ARGS`` with ``src`` first
    on the path; raises if the command fails."""
    env = {**env, "PYTHONPATH": str(src)}
    return run_argv([sys.executable, "-m", "popdispatch.cli", *args], env)


def numba_floor(repeat: int, folder: str) -> dict:
    """Median wall and CPU seconds of :data:`NUMBA_FLOOR` (its kernel cached in ``folder``)."""
    script = Path(folder) / "numba_floor.py"
    script.write_text(NUMBA_FLOOR)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(folder) / "numba")}
    run_argv([sys.executable, str(script)], env)  # warm-up: compiles and caches it
    runs = [run_argv([sys.executable, str(script)], env) for _ in range(repeat)]
    return {"wall_s": statistics.median(w for w, _ in runs),
            "cpu_s": statistics.median(c for _, c in runs), "runs": repeat}  # fmt: skip


def measure(trees: dict[str, Path], commands: dict[str, list[str]], repeat: int, env) -> dict:
    """Median wall and CPU seconds per tree and command (trees interleaved run by run)."""
    for src in trees.values():
        for args in commands.values():
            run_once(src, args, env)  # warm-up: numba's and popdispatch's caches
    times: dict[str, dict[str, list[tuple[float, float]]]] = {
        label: {name: [] for name in commands} for label in trees
    }
    for _ in range(repeat):
        for name, args in commands.items():
            for label, src in trees.items():
                times[label][name].append(run_once(src, args, env))
    return {
        label: {
            name: {
                "wall_s": statistics.median(w for w, _ in runs),
                "cpu_s": statistics.median(c for _, c in runs),
                "runs": len(runs),
            }
            for name, runs in per.items()
        }
        for label, per in times.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES", ""),
                        help="ELV profile folder (default $POPDISPATCH_PROFILES)")  # fmt: skip
    parser.add_argument("--src", action="append", default=[], metavar="LABEL=PATH")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    trees = dict(item.split("=", 1) for item in args.src) or {"this": str(ROOT / "src")}
    trees = {label: Path(path).resolve() for label, path in trees.items()}
    with tempfile.TemporaryDirectory(prefix="popdispatch-bench-cache-") as folder:
        env = {**os.environ, "POPDISPATCH_CACHE_DIR": folder}
        if args.profiles:
            env["POPDISPATCH_PROFILES"] = args.profiles
        result = measure(trees, COMMANDS, args.repeat, env)
        floor = numba_floor(args.repeat, folder)
    report = {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}",
        "load_average": os.getloadavg(),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "profiles": args.profiles or "shipped default",
        "repeat": args.repeat,
        "trees": {label: str(path) for label, path in trees.items()},
        "medians": result,
        "numba_floor": floor,
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return
    print(f"{report['date_utc']}  {report['machine']}  load {report['load_average'][0]:.1f}")
    print(f"profiles: {report['profiles']}; median of {args.repeat} runs, warm caches")
    labels = list(trees)
    for name in COMMANDS:
        cells = [f"{label} {result[label][name]['wall_s']:.3f} s wall "
                 f"({result[label][name]['cpu_s']:.3f} s cpu)" for label in labels]  # fmt: skip
        line = f"popdispatch {name:18s} " + " | ".join(cells)
        if len(labels) == 2:
            a, b = (result[label][name] for label in labels)
            line += f" | {labels[0]}/{labels[1]} wall {a['wall_s'] / b['wall_s']:.2f}x"
            line += f", cpu {a['cpu_s'] / b['cpu_s']:.2f}x"
        print(line)
    print(f"numba floor (import numba, one cached 5-line kernel) {floor['wall_s']:.3f} s wall "
          f"({floor['cpu_s']:.3f} s cpu)")  # fmt: skip


if __name__ == "__main__":
    main()
