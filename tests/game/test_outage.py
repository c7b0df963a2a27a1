"""Generator outages on a problem's own series: any length, not only a day of minutes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from popdispatch.errors import InfeasibleError, ProfileError
from popdispatch.scenarios import elv_problem


@pytest.fixture(scope="module")
def two_days():
    """The built-in ELV problem's day twice over: 2,880 steps."""
    day = elv_problem()
    return replace(
        day,
        demand=np.tile(day.demand, 2),
        load_flow=np.tile(day.load_flow, (2, 1)),
        online=np.tile(day.online, (2, 1)),
    )


def test_an_outage_past_the_first_day_marks_exactly_its_steps(two_days):
    g = list(two_days.generators).index("G114")
    problem = two_days.with_outage("G114", 2000, 2101, check=False)
    offline = np.flatnonzero(~problem.online[:, g]) + 1  # 1-based steps
    assert offline[0] == 2000 and offline[-1] == 2100 and len(offline) == 101
    assert problem.online[:, np.arange(problem.n_generators) != g].all()
    to_end = two_days.with_outage("G114", 2800, check=False)
    assert (np.flatnonzero(~to_end.online[:, g]) + 1).tolist() == list(range(2800, 2881))


@pytest.mark.parametrize(("off", "on"), [(2881, None), (0, None), (100, 2882)])
def test_an_outage_outside_the_series_names_the_step(two_days, off, on):
    with pytest.raises(ProfileError, match=r"outside 1\.\.288[01]"):
        two_days.with_outage("G114", off, on)


def test_the_capacity_check_names_the_step_past_the_first_day(two_days):
    """Without G114 the 55 kW left cannot carry the second day's step 2000 (560 of day two)."""
    with pytest.raises(InfeasibleError, match="at minute 2000 exceeds"):
        two_days.with_outage("G114", 2000, 2101)
