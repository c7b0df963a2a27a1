"""A node controller whose line's flow stands still over its limit hastens the overflowing
price: after ``STILL_GRACE`` still measurements each further one multiplies that price's step
by ``STUCK_GROWTH``, up to the least speed; the first measurement that finds the flow moving
takes back the last round's gain and ends the spell, and a later spell grows the factor at
most to the ended one's final factor over ``STUCK_GROWTH ** SPELL_BACKOFF``; on a drawn
fleet whose linear DG answered the first spell's overshoot by letting the flow back inside,
the price then climbs the rest hastened again (91 rounds; 211 with one spell a minute).
Otherwise (a line
within its limit, a controller without a speed) the step is the plain Euler step of the dual
ascent ``z += h alpha (flow - U)``, computed here by hand."""

from __future__ import annotations

import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.controller import (  # noqa: E402
    PAYOFFS,
    SPELL_BACKOFF,
    STILL_GRACE,
    STUCK_GROWTH,
    ControllerAgent,
    LineEnd,
    LinePrice,
)
from popdispatch.agents.messages import Measurement, Signals  # noqa: E402
from popdispatch.agents.schedule import Phase  # noqa: E402
from popdispatch.modes import ModeCode  # noqa: E402

LIMIT, C, ALPHA, H = 1.0, 2.0, 300.0, 1e-3  # MW, EUR/MW per MW, EUR/MW per MW per s, s


class Recording(ControllerAgent):
    """A controller that keeps what it sends instead of sending it."""

    def __init__(self, speed: float):
        price = LinePrice(PAYOFFS[ModeCode.EXACT], LIMIT, C, ALPHA, 2)
        super().__init__([LineEnd(0, 1, price, ["g"])], H, speed=speed)
        self.sent: list[Signals] = []

    def send(self, content, aid: str) -> None:
        self.sent.append(content)

    def round(self, rnd: int, flow_mw: float | None) -> float:
        """Measure ``flow_mw`` (None: no fresh measurement this round), signal; the up price."""
        if flow_mw is not None:
            self.receive(Measurement(rnd, 0, flow_mw), "plant")
        self.act(rnd, Phase.SIGNAL)
        return self.ends[0].z_up


def steps(controller: Recording, flows: list[float | None]) -> list[float]:
    """The up price's step at each round of ``flows``, in units of the plain step at an
    overflow of 0.1 MW."""
    unit = H * ALPHA * 0.1
    out, before = [], controller.ends[0].z_up
    for rnd, flow in enumerate(flows):
        z = controller.round(rnd, flow)
        out.append((z - before) / unit)
        before = z
    return out


def hastened(rounds: int) -> list[float]:
    """The steps of ``rounds`` still rounds after the first measurement, by hand."""
    return [STUCK_GROWTH ** max(0, r - STILL_GRACE) for r in range(1, rounds + 1)]


def test_a_still_overflow_grows_the_step_and_a_moving_flow_ends_it():
    grown = 4
    still = [1.1] * (1 + STILL_GRACE + grown)
    moved = [1.1 + 1e-3] * 3
    found = steps(Recording(speed=1e9), [*still, *moved, *still])
    expected = [1.0, *hastened(STILL_GRACE + grown)]
    assert found[: len(still)] == pytest.approx(expected, rel=1e-12)
    # the flow moved (by 1 % of the overflow): the last gain taken back, the plain step on
    # the new overflow; then, still again, the plain step through the grace and a factor
    # that grows at most to the last spell's over STUCK_GROWTH ** SPELL_BACKOFF
    last_gain = expected[-1] - 1.0
    rest = found[len(still) :]
    assert rest[0] == pytest.approx(1.01 - last_gain, rel=1e-12)
    assert rest[1:3] == pytest.approx([1.01, 1.01], rel=1e-12)
    ceiling = expected[-1] / STUCK_GROWTH**SPELL_BACKOFF
    again = [min(STUCK_GROWTH ** max(0, r - STILL_GRACE), ceiling) for r in range(len(still))]
    assert ceiling > 1.0 and max(again) == pytest.approx(ceiling, rel=1e-12)
    assert rest[3:] == pytest.approx(again, rel=1e-12)


def test_a_linear_dg_s_price_climbs_hastened_again_after_an_overshoot():
    """A random 4-DG fleet whose linear DG below the limited line let the flow back inside
    after the first spell's overshoot; the price had to climb the rest from 10.7 EUR/MWh."""
    import numpy as np

    from popdispatch.agents.network import Faults
    from popdispatch.agents.system import AgentSettings, run_agents
    from popdispatch.online import RunSettings
    from popdispatch.opf import solve_opf

    from helpers import random_fleet_problem

    problem = random_fleet_problem(1034, 4, 2, linear_share=0.6)
    opf = solve_opf(problem, 1)
    assert np.abs(opf.line_price).max() > 10.0  # a limit binds at the optimum (EUR/MWh)
    run = run_agents(problem, 1, RunSettings(mode="exact"), Faults(), AgentSettings(max_rounds=600))
    assert run.status == "converged" and run.rounds <= 150, (run.status, run.rounds)
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= run.accuracy_kw


def test_a_missing_measurement_keeps_the_factor_and_the_speed_caps_the_step():
    flows = [1.1] * (STILL_GRACE + 3)
    found = steps(Recording(speed=1e9), [*flows, None, 1.1])
    grown = [1.0, *hastened(STILL_GRACE + 2)]
    assert found == pytest.approx([*grown, grown[-1], grown[-1] * STUCK_GROWTH], rel=1e-12)
    speed = 1.2 * ALPHA * 0.1  # EUR/MW per s: 1.2 plain rates, below STUCK_GROWTH's
    capped = steps(Recording(speed=speed), [1.1] * (STILL_GRACE + 3))
    assert capped == pytest.approx([1.0] * (STILL_GRACE + 1) + [1.2, 1.2], rel=1e-12)


def test_no_speed_or_no_overflow_keeps_the_plain_step():
    rounds = STILL_GRACE + 4
    assert steps(Recording(speed=0.0), [1.1] * rounds) == pytest.approx([1.0] * rounds, rel=1e-12)
    # within the limit the up price (positive) falls at the plain rate of its slack, every round
    controller = Recording(speed=1e9)
    controller.ends[0].z_up = 1.0
    slack = steps(controller, [0.9] * rounds)
    assert slack == pytest.approx([-1.0] * rounds, rel=1e-12)
