"""Stuck lines (docs/exact-mode.md, "Stuck lines"): a limited line overflowed by a few watts
while every trade that would relieve it goes against the fitness order, so only its price can
move, at its rate times that overflow. Exact mode hastens such a price by at most its gap to
the trade over ``STUCK_SETTLE``, and converges on Clarabel's DC-OPF under every price law
within a few iterations, down to overflows of a tenth of a watt (before the gain: 145 to 2255
iterations, or stalled)."""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.modes.exact import ExactConstants
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf

from helpers import official_folder, radial_problem

LAWS = ("plain", "tree", "scaled")
#: Iterations within which each case is proved.
MOST = 30

def _feeder_problem(fleet: list[tuple], load_kw: dict[int, float], limit_kw: float):
    """Bus 1 with a branch to bus 3 and, through the limited line L2, to bus 2 and on to 4;
    loads at buses 1 and 2; ``fleet`` rows as
    :func:`~popdispatch.feeder.generators.make_fleet` takes them."""
    return radial_problem([(1, 2), (1, 3), (2, 4)], fleet, load_kw, {"L2": limit_kw})


def _export_limited(distance_kw: float):
    """Cheap DGs beyond L2 (bus 2: b 3, 0-5 kW; bus 4: b 2, 0-20 kW) export up to its 10 kW
    limit; the grid (b 5, 0-10 kW) makes up the rest, ``distance_kw`` above its Pmin at the
    optimum; the cheapest DG (bus 3, b 1, 10 kW) runs flat out."""
    fleet = [(1, 0.0, 5.0, 0.02, 0.0, 10.0), (3, 0.0, 1.0, 0.01, 0.0, 10.0),
             (2, 0.0, 3.0, 0.025, 0.0, 5.0), (4, 0.0, 2.0, 0.02, 0.0, 20.0)]  # fmt: skip
    return _feeder_problem(fleet, {1: 20.0 + distance_kw, 2: 7.03}, 10.0)


def _import_limited(distance_kw: float):
    """The DG at bus 3 (b 1, 10 kW) feeds what L2's 3 kW limit lets through to the loads
    beyond it; at the optimum it runs ``distance_kw`` below its Pmax, the DG at bus 4 (b 2)
    covers the rest beyond the line, the grid (b 5) is off."""
    fleet = [(1, 0.0, 5.0, 0.02, 0.0, 30.0), (3, 0.0, 1.0, 0.01, 0.0, 10.0),
             (2, 0.0, 3.0, 0.025, 0.0, 5.0), (4, 0.0, 2.0, 0.02, 0.0, 10.0)]  # fmt: skip
    return _feeder_problem(fleet, {1: 7.0 - distance_kw, 2: 10.046}, 3.0)


def _assert_proved_on_the_dc_opf(problem, minute: int, law: str) -> None:
    opf = solve_opf(problem, minute)
    assert opf.status == "optimal"
    assert np.abs(opf.line_price).max() > 0.5  # the limit binds with a price to climb
    settings = RunSettings(mode="exact", exact=ExactConstants(price_law=law))
    run = run_snapshot(problem, minute, settings)
    assert run.status == "converged", run.stall_reason
    assert run.iterations <= MOST
    assert np.abs(run.trajectory_kw[-1] - opf.p_kw).max() <= run.accuracy_kw


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("distance_kw", [3e-4, 3e-3, 3e-2])
def test_an_export_limit_with_the_grid_just_above_its_pmin(distance_kw, law) -> None:
    _assert_proved_on_the_dc_opf(_export_limited(distance_kw), 1, law)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("distance_kw", [1e-4, 1e-3, 1e-2])
def test_an_import_limit_with_a_dg_just_below_its_pmax(distance_kw, law) -> None:
    _assert_proved_on_the_dc_opf(_import_limited(distance_kw), 1, law)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize(("limit_kw", "minute"), [(10.0, 688), (3.0, 934)])
def test_elv_minutes_with_a_tight_limit(limit_kw, minute, law) -> None:
    """The ELV day with the path 505-666 limited to 10 and 3 kW: these minutes took 322 and
    481 iterations under the plain law."""
    from popdispatch.readers import read_profiles
    from popdispatch.scenarios import elv_problem

    problem = elv_problem(read_profiles(official_folder()), limits=[(505, 666, limit_kw)],
                          check=False)  # fmt: skip
    _assert_proved_on_the_dc_opf(problem, minute, law)
