"""The agents' fault table (docs/agents.md): the congestion minute (566, path 505-666 limited
to 28 kW) in exact mode under message loss, delays, duplicates, agent faults and sensor noise,
and on a ring (the relay); paper mode on a perfect and a lossy network. One run per row (seed
1): rounds, the round the set points came to rest, the first round from which every later
set point is within 0.01 kW of the DC-OPF (Clarabel; without the tripped DG for a trip; in
paper mode, whose rest is not the DC-OPF, of the engine's paper-mode rest point),
final error, messages, largest committed imbalance and largest source-bus transient, wall and
CPU time.

Usage: python benchmarks/fault_table.py [--max-rounds N] [--only SUBSTRING]
"""

from __future__ import annotations

import argparse
import time
from datetime import date

import numpy as np

from popdispatch.agents.network import FaultEvent, Faults
from popdispatch.agents.system import AgentSettings, run_agents, without
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem, peak_profiles

EXACT = RunSettings(mode="exact")
RING = RunSettings(mode="exact", dynamics="distributed-smith", graph="ring")
PAPER = RunSettings(mode="paper")


def rows() -> list[tuple[str, RunSettings, Faults, AgentSettings, bool]]:
    """(label, settings, faults, agent settings, without limits) of every row."""
    paced = AgentSettings()
    unpaced = AgentSettings(paced=False)
    table = [(f"loss {loss:g}", EXACT, Faults(loss=loss, seed=1), paced, False)
             for loss in (0.0, 0.1, 0.2, 0.3)]  # fmt: skip
    table += [(f"loss 0.1, delay {d} (paced)", EXACT, Faults(loss=0.1, delay_max=d, seed=1),
               paced, False) for d in (1, 3, 10)]  # fmt: skip
    table += [
        ("loss 0.3, delay 3 (paced)", EXACT, Faults(loss=0.3, delay_max=3, seed=1), paced, False),
        ("loss 0.1, delay 3 (unpaced)", EXACT, Faults(loss=0.1, delay_max=3, seed=1), unpaced,
         False),
        ("duplicates 0.5 (reordered)", EXACT, Faults(duplicate=0.5, seed=1), paced, False),
        ("G739 agent down rounds 5-15", EXACT,
         Faults(events=(FaultEvent("crash", "G739", 5, 10),)), paced, False),
        ("C505 crash at round 60, loss 0.1", EXACT,
         Faults(loss=0.1, seed=1, events=(FaultEvent("controller-crash", "C505", 60),)), paced,
         False),
        ("G578 trip at round 20 (no limit)", EXACT,
         Faults(events=(FaultEvent("trip", "G578", 20),)), paced, True),
        ("G578 trip at round 20, loss 0.1 (no limit)", EXACT,
         Faults(loss=0.1, seed=1, events=(FaultEvent("trip", "G578", 20),)), paced, True),
        ("noise 0.01 kW", EXACT, Faults(noise_kw=0.01, seed=1),
         AgentSettings(max_rounds=400), False),
        ("ring (relay)", RING, Faults(), paced, False),
        ("ring (relay), loss 0.1, delay 3", RING, Faults(loss=0.1, delay_max=3, seed=1), paced,
         False),
        ("paper mode", PAPER, Faults(), paced, False),
        ("paper mode, loss 0.1", PAPER, Faults(loss=0.1, seed=1), paced, False),
    ]  # fmt: skip
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-rounds", type=int, default=1500)
    parser.add_argument("--only", default="")
    args = parser.parse_args()
    limited = elv_problem(peak_profiles(), [CONGESTION_PATH])
    free = elv_problem(peak_profiles(), [])
    print(f"# popdispatch agents fault table, {date.today()}, seed 1, at most "
          f"{args.max_rounds} rounds")  # fmt: skip
    print("| case | status | rounds | at rest | within 0.01 kW from | final error kW | messages "
          "| per agent per round | lost | max committed imbalance W | max source transient W "
          "| wall s | CPU s |")  # fmt: skip
    print("| --- " * 13 + "|")
    for label, settings, faults, opts, unlimited in rows():
        if args.only not in label:
            continue
        problem = free if unlimited else limited
        tripped = [e.agent for e in faults.events if e.kind == "trip"]
        opf = solve_opf(without(problem, PEAK_MINUTE, tripped), PEAK_MINUTE).p_kw
        if settings.mode == "paper":  # its yardstick: the engine's rest point
            opf = run_snapshot(problem, PEAK_MINUTE, settings).setpoints_kw
        if opts.max_rounds == AgentSettings().max_rounds:
            opts = AgentSettings(**{**opts.__dict__, "max_rounds": args.max_rounds})
        cpu = time.process_time()
        run = run_agents(problem, PEAK_MINUTE, settings, faults, opts)
        cpu = time.process_time() - cpu
        error = np.abs(run.trajectory_kw - opf).max(axis=1)
        within = next((r for r in range(len(error)) if (error[r:] < 0.01).all()), None)
        final = float(np.abs(run.setpoints_kw - opf).max())
        print(
            f"| {label} | {run.status} | {run.rounds} | {run.rest_round} | {within} | "
            f"{final:.1e} | {run.messages:,} | {run.messages_per_agent_round:.1f} | "
            f"{run.lost:,} | {run.max_imbalance_w:.1e} | {run.max_transient_w:.2g} | "
            f"{run.wall_seconds:.1f} | {cpu:.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
