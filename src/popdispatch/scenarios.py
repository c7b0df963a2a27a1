"""The paper's experiments as named scenarios (section III).

- ``base-day``: ieee-elv, no line limits, Smith dynamics, the whole day against the DC-OPF.
- ``congestion``: minute 566, every line between buses 505 and 666 limited to 28 kW, Smith.
  The paper reports detection at iteration 53 and convergence at iteration 201.
- ``extinction``: replicator dynamics never use an efficient generator that starts at zero
  share (here Generator 2, bus 114, the cheapest), while Smith dynamics reach the optimum.
- ``voltage`` (issue 14): ``case33bw`` with the source and four DGs whose cheapest dispatch
  (all from the source) leaves the far end below 0.95 p.u.; the DC exact dispatch, the
  voltage-aware dispatch (voltage mode, against the LinDistFlow OPF) and pandapower's AC OPF,
  each checked in AC (docs/voltage.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from popdispatch.feeder.cases import elv_snapshot_566_kw, ieee_elv
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles, single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import DispatchProblem, build_problem
from popdispatch.online import DayResult, RunSettings, SnapshotResult, run_day, run_snapshot
from popdispatch.opf import OpfResult, solve_opf, solve_opf_day
from popdispatch.report.progress import Progress

PEAK_MINUTE = 566
CONGESTION_PATH = (505, 666, 28.0)
EXTINCT_GENERATOR = "G114"


def apply_path_limits(feeder: Feeder, limits: Sequence[tuple[int, int, float]]) -> Feeder:
    """Limit every original line on the path between buses ``a`` and ``b`` to ``kw`` kW."""
    for bus_a, bus_b, kw in limits:
        if not kw >= 0:
            raise ValueError(f"line limit {kw} kW between buses {bus_a} and {bus_b} is invalid")
        names = feeder.path_lines(bus_a, bus_b)
        feeder = feeder.with_line_limits(pd.Series(float(kw), index=names))
    return feeder


def peak_profiles() -> LoadProfiles:
    """Official loads of minute 566 from pandapower's snapshot (no profile folder needed)."""
    return single_minute_profiles(
        PEAK_MINUTE, elv_snapshot_566_kw(), "official minute 566 (pandapower on_peak_566)"
    )


def elv_problem(
    profiles: LoadProfiles | None = None,
    limits: Sequence[tuple[int, int, float]] = (),
    feeder: Feeder | None = None,
    check: bool = True,
) -> DispatchProblem:
    """The ieee-elv dispatch problem (or ``feeder``'s) with optional path limits.

    Without ``profiles`` the loads are the official ones of minute 566 (pandapower snapshot).
    ``check``: as in :func:`popdispatch.game.problem.build_problem` (every minute's demand
    within the fleet's range); the CLI checks only the minutes it runs.
    """
    feeder = apply_path_limits(feeder or ieee_elv(), limits)
    return build_problem(reduce_feeder(feeder), profiles or peak_profiles(), check)


@dataclass(frozen=True)
class SnapshotComparison:
    """A one-minute run and the DC-OPF of the same problem (``opf_unconstrained``: no limits)."""

    run: SnapshotResult
    opf: OpfResult
    opf_unconstrained: OpfResult | None = None

    @property
    def max_abs_error_kw(self) -> float:
        return float(np.max(np.abs(self.run.setpoints_kw - self.opf.p_kw)))


@dataclass(frozen=True)
class DayComparison:
    """An online day and the DC-OPF of every simulated minute (``opf_kw``: minutes x generators).

    Minutes whose DC-OPF is infeasible keep the dynamics' results; their DC-OPF values are NaN
    and comparisons (errors, energies, costs) use the :attr:`feasible` minutes only.
    """

    run: DayResult
    opf: list[OpfResult]

    @property
    def feasible(self) -> np.ndarray:
        """Per simulated minute: whether its DC-OPF exists."""
        return np.array([o.status == "optimal" for o in self.opf], dtype=bool)

    @property
    def infeasible_minutes(self) -> list[int]:
        """1-based minutes whose DC-OPF is infeasible (the DC-OPF's verdict, not the dynamics')."""
        return [int(m) for m in self.run.minutes[~self.feasible]]

    @property
    def opf_kw(self) -> np.ndarray:
        return np.array([o.p_kw for o in self.opf])

    @property
    def abs_error_kw(self) -> np.ndarray:
        return np.abs(self.run.setpoints_kw - self.opf_kw)


def snapshot_vs_opf(
    problem: DispatchProblem, minute: int, settings: RunSettings | None = None
) -> SnapshotComparison:
    """Run one minute and solve its DC-OPF."""
    return SnapshotComparison(run_snapshot(problem, minute, settings), solve_opf(problem, minute))


def day_vs_opf(
    problem: DispatchProblem,
    settings: RunSettings | None = None,
    minutes=None,
    progress: Progress | None = None,
) -> DayComparison:
    """Run the online day and solve the DC-OPF of each minute (with ``progress`` bars).

    One DC-OPF solver serves the whole day (:func:`popdispatch.opf.solve_opf_day`: only its
    bounds change from minute to minute); building a solver per minute cost about 2 ms each,
    i.e. seconds per day, for the same results.
    """
    settings = settings or RunSettings()
    progress = progress or Progress(quiet=True)
    label = f"online day ({settings.dynamics}, {settings.mode} mode)"
    total = len(problem.demand) if minutes is None else len(minutes)
    with progress.counter(label, total) as advance:
        run = run_day(problem, settings, minutes, progress=advance)
    minutes_bar = progress.iterate(run.minutes, "DC-OPF per minute", len(run.minutes))
    return DayComparison(run, solve_opf_day(problem, minutes_bar))


def base_day(profiles: LoadProfiles, settings: RunSettings | None = None) -> DayComparison:
    """``base-day``: no line limits, Smith dynamics (unless ``settings`` say otherwise)."""
    return day_vs_opf(elv_problem(profiles), settings)


def congestion(
    profiles: LoadProfiles | None = None, settings: RunSettings | None = None
) -> SnapshotComparison:
    """``congestion``: minute 566 with the 505-666 path limited to 28 kW."""
    problem = elv_problem(profiles, [CONGESTION_PATH])
    free = elv_problem(profiles)
    result = snapshot_vs_opf(problem, PEAK_MINUTE, settings)
    return replace(result, opf_unconstrained=solve_opf(free, PEAK_MINUTE))


@dataclass(frozen=True)
class ExtinctionResult:
    """Replicator and Smith runs from the same state with ``generator`` at zero share."""

    generator: str
    replicator: SnapshotResult
    smith: SnapshotResult
    opf: OpfResult


def extinction(
    profiles: LoadProfiles | None = None,
    minute: int = PEAK_MINUTE,
    generator: str = EXTINCT_GENERATOR,
    settings: RunSettings | None = None,
) -> ExtinctionResult:
    """``extinction``: ``generator`` starts at zero share, the others share the load equally.

    The Smith run uses ``settings`` (any mode); the replicator run always uses the paper mode,
    the only one that can run imitative dynamics (exact mode refuses them for this very reason).
    """
    problem = elv_problem(profiles)
    x0 = {g: (0.0 if g == generator else 1.0) for g in problem.generators}
    # Smith and replicator on the complete graph (the comparison of the paper's fig. 6); a
    # warm start does not apply to one minute, so none is carried over.
    base = replace(settings or RunSettings(), x0=x0, graph="complete", warm_start=None)
    imitative = replace(base, dynamics="replicator", mode="paper", integrator=None)
    return ExtinctionResult(
        generator,
        run_snapshot(problem, minute, imitative),
        run_snapshot(problem, minute, replace(base, dynamics="smith")),
        solve_opf(problem, minute),
    )


#: The ``voltage`` scenario's feeder and fleet: case33bw (pandapower's, buses numbered from 0:
#: MATPOWER bus k is bus k - 1) with the source priced below four DGs (bus, a EUR/h, b EUR/MWh,
#: c EUR/(MW^2 h), Pmin kW, Pmax kW), named by their MATPOWER bus: the cheapest dispatch buys
#: everything from the source and leaves bus 18 at 0.913 p.u. (AC).
VOLTAGE_CASE = "case33bw"
VOLTAGE_FLEET = (
    (0, 0.0, 20.0, 0.5, 0.0, 5000.0),
    (17, 0.0, 40.0, 2.0, 0.0, 600.0),
    (32, 0.0, 45.0, 2.0, 0.0, 600.0),
    (24, 0.0, 50.0, 2.0, 0.0, 500.0),
    (29, 0.0, 55.0, 2.0, 0.0, 500.0),
)
VOLTAGE_NAMES = ("source", "DG18", "DG33", "DG25", "DG30")
VOLTAGE_LIMITS = (0.95, 1.05)


def voltage_feeder() -> Feeder:
    """case33bw with the ``voltage`` scenario's fleet."""
    from popdispatch.feeder.cases import load_case
    from popdispatch.feeder.generators import make_fleet

    return load_case(VOLTAGE_CASE, fleet=make_fleet(VOLTAGE_FLEET, VOLTAGE_NAMES))


def voltage_problems(
    vmin_pu: float | None = VOLTAGE_LIMITS[0], vmax_pu: float | None = VOLTAGE_LIMITS[1]
) -> tuple[DispatchProblem, DispatchProblem, np.ndarray]:
    """``(without, with voltage limits, per-load kW)`` of the ``voltage`` scenario (one step:
    the case's own loads)."""
    from popdispatch.ac.lindistflow import with_voltage_limits
    from popdispatch.runs import network_profiles

    feeder = voltage_feeder()
    profiles = network_profiles(feeder)
    load_kw = profiles.kw.to_numpy(float)
    plain = elv_problem(profiles, (), feeder, check=True)
    return plain, with_voltage_limits(plain, load_kw, vmin_pu, vmax_pu), load_kw


@dataclass(frozen=True)
class VoltageResult:
    """The ``voltage`` scenario: the DC exact dispatch against the DC-OPF (``dc``), the
    voltage-aware one against the LinDistFlow OPF (``voltage``), their AC checks (``ac_dc``,
    ``ac_voltage``; None without power-grid-model), pandapower's AC OPF (``anchor``; None,
    with ``anchor_error`` saying why, when it is skipped or fails) and the voltage-aware
    dispatch corrected by AC power flows (``corrected``, :mod:`popdispatch.ac.correct`; with
    the AC checks)."""

    plain: DispatchProblem
    problem: DispatchProblem
    load_kw: np.ndarray
    dc: SnapshotComparison
    voltage: SnapshotComparison
    ac_dc: object | None
    ac_voltage: object | None
    anchor: object | None
    anchor_error: str | None
    corrected: object | None = None


def voltage(settings: RunSettings | None = None, ac: bool = True, anchor: bool = True):
    """``voltage``: the scenario's three dispatches (see :class:`VoltageResult`); ``settings``
    (their dynamics, graph, x0) run in exact mode, then with the scenario's voltage limits."""
    base = replace(settings or RunSettings(), mode="exact", vmin_pu=None, vmax_pu=None,
                   integrator=None, warm_start=None)  # fmt: skip
    plain, problem, load_kw = voltage_problems()
    aware = replace(base, vmin_pu=problem.vmin_pu, vmax_pu=problem.vmax_pu)
    dc = snapshot_vs_opf(plain, 1, base)
    limited = snapshot_vs_opf(problem, 1, aware)
    ac_dc = ac_voltage = corrected = None
    if ac:
        from popdispatch.ac import check_snapshot
        from popdispatch.ac.correct import ac_correct

        ac_dc, ac_voltage = (
            check_snapshot(p, None, r) for p, r in ((plain, dc), (problem, limited))
        )
        corrected = ac_correct(problem, load_kw[0], 1, aware)
    found, error = _anchor(problem, load_kw) if anchor else (None, "not asked for")
    return VoltageResult(plain, problem, load_kw, dc, limited, ac_dc, ac_voltage, found, error,
                         corrected)  # fmt: skip


def _anchor(problem: DispatchProblem, load_kw: np.ndarray):
    """pandapower's AC OPF of the problem's feeder and limits, or ``(None, why not)``."""
    from popdispatch.ac.runopp import ACOpfError, ac_opf

    try:
        return ac_opf(problem.feeder.original, load_kw[0], problem.vmin_pu, problem.vmax_pu), None
    except ACOpfError as exc:
        return None, str(exc)


SCENARIOS = ("base-day", "congestion", "extinction", "voltage")
