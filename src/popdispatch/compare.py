"""A run against its yardstick, for any feeder: the dispatch problem of a feeder with path
limits (:func:`elv_problem`), one minute or a day of dynamics beside the DC-OPF of the same
problem (:func:`snapshot_vs_opf`, :func:`day_vs_opf`) and what they hold
(:class:`SnapshotComparison`, :class:`DayComparison`). The paper's experiments
(:mod:`popdispatch.scenarios`), the AC check (:mod:`popdispatch.ac`), the reports and the
commands build on these.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from popdispatch.cases.builtin import PEAK_MINUTE, elv_snapshot_566_kw, ieee_elv
from popdispatch.errors import OptionError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles, single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import DispatchProblem, build_problem
from popdispatch.online import DayResult, RunSettings, SnapshotResult, run_day, run_snapshot
from popdispatch.opf import OpfResult, solve_opf, solve_opf_day
from popdispatch.progress import Progress


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
    feeder: Feeder | DcNetwork | None = None,
    check: bool = True,
) -> DispatchProblem:
    """The ieee-elv dispatch problem (or ``feeder``'s: a radial feeder or a meshed
    :class:`~popdispatch.feeder.dcnet.DcNetwork`, :func:`mesh_problem`) with optional path
    limits (on a mesh: limits of the branches joining the two buses).

    Without ``profiles`` the loads are the official ones of minute 566 (pandapower snapshot).
    ``check``: as in :func:`popdispatch.game.problem.build_problem` (every minute's demand
    within the fleet's range); the CLI checks only the minutes it runs.
    """
    feeder = apply_path_limits(feeder or ieee_elv(), limits)
    if isinstance(feeder, DcNetwork):
        return mesh_problem(feeder, profiles, check)
    return build_problem(reduce_feeder(feeder), profiles or peak_profiles(), check)


def mesh_problem(
    net: DcNetwork, profiles: LoadProfiles | None = None, check: bool = True
) -> DispatchProblem:
    """The dispatch problem of a meshed network (:func:`popdispatch.game.mesh.
    build_mesh_problem`) with the per-load kW of ``profiles`` at its load buses (default its
    own demand, one step)."""
    from popdispatch.game.mesh import build_mesh_problem

    if profiles is None:
        return build_mesh_problem(net, check=check)
    demand = net.bus_demand_mw(profiles.for_loads(net.loads.index).kw.to_numpy(float))
    return build_mesh_problem(net, demand, profiles.source, check)


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
    bounds change from minute to minute), not one solver per minute.
    """
    settings = settings or RunSettings()
    progress = progress or Progress(quiet=True)
    label = f"online day ({settings.dynamics}, {settings.mode} mode)"
    total = len(problem.demand) if minutes is None else len(minutes)
    with progress.counter(label, total) as advance:
        run = run_day(problem, settings, minutes, progress=advance)
    minutes_bar = progress.iterate(run.minutes, "DC-OPF per minute", len(run.minutes))
    return DayComparison(run, solve_opf_day(problem, minutes_bar))


def check_voltage(problem: DispatchProblem, settings: RunSettings) -> None:
    """:class:`OptionError` where the problem's voltage limits are not the settings' (a
    problem built without :func:`with_voltage`, or for other limits)."""
    want = (settings.vmin_pu or 0.0, settings.vmax_pu or 2.0) if settings.voltage_limited else None
    have = (problem.vmin_pu, problem.vmax_pu) if not np.isnan(problem.vmin_pu) else None
    if want != have:
        raise OptionError(
            f"the run's voltage limits {want or 'none'} are not the problem's {have or 'none'}: "
            "build the problem with popdispatch.runs.with_voltage(problem, profiles, settings)",
            "--vmin",
        )
