"""Exact mode's constants side by side: the numbers behind docs/exact-mode.md, "Choosing the
constants".

Usage: python benchmarks/tune_exact.py [--fleets 120] [--seed 1] [--profiles DIR]
    "gain=300,rate_cap=10" "revision=capacity" ...

Each argument is one set of :class:`popdispatch.modes.exact.ExactConstants` (``name=value``
pairs; an empty string is the defaults). For each set, in one process and on the same cases:

- ``--fleets`` random (case, fleet, limit) triples of ``benchmarks/fleet_cases.py`` (MATPOWER
  radial cases, one binding limit in half of them) from uniform shares: iterations to
  ``converged`` (median, p95, max; runs not converged in 1000 iterations counted apart) and
  evaluations of the game and field per iteration;
- the ELV congestion minute (566, line 505:666 at 28 kW) from uniform shares: iterations and
  evaluations;
- the ELV day with that limit (``--profiles``, else ``../shared/ieee-elv``): iterations over
  the day, minutes converged, the engine's wall time;
- the synthetic 1k and 10k feeders of ``benchmarks/scale_cases.py`` (every line limited):
  iterations (``-`` when not converged in 400).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fleet_cases import fleet_case, matpower_feeder, matpower_paths  # noqa: E402
from scale_cases import all_cases  # noqa: E402

from popdispatch.integrate import Status  # noqa: E402
from popdispatch.modes.exact import ExactConstants  # noqa: E402
from popdispatch.online import Engine, RunSettings, initial_shares, run_day  # noqa: E402
from popdispatch.runs import load_profiles  # noqa: E402
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def constants_of(spec: str) -> ExactConstants:
    """``"gain=300,revision=capacity"`` as :class:`ExactConstants` (numbers as floats)."""
    values: dict[str, object] = {}
    for pair in filter(None, spec.split(",")):
        name, _, text = pair.partition("=")
        try:
            values[name.strip()] = float(text)
        except ValueError:
            values[name.strip()] = text.strip()
    return ExactConstants(**values)


def random_fleets(count: int, seed: int) -> list:
    rng = np.random.default_rng(seed)
    paths = matpower_paths()
    names = sorted(paths)
    feeders: dict = {}
    problems = []
    for _ in range(count):
        name = names[rng.integers(len(names))]
        if name not in feeders:
            feeders[name] = matpower_feeder(paths[name])
        problems.append(fleet_case(rng, name, feeders[name], bool(rng.random() < 0.5)).problem)
    return problems


def iterations(settings: RunSettings, problems: list, horizon: int) -> tuple[np.ndarray, float]:
    """Iterations to ``converged`` per problem (``horizon + 1`` where not) and the mean
    evaluations per iteration."""
    counts, evaluations = [], 0
    for problem in problems:
        engine = Engine(problem, settings)
        result = engine.run_minute(initial_shares(problem, "uniform", 1), 1,
                                   max_iterations=horizon, record=False)  # fmt: skip
        done = result.status == Status.CONVERGED
        counts.append(result.iterations if done else horizon + 1)
        evaluations += engine.evaluations
    counts = np.array(counts)
    return counts, evaluations / max(np.minimum(counts, horizon).sum(), 1)


def row(spec: str, fleets: list, congestion, day, synthetic: list) -> str:
    settings = RunSettings(mode="exact", exact=constants_of(spec))
    its, per_iteration = iterations(settings, fleets, 1000)
    engine = Engine(congestion, settings)
    minute = engine.run_minute(initial_shares(congestion, "uniform", PEAK_MINUTE), PEAK_MINUTE)
    whole = run_day(day, settings)
    synthetic_its, _ = iterations(settings, synthetic, 400)
    shown = ["-" if n > 400 else str(n) for n in synthetic_its]
    missed = int((its > 1000).sum())
    return (f"| `{spec or 'defaults'}` | {np.median(its):.0f} / {np.percentile(its, 95):.0f} / "
            f"{'-' if missed else its.max()} | {missed} | {per_iteration:.0f} | "
            f"{minute.iterations} / {engine.evaluations} | {int(whole.iterations.sum())} / "
            f"{int(whole.converged.sum())} / {whole.wall_seconds * 1e3:.0f} | "
            f"{', '.join(shown)} |")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("specs", nargs="*", default=[""])
    parser.add_argument("--fleets", type=int, default=120)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--profiles", type=Path, default=ROOT.parent / "shared" / "ieee-elv")
    args = parser.parse_args()
    fleets = random_fleets(args.fleets, args.seed)
    congestion = elv_problem(limits=[CONGESTION_PATH])
    day = elv_problem(profiles=load_profiles(args.profiles), limits=[CONGESTION_PATH])
    synthetic = [build() for name, _, build in all_cases(sizes=(1000, 10000))
                 if name.startswith("synthetic")]  # fmt: skip
    print("| constants | fleets: iterations median / p95 / max | not converged | "
          "evaluations per iteration | ELV minute: iterations / evaluations | "
          "ELV day: iterations / minutes converged / ms | synthetic 1k, 10k: iterations |")
    print("|---|---|---|---|---|---|---|")
    for spec in args.specs:
        print(row(spec, fleets, congestion, day, synthetic), flush=True)


if __name__ == "__main__":
    main()
