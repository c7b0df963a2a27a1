"""Exact mode on every scale: iterations, evaluations, the certified distance to the DC-OPF,
and the engine's time against the central QP's on the same snapshot.

Usage: python benchmarks/bench_scale.py [--cases SUBSTRING,...] [--sizes 1000,10000,100000]
    [--horizon 3000] [--laws plain,tree,scaled]

For every case of ``benchmarks/scale_cases.py`` (the built-in cases and MATPOWER radial cases
without and with a binding limit, synthetic 1k/10k/100k feeders with every candidate line
limited, the 1k feeder times 100): one exact-mode snapshot from uniform shares with the default
settings up to ``--horizon`` iterations, against the DC-OPF (``popdispatch.opf``, Clarabel).
Prints one row per case and price law: buses, limited lines (binding ones), iterations,
game/field evaluations per iteration, the largest ``|p - p_opf|`` (kW), the certificate's bound
and the accuracy (kW), the status, the engine's time and the QP's (one run each, kernels
compiled beforehand).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from scale_cases import all_cases, matpower_missing  # noqa: E402

from popdispatch.game.parameters import PriceLaw  # noqa: E402
from popdispatch.online import RunSettings, run_snapshot  # noqa: E402
from popdispatch.opf import OpfSolver  # noqa: E402


def run_case(problem, horizon: int, law: PriceLaw = PriceLaw.PLAIN) -> dict:
    """One exact-mode snapshot of minute 1 from uniform shares with price law ``law`` (engine
    time only, kernels compiled beforehand), and its DC-OPF (Clarabel, solver built and run
    once, timed in the same process)."""
    settings = RunSettings(mode="exact")
    settings = replace(settings, exact=replace(settings.exact, price_law=law),
                       integrator=replace(settings.stepping, max_iterations=horizon))  # fmt: skip
    run_snapshot(problem, 1, settings)  # compiles this configuration's kernels
    run = run_snapshot(problem, 1, settings)
    began = time.perf_counter()
    opf = OpfSolver(problem).solve(1)
    qp_seconds = time.perf_counter() - began
    return {
        "lines": len(problem.limit),
        "binding": int(np.sum(np.abs(opf.line_price) > 1e-6)),
        "iterations": run.iterations,
        "evaluations": run.evaluations / max(run.iterations, 1),
        "error_kw": float(np.max(np.abs(run.setpoints_kw - opf.p_kw))),
        "bound_kw": run.distance_bound_kw,
        "accuracy_kw": run.accuracy_kw,
        "status": run.status,
        "seconds": run.wall_seconds,
        "qp_seconds": qp_seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="", help="comma-separated substrings of case names")
    parser.add_argument("--sizes", default="1000,10000,100000")
    parser.add_argument("--horizon", type=int, default=3000)
    parser.add_argument("--laws", default="plain,tree,scaled", help="price laws, comma-separated")
    args = parser.parse_args()
    wanted = [w for w in args.cases.split(",") if w]
    sizes = tuple(int(s) for s in args.sizes.split(",") if s)
    laws = [PriceLaw.parse(w) for w in args.laws.split(",") if w]
    print(
        f"# popdispatch exact mode on every scale, {date.today()}, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )
    print("| case | buses | limits | limited (binding) | price law | iterations | evaluations"
          "/iteration | max abs(p - p_opf), kW | proved within, kW | accuracy, kW | status | "
          "engine ms | QP ms |")  # fmt: skip
    print("|" + " --- |" * 13)
    for name, limits, build in all_cases(sizes):
        if wanted and not any(w in name for w in wanted):
            continue
        if matpower_missing(name):
            print(f"| {name} | skipped: {matpower_missing(name)} |")
            continue
        problem = build()
        buses = problem.feeder.original.buses.shape[0]
        for law in laws:
            row = run_case(problem, args.horizon, law)
            print(
                f"| {name} | {buses} | {limits} | {row['lines']} ({row['binding']}) | "
                f"{law.name.lower()} | {row['iterations']} | {row['evaluations']:.1f} | "
                f"{row['error_kw']:.2g} | {row['bound_kw']:.2g} | {row['accuracy_kw']:.2g} | "
                f"{row['status']} | {row['seconds'] * 1e3:.1f} | {row['qp_seconds'] * 1e3:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
