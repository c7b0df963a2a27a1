"""The paper's claim measured: population dynamics against dual decomposition and ADMM on
the same agents, faults and message counter (docs/comparison.md is this script's output).

1. Equal-effort tuning: every algorithm gets the same nine-point grid over its one or two
   parameters on a case that is not reported (kerber-dorfnetz with one binding limit,
   ``compare_cases.TUNING``), perfect network; the point with the fewest rounds to
   convergence wins (ties: fewest messages; none converged: smallest final distance).
2. The table: the ELV congestion minute, case33bw and case141 with a binding limit (and each
   OpenDSS feeder given by ``--opendss``, e.g. IEEE 123, read from where the user keeps it),
   on a perfect network and with 10 % and 30 % message loss, three seeds each, with the tuned
   parameters.
3. With ``--meshed``, instead of the radial cases: MATPOWER's case14 and case300 with two
   lines congested (``compare_cases.MESHED``), on a perfect network and with 10 % loss, the
   algorithms that run on a mesh (ADMM by proximal message passing follows a radial
   feeder's tree and is left out, saying so).

Usage: ``python benchmarks/bench_compare.py [--rounds 6000] [--seeds 3] [--out DIR]
[--algorithms A,B] [--opendss MASTER.dss] [--meshed]`` (prints markdown; ``--out`` also
writes compare.csv and figures per case).
The paper's rule (``smith-paper``, ``distributed-smith-paper``) is tuned the same way on its
one parameter, its round step; it rests away from the DC-OPF, so its tuning falls to the
smallest final distance.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from compare_cases import CASES, MESHED, TUNING, matpower_mesh, opendss_case  # noqa: E402

from popdispatch.algorithms import (  # noqa: E402
    AdmmParams,
    ConsensusAdmmParams,
    DualParams,
    Faults,
    RunOptions,
    SmithParams,
    run_algorithm,
)
from popdispatch.algorithms.comparison import (  # noqa: E402
    compare_algorithms,
    distance_figure,
    runnable,
    runs_table,
    summary_table,
)

NAMES = ("smith", "distributed-smith", "dual-decomposition", "fast-dual-decomposition", "admm",
         "consensus-admm", "smith-paper", "distributed-smith-paper")
#: ADMM's penalty in units of exact mode's scales S / P, four decades.
RHO_SCALES = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
#: The paper's rule's one parameter: the round step in units of the engine's paper-mode
#: Euler substep (dt / substeps = 0.1 ms).
PAPER_STEPS = (0.3, 1.0, 3.0)
#: Population dynamics' grid: the round step in units of the agents' round step (1: theirs,
#: popdispatch.online.stiffness.round_step) and exact mode's price rate down from its default
#: (3000, popdispatch.modes.exact.NEWTON_PRICE_RATE).
STEPS, PRICE_RATES = (0.1, 0.3, 1.0), (300.0, 1000.0, 3000.0)
GRIDS = {
    "smith": [SmithParams(step=s, price_rate=r) for s in STEPS for r in PRICE_RATES],
    "distributed-smith": [SmithParams(step=s, price_rate=r, graph="ring")
                          for s in STEPS for r in PRICE_RATES],
    "dual-decomposition": [DualParams(a, b) for a in (0.5, 1.0, 1.9) for b in (0.1, 1.0, 10.0)],
    "fast-dual-decomposition": [DualParams(a, b, accelerated=True) for a in (0.5, 1.0, 1.9)
                                for b in (0.1, 1.0, 10.0)],
    "admm": [AdmmParams(rho_scale=r) for r in RHO_SCALES],
    "consensus-admm": [ConsensusAdmmParams(rho_scale=r) for r in RHO_SCALES],
    "smith-paper": [SmithParams(step=s, mode="paper") for s in PAPER_STEPS],
    "distributed-smith-paper": [SmithParams(step=s, graph="ring", mode="paper")
                                for s in PAPER_STEPS],
}  # fmt: skip


def tune(options: RunOptions, names=NAMES) -> dict:
    """The grid point of each algorithm that wins on the tuning case (module docstring)."""
    label, build, minute = TUNING
    problem = build()
    best = {}
    for name in names:
        scored = []
        for params in GRIDS[name]:
            run = run_algorithm(name, problem, minute, Faults(), params, options)
            s = run.summary()
            key = (0, s["converged_round"], s["messages"]) if s["status"] == "converged" \
                else (1, s["final_distance_kw"])  # fmt: skip
            scored.append((key, params))
            print(
                f"  tune {name} {params}: {s['status']} round {s['converged_round']} "
                f"distance {s['final_distance_kw']:.3g} kW",
                file=sys.stderr,
                flush=True,
            )
        best[name] = min(scored, key=lambda t: t[0])[1]
    return best


def markdown(frame) -> str:
    """A pipe table of ``frame`` (numbers to four significant digits)."""

    def cell(v) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(frame.columns) + " |", "|" + " --- |" * len(frame.columns)]
    lines += [
        "| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(index=False)
    ]
    return "\n".join(lines)


def report(label: str, problem, minute: int, names, losses, args, options, params) -> None:
    """Print the summary table of ``names`` on ``problem`` at each loss in ``losses`` (and
    write each one's compare.csv and figure under ``args.out``)."""
    for loss in losses:
        faults = Faults(loss=loss)
        runs = compare_algorithms(problem, minute, names, faults, args.seeds, options, params)
        table = runs_table(runs)
        print(f"### {label}, {faults.label()}, {args.seeds} seeds\n")
        print(markdown(summary_table(table)))
        print(flush=True)
        if args.out is not None:
            folder = args.out / f"{label.split(',')[0].replace(' ', '-')}-loss{loss:g}"
            folder.mkdir(parents=True, exist_ok=True)
            table.to_csv(folder / "compare.csv", index=False)
            distance_figure(runs).savefig(folder / "distance.png", dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=6000)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", type=Path)
    parser.add_argument("--opendss", type=Path, action="append", default=[],
                        help="an OpenDSS master file to add as a case with the test fleet and "
                        "one binding limit (repeatable; e.g. IEEE123Master.dss)")
    parser.add_argument("--algorithms", default=",".join(NAMES),
                        help="comma-separated subset of the algorithms (default: all)")
    parser.add_argument("--meshed", action="store_true",
                        help="the meshed cases (case14, case300) instead of the radial ones")
    args = parser.parse_args()
    names = tuple(n for n in args.algorithms.split(",") if n)
    unknown = [n for n in names if n not in NAMES]
    if unknown or not names:
        parser.error(f"--algorithms: unknown {unknown[0]!r}" if unknown else "--algorithms: none")
    options = RunOptions(max_rounds=args.rounds)
    start = time.perf_counter()
    params = tune(options, names)
    print("## Tuned parameters (grid on", TUNING[0] + ")\n")
    for name, p in params.items():
        print(f"- {name}: {p}")
    print()
    if args.meshed:
        for case, lines in MESHED.items():
            problem, limits = matpower_mesh(case, lines)
            kept, notes = runnable(problem, names)
            label = f"{case}, " + ", ".join(f"{a}:{b}={kw:.6f}" for a, b, kw in limits)
            for note in notes:
                print(f"- {case}: {note}")
            report(label, problem, 1, kept, (0.0, 0.1), args, options, params)
    else:
        cases = dict(CASES)
        for master in args.opendss:
            cases[f"{master.stem}, one binding limit"] = (lambda m=master: opendss_case(m), 1)
        for label, (build, minute) in cases.items():
            report(label, build(), minute, names, (0.0, 0.1, 0.3), args, options, params)
    print(f"(bench_compare: {time.perf_counter() - start:.0f} s; rounds {args.rounds})",
          file=sys.stderr)  # fmt: skip


if __name__ == "__main__":
    main()
