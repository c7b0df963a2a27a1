"""A node controller whose line's flow has settled inside both limits, with both prices
positive, nets them: both lowered by ``min(mu_up, mu_down)``, the multipliers ``max(0, z + C
excess)`` at the measured flow, so the broadcast is unchanged and the line's dual term
``z_up (f - U) + z_down (-f - U)`` rises. The steps are computed here by hand (the plain Euler
step of the dual ascent, then the netting); and on a drawn case33bw fleet whose two prices
both stayed positive for 120 rounds, the agents now reach the DC-OPF (Clarabel) in at most
200 rounds."""

from __future__ import annotations

import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.controller import (  # noqa: E402
    NET_SETTLED,
    PAYOFFS,
    ControllerAgent,
    LineEnd,
    LinePrice,
)
from popdispatch.agents.messages import Measurement  # noqa: E402
from popdispatch.agents.schedule import Phase  # noqa: E402
from popdispatch.modes import ModeCode  # noqa: E402

from helpers import agents_on_a_matpower_fleet, assert_converged_on_the_dc_opf  # noqa: E402

LIMIT, C, ALPHA, H = 1.0, 2.0, 300.0, 1e-3  # MW, EUR/MW per MW, EUR/MW per MW per s, s


class Recording(ControllerAgent):
    """A controller of one line that keeps what it sends instead of sending it."""

    def __init__(self, z_up: float, z_down: float, net: bool = True):
        price = LinePrice(PAYOFFS[ModeCode.EXACT], LIMIT, C, ALPHA, 2)
        end = LineEnd(0, 1, price, ["g"], z_up=z_up, z_down=z_down)
        super().__init__([end], H, net=net)
        self.sent: list = []

    def send(self, content, aid: str) -> None:
        self.sent.append(content)

    def rounds(self, flows: list[float]) -> tuple[float, float]:
        """Measure each flow (MW) in turn and signal; the prices after the last round."""
        for rnd, flow in enumerate(flows):
            self.receive(Measurement(rnd, 0, flow), "plant")
            self.act(rnd, Phase.SIGNAL)
        return self.ends[0].z_up, self.ends[0].z_down


def plain(z_up: float, z_down: float, flow: float) -> tuple[float, float]:
    """One Euler step of the dual ascent, by hand."""
    return (max(z_up + H * ALPHA * (flow - LIMIT), 0.0),
            max(z_down + H * ALPHA * (-flow - LIMIT), 0.0))  # fmt: skip


def netted(z_up: float, z_down: float, flow: float) -> tuple[float, float]:
    """The netting, by hand."""
    mu_up = max(0.0, z_up + C * (flow - LIMIT))
    mu_down = max(0.0, z_down + C * (-flow - LIMIT))
    common = min(mu_up, mu_down)
    return z_up - common, z_down - common


def broadcast(z_up: float, z_down: float, flow: float) -> float:
    """The net price the line's generators receive, EUR/MW."""
    return max(0.0, z_up + C * (flow - LIMIT)) - max(0.0, z_down + C * (-flow - LIMIT))


def test_a_settled_line_nets_its_two_prices():
    flows = [0.3, 0.3 + 0.05 * NET_SETTLED * 0.7]  # the second moved 5 % of what settles
    found = Recording(5.0, 7.0).rounds(flows)
    first = plain(5.0, 7.0, flows[0])  # moved unknown: not settled yet
    stepped = plain(*first, flows[1])
    expected = netted(*stepped, flows[1])
    assert found == pytest.approx(expected, rel=1e-12)
    f = flows[1]
    after = (found[0] + C * (f - LIMIT), found[1] + C * (-f - LIMIT))
    assert min(after) == pytest.approx(0.0, abs=1e-12)  # one multiplier left
    assert sum(found) < sum(stepped)
    assert broadcast(*found, flows[1]) == pytest.approx(broadcast(*stepped, flows[1]), abs=1e-12)
    dual_term = [z_up * (flows[1] - LIMIT) + z_down * (-flows[1] - LIMIT)
                 for z_up, z_down in (stepped, found)]  # fmt: skip
    assert dual_term[1] > dual_term[0]


def _plain_rounds(z_up: float, z_down: float, flows: list[float]) -> tuple[float, float]:
    z = (z_up, z_down)
    for flow in flows:
        z = plain(*z, flow)
    return z


@pytest.mark.parametrize(
    "flows",
    [
        pytest.param([0.3, 0.3 + 2 * NET_SETTLED * 0.7], id="moving"),
        pytest.param([1.2, 1.2], id="overflowing"),
        pytest.param([-1.0, -1.0], id="at-the-limit"),
        pytest.param([0.0, 0.0], id="one-multiplier-zero"),
    ],
)
def test_a_line_that_has_not_settled_inside_keeps_both_prices(flows):
    """Moving by more than ``NET_SETTLED`` of the slack, overflowing, at a limit (no slack), or
    one direction's multiplier zero at the flow (``z_down + C (-f - U) < 0``: netting would
    change the broadcast): the plain steps only."""
    z_down = 1.5 if flows[0] == 0.0 else 7.0
    found = Recording(5.0, z_down).rounds(flows)
    assert found == pytest.approx(_plain_rounds(5.0, z_down, flows), rel=1e-12)


def test_a_controller_that_does_not_net_keeps_both_prices():
    flows = [0.3, 0.3]
    found = Recording(5.0, 7.0, net=False).rounds(flows)
    assert found == pytest.approx(_plain_rounds(5.0, 7.0, flows), rel=1e-12)


#: MATPOWER's case33bw with a drawn fleet (three linear generators) and line 20-21 limited to
#: 9.682 kW: after an early swing both prices of the line stayed positive (16.6 and 17.1
#: EUR/MWh) while the flow sat near 0, decaying together at alpha U for 120 rounds.
FLEET33 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,src,35.6793621,0,0,7430
21,g0,24.6266927,27.8653965,0,770.396917
9,g1,14.2756527,66.3793263,186.093693,386.825323
6,g2,47.7912391,0,221.590269,1101.32671
25,g3,46.4616028,0,0,418.249966
"""


@pytest.mark.parametrize("graph", ["complete", "ring"])
def test_a_small_limit_with_both_prices_positive_in_under_200_rounds(tmp_path, graph):
    """The drawn case33bw fleet reaches the DC-OPF in at most 200 rounds (231 on the complete
    graph without the netting)."""
    out, opf, setpoints = agents_on_a_matpower_fleet(
        tmp_path, "case33bw", FLEET33, (20, 21, 9.682), graph
    )
    assert abs(opf.line_price[0]) > 0.1  # the line binds at the optimum (EUR/MWh)
    assert_converged_on_the_dc_opf(out, opf, setpoints, 200)
