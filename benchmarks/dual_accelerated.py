"""An experiment beside the comparison (docs/comparison.md, "Dual decomposition on the ELV
minute"): dual decomposition with Nesterov's fast gradient on the dual (Giselsson, Doan,
Keviczky and Rantzer, "Accelerated gradient methods and dual decomposition in distributed
model predictive control", Automatica 49(3), 2013) and the gradient restart of O'Donoghue
and Candes ("Adaptive restart for accelerated gradient schemes", Found. Comput. Math. 15,
2015), the same messages as ``dual-decomposition`` plus a restart test over every price.

Two restart tests: ``joint`` (``grad . (x - x_last)`` summed over the balance price and
every line price: the controllers would have to send their terms to the coordinator, one
scalar each a round, which this experiment does not count) and ``local`` (each price holder
on its own prices: no extra message). Each is tuned on the comparison's tuning case with
dual decomposition's nine-point grid, then run on the reported cases on a perfect network.

Usage: ``python benchmarks/dual_accelerated.py [--rounds 6000]`` (prints markdown).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from compare_cases import CASES, TUNING  # noqa: E402

from popdispatch.algorithms import DualParams, Faults, RunOptions, run_algorithm  # noqa: E402
from popdispatch.algorithms.dual import DualDecomposition  # noqa: E402
from popdispatch.algorithms.registry import ALGORITHMS, Entry  # noqa: E402

GRID = [DualParams(a, b) for a in (0.5, 1.0, 1.9) for b in (0.1, 1.0, 10.0)]


class AcceleratedDual(DualDecomposition):
    """Dual decomposition whose price holders send Nesterov's extrapolated prices."""

    joint = True

    def __init__(self, *args):
        super().__init__(*args)
        self.x = np.r_[self.lam, self.mu.ravel()]  # the last ascent point
        self.t = np.ones(1 + len(self.mu))  # each holder's momentum counter

    def local_update(self, inbox, round_: int) -> None:
        lam, mu = self.lam, self.mu.copy()
        super().local_update(inbox, round_)  # the DGs answer; plain ascent from (lam, mu)
        x = np.r_[self.lam, self.mu.ravel()]  # the ascent point from the prices sent
        step = x - self.x
        grad = (x - np.r_[lam, mu.ravel()]) / np.r_[self.alpha, np.repeat(self.beta, 2)]
        terms = np.r_[grad[0] * step[0], (grad[1:] * step[1:]).reshape(-1, 2).sum(axis=1)]
        restart = np.full(len(self.t), terms.sum() < 0) if self.joint else terms < 0
        self.t[restart] = 1.0
        t = (1.0 + np.sqrt(1.0 + 4.0 * self.t**2)) / 2.0
        weight = np.r_[(self.t[0] - 1) / t[0], np.repeat((self.t[1:] - 1) / t[1:], 2)]
        y = x + weight * step
        y[1:] = np.maximum(y[1:], 0.0)
        self.x, self.t = x, t
        self.lam, self.mu = float(y[0]), y[1:].reshape(-1, 2)


class LocalRestart(AcceleratedDual):
    joint = False


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=6000)
    options = RunOptions(max_rounds=parser.parse_args().rounds)
    ALGORITHMS["accelerated-joint"] = Entry(AcceleratedDual, DualParams)
    ALGORITHMS["accelerated-local"] = Entry(LocalRestart, DualParams)
    _, build, minute = TUNING
    tuning = build()
    print("| variant | tuned (rounds on the tuning case) | " + " | ".join(CASES) + " |")
    print("| --- | --- |" + " --- |" * len(CASES))
    for name in ("accelerated-joint", "accelerated-local"):
        scored = []
        for params in GRID:
            s = run_algorithm(name, tuning, minute, Faults(), params, options).summary()
            key = (s["status"] != "converged", s["converged_round"] or 0, s["messages"])
            scored.append((key, params))
        key, best = min(scored, key=lambda t: t[0])
        cells = []
        for build_case, case_minute in CASES.values():
            run = run_algorithm(name, build_case(), case_minute, Faults(), best, options)
            cells.append(f"{run.converged_round}" if run.status == "converged"
                         else f"not in {run.rounds}: {run.distance_kw[-1]:.3g} kW")  # fmt: skip
        print(f"| {name} | {best.balance_step:g}, {best.line_step:g} ({key[1]}) | "
              + " | ".join(cells) + " |")  # fmt: skip


if __name__ == "__main__":
    main()
