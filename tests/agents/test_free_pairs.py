"""With the local step, a pair of *free* generators (linear cost, no limited line above either)
trades as much as the flux limiter lets it in one round: such a pair's gap is the difference
of two constant marginal costs, which no trade closes and no other generator's fitness feels,
and the plain step moved the power at a constant crawl. The scaling is checked here against
the sender's movable mass by hand, a generator that is not free is left alone, and on a drawn
case94pi fleet (two linear DGs 0.17 EUR/MWh apart, 586 kW to move, no limit) the agents reach
the DC-OPF (Clarabel) in at most 30 rounds on the complete graph (200 before) and 100 on the
ring."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.messages import Status  # noqa: E402
from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.population import build_agents  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402

from helpers import (  # noqa: E402
    agents_on_a_matpower_fleet,
    assert_converged_on_the_dc_opf,
    random_fleet_problem,
)

#: MATPOWER's case94pi with a drawn fleet and no limit: the source and g1 are linear, 0.17
#: EUR/MWh apart, and g1 must fall from its Pmax to its Pmin.
FLEET94 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,src,45.6374581,0,0,9594
6,g0,46.891083,858.114633,0,1085.63937
25,g1,45.8077047,0,51.571106,637.283571
24,g2,25.8472376,10.5880225,0,540.576987
"""


def free_generator(seed: int):
    """A generator of a random fleet made linear and free of limited lines (the fleet drawn
    without limits), with its step."""
    problem = random_fleet_problem(seed, 4, 0)
    problem.c[0] = 0.0
    system = build_agents(problem, 1, RunSettings(mode="exact"), 1e-3, Faults(),
                          local_step=True)  # fmt: skip
    return system.generators[0]


def status(f: float, free: bool) -> Status:
    return Status(1, f, 0.0, 0.0, free=free)


@pytest.mark.parametrize("seed", range(4))
def test_free_pairs_are_scaled_to_empty_the_movable_mass(seed):
    generator = free_generator(seed)
    assert generator.rule.free
    rng = np.random.default_rng(seed)
    known = [status(10.0, True), status(10.5, True), status(11.0, False), status(9.0, True)]
    f = np.array([9.5, *(s.f for s in known)])  # the worse free neighbour (9.0) is no receiver
    w = rng.uniform(0.1, 1.0, 5)
    before = w.copy()
    v0, mass0, h = 0.7, 0.02, generator.rule.step_s
    generator._free_pairs(f, w, v0, mass0, known)
    free = np.array([False, True, True, False, False])
    assert h * v0 * np.sum(w[free] * (f[free] - f[0])) == pytest.approx(mass0, rel=1e-12)
    ratio = w[free] / before[free]
    assert ratio[0] == pytest.approx(ratio[1], rel=1e-12) and ratio[0] > 1.0  # one factor
    assert np.array_equal(w[~free], before[~free])


def test_a_pair_that_already_empties_the_mass_or_ties_is_left_alone():
    generator = free_generator(0)
    known = [status(10.0, True)]
    w = np.array([0.5, 0.5])
    generator._free_pairs(np.array([9.0, 10.0]), w, 1.0, 1e-9, known)  # mass already covered
    assert np.array_equal(w, [0.5, 0.5])
    generator._free_pairs(np.array([10.0, 10.0]), w, 1.0, 0.02, known)  # a tie: no gap
    assert np.array_equal(w, [0.5, 0.5])


@pytest.mark.parametrize("seed", range(4))
def test_a_generator_below_a_limited_line_or_with_a_curve_is_not_free(seed):
    problem = random_fleet_problem(seed, 5, 2)
    system = build_agents(problem, 1, RunSettings(mode="exact"), 1e-3, Faults(),
                          local_step=True)  # fmt: skip
    for generator in system.generators:
        rule = generator.rule
        assert rule.free == (rule.c == 0.0 and not rule.lines_above)
    plain = build_agents(problem, 1, RunSettings(mode="exact"), 1e-3, Faults())
    assert not any(g.rule.free for g in plain.generators)  # without the local step


@pytest.mark.parametrize("graph, most", [("complete", 30), ("ring", 100)])
def test_two_linear_dgs_close_their_gap_in_a_few_rounds(tmp_path, graph, most):
    out, opf, setpoints = agents_on_a_matpower_fleet(tmp_path, "case94pi", FLEET94, None, graph)
    assert_converged_on_the_dc_opf(out, opf, setpoints, most)
