"""Several algorithms on the same minute, the same faults and seeds: the table (one row per
algorithm and seed), its per-algorithm summary and the figures (distance to the DC-OPF
against rounds and against messages, one line per algorithm, the seeds as a band)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from popdispatch.algorithms.network import Faults
from popdispatch.algorithms.registry import ALGORITHMS
from popdispatch.algorithms.runner import AlgorithmRun, RunOptions, run_algorithm
from popdispatch.errors import OptionError
from popdispatch.game.problem import DispatchProblem


def check_algorithms(problem: DispatchProblem, names: Sequence[str]) -> None:
    """:class:`~popdispatch.errors.OptionError` (``--algorithms``) naming the first algorithm
    of ``names`` that cannot run ``problem`` (ADMM on a meshed network), before any work."""
    for name in names:
        try:
            ALGORITHMS[name].cls.check(problem)
        except OptionError as exc:
            raise OptionError(f"{exc} (leave {name} out of --algorithms)", exc.option) from None


def runnable(problem: DispatchProblem, names: Sequence[str]) -> tuple[list[str], list[str]]:
    """``(the algorithms of names that can run problem, one line per one that cannot: why)``."""
    kept, notes = [], []
    for name in names:
        try:
            ALGORITHMS[name].cls.check(problem)
        except OptionError as exc:
            notes.append(f"{name} left out: {exc}")
            continue
        kept.append(name)
    return kept, notes


def on_graph(names: Sequence[str], graph: str) -> dict:
    """The parameters (by name) of the algorithms of ``names`` that run on a sparse
    communication graph (distributed Smith, paper or exact), on the named ``graph``
    (:data:`popdispatch.dynamics.GRAPHS`) instead of their default ring; an
    :class:`~popdispatch.errors.OptionError` (``--graph``) if none of them does."""
    defaults = {n: ALGORITHMS[n].params() for n in names}
    sparse = {n: p for n, p in defaults.items() if getattr(p, "graph", "complete") != "complete"}
    if not sparse:
        raise OptionError("it applies to distributed-smith and distributed-smith-paper only, "
                          "and --algorithms names neither", "--graph")  # fmt: skip
    return {name: replace(params, graph=graph) for name, params in sparse.items()}


def compare_algorithms(problem: DispatchProblem, minute: int, names: Sequence[str],
                       faults: Faults, seeds: int = 1, options: RunOptions | None = None,
                       params: dict | None = None) -> dict[str, list[AlgorithmRun]]:  # fmt: skip
    """Each algorithm once per seed ``faults.seed, faults.seed + 1, ...`` (``params``: by
    algorithm name, else its defaults). Without random faults (no loss, delay or duplicate)
    every seed gives the same run: it is run once and stands for each seed."""
    params = params or {}
    check_algorithms(problem, names)
    draws = seeds if not faults.perfect else 1
    runs = {name: [run_algorithm(name, problem, minute, replace(faults, seed=faults.seed + s),
                                 params.get(name), options) for s in range(draws)]
            for name in names}  # fmt: skip
    return {name: group * (seeds // draws) for name, group in runs.items()}


def runs_table(runs: dict[str, list[AlgorithmRun]], seed0: int = 0) -> pd.DataFrame:
    """One row per algorithm and seed: the run's totals (units in the column names)."""
    rows = []
    for group in runs.values():
        for s, run in enumerate(group):
            row = {k: v for k, v in run.summary().items() if k not in ("reveals", "loss_handling")}
            row["seed"] = seed0 + s
            row["reveals"] = "; ".join(f"{role}: {', '.join(what)}"
                                       for role, what in run.reveals.items())  # fmt: skip
            rows.append(row)
    table = pd.DataFrame(rows)
    first = ["algorithm", "seed", "status", "converged_round"]
    return table[first + [c for c in table.columns if c not in first]]


def summary_table(table: pd.DataFrame) -> pd.DataFrame:
    """Per algorithm: runs converged, median rounds and messages to convergence (converged
    runs), medians of the run's totals and the worst final distance and imbalance."""
    out = []
    for name, group in table.groupby("algorithm", sort=False):
        done = group[group.status == "converged"]
        out.append({
            "algorithm": name, "converged": f"{len(done)}/{len(group)}",
            "rounds": float(done.converged_round.median()) if len(done) else np.nan,
            "messages": float(done.messages.median()) if len(done) else np.nan,
            "scalars": float(done.scalars.median()) if len(done) else np.nan,
            "bytes_total": float(group.bytes_total.median()),
            "messages_per_agent_round": float(group.messages_per_agent_round.median()),
            "partners_max": int(group.partners_max.max()),
            "final_distance_kw": float(group.final_distance_kw.max()),
            "max_abs_imbalance_kw": float(group.max_abs_imbalance_kw.max()),
        })  # fmt: skip
    return pd.DataFrame(out)


def distance_figure(runs: dict[str, list[AlgorithmRun]]):
    """Distance to the DC-OPF (kW, log) against rounds and against messages: the median
    over seeds as a line, the range over seeds as a band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_round, by_message) = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for name, group in runs.items():
        length = max(len(r.distance_kw) for r in group)
        d = np.array([np.pad(r.distance_kw, (0, length - len(r.distance_kw)), mode="edge")
                      for r in group])  # fmt: skip
        msgs = np.array([np.pad(r.messages, (0, length - len(r.messages)), mode="edge")
                         for r in group])  # fmt: skip
        floor = 1e-6
        lo, mid, hi = (np.maximum(q, floor) for q in np.quantile(d, [0, 0.5, 1], axis=0))
        rounds = np.arange(length)
        (line,) = by_round.plot(rounds, mid, label=name)
        by_round.fill_between(rounds, lo, hi, color=line.get_color(), alpha=0.2)
        m = np.median(msgs, axis=0)
        by_message.plot(m, mid, color=line.get_color(), label=name)
        by_message.fill_between(m, lo, hi, color=line.get_color(), alpha=0.2)
    tol = min(r.tol_kw for group in runs.values() for r in group)
    for ax, label in ((by_round, "rounds"), (by_message, "messages")):
        ax.axhline(tol, color="grey", lw=0.8, ls="--")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    by_round.set_ylabel("largest distance to the DC-OPF, kW")
    by_round.legend()
    fig.tight_layout()
    return fig
