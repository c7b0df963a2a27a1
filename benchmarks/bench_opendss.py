"""Real OpenDSS feeders: the IEEE 8500-node feeder and EPRI's ckt24, read and dispatched.

Usage: python benchmarks/bench_opendss.py [FEEDERS_FOLDER] [--repeat 5] [--json]

Three measurements, each the median of ``--repeat`` runs (with the minimum, the process's CPU
time where it is this process, and the load average: other work on the machine shows in the
wall time):

1. ``popdispatch feeder --net ieee8500/Run_8500Node.dss -q`` end to end, in a subprocess
   (start-up, imports, the run script compiled in place, the reduction, the description
   printed): target under 3 s.
2. an exact-mode snapshot of the 8500 with a fleet and a binding limit (200 kW into bus
   l3312692, the fleet of ``tests/readers/test_big_feeders.py``): engine time
   (``SnapshotResult.wall_seconds``), target under 0.1 s. The first run compiles the kernels
   and is not counted.
3. the radial ckt24's year of hourly load shapes (8,760 steps, ``--series`` default yearly)
   in exact mode with the same kind of fleet, no ratings: engine time of the day
   (``DayResult.wall_seconds``; building the problem and the 8,760 DC-OPFs not included),
   target under 10 s; then the same year with 300 kW into bus n274191 (its DG's 900 kW held
   back whenever the local load is low: the limit binds in part of the hours, counted), with
   exact mode's default warm start (``merit``: each hour starts in merit order, limits
   ignored) and with ``--warm-start setpoints`` (each hour starts from the last one's set
   points).

FEEDERS_FOLDER defaults to ``$POPDISPATCH_FEEDERS``, else ``../shared/feeders``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import pandas as pd

TARGETS_S = {"feeder_8500_s": 3.0, "snapshot_8500_engine_s": 0.1, "ckt24_year_engine_s": 10.0,
             "ckt24_year_binding_engine_s": 10.0,
             "ckt24_year_binding_setpoints_engine_s": 10.0}  # fmt: skip
CKT24_OPEN = ("Line.05410_107831ug", "Line.05410_115682ug")
_PARENT_24 = "n274183"  # the bus above n274191 (its parent in the radial ckt24)


def feeders_folder(given: str | None) -> Path:
    env = os.environ.get("POPDISPATCH_FEEDERS", "").strip()
    folder = Path(given or env or Path(__file__).resolve().parents[2] / "shared" / "feeders")
    if not (folder / "opendss" / "ieee8500" / "Run_8500Node.dss").is_file():
        raise SystemExit(f"OpenDSS feeders not found in {folder} (give FEEDERS_FOLDER)")
    return folder


def fleet(names: list[str]) -> pd.DataFrame:
    from popdispatch.feeder.generators import make_fleet

    rows = [("sourcebus", 0.0, 60.0, 0.002, 0.0, 80000.0)]
    rows += [(bus, 0.0, 10.0 + 5 * k, 0.01, 0.0, 900.0) for k, bus in enumerate(names)]
    table = make_fleet([(0, *r[1:]) for r in rows], [f"G{k}" for k in range(len(rows))])
    table["bus"] = [r[0] for r in rows]
    return table


def time_feeder_command(run_script: Path, repeat: int) -> list[float]:
    program = Path(sys.executable).with_name("popdispatch")  # the installed command
    command = [str(program)] if program.is_file() else [sys.executable, "-m", "popdispatch.cli"]
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run(
            [*command, "feeder", "--net", str(run_script), "-q"],
            check=True, stdout=subprocess.DEVNULL,
        )  # fmt: skip
        times.append(time.perf_counter() - start)
    return times


def snapshot_8500(master: Path, repeat: int) -> list[float]:
    from popdispatch.feeder.profiles import single_minute_profiles
    from popdispatch.feeder.reduction import reduce_feeder
    from popdispatch.game.problem import build_problem
    from popdispatch.online import RunSettings, run_snapshot
    from popdispatch.readers.opendss_direct import read_opendss_master

    feeder = read_opendss_master(
        master, fleet=fleet(["l3312692", "l3029183", "m1026736"]), ratings=False
    )
    feeder = feeder.with_line_limits(pd.Series(200.0, index=feeder.path_lines("l3312692",
                                              _parent(feeder, "l3312692"))))  # fmt: skip
    problem = build_problem(reduce_feeder(feeder),
                            single_minute_profiles(1, feeder.loads.p_kw, feeder.name))  # fmt: skip
    settings = RunSettings(mode="exact")
    first = run_snapshot(problem, 1, settings)  # compiles the kernels (cached on disk after)
    assert first.status == "converged", first.status
    from popdispatch.opf import solve_opf

    assert abs(solve_opf(problem, 1).line_price).max() > 1e-3, "the limit does not bind"
    return [run_snapshot(problem, 1, settings).wall_seconds for _ in range(repeat)]


def _parent(feeder, name: str) -> int:
    child = feeder.bus_id(name)
    tree = feeder.bus_tree()
    return int(feeder.buses.index[tree.parent[feeder.buses.index.get_loc(child)]])


def ckt24_year(
    master: Path, repeat: int, limit_kw: float | None = None, warm_start: str | None = None
) -> list[float]:
    from popdispatch.cases.sources import FeederSource
    from popdispatch.online import RunSettings, run_day
    from popdispatch.runs import load_run

    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "ckt24_radial.dss"
        script.write_text(f"Compile ({master})\n" + "".join(f"Open {e} 1\n" for e in CKT24_OPEN))
        fleet_file = Path(tmp) / "fleet.csv"
        table = fleet(["n274191", "n274364", "n283927"])
        table.rename(columns={"b": "b_eur_per_mwh", "c": "c_eur_per_mw2h"}).assign(
            name=table.index
        ).to_csv(fleet_file, index=False)
        source = FeederSource(net=script, fleet=fleet_file, ratings=False)
        limits = [] if limit_kw is None else [("n274191", _PARENT_24, limit_kw)]
        problem, _ = load_run(source, limits=limits)
    settings = RunSettings(mode="exact", warm_start=warm_start)
    times = []
    for _ in range(repeat):
        day = run_day(problem, settings)
        assert bool(day.converged.all()), f"{int((~day.converged).sum())} steps not converged"
        times.append(day.wall_seconds)
    if limit_kw is not None:  # at the limit within the run's tolerance (1e-6 of demand)
        flows = problem.line_load_flow[:, 0] - problem.down[0] @ day.setpoints_kw.T / 1e3
        at_limit = abs(flows) >= limit_kw / 1e3 - 1e-6 * problem.demand
        print(
            f"ckt24 year, {limit_kw:g} kW into n274191, warm start {warm_start or 'merit'}: "
            f"at the limit in {int(at_limit.sum())} of 8760 hours",
            file=sys.stderr,
        )
    return times


def stats(times: list[float]) -> dict:
    return {"median": statistics.median(times), "min": min(times), "runs": len(times)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("feeders", nargs="?", help="the folder holding opendss/")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args()
    folder = feeders_folder(args.feeders) / "opendss"
    warnings.simplefilter("ignore", UserWarning)

    results = {
        "feeder_8500_s": stats(
            time_feeder_command(folder / "ieee8500" / "Run_8500Node.dss", args.repeat)
        ),  # fmt: skip
        "snapshot_8500_engine_s": stats(
            snapshot_8500(folder / "ieee8500" / "Master.dss", args.repeat)
        ),  # fmt: skip
        "ckt24_year_engine_s": stats(
            ckt24_year(folder / "ckt24" / "master_ckt24.dss", max(1, args.repeat // 2))
        ),  # fmt: skip
        "ckt24_year_binding_engine_s": stats(
            ckt24_year(folder / "ckt24" / "master_ckt24.dss", max(1, args.repeat // 2), 300.0)
        ),
        "ckt24_year_binding_setpoints_engine_s": stats(
            ckt24_year(
                folder / "ckt24" / "master_ckt24.dss", max(1, args.repeat // 2), 300.0, "setpoints"
            )
        ),
    }
    for key, target in TARGETS_S.items():
        results[key]["target"] = target
        results[key]["met"] = results[key]["median"] < target
    results["cpu"] = platform.processor() or platform.machine()
    results["cores"] = os.cpu_count()
    results["load_average"] = os.getloadavg()
    if args.json:
        print(json.dumps(results, indent=2))
        return
    for key in TARGETS_S:
        r = results[key]
        print(f"{key:<38} median {r['median']:.3f} s (min {r['min']:.3f} s, {r['runs']} runs), "
              f"target < {r['target']:g} s: {'met' if r['met'] else 'NOT met'}")  # fmt: skip
    print(f"load average {results['load_average']}, {results['cores']} cores")


if __name__ == "__main__":
    main()
