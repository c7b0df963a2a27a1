"""The agents' message metrics (rounds, messages, scalars sent), counted by hand on tiny
feeders whose generators are at the optimum from the start, so that the only messages are
the ones every round sends whatever the dynamics."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.messages import Decision, Relayed, Signals, Status, scalars  # noqa: E402
from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents  # noqa: E402
from popdispatch.feeder.generators import make_fleet  # noqa: E402
from popdispatch.feeder.model import Feeder  # noqa: E402
from popdispatch.feeder.profiles import single_minute_profiles  # noqa: E402
from popdispatch.feeder.reduction import reduce_feeder  # noqa: E402
from popdispatch.game.problem import build_problem  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402


def twins(n_generators: int):
    """A path of ``n + 1`` buses, the load at its end, ``n`` generators of the same cost at
    the others (one each): uniform shares are the DC-OPF, every fitness equal, no offers."""
    n_buses = n_generators + 1
    buses = pd.DataFrame({"x": np.arange(n_buses, dtype=float), "y": 0.0},
                         index=pd.Index(np.arange(1, n_buses + 1), name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": np.arange(1, n_buses), "to_bus": np.arange(2, n_buses + 1),
         "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001, "limit_kw": np.inf},
        index=pd.Index([f"L{i}" for i in range(1, n_buses)], name="line"),
    )  # fmt: skip
    loads = pd.DataFrame({"bus": [n_buses]}, index=pd.Index(["LD"], name="load"))
    fleet = make_fleet([(bus, 0.0, 10.0, 0.01, 0.0, 20.0) for bus in range(1, n_buses)])
    feeder = Feeder("twins", buses, lines, loads, 1, fleet)
    load = pd.Series([6.0 * n_generators], index=loads.index)
    return build_problem(reduce_feeder(feeder), single_minute_profiles(1, load, "twins"))


def test_scalars_count_the_real_numbers_of_a_message():
    """Rounds, indices, flags and names are not counted; floats anywhere are."""
    assert scalars(Status(3, 1.0, 0.5, 0.25, 0.1, 0.2, 7)) == 5
    assert scalars(Signals(3, {"0": 2.0, "4": -1.0})) == 2
    assert scalars(Decision("a/3/b", True, 0.5, 4)) == 1
    assert scalars(Relayed("a", Status(3, 1.0, 0.5, 0.25), ("r",))) == 5
    assert scalars(Status(3, 1.0, 0.5, 0.25, 0.1, 0.2, 7, 0.9)) == 6  # with the step factor


def test_two_generators_exchange_one_status_each_per_round():
    """Complete graph of two, no limited line (no plant measurements, no controllers): each
    round each generator sends its status (f, w, v, mass, room and, with the local step, its
    step factor: 6 scalars) to the other."""
    problem = twins(2)
    run = run_agents(problem, 1, RunSettings(mode="exact"), Faults())
    assert run.status == "converged" and run.rounds > 0
    assert run.messages == 2 * run.rounds
    assert run.scalars_sent == 2 * 6 * run.rounds
    plain = run_agents(problem, 1, RunSettings(mode="exact"), Faults(),
                       AgentSettings(local_step=False))  # fmt: skip
    assert plain.scalars_sent == 2 * 5 * plain.rounds  # no step factor to send


def test_a_path_of_three_also_sends_standings():
    """A path graph of three (distributed Smith): each round the middle generator sends its
    standing (rate, room, mass: 3 scalars) and its status (6) to both ends, each end to the
    middle: 4 standings and 4 statuses, 36 scalars. The standings go out at a round's first
    tick, the plant's measurement, which also opens the round after the last one counted (the
    run stops at its measurement, when it is judged at rest): 4 more, 12 scalars."""
    problem = twins(3)
    settings = RunSettings(mode="exact", dynamics="distributed-smith", graph="path")
    run = run_agents(problem, 1, settings, Faults())
    assert run.status == "converged" and run.rounds > 0
    assert run.messages == 8 * run.rounds + 4
    assert run.scalars_sent == (4 * 3 + 4 * 6) * run.rounds + 4 * 3
