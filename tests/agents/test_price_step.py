"""With the local step on the complete graph the round step is set by the coupling between
generators alone, ``h = 1.5 / (gain D S / P)``, and each line price integrates at its own step:
its rate capped at ``C / (2 h)``, so that a round moves it by at most half its proportional
part, the step the price loop's bound gave the whole round before. On a ring, and where a
generator lies below two limited lines, both stay as they were. The rates and steps are
computed here by hand from the fleet; on a drawn case17me fleet the agents now reach the DC-OPF
(Clarabel) in at most 100 rounds (141 before, and the price step without the generators'
memory of a priced line oscillated across the line's band for 1500 rounds). Under the scaled
price law each generator's own factor counts each line above it at that line's own
proportional weight ``C_k`` (a drawn case94pi fleet, whose factors counted the game's ``C``,
oscillated for 1500 rounds at the larger step)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.population import build_agents, default_step  # noqa: E402
from popdispatch.modes.exact import ExactConstants  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402

from helpers import (  # noqa: E402
    FLEET17,
    agents_on_a_matpower_fleet,
    assert_converged_on_the_dc_opf,
    random_fleet_problem,
)

SMITH = RunSettings(mode="exact")
SCALED = RunSettings(mode="exact", exact=ExactConstants(price_law="scaled"))

#: MATPOWER's case94pi with a drawn fleet; line 22-87 limited to 43.93 kW binds.
FLEET94 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,src,31.3044064,0.0977561018,0,9594
44,g0,7.92112248,0.034174015,259.677951,1419.6121
20,g1,33.8179034,0.433498819,43.7424927,321.890255
87,g2,42.297419,0,0,579.44289
61,g3,13.8912892,0.192640725,0,1206.86396
"""
RING = RunSettings(mode="exact", dynamics="distributed-smith", graph="ring")


def coupling_rate(problem, settings) -> float:
    """``gain D S / P`` (1/s): ``S`` the spread of marginal costs over the generators' ranges
    (EUR/MWh), ``P`` = ``D`` the demand (MW), ``gain`` the game's revision gain."""
    top = (problem.b + 2 * problem.c * problem.pmax).max()
    bottom = (problem.b + 2 * problem.c * problem.pmin).min()
    return settings.game_constants(problem).gain * (top - bottom)


def line_constants(system) -> list[tuple[float, float]]:
    """Each controller line end's ``(C, alpha)`` as its price map holds them."""
    return [(float(e.price.params.C), float(e.price.params.price_rate))
            for c in system.controllers.values() for e in c.ends]  # fmt: skip


def nested(problem) -> bool:
    """Whether a generator lies below two limited lines (walked up the feeder by hand)."""
    for line in problem.generator_line:
        count, k = 0, int(line)
        while k >= 0:
            count, k = count + 1, int(problem.line_up[k])
        if count > 1:
            return True
    return False


@pytest.mark.parametrize("seed", range(8))
def test_the_complete_graph_round_step_is_the_coupling_bound(seed):
    """Unless limited lines are nested: then, as on a ring, the price loop may bind."""
    problem = random_fleet_problem(seed, 5, 2)
    assert len(problem.limit)
    h = default_step(problem, SMITH, 1, local=True)
    if nested(problem):
        assert h <= 1.5 / coupling_rate(problem, SMITH) * (1 + 1e-9)
        assert h == default_step(problem, RING, 1, local=True)
    else:
        assert h == pytest.approx(1.5 / coupling_rate(problem, SMITH), rel=1e-9)
    ring = default_step(problem, RING, 1, local=True)
    assert ring <= 1.5 / coupling_rate(problem, RING) * (1 + 1e-9)  # the price loop may bind


@pytest.mark.parametrize("seed", range(8))
def test_each_price_rate_is_capped_at_half_its_weight_per_round(seed):
    """Capped on the complete graph without nested lines; the plain rates otherwise."""
    problem = random_fleet_problem(seed, 5, 2)
    h = default_step(problem, SMITH, 1, local=True)
    plain = line_constants(build_agents(problem, 1, SMITH, h, Faults(), local_step=False))
    local = line_constants(build_agents(problem, 1, SMITH, h, Faults(), local_step=True))
    assert len(plain) == len(local) > 0
    for (C, alpha), (C_local, alpha_local) in zip(plain, local, strict=True):
        assert C_local == C
        capped = alpha if nested(problem) else min(alpha, C / (2 * h))
        assert alpha_local == pytest.approx(capped, rel=1e-12)
    ring = line_constants(build_agents(problem, 1, RING, h, Faults(), local_step=True))
    assert ring == line_constants(build_agents(problem, 1, RING, h, Faults(), local_step=False))


def test_a_drawn_fleet_reaches_the_dc_opf_in_100_rounds(tmp_path):
    """The case17me fleet with line 16-17 limited, on the complete graph."""
    out, opf, setpoints = agents_on_a_matpower_fleet(
        tmp_path, "case17me", FLEET17, (16, 17, 714.7), "complete"
    )
    assert abs(opf.line_price[0]) > 1.0  # the line binds at the optimum (EUR/MWh)
    assert_converged_on_the_dc_opf(out, opf, setpoints, 100)


@pytest.mark.parametrize("seed", range(8))
def test_each_generator_counts_its_lines_at_their_own_weight(seed):
    """Under the scaled law ``C_k`` differs from line to line: under the prices' own step each
    generator's slopes are half the weights of the lines above it, as their controllers hold
    them, and it keeps counting a line for 10 rounds after its price; otherwise half the
    game's ``C`` and only while priced."""
    problem = random_fleet_problem(seed, 5, 2)
    system = build_agents(problem, 1, SCALED, 1e-3, Faults(), local_step=True)
    weight = {e.line: float(e.price.params.C) for c in system.controllers.values()
              for e in c.ends}  # fmt: skip
    game_C = float(SCALED.game_constants(problem).C)
    assert any(w > game_C * (1 + 1e-9) for w in weight.values())  # sqrt(s_k) > 1 somewhere
    for generator in system.generators:
        rule = generator.rule
        if nested(problem):
            assert rule.price_slopes == tuple(0.5 * game_C for _ in rule.lines_above)
            assert rule.priced_memory == 0
        else:
            assert rule.price_slopes == tuple(0.5 * weight[k] for k in rule.lines_above)
            assert rule.priced_memory == 10
    ring_C = float(RING.game_constants(problem).C)
    for generator in build_agents(problem, 1, RING, 1e-3, Faults(), local_step=True).generators:
        rule = generator.rule
        assert rule.price_slopes == tuple(0.5 * ring_C for _ in rule.lines_above)
        assert rule.priced_memory == 0


def test_a_nearly_linear_dg_below_a_line_is_not_freed_while_the_flow_is_inside():
    """A random 4-DG fleet whose one DG below the limited line is nearly linear: with a
    memory of 5 rounds it was freed while the flow crept toward the limit inside the band,
    dropped its whole output in one round and cycled for 1500 rounds (41 rounds before the
    prices took their own step)."""
    from popdispatch.agents.system import AgentSettings, run_agents
    from popdispatch.opf import solve_opf

    problem = random_fleet_problem(1032, 4, 1, linear_share=0.6)
    opf = solve_opf(problem, 1)
    assert abs(opf.line_price[0]) > 0.5  # the line binds at the optimum (EUR/MWh)
    run = run_agents(problem, 1, SMITH, Faults(), AgentSettings(max_rounds=600))
    assert run.status == "converged" and run.rounds <= 100, (run.status, run.rounds)
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= run.accuracy_kw


def test_a_drawn_fleet_under_the_scaled_law_reaches_the_dc_opf(tmp_path):
    """The case94pi fleet with line 22-87 limited, on the complete graph, scaled law."""
    out, opf, setpoints = agents_on_a_matpower_fleet(
        tmp_path, "case94pi", FLEET94, (22, 87, 43.93), "complete", "--price-law", "scaled"
    )
    assert abs(opf.line_price[0]) > 1.0  # the line binds at the optimum (EUR/MWh)
    assert_converged_on_the_dc_opf(out, opf, setpoints, 100)
