"""``--ac-correct``: an outer loop that moves the voltage-aware dispatch to the AC optimum.

LinDistFlow drops the losses, so at a dispatch whose LinDistFlow voltages sit at ``vmin`` the AC
voltages are lower by the linearization error, and the source buys the losses at its own price
while a DG that reduces them is worth more than its marginal cost says. Between runs of the
voltage mode (one step), the loop updates from AC power flows at the last dispatch ``p_k``
(one batch: the dispatch, and each generator a little up):

- **voltage offsets**: each monitored bus's squared voltage becomes ``v_AC^2(p_k) + S (p -
  p_k)``, i.e. its LinDistFlow base moves by ``delta_j = v_AC,j^2(p_k) - v_LDF,j^2(p_k)`` (the
  sensitivities ``S`` stay LinDistFlow's 2 R / Z_base: they set how the optimum trades DGs, not
  where the limit is);
- **losses**: the demand becomes ``P_d + L(p_k)`` (the generators, not the ideal source, supply
  the losses), and each generator's cost is divided by ``1 - dL/dp_i`` (its penalty factor: the
  marginal loss of an injection at its bus, the source absorbing it; by differences of AC power
  flows), the classical condition ``C_i'(p_i) = lambda (1 - dL/dp_i)`` of the lossy dispatch.

It stops when the corrected model's voltages at the dispatch equal the AC ones within
``tol_pu`` (p.u.) at every monitored bus (:func:`model_error_pu`) and the AC voltages there
keep the limits within ``tol_pu`` (:func:`ac_miss_pu`; the dispatch keeps the corrected
model's limits up to the run's own stopping tolerance, far below ``tol_pu``). Each round is
an ordinary run of the voltage mode against its LinDistFlow OPF (the distance certificate
applies to the corrected problem); the result reports the AC check of the last dispatch.
:mod:`popdispatch.ac.correct_day` runs the same loop at every step of a day, warm-started
from the step before.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import pandas as pd

from popdispatch.ac.check import ACDay, ACFlows, ACSnapshot, power_flow, snapshot_of, step_table
from popdispatch.ac.limits import limits_summary
from popdispatch.ac.network import ACNetwork, build_network
from popdispatch.compare import SnapshotComparison, snapshot_vs_opf
from popdispatch.constants import KW_PER_MW
from popdispatch.errors import OptionError
from popdispatch.game.problem import DispatchProblem
from popdispatch.online import RunSettings

#: Injection step of the loss-factor differences, kW per kW of demand (1e-4: 0.37 kW on
#: case33bw; losses are smooth, so the one-sided difference errs by the step's order).
LOSS_STEP = 1e-4
#: Default stopping tolerance: largest difference between the corrected model's voltage and
#: the AC voltage at the dispatch, p.u.
TOL_PU = 1e-5
#: Default largest number of rounds (voltage-mode runs) per step.
ROUNDS = 10


class Measured(NamedTuple):
    """One batch of AC power flows at a dispatch (:meth:`Meter.measure`).

    ``flows``: row 0 the dispatch, row ``1 + i`` generator ``i`` up by the loss step;
    ``load_kw``, ``generator_kw``: the batch's inputs (kW, feeder order); ``minute``: the
    step; ``losses_kw``: the dispatch's losses, kW; ``factors``: ``dL/dp_i`` per generator
    (problem order, kW per kW); ``v_sq``: the dispatch's AC squared voltages at the monitored
    buses, p.u.^2."""

    flows: ACFlows
    load_kw: np.ndarray
    generator_kw: np.ndarray
    minute: int
    losses_kw: float
    factors: np.ndarray
    v_sq: np.ndarray

    def day(self) -> ACDay:
        """The AC check of the dispatch (the batch's first row) as a one-step :class:`ACDay`."""
        index = pd.Index([self.minute], name="minute")
        network = self.flows.network
        first = self.flows.first()
        table = step_table(network, first, self.load_kw[:1], self.generator_kw[:1], index)
        return ACDay(network, table, first)


@dataclass(frozen=True)
class Corrections:
    """What the AC power flows change in a step's problem: ``offset`` (per monitored bus,
    added to the LinDistFlow base, p.u.^2), ``losses_kw`` (added to the demand, kW) and
    ``factors`` (``dL/dp`` per generator: costs divided by ``1 - factors``)."""

    offset: np.ndarray
    losses_kw: float
    factors: np.ndarray

    @classmethod
    def none(cls, problem: DispatchProblem) -> Corrections:
        return cls(np.zeros(problem.n_voltage), 0.0, np.zeros(problem.n_generators))

    def updated(
        self, current: DispatchProblem, minute: int, p_mw: np.ndarray, measured: Measured
    ) -> tuple[Corrections, float]:
        """The corrections measured at dispatch ``p_mw`` (MW) of the corrected problem
        ``current``, and the corrected model's error there (:func:`model_error_pu`)."""
        model_sq = current.voltage_sq(p_mw, minute)
        offset = self.offset + measured.v_sq - model_sq
        error = model_error_pu(measured.v_sq, model_sq)
        return Corrections(offset, measured.losses_kw, measured.factors), error


def settled(error_pu: float, miss_pu: float, tol_pu: float) -> bool:
    """Whether a round ends the loop: the model's error (:func:`model_error_pu`) and the AC
    voltages' miss of the limits (:func:`ac_miss_pu`) both within ``tol_pu`` (p.u.)."""
    return error_pu <= tol_pu and miss_pu <= tol_pu


def ac_miss_pu(ac_sq: np.ndarray, vmin_pu: float, vmax_pu: float) -> float:
    """How far the AC voltages (squared, p.u.^2) fall outside ``[vmin_pu, vmax_pu]``, p.u.
    (0 where they keep them)."""
    v = np.sqrt(ac_sq)
    return float(max(np.max(vmin_pu - v, initial=0.0), np.max(v - vmax_pu, initial=0.0)))


def model_error_pu(ac_sq: np.ndarray, model_sq: np.ndarray) -> float:
    """The largest ``|v_AC - v_model|`` over the monitored buses, p.u. (squared voltages in,
    p.u.^2): how far the model the dispatch kept is from the AC voltages at that dispatch."""
    if not len(ac_sq):
        return 0.0
    model = np.sqrt(np.maximum(model_sq, 0.0))
    return float(np.max(np.abs(np.sqrt(ac_sq) - model)))


class Rows:
    """A problem's per-step arrays (demand, controllers' loads-only values, voltage bases),
    copied once and corrected one step at a time in place (:meth:`problem`)."""

    def __init__(self, problem: DispatchProblem):
        self.original = problem
        self.demand = problem.demand.copy()
        self.load_flow = problem.load_flow.copy()
        self.base = problem.voltage_base.copy()

    def problem(self, minute: int, corrections: Corrections) -> DispatchProblem:
        """The problem with step ``minute``'s voltage bases moved by the offsets, its demand
        raised by the losses and the costs divided by ``1 - dL/dp`` (other steps as last
        corrected: a run reads only its own step)."""
        p, row = self.original, minute - 1
        n_lines, n_v = len(p.limit), p.n_voltage
        self.base[row] = p.voltage_base[row] + corrections.offset
        self.load_flow[row, n_lines : n_lines + n_v] = (p.vmin_pu**2 - self.base[row]) / (
            p.voltage_scale
        )
        self.load_flow[row, n_lines + n_v :] = (self.base[row] - p.vmax_pu**2) / p.voltage_scale
        self.demand[row] = p.demand[row] + corrections.losses_kw / KW_PER_MW
        penalty = 1.0 / (1.0 - corrections.factors)
        return replace(p, voltage_base=self.base, load_flow=self.load_flow, demand=self.demand,
                       b=p.b * penalty, c=p.c * penalty)  # fmt: skip


class Meter:
    """AC power flows of one problem's full feeder (:func:`measure`), the network built once."""

    def __init__(self, problem: DispatchProblem, **model_options):
        feeder = problem.feeder.original
        self.network: ACNetwork = build_network(feeder, **model_options)
        self.order = feeder.generators.index.get_indexer(problem.generators)
        self.positions = feeder.buses.index.get_indexer(problem.voltage_buses)
        self.n_fleet = len(feeder.generators)

    def measure(self, load_kw: np.ndarray, p_kw: np.ndarray, minute: int) -> Measured:
        """One batch at dispatch ``p_kw`` (kW, problem order) with per-load demand ``load_kw``
        (kW, feeder order): the dispatch and each generator up by ``LOSS_STEP`` of the demand
        (the ideal source absorbing it), so ``dL/dp_i`` by differences."""
        n = len(p_kw)
        step = LOSS_STEP * float(np.sum(load_kw))
        batch = np.zeros((n + 1, self.n_fleet))
        batch[:, self.order] = p_kw + np.vstack([np.zeros(n), step * np.eye(n)])
        loads = np.repeat(np.atleast_2d(load_kw), n + 1, axis=0)
        flows = power_flow(self.network, loads, batch, steps=np.full(n + 1, minute))
        losses = flows.losses_kw
        v = np.abs(flows.v[self.positions, 0])
        return Measured(flows, loads, batch, minute, float(losses[0]),
                        (losses[1:] - losses[0]) / step, v**2)  # fmt: skip


@dataclass(frozen=True)
class CorrectedRun:
    """The last round of :func:`ac_correct`.

    Attributes
    ----------
    problem : the corrected problem (shifted voltage bases, demand with losses, penalised costs).
    result : its run against its LinDistFlow OPF (set points kW; costs of the corrected problem).
    ac : the AC check of its set points.
    rounds : runs made.
    offset_change_pu : the corrected model's error at the last dispatch, p.u.
        (:func:`model_error_pu`: the change of the voltages there by the offsets the last
        power flow measured).
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
        """The ``ac_correct`` JSON object, with the ``voltage_limits`` verdict of the AC
        voltages (:func:`popdispatch.ac.limits.limits_summary`)."""
        v = self.ac.buses["v_pu"]
        run = self.result.run
        steps = self.ac.totals.to_frame().T
        steps.index = [self.ac.minute]
        original = self.problem
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
            "ac_v_min_bus": _plain(v.idxmin()),
            "ac_v_max_pu": float(v.max()),
            "voltage_limits": limits_summary(steps, original.vmin_pu, original.vmax_pu),
        }  # fmt: skip


def ac_correct(
    problem: DispatchProblem,
    load_kw: np.ndarray,
    minute: int,
    settings: RunSettings,
    *,
    rounds: int = ROUNDS,
    tol_pu: float = TOL_PU,
    **model_options,
) -> CorrectedRun:
    """The voltage-aware dispatch of ``minute`` corrected by AC power flows (module
    docstring). ``problem``: with voltage rows (:func:`popdispatch.ac.lindistflow.
    with_voltage_limits`); ``load_kw``: the minute's per-load demand (kW, feeder order);
    ``rounds``: at most this many runs, each from ``settings.x0``; ``tol_pu``: stop when the
    corrected model's voltages at the dispatch are within this of the AC ones and the AC
    voltages within this of the limits (p.u., :func:`settled`);
    ``model_options``: of the AC model (:func:`popdispatch.ac.check_setpoints`)."""
    if rounds < 1 or not tol_pu > 0.0:
        raise OptionError(f"the AC correction needs rounds >= 1 and tol_pu > 0 (got {rounds}, "
                          f"{tol_pu})", "--ac-correct")  # fmt: skip
    loads = np.asarray(load_kw, dtype=float).reshape(-1)
    meter, rows = Meter(problem, **model_options), Rows(problem)
    corrections = Corrections.none(problem)
    for done in range(1, rounds + 1):
        current = rows.problem(minute, corrections)
        result = snapshot_vs_opf(current, minute, settings)
        p_kw = result.run.setpoints_kw
        measured = meter.measure(loads, p_kw, minute)
        corrections, error = corrections.updated(current, minute, p_kw / KW_PER_MW, measured)
        miss = ac_miss_pu(measured.v_sq, problem.vmin_pu, problem.vmax_pu)
        if settled(error, miss, tol_pu) or done == rounds:
            ac = snapshot_of(measured.day())
            cost = true_cost(problem, p_kw, float(ac.totals["source_extra_kw"]))
            return CorrectedRun(current, result, ac, done, error, cost)
    raise AssertionError("unreachable")  # pragma: no cover


def true_cost(problem: DispatchProblem, p_kw: np.ndarray, source_extra_kw: float) -> float:
    """The original costs of ``p_kw`` (kW, problem order) with what the source supplied beyond
    it (``source_extra_kw``) bought at the cost of the generator at the source bus (EUR/h);
    without one, the generators' costs alone."""
    from popdispatch.opf import generation_cost

    p = np.array(p_kw, dtype=float)
    feeder = problem.feeder.original
    buses = feeder.generators.loc[problem.generators, "bus"].to_numpy()
    at_source = np.flatnonzero(buses == feeder.source_bus)
    if len(at_source):
        p[at_source[0]] += source_extra_kw
    return float(generation_cost(problem, p / KW_PER_MW))


def _plain(value):
    """A bus id as JSON (numpy integers as int)."""
    return value.item() if isinstance(value, np.generic) else value
