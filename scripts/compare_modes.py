"""Print the paper-mode vs exact-mode table of docs/exact-mode.md (official data needed).

Usage: python scripts/compare_modes.py [PROFILE_FOLDER]   (default ../shared/ieee-elv)
"""

from __future__ import annotations

import sys
from pathlib import Path

from popdispatch.online import RunSettings
from popdispatch.readers import read_profiles
from popdispatch.scenarios import CONGESTION_PATH, day_vs_opf, elv_problem, snapshot_vs_opf


def snapshot_row(name: str, limits, mode: str) -> str:
    result = snapshot_vs_opf(elv_problem(limits=limits), 566, RunSettings(mode=mode))
    run = result.run
    overflow = run.overflow_kw.max(initial=0.0)
    return (
        f"| {name} | {mode} | {run.status} at {run.converged_at} | "
        f"{result.max_abs_error_kw:.2g} | {overflow:.2g} |"
    )


def day_row(name: str, profiles, limits, mode: str) -> str:
    result = day_vs_opf(elv_problem(profiles, limits), RunSettings(mode=mode))
    err = result.abs_error_kw.max(axis=1)
    within = int((err <= 0.1).sum())
    overflow = result.run.overflow_kw.max(initial=0.0)
    return (
        f"| {name} | {mode} | {within}/1440 minutes within 0.1 kW, mean "
        f"{result.run.iterations.mean():.0f} iterations/minute | {err.max():.2g} | "
        f"{overflow:.2g} |"
    )


def main() -> None:
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/ieee-elv")
    profiles = read_profiles(folder)
    print("| experiment | mode | result | max error vs DC-OPF, kW | max overflow, kW |")
    print("| --- | --- | --- | --- | --- |")
    for mode in ("paper", "exact"):
        print(snapshot_row("minute 566, no limits", [], mode))
    for mode in ("paper", "exact"):
        print(snapshot_row("congestion: 505-666 at 28 kW", [CONGESTION_PATH], mode))
    for mode in ("paper", "exact"):
        print(day_row("base day", profiles, [], mode))
    for mode in ("paper", "exact"):
        print(day_row("day, 505-666 at 28 kW", profiles, [CONGESTION_PATH], mode))


if __name__ == "__main__":
    main()
