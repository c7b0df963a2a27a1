"""A day with minutes whose DC-OPF is infeasible: those minutes' line prices run past their cap,
and the minutes after them still land on their DC-OPF (Clarabel) as if the runaway had not
happened."""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.online import RunSettings, run_day
from popdispatch.opf import solve_opf

from helpers import official_folder, radial_problem


def _two_bus_day(loads_kw: list[float]):
    """Grid at bus 1 (b 50, c 0.1, 200 kW), an expensive DG at bus 2 (b 60, c 1, 20 kW) beside
    the load, the line between limited to 10 kW: a load over 30 kW has no dispatch."""
    fleet = [(1, 0.0, 50.0, 0.1, 0.0, 200.0), (2, 0.0, 60.0, 1.0, 0.0, 20.0)]
    return radial_problem([(1, 2)], fleet, {2: loads_kw}, {"L2": 10.0})


def _assert_feasible_minutes_on_the_dc_opf(problem, day) -> None:
    """Every minute whose DC-OPF exists is converged (proved) and within its accuracy of it;
    the engine's runaway minutes are exactly those without one."""
    opf = [solve_opf(problem, int(m)) for m in day.minutes]
    infeasible = np.array([o.status != "optimal" for o in opf])
    assert infeasible.any()
    np.testing.assert_array_equal(day.infeasible, infeasible)
    for row in np.flatnonzero(~infeasible):
        assert day.converged[row], f"minute {day.minutes[row]}"
        error = np.abs(day.setpoints_kw[row] - opf[row].p_kw).max()
        assert error <= day.accuracy_kw[row], f"minute {day.minutes[row]}: {error} kW"


def test_the_minute_after_an_infeasible_one_lands_on_its_dc_opf() -> None:
    problem = _two_bus_day([15.0, 40.0, 15.0, 18.0, 45.0, 45.0, 12.0])
    day = run_day(problem, RunSettings(mode="exact"))
    np.testing.assert_array_equal(day.infeasible, [False, True, False, False, True, True, False])
    _assert_feasible_minutes_on_the_dc_opf(problem, day)


@pytest.mark.slow
def test_elv_runaway_minutes_are_the_infeasible_ones() -> None:
    """The ELV day around its peak with the path 505-666 limited to 10 kW: minutes 564-568
    have no DC-OPF; the six after them do."""
    from popdispatch.readers import read_profiles
    from popdispatch.scenarios import elv_problem

    problem = elv_problem(read_profiles(official_folder()), limits=[(505, 666, 10.0)],
                          check=False)  # fmt: skip
    day = run_day(problem, RunSettings(mode="exact"), minutes=np.arange(560, 581))
    _assert_feasible_minutes_on_the_dc_opf(problem, day)


def test_an_infeasible_snapshot_reports_the_prices_it_ended_with() -> None:
    """The engine continues after an infeasible minute from where it started, but the minute
    itself is reported at its end: set points and the prices that ran past their cap."""
    from popdispatch.modes import get_mode
    from popdispatch.online import run_snapshot

    problem = _two_bus_day([15.0, 40.0])
    run = run_snapshot(problem, 2, RunSettings(mode="exact"))
    assert run.status == "infeasible"
    assert np.abs(run.line_price_eur_per_mwh).max() > get_mode("exact").price_cap(problem)
    np.testing.assert_allclose(run.trajectory_kw[-1], [20.0, 20.0])  # the DG at its Pmax
