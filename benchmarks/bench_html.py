"""Benchmark of the interactive HTML report: seconds to write the ieee-elv day report beyond the
day itself, and the file's size (targets: under 5 s, under 10 MB; issue 17).

Usage: python benchmarks/bench_html.py [--profiles DIR] [--repeat N] [--voltages]

The day is ``popdispatch day --mode exact --limit 505:666=28`` (official profiles from DIR or
``$POPDISPATCH_PROFILES``, else the shipped default ones), run once; then the report is written
once (the first time, as in a command, including plotly's import) and N more times, whose
median is printed. ``--voltages`` adds the AC check's bus voltages (needs the ``ac`` extra).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import tempfile
import time
from datetime import date
from pathlib import Path

from popdispatch.online import RunSettings
from popdispatch.report.interactive import write_day_html
from popdispatch.report.summaries import day_summary
from popdispatch.runs import FeederSource, load_run, run_day_vs_opf
from popdispatch.scenarios import CONGESTION_PATH


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profiles", default=os.environ.get("POPDISPATCH_PROFILES"))
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--voltages", action="store_true")
    args = parser.parse_args()
    folder = Path(args.profiles) if args.profiles else None
    problem, profiles = load_run(FeederSource(), folder, None, [CONGESTION_PATH])
    start = time.perf_counter()
    comparison = run_day_vs_opf(problem, RunSettings(mode="exact"))
    day_seconds = time.perf_counter() - start
    summary = day_summary(problem, comparison, [CONGESTION_PATH])
    voltages = None
    if args.voltages:
        from popdispatch.ac.check import check_day

        voltages = check_day(problem, profiles, comparison).v_pu()
    print(
        f"# popdispatch HTML report benchmark, {date.today()}, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; loads: {profiles.source}"
    )
    print(f"day and its DC-OPFs (not part of the report): {day_seconds:.3f} s")
    with tempfile.TemporaryDirectory() as folder_out:
        path = Path(folder_out) / "report.html"
        times = []
        for _ in range(args.repeat + 1):
            start = time.perf_counter()
            write_day_html(path, comparison, problem, profiles, run_info=summary,
                           voltages_pu=voltages)  # fmt: skip
            times.append(time.perf_counter() - start)
        size = path.stat().st_size
    label = "with voltages" if voltages is not None else "without voltages"
    print(f"write the day report ({label}): first {times[0]:.3f} s (imports plotly, as one CLI "
          f"run does), then median {statistics.median(times[1:]):.3f} s of {args.repeat} "
          f"(min {min(times[1:]):.3f}, max {max(times[1:]):.3f}); target < 5 s")  # fmt: skip
    print(f"file size: {size / 1e6:.2f} MB; target < 10 MB")


if __name__ == "__main__":
    main()
