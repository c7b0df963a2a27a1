"""What ``day --ac-correct`` costs per step: the AC-corrected day against the uncorrected
voltage-mode day.

Usage: python benchmarks/bench_ac_day.py [--case FILE] [--vmin PU] [--elv-vmin PU]
       [--elv-vmax PU] [--minutes START-END] [--json]

Two series, each the voltage-mode day (exact mode with voltage limits, against the
LinDistFlow OPF) and then the same steps corrected by AC power flows
(:func:`popdispatch.ac.correct_day.ac_correct_day`, every step warm-started from the step
before):

- a MATPOWER radial case (default ``../shared/feeders/matpower/case69.m``; 69 buses) with a
  grid source and three DGs (:data:`FLEET`), its loads following the official ELV profiles
  for a day at one minute: each bus's nominal load times the mean of ten official profiles
  (seeded choice), scaled to peak at the nominal load; ``--vmin`` (default 0.95 p.u.);
- the IEEE European LV feeder (906 buses, 55 loads, the paper's six generators) with its
  official profiles (``../shared/ieee-elv``), the whole day, ``--elv-vmax`` (default 1.002
  p.u.: binding at 679 minutes where the DGs export; a ``--vmin`` that binds on this feeder
  is infeasible at its peak minutes, 0.9925 p.u. already at two).

Per series: the uncorrected day's engine time per step (``DayResult.wall_seconds`` over the
steps, the kernels compiled before; and the process's CPU time of the whole ``run_day``,
certificates included) and its AC check (one batch for every step), the
corrected day's rounds, AC power flows and wall seconds per step (medians, means and
largest; CPU seconds; the mean wall time in its engine runs, power flows and certificates),
and how far each day's AC voltages miss the limits (worst step, steps outside the
1e-5 p.u. tolerance). The load average is printed: other work on the machine shows in the
wall times.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.ac import check_day, correct_day
from popdispatch.ac.check import minute_loads
from popdispatch.ac.correct import Meter
from popdispatch.ac.correct_day import ac_correct_day
from popdispatch.ac.limits import limits_summary
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.online import Engine, RunSettings, run_day
from popdispatch.runs import FeederSource, load_feeder, load_run, with_voltage
from popdispatch.scenarios import elv_problem

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared"
#: The MATPOWER case's fleet: bus, name, b EUR/MWh, c EUR/MW^2h, pmin kW, pmax kW.
FLEET = (
    "bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw\n"
    "1,grid,20,0.5,0,6000\n61,DG61,40,2,0,800\n64,DG64,45,2,0,600\n27,DG27,50,2,0,400\n"
)
PROFILES = 100


def official_shapes(folder: Path, loads: int, seed: int = 1) -> np.ndarray:
    """(1440, loads): per load the mean of ten official ELV profiles, scaled to peak 1."""
    rng = np.random.default_rng(seed)
    files = folder / "Daily_1min_100profiles"
    table = np.column_stack(
        [np.loadtxt(files / f"load_profile_{k}.txt") for k in range(1, PROFILES + 1)]
    )
    picks = [rng.choice(PROFILES, size=10, replace=False) for _ in range(loads)]
    shapes = np.column_stack([table[:, p].mean(axis=1) for p in picks])
    return shapes / shapes.max(axis=0)


def matpower_series(case: Path, fleet: Path, elv: Path, settings: RunSettings):
    """``(problem, profiles)``: the case with :data:`FLEET` and a day of loads shaped as
    :func:`official_shapes`."""
    feeder = load_feeder(FeederSource(net=case, fleet=fleet))
    nominal = feeder.loads["p_kw"].to_numpy(float)
    kw = official_shapes(elv, len(nominal)) * nominal
    table = pd.DataFrame(kw, index=pd.RangeIndex(1, len(kw) + 1, name="minute"),
                         columns=feeder.loads.index)  # fmt: skip
    profiles = LoadProfiles(table, f"{case.name} loads x official ELV shapes")
    problem = elv_problem(profiles, (), feeder, check=False)
    return with_voltage(problem, profiles, settings), profiles


def elv_series(elv: Path, settings: RunSettings):
    """``(problem, profiles)``: the ELV feeder with its official profiles."""
    problem, profiles = load_run(FeederSource(), profiles=elv)
    return with_voltage(problem, profiles, settings), profiles


#: The parts of a corrected step timed apart: (name, owner, attribute).
PARTS = (
    ("engine", Engine, "run_day_chunk"),
    ("power_flows", Meter, "measure"),
    ("certificate", correct_day, "_verdicts"),
)


@contextlib.contextmanager
def timed_parts():
    """Seconds spent in each of :data:`PARTS` while the block runs (wrapped, then restored)."""
    spent: dict[str, float] = defaultdict(float)
    saved = [(owner, name, getattr(owner, name)) for _, owner, name in PARTS]

    def wrap(part, func):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return func(*args, **kwargs)
            finally:
                spent[part] += time.perf_counter() - start

        return timed

    for (part, owner, name), (_, _, func) in zip(PARTS, saved, strict=True):
        setattr(owner, name, wrap(part, func))
    try:
        yield spent
    finally:
        for owner, name, func in saved:
            setattr(owner, name, func)


def measure(problem, profiles, settings: RunSettings, minutes: np.ndarray) -> dict:
    """The uncorrected and the corrected day over ``minutes``: cost per step and AC misses."""
    run_day(problem, settings, minutes[:2])  # compile outside the timing
    cpu = time.process_time()
    day = run_day(problem, settings, minutes)
    day_cpu = time.process_time() - cpu
    start = time.perf_counter()
    ac = check_day(problem, profiles, day)
    ac_seconds = time.perf_counter() - start
    plain = limits_summary(ac.steps, problem.vmin_pu, problem.vmax_pu)
    loads = minute_loads(problem.feeder.original, profiles, minutes)
    with timed_parts() as spent:
        start, cpu = time.perf_counter(), time.process_time()
        corrected = ac_correct_day(problem, loads, minutes, settings)
        wall, corrected_cpu = time.perf_counter() - start, time.process_time() - cpu
    s, c = corrected.steps, corrected.summary()
    n = len(minutes)
    parts = {f"{part}_s_per_step_mean": seconds / n for part, seconds in spent.items()}
    return {
        "steps": n,
        "uncorrected": {
            "engine_s_per_step_mean": day.wall_seconds / n,
            "cpu_s_per_step_mean": day_cpu / n,
            "ac_check_s_per_step_mean": ac_seconds / n,
            "iterations_median": float(np.median(day.iterations)),
            "converged_steps": int(day.converged.sum()),
            "miss_pu": _miss(plain),
            "steps_outside": plain["steps_outside"],
        },
        "corrected": {
            "wall_s": wall,
            "cpu_s_per_step_mean": corrected_cpu / n,
            "s_per_step_median": float(s["seconds"].median()),
            "s_per_step_mean": float(s["seconds"].mean()),
            "s_per_step_max": float(s["seconds"].max()),
            "rounds_per_step_median": float(s["rounds"].median()),
            "rounds_per_step_mean": float(s["rounds"].mean()),
            "rounds_per_step_max": int(s["rounds"].max()),
            "power_flows_per_step_median": float(s["power_flows"].median()),
            "power_flows_per_step_mean": float(s["power_flows"].mean()),
            "iterations_per_step_median": float(s["iterations"].median()),
            **parts,
            "statuses": s["status"].value_counts().to_dict(),
            "settled_steps": c["settled_steps"],
            "miss_pu": _miss(c["voltage_limits"]),
            "steps_outside": c["voltage_limits"]["steps_outside"],
        },
    }


def _miss(limits: dict) -> float:
    """The worst miss of either limit, p.u."""
    return max(limits["below_vmin_pu"] or 0.0, limits["above_vmax_pu"] or 0.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=Path, default=SHARED / "feeders/matpower/case69.m")
    parser.add_argument("--vmin", type=float, default=0.95, help="p.u., the MATPOWER case")
    parser.add_argument("--elv", type=Path, default=SHARED / "ieee-elv")
    parser.add_argument("--elv-vmin", type=float, help="p.u., the ELV feeder")
    parser.add_argument("--elv-vmax", type=float, default=1.002, help="p.u., the ELV feeder")
    parser.add_argument("--minutes", help="START-END (default the whole day)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    first, last = (int(v) for v in args.minutes.split("-")) if args.minutes else (1, 1440)
    minutes = np.arange(first, last + 1)
    fleet = Path(os.environ.get("TMPDIR", "/tmp")) / "bench_ac_day_fleet.csv"
    fleet.write_text(FLEET)
    out = {}
    settings = RunSettings(mode="exact", vmin_pu=args.vmin)
    problem, profiles = matpower_series(args.case, fleet, args.elv, settings)
    out[args.case.stem] = measure(problem, profiles, settings, minutes)
    settings = RunSettings(mode="exact", vmin_pu=args.elv_vmin, vmax_pu=args.elv_vmax)
    problem, profiles = elv_series(args.elv, settings)
    out["ieee-elv"] = measure(problem, profiles, settings, minutes)
    out["loadavg"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, indent=1, default=str))
        return
    for name in (args.case.stem, "ieee-elv"):
        r = out[name]
        u, c = r["uncorrected"], r["corrected"]
        print(f"{name}, {r['steps']} steps")
        print(f"  uncorrected: engine {u['engine_s_per_step_mean'] * 1e3:.2f} ms/step (mean; "
              f"CPU of the day run {u['cpu_s_per_step_mean'] * 1e3:.2f}), "
              f"AC check {u['ac_check_s_per_step_mean'] * 1e3:.2f} ms/step, "
              f"{u['iterations_median']:g} iterations (median), {u['converged_steps']} "
              f"converged; AC misses the limits by up to {u['miss_pu']:.2e} p.u., "
              f"{u['steps_outside']} steps outside")  # fmt: skip
        print(f"  corrected: {c['s_per_step_median'] * 1e3:.2f} ms/step median (mean "
              f"{c['s_per_step_mean'] * 1e3:.2f}, max {c['s_per_step_max'] * 1e3:.1f}; CPU mean "
              f"{c['cpu_s_per_step_mean'] * 1e3:.2f}), rounds "
              f"median {c['rounds_per_step_median']:g} (mean {c['rounds_per_step_mean']:.2f}, "
              f"max {c['rounds_per_step_max']}), AC power flows median "
              f"{c['power_flows_per_step_median']:g} (mean {c['power_flows_per_step_mean']:.1f}"
              f"), {c['iterations_per_step_median']:g} iterations; {c['statuses']}, "
              f"{c['settled_steps']} settled; AC misses the limits by up to "
              f"{c['miss_pu']:.2e} p.u., {c['steps_outside']} steps outside; "
              f"{c['wall_s']:.1f} s in all")  # fmt: skip
        print("  corrected, mean ms/step: " + ", ".join(
            f"{part} {c[f'{part}_s_per_step_mean'] * 1e3:.2f}" for part, _, _ in PARTS))
    print(f"load average {out['loadavg']}")


if __name__ == "__main__":
    main()
