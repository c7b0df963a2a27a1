"""The named records the compiled game takes: built in one place, read by name."""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.parameters import GameParameters, GameWork, MinuteInputs
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem


@pytest.fixture(scope="module")
def problem():
    return elv_problem(limits=[CONGESTION_PATH])


def test_game_parameters_name_the_problem_and_the_constants(problem):
    fp = FitnessParameters(B=900.0, m=300.0, C=800.0, gain=50.0, price_rate=2.0)
    params = GameParameters.of(problem, fp)
    assert params.pmax is problem.pmax and params.line_up is problem.line_up
    assert (params.B, params.m, params.C, params.gain, params.price_rate) == (
        900.0, 300.0, 800.0, 50.0, 2.0,
    )  # fmt: skip


def test_minute_inputs_share_bounds_are_zero_offline(problem):
    minute = MinuteInputs.of(problem, PEAK_MINUTE)
    demand = float(problem.demand[PEAK_MINUTE - 1])
    assert minute.demand == demand
    np.testing.assert_array_equal(minute.load_flow, problem.load_flow[PEAK_MINUTE - 1])
    online = problem.online[PEAK_MINUTE - 1]
    np.testing.assert_array_equal(minute.lo, np.where(online, problem.pmin, 0.0) / demand)
    np.testing.assert_array_equal(minute.hi, np.where(online, problem.pmax, 0.0) / demand)


def test_game_work_has_one_value_per_limited_line():
    """One value per limited line in each line scratch; the rates in force, one per generator,
    only for a game whose rates follow its state (else empty: the field reads the
    parameters' own)."""
    work = GameWork.empty(3, n_generators=2)
    assert all(getattr(work, name).shape == (3,)
               for name in ("flow", "parent_side", "child_side", "path"))  # fmt: skip
    assert work.rate.shape == (0,)
    assert GameWork.empty(3, 5, n_generators=5).rate.shape == (5,)
