"""The one message counter: exchanges counted by hand equal the counter; faults do what they
say (loss, duplicates, delays, a crash)."""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.algorithms import Faults, Network, RunOptions, run_algorithm
from popdispatch.algorithms.network import HEADER_BYTES, SCALAR_BYTES
from popdispatch.scenarios import elv_problem


def test_two_agents_counted_by_hand():
    net = Network()
    net.send("A", "B", "offer", [1.0, 2.0], reveals="set point")
    net.send("B", "A", "ack", [3.0])
    c = net.counters
    assert (c.messages, c.scalars) == (2, 3)
    assert c.bytes == 2 * 16 + 3 * 8 == 2 * HEADER_BYTES + 3 * SCALAR_BYTES
    assert dict(c.sent_by) == {"A": 1, "B": 1}
    assert c.partners["A"] == {"B"} and c.partners["B"] == {"A"}
    assert dict(c.reveals) == {"A": {"set point"}}
    assert net.deliver(1)["B"][0].values == (1.0, 2.0)  # sent in round 0, due in round 1


def test_a_relayed_message_is_one_message_per_hop():
    net = Network()
    net.send("A", "C", "transfer", [5.0], via=("B",))
    assert (net.counters.messages, net.counters.bytes) == (2, 2 * (16 + 8))
    assert not net.deliver(1)
    assert net.deliver(2)["C"][0].via == ("B",)


def test_loss_duplicates_and_delays_are_accounted():
    net = Network(Faults(loss=0.3, duplicate=0.2, delay_max=3, seed=4))
    for _ in range(4000):
        net.send("A", "B", "x", [0.0])
    delivered = sum(len(net.deliver(r).get("B", [])) for r in range(1, 8))
    c = net.counters
    assert c.messages == 4000
    assert 0.27 < c.lost / 4000 < 0.33
    assert delivered == 4000 - c.lost + c.duplicated
    assert 0.17 < c.duplicated / (4000 - c.lost) < 0.23


def test_a_crashed_agent_sends_and_receives_nothing():
    net = Network(Faults(crash=("B", 2)))
    net.deliver(2)
    net.send("B", "A", "x", [1.0])
    net.send("A", "B", "x", [1.0])
    assert net.counters.sent_by == {"A": 1}
    assert not net.deliver(3)


@pytest.mark.parametrize("name", ["dual-decomposition", "admm"])
def test_runs_counted_by_hand(name):
    """The ELV minute 566 without limits, 6 DGs, one zone and no node controller: dual
    decomposition sends 6 cost curves (to the coordinator), then the coordinator's price to
    each DG in every round 0..R; ADMM 6 cost curves (to the zone's holder), then in every
    round 0..R either 6 terminal powers (even rounds) or 6 (pbar, u, rho) (odd rounds)."""
    rounds = 20
    run = run_algorithm(name, elv_problem(), 566, options=RunOptions(max_rounds=rounds,
                                                                     hold=10**6))  # fmt: skip
    assert run.rounds == rounds
    assert run.messages[-1] == 6 + 6 * (rounds + 1)
    curves = 6 * 4
    per_round = 6 * 1 if name == "dual-decomposition" else None
    if per_round:
        assert run.scalars[-1] == curves + per_round * (rounds + 1)
    else:  # 11 even rounds of 1 scalar, 10 odd rounds of 3
        assert run.scalars[-1] == curves + 6 * 11 + 6 * 3 * 10
    assert run.bytes == 16 * run.messages[-1] + 8 * run.scalars[-1]
    assert run.agents == 7 and run.partners_max == 6
    assert np.isclose(run.messages_per_agent_round, run.messages[-1] / (7 * rounds))
