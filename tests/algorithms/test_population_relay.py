"""The relay of distributed Smith by messages (``popdispatch compare``'s runtime,
algorithms/population.py) sends what the engine's relay defines: within each relay group every
DG sends to every better receiver of the group at ``w_b v_a [f_b - f_a]_+``, on top of the
direct flow to a neighbour, the flow shared among the receivers. The yardstick is the plain
networkx/numpy statement of the field (:mod:`popdispatch.reference`: the weights, their
neighbourhood normalisation and ``relay_matrix``), at the state the DGs report."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest

from popdispatch.algorithms import SmithParams
from popdispatch.algorithms.base import Minute
from popdispatch.algorithms.network import Network
from popdispatch.algorithms.population import PopulationDynamics
from popdispatch.dynamics.newton import reference_local
from popdispatch.reference import relay_matrix, slow_members, weights

from helpers import random_limited_problem


def _state_at_pmax(minute: Minute, blocked: list[int]) -> np.ndarray | None:
    """Set points (MW) summing to the demand with the DGs ``blocked`` at their Pmax and every
    other DG at the same fraction of its range, well inside it (None if the demand does not
    allow it)."""
    lo, hi, demand = minute.lo, minute.hi, minute.demand
    others = ~np.isin(np.arange(len(lo)), blocked)
    rest = demand - hi[blocked].sum() - lo[others].sum()
    t = rest / (hi[others] - lo[others]).sum()
    if not 0.1 < t < 0.9:
        return None
    p = lo + t * (hi - lo)
    p[blocked] = hi[blocked]
    return p


def _transfers_at(problem, p: np.ndarray) -> tuple[PopulationDynamics, dict]:
    """The MW each DG sends each other one in the first round whose reports and relay
    announcements all describe set points ``p`` (transfers recorded, not made, so ``p``
    holds), by (sender, receiver)."""
    algorithm = PopulationDynamics(Minute.of(problem, 1), Network(),
                                   SmithParams(step=1e-6, graph="ring"))  # fmt: skip
    algorithm.p[:] = p
    sent: dict = defaultdict(float)

    def record(i, j, amount, round_, via=()):
        sent[i, j] += amount

    algorithm._send_transfer = record
    algorithm.exchange(0)
    for r in range(1, 8):  # by round 5 every report and announcement heard describes p
        algorithm.local_update(algorithm.net.deliver(r), r)
        sent.clear()
        algorithm.exchange(r)
    return algorithm, sent


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("chain", [1, 2])
def test_the_message_relay_sends_the_engines_relay_flows(seed, chain):
    """``chain`` neighbours on the ring at their Pmax: one relay, or a route through two."""
    rng = np.random.default_rng(seed)
    problem = random_limited_problem(rng, 18, 7, 0)
    minute = Minute.of(problem, 1)
    runs = [[(k + e) % 7 for e in range(chain)] for k in range(7)]
    candidates = [(run, _state_at_pmax(minute, run)) for run in runs]
    blocked, p = next(((k, s) for k, s in candidates if s is not None), (None, None))
    if p is None:
        pytest.skip("no DGs can sit at their Pmax with the others inside their ranges")
    algorithm, sent = _transfers_at(problem, p)
    demand, graph, rate = minute.demand, algorithm.graph, algorithm.rate
    f = algorithm.own[:, 0]  # the fitness each DG reports
    w, v, room, mass = weights(algorithm.field, p / demand, f, minute.lo / demand,
                               minute.hi / demand, minute.hi > minute.lo, rate)  # fmt: skip
    w, v = reference_local(graph, rate, w, v, room, mass)
    direct = graph * w[:, None] * v[None, :] * np.maximum(f[:, None] - f[None, :], 0.0)
    T = direct + relay_matrix(f, w, v, graph, mass, room, slow_members(rate, graph))
    expected = algorithm.h * demand * T.T  # [sender, receiver], MW
    assert np.all(algorithm.own[blocked, 3] == 1.0)  # the DGs at Pmax relay
    relayed = [(a, b) for a in range(7) for b in range(7) if graph[a, b] == 0 and a != b]
    assert any(expected[a, b] > 0 for a, b in relayed)  # the relay carries something
    got = np.zeros_like(expected)
    for (a, b), amount in sent.items():
        got[a, b] = amount
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12 * demand)
