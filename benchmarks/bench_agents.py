"""Benchmark of the agents (mango's simulated world): the congestion minute (566, path 505-666
limited to 28 kW), exact mode, perfect network, 10 % loss, and 10 % loss with delays up to 3
rounds (paced rounds, the default): wall and CPU time of the simulation (CPU time: this
process alone, a fairer figure on a shared machine), rounds, messages, error against the
DC-OPF.

Usage: python benchmarks/bench_agents.py [--repeat N]
Prints medians of N runs (after one warm-up run that loads the compiled kernels).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from datetime import date

import numpy as np

from popdispatch.agents.network import Faults
from popdispatch.agents.system import AgentSettings, run_agents
from popdispatch.online import RunSettings
from popdispatch.opf import solve_opf
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem, peak_profiles

CASES = {
    "perfect network": Faults(),
    "10 % loss": Faults(loss=0.1, seed=1),
    "10 % loss, delays up to 3 rounds": Faults(loss=0.1, delay_max=3, seed=1),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    problem = elv_problem(peak_profiles(), [CONGESTION_PATH])
    opf_kw = solve_opf(problem, PEAK_MINUTE).p_kw
    settings = RunSettings(mode="exact")
    print(
        f"# popdispatch agents benchmark, {date.today()}, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}"
    )
    run_agents(problem, PEAK_MINUTE, settings, Faults(), AgentSettings(max_rounds=5))  # warm-up
    print("| network | wall s | CPU s | rounds | within 0.01 kW from round | messages | lost "
          "| msgs/agent/round | final error kW | max imbalance W |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for label, faults in CASES.items():
        runs, cpu = [], []
        for _ in range(args.repeat):
            start = time.process_time()
            runs.append(
                run_agents(problem, PEAK_MINUTE, settings, faults, AgentSettings(max_rounds=600))
            )
            cpu.append(time.process_time() - start)
        run = runs[-1]
        error = np.abs(run.trajectory_kw - opf_kw).max(axis=1)
        within = next((r for r in range(len(error)) if (error[r:] < 0.01).all()), None)
        final = float(np.abs(run.setpoints_kw - opf_kw).max())
        wall = statistics.median(r.wall_seconds for r in runs)
        print(
            f"| {label} | {wall:.2f} | {statistics.median(cpu):.2f} | {run.rounds} | {within} | "
            f"{run.messages} | {run.lost} | {run.messages_per_agent_round:.2f} | {final:.2g} | "
            f"{run.max_imbalance_w:.2g} |"
        )


if __name__ == "__main__":
    main()
