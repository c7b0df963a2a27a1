"""Under the prices' own step a line's controllers tell the generators when both of the line's
directions price the flow (``max(0, z_up + C (f - U))`` and ``max(0, z_down + C (-f - U))``
both positive): the net price then moves by ``2 C`` per MW of flow, each side's half price by
``C``, and a generator below the line counts it twice in its own step factor. The flags are
computed here by hand from the prices and the flow; the slopes from the rule's; and on a
drawn case16am fleet, whose flow swung across the line's band while both prices climbed for
231 rounds, the agents now reach the DC-OPF (Clarabel) in at most 100."""

from __future__ import annotations

import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.controller import (  # noqa: E402
    PAYOFFS,
    ControllerAgent,
    LineEnd,
    LinePrice,
)
from popdispatch.agents.messages import Measurement, Signals  # noqa: E402
from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.population import build_agents  # noqa: E402
from popdispatch.agents.schedule import Phase  # noqa: E402
from popdispatch.modes import ModeCode  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402

from helpers import (  # noqa: E402
    agents_on_a_matpower_fleet,
    assert_converged_on_the_dc_opf,
    random_fleet_problem,
)

LIMIT, C, ALPHA, H = 1.0, 2.0, 300.0, 1e-3  # MW, EUR/MW per MW, EUR/MW per MW per s, s

#: MATPOWER's case16am with a drawn fleet; line 7-9 limited to 104.7 kW binds, ``g1`` alone
#: below it.
FLEET16 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,src,38.3214172,0,0,57400
3,g0,18.9947077,0.267060685,597.153952,8120.99091
9,g1,11.3009426,43.8346154,0,5283.07054
4,g2,12.1818473,509.369151,0,7782.83
6,g3,13.6955675,975.405431,0,1815.48792
"""


class Recording(ControllerAgent):
    """A controller of one line (receivers ``g`` on its side, ``h`` on the other) that keeps
    what it sends instead of sending it."""

    def __init__(self, z_up: float, z_down: float, tell_both: bool = True):
        price = LinePrice(PAYOFFS[ModeCode.EXACT], LIMIT, C, ALPHA, 2)
        end = LineEnd(0, 1, price, ["g"], z_up=z_up, z_down=z_down, other_receivers=["h"])
        super().__init__([end], H, tell_both=tell_both)
        self.sent: list = []

    def send(self, content, aid: str) -> None:
        self.sent.append((content, aid))

    def signal_at(self, flow: float) -> Signals:
        """Measure ``flow`` (MW), signal once; what went to ``g``."""
        self.receive(Measurement(0, 0, flow), "plant")
        self.act(0, Phase.SIGNAL)
        return next(content for content, aid in self.sent if aid == "g")


def both_by_hand(z_up: float, z_down: float, flow: float) -> bool:
    return z_up + C * (flow - LIMIT) > 0.0 and z_down + C * (-flow - LIMIT) > 0.0


@pytest.mark.parametrize(
    "z_up, z_down, flow",
    [
        (5.0, 5.0, 0.5),  # both multipliers positive inside the band
        (5.0, 0.5, 0.5),  # the down direction's multiplier is 0 there
        (0.0, 0.0, 1.5),  # only the overflowing direction
        (0.5, 9.0, -0.9),  # both, near the lower limit
        (3.0, 3.0, 0.0),  # each multiplier exactly 1
        (2.0, 2.0, 0.0),  # each exactly 0: not positive
    ],
)
def test_the_controller_tells_when_both_directions_price_the_flow(z_up, z_down, flow):
    sent = Recording(z_up, z_down).signal_at(flow)
    assert sent.both == (("0",) if both_by_hand(z_up, z_down, flow) else ())
    assert Recording(z_up, z_down, tell_both=False).signal_at(flow).both == ()


@pytest.mark.parametrize("seed", range(6))
def test_a_line_both_directions_price_counts_twice_in_the_own_factor(seed):
    problem = random_fleet_problem(seed, 5, 1)
    system = build_agents(problem, 1, RunSettings(mode="exact"), 1e-3, Faults(),
                          local_step=True)  # fmt: skip
    below = [g for g in system.generators if g.rule.lines_above]
    assert below
    for generator in below:
        (k,), (slope,) = generator.rule.lines_above, generator.rule.price_slopes
        line = str(k)
        generator.receive(Signals(1, {line: 4.0}), "c")
        assert generator._price_slope(1) == pytest.approx(slope, rel=1e-15)
        generator.receive(Signals(2, {line: 4.0}, (line,)), "c")
        assert generator._price_slope(2) == pytest.approx(2.0 * slope, rel=1e-15)
        generator.receive(Signals(3, {line: 0.0}), "c")  # unpriced, remembered, one direction
        assert generator._price_slope(3) == pytest.approx(slope, rel=1e-15)


def test_a_drawn_fleet_whose_prices_both_climbed_reaches_the_dc_opf(tmp_path):
    """The case16am fleet with line 7-9 limited, on the complete graph."""
    out, opf, setpoints = agents_on_a_matpower_fleet(
        tmp_path, "case16am", FLEET16, (7, 9, 104.7), "complete"
    )
    assert abs(opf.line_price[0]) > 1.0  # the line binds at the optimum (EUR/MWh)
    assert_converged_on_the_dc_opf(out, opf, setpoints, 100)
