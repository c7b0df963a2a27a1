"""When a run at rest above its accuracy goes on: its proved bound halved since the rest
before, or, falling at the same rate, it would reach the accuracy within the horizon. The
rounds to the accuracy computed here by hand from the geometric rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.world import REST_PROGRESS, Falling  # noqa: E402

ACCURACY = 1e-5  # MW


def test_a_bound_falling_slowly_goes_on_while_the_accuracy_is_within_the_horizon():
    # 3.1e-5 MW after 2.0e-5 / 0.7 twenty rounds before: by 0.7 every 20 rounds
    falling = Falling(3.1e-5, 3.1e-5 / 0.7, 20)
    by_hand = 20 * math.log(ACCURACY / 3.1e-5) / math.log(0.7)  # 63.4 rounds
    assert falling.rounds_to(ACCURACY) == pytest.approx(by_hand, rel=1e-12)
    assert falling.goes_on(ACCURACY, remaining=64, progress=REST_PROGRESS)
    assert not falling.goes_on(ACCURACY, remaining=63, progress=REST_PROGRESS)


def test_a_halved_bound_goes_on_whatever_the_horizon_and_a_flat_one_stops():
    assert Falling(1e-4, 2.1e-4, 10).goes_on(ACCURACY, remaining=0, progress=REST_PROGRESS)
    assert Falling(1e-4, np.inf, 10).goes_on(ACCURACY, remaining=0, progress=REST_PROGRESS)
    flat = Falling(1e-4, 1e-4, 10)
    assert flat.rounds_to(ACCURACY) == math.inf
    assert not flat.goes_on(ACCURACY, remaining=10**9, progress=REST_PROGRESS)
    rising = Falling(1e-4, 0.9e-4, 10)
    assert not rising.goes_on(ACCURACY, remaining=10**9, progress=REST_PROGRESS)


def test_a_bound_within_the_accuracy_stops():
    done = Falling(0.5 * ACCURACY, 4 * ACCURACY, 10)
    assert done.rounds_to(ACCURACY) == 0.0
    assert not done.goes_on(ACCURACY, remaining=10**9, progress=REST_PROGRESS)
