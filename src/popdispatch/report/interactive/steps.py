"""The numbers an interactive report shows, one row per step (a minute of a day, an iteration
of a snapshot), and which steps get a map frame.

Everything is computed from what a run keeps: set points (kW), the DC-OPF, the loads of each
minute and the problem's radial DC flow model (:func:`popdispatch.feeder.tree.line_flows`,
paper eq. 1d: a line carries the net demand of its subtree). Powers in kW, prices in EUR/MWh
(Table I's coefficients on MW, per hour), voltages in p.u.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from popdispatch.compare import DayComparison, SnapshotComparison
from popdispatch.errors import FeederError
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.feeder.tree import line_flows
from popdispatch.game.problem import KW_PER_MW, DispatchProblem

#: A limited line within this of its limit is binding; beyond it, overloaded (kW).
BINDING_TOL_KW = 0.01

#: Congestion states of a limited line, as stored per step.
IDLE, BINDING, OVERLOADED = 0, 1, 2


@dataclass(frozen=True)
class Steps:
    """Per step: what the dynamics did and what the DC-OPF says.

    Attributes
    ----------
    kind : ``"minute"`` (a day) or ``"iteration"`` (a snapshot, 0.01 s each).
    values : the step numbers (1-based minutes, or iterations from 0).
    setpoints_kw, opf_kw : (steps, generators), kW; the DC-OPF is NaN where infeasible.
    flows_kw : (steps, reduced lines), kW, + away from the source.
    online : (steps, generators), whether each generator is available.
    demand_kw : (steps,), kW.
    opf_price : (steps, limited lines), the DC-OPF's line duals, EUR/MWh (NaN: infeasible).
    signal : eq.-8 signal of each limited line's parent-end controller, EUR/MWh, (steps,
        limited lines), computed from the dynamics' flows (what paper mode broadcasts); the
        child end sends the opposite value.
    voltages_pu : index step value, columns bus ids, p.u. (None without an AC check).
    times : per step, the start of its interval (``HH:MM`` in an undated day, else
        ``YYYY-MM-DD HH:MM``; a snapshot's iterations all carry their minute's).
    step_name : what a step is called in titles: ``"minute"`` in a day of one-minute steps,
        ``"step"`` in other series, ``"iteration"`` in a snapshot.
    """

    kind: str
    values: np.ndarray
    setpoints_kw: np.ndarray
    opf_kw: np.ndarray
    flows_kw: np.ndarray
    online: np.ndarray
    demand_kw: np.ndarray
    opf_price: np.ndarray
    signal: np.ndarray
    voltages_pu: pd.DataFrame | None = None
    times: list[str] | None = None
    step_name: str = "minute"

    def take(self, rows: np.ndarray) -> Steps:
        """The same steps restricted to ``rows``."""
        voltages = self.voltages_pu
        if voltages is not None:
            voltages = voltages[voltages.index.isin(self.values[rows])]
        times = None if self.times is None else [self.times[r] for r in rows]
        arrays = {name: getattr(self, name)[rows] for name in (
            "values", "setpoints_kw", "opf_kw", "flows_kw", "online", "demand_kw", "opf_price",
            "signal")}  # fmt: skip
        return replace(self, **arrays, voltages_pu=voltages, times=times)

    def limited_flows_kw(self, problem: DispatchProblem) -> np.ndarray:
        """(steps, limited lines): flows of the limited lines, kW."""
        return self.flows_kw[:, problem.lines]

    def loading(self, problem: DispatchProblem) -> np.ndarray:
        """(steps, limited lines): |flow| / limit (1.0 = at the limit)."""
        return np.abs(self.limited_flows_kw(problem)) / (problem.limit * KW_PER_MW)

    def line_states(self, problem: DispatchProblem) -> np.ndarray:
        """(steps, limited lines): :data:`IDLE`, :data:`BINDING` or :data:`OVERLOADED`."""
        excess = np.abs(self.limited_flows_kw(problem)) - problem.limit * KW_PER_MW
        return np.where(excess > BINDING_TOL_KW, OVERLOADED,
                        np.where(excess >= -BINDING_TOL_KW, BINDING, IDLE))  # fmt: skip

    @property
    def abs_error_kw(self) -> np.ndarray:
        """(steps,): largest |set point - DC-OPF| over the generators, kW (NaN: no DC-OPF)."""
        error = np.abs(self.setpoints_kw - self.opf_kw)
        known = np.isfinite(error).all(axis=1)
        return np.where(known, np.nanmax(np.where(known[:, None], error, 0.0), axis=1), np.nan)


def time_labels(profiles: LoadProfiles, minutes) -> list[str]:
    """Start of each 1-based step of ``profiles``' series: ``HH:MM`` in an undated day (the
    ELV day: minute 566 starts at 09:25), ``YYYY-MM-DD HH:MM`` in a dated series."""
    timeline = getattr(profiles, "timeline", None)
    if timeline is None:  # profiles without a timeline: a day of minutes
        return [f"{(m - 1) // 60:02d}:{(m - 1) % 60:02d}" for m in np.asarray(minutes, int)]
    return [label[:16].replace("T", " ") if "T" in label else label[:5]
            for label in timeline.labels(minutes)]  # fmt: skip


def step_name(profiles: LoadProfiles) -> str:
    """``"minute"`` for a series of one-minute steps, else ``"step"``."""
    timeline = getattr(profiles, "timeline", None)
    return "minute" if timeline is None or timeline.step_minutes == 1.0 else "step"


def ordered_loads_kw(problem: DispatchProblem, profiles: LoadProfiles, minutes) -> np.ndarray:
    """(minutes, loads): per-load demand (kW) at the given 1-based minutes, in the order of the
    problem's loads."""
    table = profiles.for_loads(problem.feeder.original.loads.index).kw
    return table.loc[np.asarray(minutes, dtype=np.int64)].to_numpy(float)


def all_flows_kw(problem: DispatchProblem, setpoints_kw: np.ndarray, load_kw: np.ndarray):
    """(steps, reduced lines): DC flows (kW, + away from the source) for set points (steps,
    generators) and per-load demand (steps, loads), both kW. The same model as
    :meth:`DispatchProblem.all_line_flows_mw`, for many steps at once."""
    reduced = problem.feeder
    injection = -reduced.load_injection_kw(np.atleast_2d(load_kw))
    nodes = reduced.generators["node"].to_numpy()
    generation = np.zeros((len(setpoints_kw), reduced.n_nodes))
    for i, node in enumerate(nodes):
        generation[:, node] += setpoints_kw[:, i]
    return line_flows(reduced.tree, injection + generation)


def eq8_signals(problem: DispatchProblem, flows_kw: np.ndarray, C: float) -> np.ndarray:
    """(steps, limited lines): the parent-end controller's eq.-8 signal, EUR/MWh, for the
    limited-line flows ``flows_kw`` (kW): ``-(p_ij - U) C`` above the limit, ``-(p_ij + U) C``
    below minus the limit, 0 between (p_ij, U in MW; :func:`popdispatch.game.controllers.
    overflow_signal`, vectorised over steps and lines)."""
    flow = np.asarray(flows_kw, dtype=float) / KW_PER_MW
    limit = problem.limit[None, :]
    over = np.where(flow > limit, flow - limit, np.where(flow < -limit, flow + limit, 0.0))
    return -over * float(C)


def day_steps(
    comparison: DayComparison,
    problem: DispatchProblem,
    profiles: LoadProfiles,
    voltages_pu: pd.DataFrame | None = None,
) -> Steps:
    """The steps of an online day: one per simulated minute."""
    run = comparison.run
    minutes = np.asarray(run.minutes, dtype=np.int64)
    flows = all_flows_kw(problem, run.setpoints_kw, ordered_loads_kw(problem, profiles, minutes))
    price = np.array([o.line_price for o in comparison.opf]).reshape(len(minutes), -1)
    return Steps(
        kind="minute",
        values=minutes,
        setpoints_kw=run.setpoints_kw,
        opf_kw=comparison.opf_kw.reshape(run.setpoints_kw.shape),
        flows_kw=flows,
        online=np.asarray(run.online, dtype=bool).reshape(run.setpoints_kw.shape),
        demand_kw=np.asarray(run.demand_kw, dtype=float),
        opf_price=price,
        signal=eq8_signals(problem, flows[:, problem.lines], run.settings.fitness.C),
        voltages_pu=check_voltages(voltages_pu, problem, minutes),
        times=time_labels(profiles, minutes),
        step_name=step_name(profiles),
    )


def snapshot_steps(
    comparison: SnapshotComparison,
    problem: DispatchProblem,
    profiles: LoadProfiles,
    voltages_pu: pd.Series | None = None,
) -> Steps:
    """The steps of a snapshot: one per iteration of its trajectory (the loads are those of
    its minute throughout). ``voltages_pu`` (bus -> p.u.) belongs to the final set points."""
    run, opf = comparison.run, comparison.opf
    iterations = np.arange(run.iterations + 1)
    n = len(iterations)
    load = ordered_loads_kw(problem, profiles, [run.minute])
    flows = all_flows_kw(problem, run.trajectory_kw, np.repeat(load, n, axis=0))
    voltages = None
    if voltages_pu is not None:
        voltages = pd.DataFrame([voltages_pu], index=[int(iterations[-1])])
        voltages = check_voltages(voltages, problem, iterations[-1:])
    return Steps(
        kind="iteration",
        values=iterations,
        setpoints_kw=run.trajectory_kw,
        opf_kw=np.tile(opf.p_kw, (n, 1)),
        flows_kw=flows,
        online=np.tile(problem.online[run.minute - 1], (n, 1)),
        demand_kw=np.full(n, run.demand_kw),
        opf_price=np.tile(np.asarray(opf.line_price, dtype=float), (n, 1)),
        signal=eq8_signals(problem, flows[:, problem.lines], run.settings.fitness.C),
        voltages_pu=voltages,
        times=time_labels(profiles, [run.minute]) * n,
        step_name="iteration",
    )


def check_voltages(
    voltages_pu: pd.DataFrame | None, problem: DispatchProblem, steps: np.ndarray
) -> pd.DataFrame | None:
    """Voltages (index step, columns original bus ids, p.u.) checked against the feeder's buses
    and the steps run; :class:`FeederError` naming the first unknown bus, step or bad value."""
    if voltages_pu is None:
        return None
    table = pd.DataFrame(voltages_pu)
    buses = problem.feeder.original.buses.index
    unknown = [bus for bus in table.columns if bus not in buses]
    if unknown:
        raise FeederError(f"voltages_pu gives bus {unknown[0]!r}, not a bus of the feeder")
    extra = np.setdiff1d(table.index.to_numpy(), steps)
    if len(extra):
        raise FeederError(f"voltages_pu gives step {extra[0]}, which the run did not simulate")
    values = table.to_numpy(float)
    bad = ~(np.isnan(values) | ((values > 0) & (values < 2)))
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise FeederError(
            f"voltages_pu at bus {table.columns[col]!r}, step {table.index[row]}: "
            f"{values[row, col]} p.u. is not a voltage magnitude"
        )
    return table


def limit_states(steps: Steps, problem: DispatchProblem) -> np.ndarray:
    """(steps, generators): -1 at the lower limit in force, +1 at the upper, 0 between
    (within :data:`BINDING_TOL_KW`; offline generators are at both, counted -1)."""
    lower = np.where(steps.online, problem.pmin, 0.0) * KW_PER_MW
    upper = np.where(steps.online, problem.pmax, 0.0) * KW_PER_MW
    p = steps.setpoints_kw
    return np.where(p <= lower + BINDING_TOL_KW, -1, np.where(p >= upper - BINDING_TOL_KW, 1, 0))


def frame_rows(steps: Steps, problem: DispatchProblem, every: int) -> np.ndarray:
    """Rows of ``steps`` that get a map frame: the first, the last, every ``every``-th, and each
    step where something changes: a limited line's state (idle, binding, overloaded), a
    generator reaching or leaving one of its limits (the marginal generators change), a
    generator going off- or online, or the DC-OPF's feasibility."""
    n = len(steps.values)
    keep = np.zeros(n, dtype=bool)
    keep[::every] = True
    keep[[0, -1]] = True
    feasible = np.isfinite(steps.opf_kw).all(axis=1)
    columns = (steps.line_states(problem), limit_states(steps, problem), steps.online,
               feasible[:, None])  # fmt: skip
    for column in columns:
        keep[1:] |= (column[1:] != column[:-1]).any(axis=1)
    return np.flatnonzero(keep)


def default_every(steps: Steps, target_frames: int) -> int:
    """Steps between regular frames so that about ``target_frames`` regular frames remain."""
    return max(1, int(np.ceil(len(steps.values) / target_frames)))
