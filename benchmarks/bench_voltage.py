"""Voltage-mode benchmark: what the voltage prices cost (issue 14, part 2).

Usage: python benchmarks/bench_voltage.py [--repeat 7] [--json]

The ``voltage`` scenario's minute (case33bw, source and four DGs, 0.95-1.05 p.u., 32 monitored
buses) in exact mode (no voltage rows: the DC-OPF) and in the voltage mode (against the
LinDistFlow OPF), each ``--repeat`` times after one warm-up run (compilation and disk cache
outside the timing); then ``--ac-correct``'s outer loop (AC power flows and reruns). Prints
the median engine wall time (``SnapshotResult.wall_seconds``), iterations, the distance from
the yardstick and the load average (other work on the machine shows in the wall time).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np

from popdispatch.online import RunSettings
from popdispatch.runs import run_snapshot_vs_opf
from popdispatch.scenarios import VOLTAGE_LIMITS, voltage_problems


def measure(problem, settings: RunSettings, repeat: int) -> dict:
    """Median engine time (s) of ``repeat`` snapshot runs, iterations and error (kW)."""
    run_snapshot_vs_opf(problem, 1, settings)  # warm-up
    times, result = [], None
    for _ in range(repeat):
        result = run_snapshot_vs_opf(problem, 1, settings)
        times.append(result.run.wall_seconds)
    error = float(np.max(np.abs(result.run.setpoints_kw - result.opf.p_kw)))
    return {"median_s": statistics.median(times), "min_s": min(times),
            "iterations": result.run.iterations, "status": result.run.status,
            "error_kw": error}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    plain, problem, load_kw = voltage_problems()
    vmin, vmax = VOLTAGE_LIMITS
    out = {
        "exact": measure(plain, RunSettings(mode="exact"), args.repeat),
        "voltage": measure(problem, RunSettings(mode="exact", vmin_pu=vmin, vmax_pu=vmax),
                           args.repeat),
    }  # fmt: skip
    try:
        from popdispatch.ac.correct import ac_correct

        settings = RunSettings(mode="exact", vmin_pu=vmin, vmax_pu=vmax)
        start = time.perf_counter()
        corrected = ac_correct(problem, load_kw[0], 1, settings)
        out["ac_correct"] = {"wall_s": time.perf_counter() - start, "rounds": corrected.rounds}
    except ImportError as exc:  # power-grid-model missing
        out["ac_correct"] = {"skipped": str(exc)}
    out["loadavg"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, indent=1))
        return
    for name in ("exact", "voltage"):
        r = out[name]
        print(f"{name:8s} median {r['median_s'] * 1e3:.2f} ms (min {r['min_s'] * 1e3:.2f}), "
              f"{r['iterations']} iterations, {r['status']}, {r['error_kw']:.2e} kW from the "
              "yardstick")  # fmt: skip
    print(f"ac_correct {out['ac_correct']}; load average {out['loadavg']}")


if __name__ == "__main__":
    main()
