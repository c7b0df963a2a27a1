"""Exact mode on every scale (issue 12): iterations, evaluations and distance to the DC-OPF.

Usage: python benchmarks/bench_scale.py [--cases SUBSTRING,...] [--sizes 1000,10000,100000]
    [--horizon 3000] [--rtol 1e-5] [--laws plain,tree,scaled]

For every case of ``benchmarks/scale_cases.py`` (the built-in cases and MATPOWER radial cases
without and with a binding limit, synthetic 1k/10k/100k feeders with every candidate line
limited, the 1k feeder times 100): one exact-mode snapshot from uniform shares with the default
settings (tolerance 1e-6 of demand) up to ``--horizon`` iterations, against the DC-OPF
(``popdispatch.opf.solve_opf``). Prints one row per case: buses, limited lines (binding ones),
iterations, game/field evaluations per iteration, the largest ``|p - p_opf|`` (kW) and its
bound ``max(1e-6 * demand, 0.001 kW)``, the status and the engine's time (kernels compiled
beforehand; one run, not a median: the iteration counts are the point). ``--laws``: the price
laws to run on every case, one row each (``modes.exact.PriceLaw``; default: all three).
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
from popdispatch.integrate import Status  # noqa: E402
from popdispatch.online import Engine, RunSettings, initial_shares  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402


def run_case(
    problem, horizon: int, rtol: float | None = None, law: PriceLaw = PriceLaw.PLAIN
) -> dict:
    """One exact-mode snapshot of minute 1 from uniform shares with price law ``law``, and its
    DC-OPF (``rtol``: the Heun error control instead of the mode's default)."""
    settings = RunSettings(mode="exact")
    settings = replace(settings, exact=replace(settings.exact, price_law=law))
    integrator = replace(settings.stepping, max_iterations=horizon)
    if rtol is not None:
        integrator = replace(integrator, rtol=rtol)
    settings = replace(settings, integrator=integrator)
    engine = Engine(problem, settings)
    x = initial_shares(problem, "uniform", 1)
    engine.warm_up(x, 1)
    start = engine.evaluations
    began = time.perf_counter()
    run = engine.run_minute(x, 1, record=False)
    seconds = time.perf_counter() - began
    p_mw = run.x * problem.demand[0]
    status = Status(run.status).name.lower()
    if run.status == Status.CONVERGED:
        reason = engine.stall_reasons(np.array([1]), p_mw[None], engine.z[None],
                                      np.array([True]))[0]  # fmt: skip
        status = "converged" if reason is None else "stalled"
    opf = solve_opf(problem, 1)
    return {
        "lines": len(problem.limit),
        "binding": int(np.sum(np.abs(opf.line_price) > 1e-6)),
        "iterations": run.iterations,
        "evaluations": (engine.evaluations - start) / max(run.iterations, 1),
        "error_kw": float(np.max(np.abs(p_mw * 1e3 - opf.p_kw))),
        "bound_kw": max(1e-6 * opf.demand_kw, 1e-3),
        "demand_kw": opf.demand_kw,
        "status": status,
        "seconds": seconds,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="", help="comma-separated substrings of case names")
    parser.add_argument("--sizes", default="1000,10000,100000")
    parser.add_argument("--horizon", type=int, default=3000)
    parser.add_argument("--rtol", type=float, default=None,
                        help="Heun error control (default: exact mode's, 1e-5)")  # fmt: skip
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
          "/iteration | max abs(p - p_opf), kW | bound, kW | status | engine ms |")  # fmt: skip
    print("| --- | ---: | --- | ---: | --- | ---: | ---: | ---: | ---: | --- | ---: |")
    for name, limits, build in all_cases(sizes):
        if wanted and not any(w in name for w in wanted):
            continue
        if matpower_missing(name):
            print(f"| {name} | skipped: {matpower_missing(name)} |")
            continue
        problem = build()
        buses = problem.feeder.original.buses.shape[0]
        for law in laws:
            row = run_case(problem, args.horizon, args.rtol, law)
            print(
                f"| {name} | {buses} | {limits} | {row['lines']} ({row['binding']}) | "
                f"{law.name.lower()} | {row['iterations']} | {row['evaluations']:.1f} | "
                f"{row['error_kw']:.2g} | {row['bound_kw']:.2g} | {row['status']} | "
                f"{row['seconds'] * 1e3:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
