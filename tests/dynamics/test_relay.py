"""The relay of distributed Smith (docs/agents.md, "the relay"): the compiled flows against a
plain networkx/numpy reference, and exact-mode distributed Smith on any connected graph landing
on the DC-OPF (solve_opf, Clarabel) within 0.001 kW."""

from __future__ import annotations

from dataclasses import replace

import networkx as nx
import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import sparse

from popdispatch.dynamics.pairwise import RELAY_MASS, graph_flows, relay_flows, slow_relays
from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

from helpers import random_limited_problem
from qp_exact import exact_dc_opf

#: Set points within this of the DC-OPF (issue 15), kW.
OPF_ATOL_KW = 1e-3


def nobody(n: int) -> np.ndarray:
    """No strategy relays by rate."""
    return np.zeros(n, dtype=bool)


def margin(mass: float, room: float) -> float:
    """Room or movable mass (shares) at or below which a strategy relays: 1e-3 of its range
    ``mass + room``, at least ``RELAY_MASS``; ``RELAY_MASS`` where the room is unbounded."""
    return RELAY_MASS if np.isinf(room) else max(RELAY_MASS, 1e-3 * (mass + room))


def reference_relay(f, w, v, graph: nx.Graph, slow=None, room=None):
    """``(inflow, outflow)`` of the relay by its definition: the connected sets ``S``
    (networkx) of the blocked strategies (offline, or movable mass ``v`` or ``room`` within
    :func:`margin`) and those that relay by rate (``slow``), their groups ``S + N(S)``, and
    within each group ``w_b v_a [f_b - f_a]_+`` from every member ``a`` to every member ``b``
    with ``w_b > 0`` and room above ``RELAY_MASS``."""
    n = len(f)
    slow = nobody(n) if slow is None else slow
    room = np.full(n, np.inf) if room is None else room
    blocked = [k for k in range(n) if slow[k] or not (
        w[k] > 0 and v[k] > margin(v[k], room[k]) and room[k] > margin(v[k], room[k]))]
    flows = np.zeros((n, n))  # [receiver, sender]
    for members in nx.connected_components(graph.subgraph(blocked)):
        group = set(members) | {b for k in members for b in graph.neighbors(k)}
        for b in group:
            if w[b] > 0 and room[b] > RELAY_MASS:
                for a in group:
                    flows[b, a] += w[b] * v[a] * max(f[b] - f[a], 0.0)
    return flows.sum(axis=1), flows.sum(axis=0)


@st.composite
def connected_graphs(draw, min_n: int = 2, max_n: int = 12) -> nx.Graph:
    """Trees, rings, paths, stars and random connected graphs on ``0..n-1``."""
    n = draw(st.integers(min_n, max_n))
    kind = draw(st.sampled_from(["tree", "ring", "path", "star", "random"]))
    seed = draw(st.integers(0, 2**31))
    rng = np.random.default_rng(seed)
    if kind == "ring" and n >= 3:
        graph = nx.cycle_graph(n)
    elif kind == "star":
        graph = nx.star_graph(n - 1)
    elif kind in ("tree", "random"):
        graph = nx.Graph()
        graph.add_nodes_from(range(n))
        graph.add_edges_from((i, int(rng.integers(0, i))) for i in range(1, n))
        if kind == "random":
            for a, b in rng.integers(0, n, size=(n, 2)):
                if a != b:
                    graph.add_edge(int(a), int(b))
    else:
        graph = nx.path_graph(n)
    order = rng.permutation(n)  # generators in any position of the graph
    return nx.relabel_nodes(graph, {i: int(order[i]) for i in range(n)})


def csr(graph: nx.Graph, n: int):
    matrix = sparse.csr_matrix(nx.to_numpy_array(graph, nodelist=range(n), weight=None))
    return matrix.indptr.astype(np.int64), matrix.indices.astype(np.int64)


@settings(max_examples=300, deadline=None)
@given(graph=connected_graphs(), seed=st.integers(0, 2**31))
def test_compiled_relay_equals_the_reference(graph, seed):
    rng = np.random.default_rng(seed)
    n = graph.number_of_nodes()
    f = rng.normal(size=n).round(1)  # ties too
    w = np.where(rng.random(n) < 0.4, 0.0, 1.0)
    v = np.where(rng.random(n) < 0.3, rng.choice([0.0, RELAY_MASS / 2], n), rng.random(n))
    slow = rng.random(n) < 0.2
    # unbounded room (the paper's fields) or room from far to within 1e-3 of the range
    room = np.where(rng.random(n) < 0.3, np.inf,
                    v * rng.choice([0.0, 1e-4, 9e-4, 1.1e-3, 0.5, 10.0], n))  # fmt: skip
    indptr, indices = csr(graph, n)
    inflow, outflow = np.zeros(n), np.zeros(n)
    relay_flows(f, w, v, v, room, slow, indptr, indices, np.empty(n, dtype=np.int64), inflow,
                outflow)  # fmt: skip
    ref_in, ref_out = reference_relay(f, w, v, graph, slow, room)
    np.testing.assert_allclose(inflow, ref_in, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(outflow, ref_out, rtol=1e-12, atol=1e-15)


def test_the_only_path_to_the_source_through_a_filling_generator():
    """A benchmark fleet (case16am's fleet of the fleet benchmark, run 205) on a path feeder:
    the source reaches the others only through g0, a linear generator whose optimum is its
    Pmax. Relaying only from its last ``RELAY_MASS`` of room (2.9 W) g0 held the rest behind
    it for 224 iterations (5.7 MW from the DC-OPF for 212); relaying from 1e-3 of its range
    it opens the path while it fills, within the 200 iterations exact mode promises."""
    problem = only_path_fleet()
    graph = nx.Graph([("g0", "g1"), ("g0", "g2"), ("g1", "g2"), ("g1", "g3"), ("src", "g0")])
    run = run_snapshot(problem, 1, RunSettings(mode="exact", dynamics="distributed-smith",
                                               graph=graph))  # fmt: skip
    optimum_kw = exact_dc_opf(problem) * 1e3
    assert run.status == "converged", run.stall_reason
    assert run.iterations <= 200
    assert np.abs(run.setpoints_kw - optimum_kw).max() <= run.accuracy_kw
    assert optimum_kw[1] == pytest.approx(problem.pmax[1] * 1e3)  # g0 at its Pmax


def only_path_fleet():
    """The fleet of :func:`test_the_only_path_to_the_source_through_a_filling_generator` on
    a six-bus path, 28.7 MW of load at its end, no line limit."""
    rows = [(1, 0.0, 32.531470562325325, 0.9794055249247405, 0.0, 57400.0),
            (2, 0.0, 51.140866643180416, 0.0, 0.0, 2523.5752818184137),
            (3, 0.0, 40.36367903604952, 0.14436347967587884, 0.0, 4870.213659085953),
            (4, 0.0, 24.398326046001586, 1007.7760321845767, 0.0, 8508.625702037469),
            (5, 0.0, 43.62929087986328, 0.08656632872487255, 1945.3836306748651,
             6114.087331828889)]  # fmt: skip
    buses = pd.DataFrame({"x": np.arange(6.0), "y": 0.0},
                         index=pd.Index(np.arange(1, 7), name="bus"))  # fmt: skip
    lines = pd.DataFrame({"from_bus": np.arange(1, 6), "to_bus": np.arange(2, 7),
                          "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001,
                          "limit_kw": np.inf},
                         index=pd.Index([f"L{i}" for i in range(2, 7)], name="line"))  # fmt: skip
    loads = pd.DataFrame({"bus": [6]}, index=pd.Index(["LD6"], name="load"))
    fleet = make_fleet(rows, names=["src", "g0", "g1", "g2", "g3"])
    feeder = Feeder("only path", buses, lines, loads, 1, fleet)
    load = pd.Series([28700.0], index=loads.index)
    return build_problem(reduce_feeder(feeder), single_minute_profiles(1, load, "fleet"))


def test_no_blocked_strategy_leaves_the_graph_flows_alone():
    """Interior everywhere: the relay adds nothing (bitwise the pairwise flows alone)."""
    rng = np.random.default_rng(3)
    n = 9
    graph = nx.cycle_graph(n)
    f, w, v = rng.normal(size=n), np.ones(n), rng.uniform(0.1, 1.0, n)
    indptr, indices = csr(graph, n)
    inflow, outflow = np.zeros(n), np.zeros(n)
    graph_flows(f, w, v, indptr, indices, inflow, outflow)
    before = inflow.copy(), outflow.copy()
    no_limit = np.full(len(f), np.inf)
    relay_flows(f, w, v, v, no_limit, nobody(n), indptr, indices, np.empty(n, dtype=np.int64),
                inflow, outflow)  # fmt: skip
    assert np.array_equal(inflow, before[0]) and np.array_equal(outflow, before[1])


def test_a_saturated_chain_relays_between_its_ends():
    """Path 0-1-2-3: 1 and 2 at their upper limit (w = 0, v > 0) between a dear sender 0 and a
    cheap receiver 3: the direct flows never reach 3; the relay moves ``w_3 v_0 (f_3 - f_0)``."""
    f = np.array([1.0, 5.0, 6.0, 4.0])
    w = np.array([1.0, 0.0, 0.0, 1.0])
    v = np.array([0.5, 0.2, 0.3, 0.1])
    indptr, indices = csr(nx.path_graph(4), 4)
    inflow, outflow = np.zeros(4), np.zeros(4)
    no_limit = np.full(len(f), np.inf)
    relay_flows(f, w, v, v, no_limit, nobody(4), indptr, indices, np.empty(4, dtype=np.int64),
                inflow, outflow)  # fmt: skip
    # group {1, 2} + {0, 3}: best receiver 3 (0 is worse); 0 sends 3 * 0.5, 1 and 2 are better
    np.testing.assert_array_equal(inflow, [0.0, 0.0, 0.0, 1.5])
    np.testing.assert_array_equal(outflow, [1.5, 0.0, 0.0, 0.0])


def random_problem(seed: int, n_gens: int, n_limits: int):
    """A random radial feeder (tests/helpers.py) with up to ``n_limits`` limited paths."""
    rng = np.random.default_rng(seed)
    return random_limited_problem(rng, int(rng.integers(max(4, n_gens), 25)), n_gens, n_limits)


def reduced_cost_margin(problem, opf) -> float:
    """Smallest |reduced cost| (EUR/MW) of a generator at a limit in the DC-OPF (Clarabel's
    duals): near zero, the dynamics leave the limit at a speed proportional to it."""
    p_kw = opf.p_kw
    reduced = (
        problem.b + 2.0 * problem.c * p_kw / 1000.0 - opf.marginal_price
        - problem.down.T @ opf.line_price
    )  # fmt: skip
    at_limit = (p_kw <= problem.pmin * 1000 + 1e-6) | (p_kw >= problem.pmax * 1000 - 1e-6)
    return float(np.abs(reduced[at_limit]).min(initial=np.inf))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(graph=connected_graphs(min_n=2, max_n=7), seed=st.integers(0, 2**31),
       n_limits=st.integers(0, 2))  # fmt: skip
def test_distributed_smith_reaches_the_dc_opf_on_any_connected_graph(graph, seed, n_limits):
    n = graph.number_of_nodes()
    problem = random_problem(seed, n, n_limits)
    opf = solve_opf(problem, 1)
    if opf.status == "infeasible":
        return
    integrator = replace(RunSettings(mode="exact").stepping, window=20, max_iterations=60000)
    graph = nx.relabel_nodes(graph, dict(enumerate(problem.generators)))
    settings_ = RunSettings(mode="exact", dynamics="distributed-smith", graph=graph,
                            integrator=integrator)  # fmt: skip
    run = run_snapshot(problem, 1, settings_)
    error = np.abs(run.setpoints_kw - opf.p_kw).max()
    assert run.status in ("converged", "not_converged"), (run.stall_reason, sorted(graph.edges))
    if reduced_cost_margin(problem, opf) >= 0.02:
        assert error <= OPF_ATOL_KW


@pytest.mark.parametrize("graph", ["ring", "path"])
def test_the_congestion_minute_on_a_ring_or_path_reaches_the_dc_opf(graph):
    """Minute 566, 505-666 at 28 kW: without the relay distributed Smith rested 0.78 kW away
    (G1 at Pmax, G739 interior, the generators between them at Pmax)."""
    problem = elv_problem(limits=[CONGESTION_PATH])
    settings_ = RunSettings(mode="exact", dynamics="distributed-smith", graph=graph)
    run = run_snapshot(problem, PEAK_MINUTE, settings_)
    assert run.status == "converged"
    assert np.abs(run.setpoints_kw - solve_opf(problem, PEAK_MINUTE).p_kw).max() <= OPF_ATOL_KW


def test_the_relay_is_continuous_where_two_receivers_tie():
    """Star around a blocked centre 0 (at its upper limit): a dear sender 1 and two receivers
    2, 3 whose fitness cross. Every flow moves by O(eps) when ``f_3`` passes ``f_2`` by eps
    (sending to the best receiver alone moved sender 1's whole relayed flow from 2 to 3)."""
    graph = nx.star_graph(3)
    indptr, indices = csr(graph, 4)
    w = np.array([0.0, 1.0, 2.0, 0.5])
    v = np.array([0.4, 0.6, 0.3, 0.2])
    no_limit = np.full(4, np.inf)

    def flows(f3):
        f = np.array([9.0, 1.0, 3.0, f3])
        inflow, outflow = np.zeros(4), np.zeros(4)
        relay_flows(f, w, v, v, no_limit, nobody(4), indptr, indices,
                    np.empty(4, dtype=np.int64), inflow, outflow)  # fmt: skip
        return inflow, outflow

    eps = 1e-9
    below, above = flows(3.0 - eps), flows(3.0 + eps)
    np.testing.assert_allclose(below[0], above[0], rtol=0, atol=10 * eps)
    np.testing.assert_allclose(below[1], above[1], rtol=0, atol=10 * eps)
    # at the tie sender 1 sends to both: w_2 v_1 2 + w_3 v_1 2
    np.testing.assert_allclose(flows(3.0)[1][1], 2.0 * 0.6 * 2.0 + 0.5 * 0.6 * 2.0)


def test_a_generator_ten_times_slower_than_a_neighbour_relays_by_rate():
    """Path 0-1-2-3 with rates 10, 0.5, 10, 0.99: 1 is below a tenth of its fastest neighbour
    (1.0); 3 (0.99 against 10) too; 0 and 2 are not."""
    indptr, indices = csr(nx.path_graph(4), 4)
    np.testing.assert_array_equal(slow_relays(np.array([10.0, 0.5, 10.0, 0.99]), indptr, indices),
                                  [False, True, False, True])  # fmt: skip
    assert not slow_relays(np.full(4, 3.0), indptr, indices).any()


def test_a_generator_slow_by_either_of_its_rates_relays():
    """Where the rates in force move between the priced and the idle ones, a generator slow
    by either relays: path 0-1-2, priced rates (10, 0.5, 10) make 1 slow, idle rates (1, 20,
    10) make 0 slow (1 against 20); with both, 0 and 1 relay. The complete graph has none."""
    from popdispatch.dynamics.pairwise import graph_of

    indptr, indices = csr(nx.path_graph(3), 3)
    priced, idle = np.array([10.0, 0.5, 10.0]), np.array([1.0, 20.0, 10.0])
    assert graph_of(False, indptr, indices, priced).slow.tolist() == [False, True, False]
    assert graph_of(False, indptr, indices, idle).slow.tolist() == [True, False, False]
    both = graph_of(False, indptr, indices, priced, idle_rate=idle)
    assert both.slow.tolist() == [True, True, False]
    assert graph_of(True, indptr, indices, priced, idle_rate=idle).slow.size == 0


def test_the_generators_a_line_holds_relay_in_exact_mode_on_a_sparse_graph():
    """Exact mode's engine relays, besides the generators slow by rate, every generator below
    a limited line (its ``generator_line``); paper mode none; the complete graph has no relay."""
    from popdispatch.modes import get_mode
    from popdispatch.online.engine import Engine

    problem = random_limited_problem(np.random.default_rng(7), 12, 6, 2)
    below = problem.generator_line >= 0
    assert below.any() and not below.all()
    np.testing.assert_array_equal(get_mode("exact").held_relays(problem), below)
    assert not get_mode("paper").held_relays(problem).any()
    ring = Engine(problem, RunSettings(mode="exact", dynamics="distributed-smith", graph="ring"))
    assert np.all(ring.term.graph.slow[below])
    paper = Engine(problem, RunSettings(mode="paper", dynamics="distributed-smith", graph="ring"))
    assert not paper.term.graph.slow.any()  # the paper's fields take no rates either
