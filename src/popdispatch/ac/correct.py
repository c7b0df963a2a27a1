"""``--ac-correct``: an outer loop that moves the voltage-aware dispatch to the AC optimum.

LinDistFlow drops the losses, so at a dispatch whose LinDistFlow voltages sit at ``vmin`` the AC
voltages are lower by the linearization error, and the source buys the losses at its own price
while a DG that reduces them is worth more than its marginal cost says. Between runs of the
voltage mode (one minute), the loop updates from an AC power flow at the last dispatch
``p_k``:

- **voltage offsets**: each monitored bus's squared voltage becomes ``v_AC^2(p_k) + S (p -
  p_k)``, i.e. its LinDistFlow base moves by ``delta_j = v_AC,j^2(p_k) - v_LDF,j^2(p_k)`` (the
  sensitivities ``S`` stay LinDistFlow's 2 R / Z_base: they set how the optimum trades DGs, not
  where the limit is);
- **losses**: the demand becomes ``P_d + L(p_k)`` (the generators, not the ideal source, supply
  the losses), and each generator's cost is divided by ``1 - dL/dp_i`` (its penalty factor: the
  marginal loss of an injection at its bus, the source absorbing it; by differences of AC power
  flows), the classical condition ``C_i'(p_i) = lambda (1 - dL/dp_i)`` of the lossy dispatch.

It stops when no monitored bus's offset changes by more than ``tol_pu`` (p.u.) between two
rounds. Each round is an ordinary run of the voltage mode against its LinDistFlow OPF (the KKT
check applies to the corrected problem); the result reports the AC check of the last dispatch.

One minute only: a day would need per-step costs in the compiled day loop (the penalty
factors change ``b`` and ``c`` every step; docs/voltage.md, "Limits").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from popdispatch.ac.check import ACSnapshot, check_setpoints, snapshot_of
from popdispatch.constants import KW_PER_MW
from popdispatch.game.problem import DispatchProblem
from popdispatch.online import RunSettings
from popdispatch.scenarios import SnapshotComparison, snapshot_vs_opf

#: Injection step of the loss-factor differences, kW per kW of demand (1e-4: 0.37 kW on
#: case33bw; losses are smooth, so the one-sided difference errs by the step's order).
LOSS_STEP = 1e-4


@dataclass(frozen=True)
class CorrectedRun:
    """The last round of :func:`ac_correct`.

    Attributes
    ----------
    problem : the corrected problem (shifted voltage bases, demand with losses, penalised costs).
    result : its run against its LinDistFlow OPF (set points kW; costs of the corrected problem).
    ac : the AC check of its set points.
    rounds : runs made.
    offset_change_pu : the largest change of a voltage offset in the last round, p.u.
    cost_eur_per_h : the true cost of the dispatch (original coefficients), the source's
        AC supply included, EUR/h.
    """

    problem: DispatchProblem
    result: SnapshotComparison
    ac: ACSnapshot
    rounds: int
    offset_change_pu: float
    cost_eur_per_h: float

    def summary(self) -> dict:
        """The ``ac_correct`` JSON object."""
        v = self.ac.buses["v_pu"]
        run = self.result.run
        return {
            "rounds": self.rounds,
            "offset_change_pu": self.offset_change_pu,
            "status": run.status,
            "setpoints_kw": {
                str(g): float(p) for g, p in zip(run.generators, run.setpoints_kw, strict=True)
            },
            "source_extra_kw": float(self.ac.totals["source_extra_kw"]),
            "losses_kw": float(self.ac.totals["losses_kw"]),
            "cost_eur_per_h": self.cost_eur_per_h,
            "ac_v_min_pu": float(v.min()),
            "ac_v_min_bus": int(v.idxmin()),
            "ac_v_max_pu": float(v.max()),
        }  # fmt: skip


def ac_correct(
    problem: DispatchProblem,
    load_kw: np.ndarray,
    minute: int,
    settings: RunSettings,
    *,
    rounds: int = 10,
    tol_pu: float = 1e-5,
    **model_options,
) -> CorrectedRun:
    """The voltage-aware dispatch of ``minute`` corrected by AC power flows (module
    docstring). ``problem``: with voltage rows (:func:`popdispatch.ac.lindistflow.
    with_voltage_limits`); ``load_kw``: the minute's per-load demand (kW, feeder order);
    ``rounds``: at most this many runs; ``model_options``: of the AC model
    (:func:`popdispatch.ac.check_setpoints`)."""
    feeder = problem.feeder.original
    order = feeder.generators.index.get_indexer(problem.generators)
    loads = np.atleast_2d(np.asarray(load_kw, dtype=float))
    positions = feeder.buses.index.get_indexer(problem.voltage_buses)
    current, offset, change = problem, np.zeros(problem.n_voltage), np.inf
    for done in range(1, rounds + 1):
        result = snapshot_vs_opf(current, minute, settings)
        p_kw = result.run.setpoints_kw
        day = _flows(feeder, loads, p_kw, order, model_options)
        ac_sq = day.flows.v_pu[0, positions] ** 2
        new_offset = offset + ac_sq - current.voltage_sq(p_kw / KW_PER_MW, minute)
        change = float(np.max(np.abs(np.sqrt(np.maximum(new_offset + 1.0, 0.0))
                                     - np.sqrt(np.maximum(offset + 1.0, 0.0)))))  # fmt: skip
        if change <= tol_pu or done == rounds:
            ac = snapshot_of(day)
            return CorrectedRun(current, result, ac, done, change, _true_cost(problem, p_kw, ac))
        offset = new_offset
        losses = float(day.steps.iloc[0]["losses_kw"])
        factors = _loss_factors(feeder, loads, p_kw, order, losses, model_options)
        current = _corrected(problem, minute, offset, losses, factors)
    raise AssertionError("unreachable")  # pragma: no cover


def _flows(feeder, loads, p_kw, order, model_options):
    setpoints = np.zeros((1, len(feeder.generators)))
    setpoints[0, order] = p_kw
    return check_setpoints(feeder, loads, setpoints, **model_options)


def _loss_factors(feeder, loads, p_kw, order, losses_kw, model_options) -> np.ndarray:
    """``dL/dp_i`` per generator (problem order): one batch of AC power flows, each generator
    ``LOSS_STEP`` of the demand up (the ideal source absorbing it)."""
    n = len(p_kw)
    step = LOSS_STEP * float(loads.sum())
    batch = np.zeros((n, len(feeder.generators)))
    batch[:, order] = p_kw + step * np.eye(n)
    day = check_setpoints(feeder, np.repeat(loads, n, axis=0), batch, **model_options)
    return (day.steps["losses_kw"].to_numpy() - losses_kw) / step


def _corrected(problem, minute, offset, losses_kw, factors) -> DispatchProblem:
    """The problem with the voltage bases moved by ``offset`` (p.u.^2), the demand of
    ``minute`` raised by the losses and the costs divided by ``1 - dL/dp``."""
    row = minute - 1
    n_lines, n_v = len(problem.limit), problem.n_voltage
    base = problem.voltage_base.copy()
    base[row] += offset
    load_flow = problem.load_flow.copy()
    low, high = problem.vmin_pu, problem.vmax_pu
    load_flow[row, n_lines : n_lines + n_v] = (low**2 - base[row]) / problem.voltage_scale
    load_flow[row, n_lines + n_v :] = (base[row] - high**2) / problem.voltage_scale
    demand = problem.demand.copy()
    demand[row] += losses_kw / KW_PER_MW
    penalty = 1.0 / (1.0 - factors)
    return replace(problem, voltage_base=base, load_flow=load_flow, demand=demand,
                   b=problem.b * penalty, c=problem.c * penalty)  # fmt: skip


def _true_cost(problem: DispatchProblem, p_kw: np.ndarray, ac: ACSnapshot) -> float:
    """The original costs of ``p_kw`` (kW) with what the source supplied beyond it bought at
    the source generator's cost (EUR/h)."""
    from popdispatch.opf import generation_cost

    p = np.array(p_kw, dtype=float)
    feeder = problem.feeder.original
    buses = feeder.generators.loc[problem.generators, "bus"].to_numpy()
    p[np.flatnonzero(buses == feeder.source_bus)[0]] += float(ac.totals["source_extra_kw"])
    return float(generation_cost(problem, p / KW_PER_MW))
