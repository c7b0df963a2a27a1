"""Exact mode on PGLib-OPF cases (IEEE PES Power Grid Library, v23.07, CC BY 4.0): iterations
to the stated accuracy and to a 1 % optimality gap beside PowerModelsADA.jl's published
iteration counts on the same cases (DC), and engine time against the central QP (Clarabel)
in the same run, on IEEE 14, IEEE 300 and a ~2,000-bus case.

Usage: python benchmarks/bench_pglib.py [--pglib DIR] [--big case2000_goc ...] [--no-big]
       [--repeats 3] [--factors]

The PGLib files are read from ``--pglib DIR`` or the environment variable ``PGLIB_OPF_DIR``
(``pglib_opf_<case>.m``; they are not part of the repository); a case whose file is absent is
skipped with one line saying so. Each case as PGLib has it: its own ratings (``RATE_A`` on
every branch), demand and linear or quadratic costs, read by ``read_matpower_network``
(MATPOWER's DC model; PGLib's angle-difference limits are not modelled).

- *to accuracy*: the iteration the run is certified at (``converged_at``): within
  ``max(1e-3 kW, 1e-6 demand)`` (the default accuracy) of the DC-OPF, proved by the
  distance certificate; "None" when not proved.
- *to 1 %*: the first iteration from which every later one has a cost within 1 % of
  Clarabel's optimal cost (relative to it) and no limited line more than 1 % over its rating
  (relative to the rating); every iterate meets the demand exactly (``sum p = P_d``).
  PowerModelsADA's criterion: the relative error of the cost against the central solution
  below 1 % and the l2-norm of the areas' mismatches of their shared boundary values below
  0.01 (radians and p.u.).
- times: the engine's own seconds for the run (``wall_seconds``; a warm-up run first, so the
  numba cache is warm), the median of ``--repeats`` runs, against Clarabel's solve of the same
  DC-OPF (building and solving the QP, median of as many runs) in the bus-angle formulation
  (the default on a mesh); ``--factors`` also times the dense distribution-factor rows once.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from popdispatch.game.mesh import build_mesh_problem
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import OpfSolver, generation_cost
from popdispatch.readers.matpower import read_matpower_network

#: PowerModelsADA.jl v0.1.1's published iterations (docs/src/comparison.md, "DC
#: Approximation"): case -> (areas, ADMM, ATC, APP).
POWERMODELSADA = {"case14_ieee": (2, 15, 45, 21), "case300_ieee": (4, 26, 58, 36)}

HEADER = (
    "| case | buses | lines (limited / binding) | generators (quadratic) | demand MW | status "
    "| iterations to accuracy | to 1 % | evaluations per iteration | engine s | engine ms per "
    "iteration | Clarabel s | distance to Clarabel kW | certified bound kW | cost gap to "
    "Clarabel | PowerModelsADA ADMM / ATC / APP (areas) |"
)


def to_gap(problem, run, cost: float, gap: float = 0.01) -> int:
    """First iteration from which cost is within ``gap`` of ``cost`` (relative) and every
    limited line within ``gap`` of its rating (relative), for good."""
    p = run.trajectory_kw / 1e3
    costs = generation_cost(problem, p)
    flows = problem.line_load_flow[0][None, :] - p @ problem.down.T
    over = ((np.abs(flows) - problem.limit) / problem.limit).max(axis=1, initial=0.0)
    ok = (np.abs(costs - cost) <= gap * abs(cost)) & (over <= gap)
    bad = np.flatnonzero(~ok)
    return 0 if not len(bad) else int(bad[-1] + 1)


def timed(function, repeats: int):
    """``(result of the last call, median seconds)`` of ``repeats`` calls."""
    seconds = []
    for _ in range(repeats):
        began = time.perf_counter()
        result = function()
        seconds.append(time.perf_counter() - began)
    return result, statistics.median(seconds)


def row(name: str, path: Path, repeats: int, factors: bool) -> str:
    net = read_matpower_network(path)
    problem = build_mesh_problem(net)
    opf, qp_seconds = timed(lambda: OpfSolver(problem).solve(1), repeats)
    settings = RunSettings(mode="exact")
    run_snapshot(problem, 1, settings)  # warm-up: compile or load the kernels
    runs = [run_snapshot(problem, 1, settings) for _ in range(repeats)]
    run = runs[-1]
    engine_seconds = statistics.median(r.wall_seconds for r in runs)
    binding = int((np.abs(opf.line_price) > 1e-6).sum())
    cost = float(generation_cost(problem, run.setpoints_kw / 1e3))
    ada = POWERMODELSADA.get(name)
    ada_text = f"{ada[1]} / {ada[2]} / {ada[3]} ({ada[0]})" if ada else "-"
    iterations = max(run.iterations, 1)
    line = (
        f"| {name} | {len(net.buses)} | {len(net.lines)} ({len(problem.limit)} / {binding}) "
        f"| {problem.n_generators} ({int((problem.c > 0).sum())}) | {problem.demand[0]:.1f} "
        f"| {run.status} | {run.converged_at} | {to_gap(problem, run, opf.cost)} "
        f"| {run.evaluations / iterations:.1f} | {engine_seconds:.3f} "
        f"| {1e3 * engine_seconds / iterations:.2f} | {qp_seconds:.3f} "
        f"| {np.abs(run.setpoints_kw - opf.p_kw).max():.2e} | {run.distance_bound_kw:.2e} "
        f"| {(cost - opf.cost) / opf.cost:.1e} | {ada_text} |"
    )
    notes = [f"{name}: {run.iterations} iterations, rest at {run.rest_at}"
             + (f"; {run.stall_reason}" if run.stall_reason else "")
             + f"; Clarabel's formulation: {OpfSolver(problem).formulation}, cost {opf.cost:.2f}"
             f" EUR/h"]  # fmt: skip
    if factors:
        dense, seconds = timed(lambda: OpfSolver(problem, "factors").solve(1), 1)
        notes.append(
            f"{name}: Clarabel with dense factor rows {seconds:.1f} s, "
            f"{np.abs(dense.p_kw - opf.p_kw).max():.3g} kW from the angle formulation's optimum, "
            f"cost {dense.cost - opf.cost:+.3g} EUR/h"
        )
    return line, notes


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--pglib", default=os.environ.get("PGLIB_OPF_DIR"),
                        help="the pglib_opf_<case>.m files' folder (or PGLIB_OPF_DIR)")
    parser.add_argument("--big", nargs="+", default=["case2000_goc"])
    parser.add_argument("--no-big", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--factors", action="store_true",
                        help="also time Clarabel's dense factor rows on the big cases")
    args = parser.parse_args()
    if not args.pglib:
        raise SystemExit("bench_pglib.py: give --pglib DIR or PGLIB_OPF_DIR (PGLib-OPF's files)")
    cases = ["case14_ieee", "case300_ieee"] + ([] if args.no_big else args.big)
    print(HEADER)
    print("|---" * (HEADER.count("|") - 1) + "|")
    notes = []
    for name in cases:
        path = Path(args.pglib) / f"pglib_opf_{name}.m"
        if not path.is_file():
            notes.append(f"{name}: skipped, {path} is absent")
            continue
        big = name not in POWERMODELSADA
        line, more = row(name, path, args.repeats, args.factors and big)
        print(line, flush=True)
        notes += more
    print()
    for note in notes:
        print(f"- {note}")


if __name__ == "__main__":
    main()
