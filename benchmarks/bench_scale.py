"""Scaling benchmark on synthetic radial feeders: time per iteration and iterations to converge.

Usage: python benchmarks/bench_scale.py [--repeat N] [--sizes 1000,10000,100000]
    [--generators 10,100,1000] [--limited 1.0] [--horizon 3000]

For every (buses, generators) pair: a seeded synthetic feeder (popdispatch.feeder.synthetic)
with ``--limited`` of its candidate lines limited (1.0 = every line with a generator below
it: the most controllers), reduced to key nodes; one exact-mode minute at peak load from
uniform shares. Prints the medians of N runs (after one warm-up run that compiles the kernels)
of the engine time per iteration over ``--iterations`` fixed iterations, and the iterations the
run needs to converge (up to ``--horizon``), with the game/field evaluations per iteration.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from datetime import date

from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.feeder.synthetic import synthetic_feeder, synthetic_load_kw
from popdispatch.game.problem import build_problem_from_loads
from popdispatch.integrate import Integrator, Status
from popdispatch.modes import get_mode
from popdispatch.online import Engine, RunSettings, initial_shares


def scale_problem(n_buses: int, n_generators: int, limited: float):
    feeder = synthetic_feeder(n_buses, n_generators, seed=1, limited_lines=limited)
    load = synthetic_load_kw(feeder).loc[feeder.loads.index].to_numpy()
    return build_problem_from_loads(reduce_feeder(feeder), load[None, :], "synthetic peak")


def per_iteration(problem, iterations: int, repeat: int) -> tuple[float, float]:
    """Median seconds per iteration over ``iterations`` fixed iterations, evaluations each."""
    stepping = get_mode("exact").integrator
    fixed = Integrator(**{**stepping.__dict__, "max_iterations": iterations, "tol_kw": 1e-12})
    times, evaluations = [], []
    for _ in range(repeat + 1):  # the first run compiles / loads the kernels
        engine = Engine(problem, RunSettings(mode="exact", integrator=fixed))
        x = initial_shares(problem, "uniform", 1)
        start = time.perf_counter()
        steps = engine.run_minute(x, 1, record=False).iterations
        times.append((time.perf_counter() - start) / steps)
        evaluations.append(engine.evaluations / steps)
    return statistics.median(times[1:]), statistics.median(evaluations[1:])


def to_converge(problem, horizon: int) -> tuple[int, bool]:
    stepping = get_mode("exact").integrator
    capped = Integrator(**{**stepping.__dict__, "max_iterations": horizon})
    engine = Engine(problem, RunSettings(mode="exact", integrator=capped))
    run = engine.run_minute(initial_shares(problem, "uniform", 1), 1, record=False)
    return run.iterations, run.status == Status.CONVERGED


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sizes", default="1000,10000,100000")
    parser.add_argument("--generators", default="10,100,1000")
    parser.add_argument("--limited", type=float, default=1.0)
    parser.add_argument("--iterations", type=int, default=200)
    parser.add_argument("--horizon", type=int, default=3000)
    args = parser.parse_args()
    print(
        f"# popdispatch scale benchmark, {date.today()}, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; exact mode, medians of {args.repeat}"
    )
    print("buses | generators | key nodes | limited lines | ms/iteration | evaluations/iteration"
          " | iterations to converge")  # fmt: skip
    for n_buses in map(int, args.sizes.split(",")):
        for n_gen in map(int, args.generators.split(",")):
            if n_gen * 4 > n_buses:
                continue
            problem = scale_problem(n_buses, n_gen, args.limited)
            seconds, evaluations = per_iteration(problem, args.iterations, args.repeat)
            steps, converged = to_converge(problem, args.horizon)
            converge = f"{steps}" if converged else f">{args.horizon} (not converged)"
            print(
                f"{n_buses} | {n_gen} | {problem.feeder.n_nodes} | {len(problem.limit)} | "
                f"{seconds * 1e3:.3f} | {evaluations:.1f} | {converge}",
                flush=True,
            )



if __name__ == "__main__":
    main()
