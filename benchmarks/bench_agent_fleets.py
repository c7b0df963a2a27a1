"""Benchmark of the agents on random fleets (``benchmarks/fleet_cases.py``: curvatures over
five decades, linear DGs, ``Pmin > 0``, a binding limit in half the cases): exact mode from
uniform shares on a perfect network, Smith on the complete graph and distributed Smith on a
ring (the relay), with and without the local step (``AgentSettings.local_step``). Reports the
rounds to ``converged`` (the distance certificate proves the end state within the accuracy),
the status, and the distance to the project's DC-OPF (Clarabel, its own tolerance certified
as in ``bench_fleets.py``).

Usage: python benchmarks/bench_agent_fleets.py [--runs N] [--seed S] [--max-rounds R]
[--synthetic 1000] [--price-law plain|scaled]
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from datetime import date
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_fleets import feeders, qp_bound_kw  # noqa: E402
from fleet_cases import fleet_case  # noqa: E402

from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents  # noqa: E402
from popdispatch.modes.exact import ExactConstants  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402
from popdispatch.opf import OpfSolver  # noqa: E402

#: (label, dynamics, graph) of each variant.
GRAPHS = (("complete", "smith", "complete"), ("ring", "distributed-smith", "ring"))


def run_one(problem, dynamics: str, graph: str, local: bool, max_rounds: int, opf,
            law: str = "plain") -> dict:  # fmt: skip
    settings = RunSettings(mode="exact", dynamics=dynamics, graph=graph,
                           exact=ExactConstants(price_law=law))  # fmt: skip
    began = time.process_time()
    run = run_agents(problem, 1, settings, Faults(),
                     AgentSettings(max_rounds=max_rounds, local_step=local))  # fmt: skip
    return {
        "status": run.status,
        "rounds": run.rounds,
        "step_s": run.step_s,
        "distance_kw": float(np.max(np.abs(run.setpoints_kw - opf.p_kw))),
        "accuracy_kw": run.accuracy_kw,
        "qp_bound_kw": qp_bound_kw(problem, opf),
        "cpu_s": time.process_time() - began,
    }


def summary(rows: list[dict]) -> str:
    rounds = np.array([r["rounds"] for r in rows])
    ok = np.array([r["status"] == "converged" for r in rows])
    far = sum(r["status"] == "converged" and r["distance_kw"] > r["accuracy_kw"] + r["qp_bound_kw"]
              for r in rows)  # fmt: skip
    conv = rounds[ok] if ok.any() else np.array([0])
    return (f"converged {ok.sum()} of {len(rows)}; rounds of the converged median "
            f"{np.median(conv):.0f}, p95 {np.percentile(conv, 95):.0f}, max {conv.max()}; "
            f"over 200 rounds {int((rounds > 200).sum())}; converged farther than the "
            f"accuracy {far}; CPU s median {np.median([r['cpu_s'] for r in rows]):.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--max-rounds", type=int, default=2000)
    parser.add_argument("--synthetic", default="", help="synthetic feeder sizes, e.g. 1000")
    parser.add_argument("--price-law", default="plain", choices=("plain", "scaled"),
                        help="the node controllers' price law")
    args = parser.parse_args()
    bases = feeders([int(n) for n in args.synthetic.split(",") if n])
    names = sorted(bases)
    loaded: dict = {}
    rng = np.random.default_rng(args.seed)
    print(f"# bench_agent_fleets, {date.today()}, {platform.machine()}, "
          f"{platform.python_version()}, {args.runs} random fleets, seed {args.seed}, "
          f"{args.price_law} price law")  # fmt: skip
    rows: dict[tuple, list[dict]] = {}
    for _ in range(args.runs):
        name = names[rng.integers(len(names))]
        if name not in loaded:
            loaded[name] = bases[name]()
        case = fleet_case(rng, name, loaded[name], bool(rng.random() < 0.5))
        opf = OpfSolver(case.problem).solve(1)
        if opf.status != "optimal":
            continue
        for label, dynamics, graph in GRAPHS:
            for local in (False, True):
                row = run_one(case.problem, dynamics, graph, local, args.max_rounds, opf,
                              args.price_law)  # fmt: skip
                rows.setdefault((label, local), []).append(row)
                print(f"{case.label} | {label} | local {local} | {row['status']} | "
                      f"{row['rounds']} rounds | h {row['step_s']:.3g} s | "
                      f"{row['distance_kw']:.2g} kW", flush=True)  # fmt: skip
    for (label, local), found in rows.items():
        print(f"{label}, local step {local}: {summary(found)}")


if __name__ == "__main__":
    main()
