"""The paper's experiments as named scenarios (section III).

- ``base-day``: ieee-elv, no line limits, Smith dynamics, the whole day against the DC-OPF.
- ``congestion``: minute 566, every line between buses 505 and 666 limited to 28 kW, Smith.
  The paper reports detection at iteration 53 and convergence at iteration 201.
- ``extinction``: replicator dynamics never use an efficient generator that starts at zero
  share (here Generator 2, bus 114, the cheapest), while Smith dynamics reach the optimum.
- ``voltage``: ``case33bw`` with the source and four DGs whose cheapest dispatch
  (all from the source) leaves the far end below 0.95 p.u.; the DC exact dispatch, the
  voltage-aware dispatch (voltage mode, against the LinDistFlow OPF) and pandapower's AC OPF,
  each checked in AC (docs/voltage.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from popdispatch.cases.builtin import PEAK_MINUTE
from popdispatch.compare import (  # re-exported: the scenarios' problems and comparisons
    DayComparison,
    SnapshotComparison,
    apply_path_limits,
    day_vs_opf,
    elv_problem,
    peak_profiles,
    snapshot_vs_opf,
)
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import DispatchProblem
from popdispatch.online import RunSettings, SnapshotResult, run_snapshot
from popdispatch.opf import OpfResult, solve_opf

CONGESTION_PATH = (505, 666, 28.0)
EXTINCT_GENERATOR = "G114"


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
    from popdispatch.cases.builtin import load_case
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


__all__ = [
    "CONGESTION_PATH", "EXTINCT_GENERATOR", "PEAK_MINUTE", "SCENARIOS", "VOLTAGE_CASE",
    "VOLTAGE_FLEET", "VOLTAGE_LIMITS", "VOLTAGE_NAMES", "DayComparison", "ExtinctionResult",
    "SnapshotComparison", "VoltageResult", "apply_path_limits", "base_day", "congestion",
    "day_vs_opf", "elv_problem", "extinction", "peak_profiles", "snapshot_vs_opf", "voltage",
    "voltage_feeder", "voltage_problems",
]  # fmt: skip
