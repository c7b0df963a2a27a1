"""The population-game engine, faithful to the paper (issue: engine)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.dynamics import DYNAMICS, communication_graph, field_rate
from popdispatch.dynamics.fields import field_of
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem
from popdispatch.integrate import Integrator
from popdispatch.online import Engine, RunSettings, run_day, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.readers import read_profiles
from popdispatch.scenarios import congestion, elv_problem, extinction, snapshot_vs_opf

from helpers import official_folder, random_feeder


@pytest.fixture(scope="module")
def peak_problem():
    return elv_problem()


@pytest.fixture(scope="module")
def official_problem():
    return elv_problem(read_profiles(official_folder()))


def test_minute_566_smith_matches_dc_opf(peak_problem):
    result = snapshot_vs_opf(peak_problem, 566)
    assert result.opf.status == "optimal"
    np.testing.assert_allclose(result.opf.p_kw, [2.358, 10, 5, 10, 20, 10], atol=1e-3)
    assert result.run.converged_at is not None
    assert result.max_abs_error_kw < 0.1
    assert abs(result.run.setpoints_kw.sum() - 57.358) < 1e-6


def test_congestion_scenario():
    result = congestion()
    run, free = result.run, result.opf_unconstrained
    gens = list(run.generators)
    g739, g1 = gens.index("G739"), gens.index("G1")
    assert run.setpoints_kw[g739] < free.p_kw[g739] - 1.0  # penalized below its free optimum
    assert run.setpoints_kw[g1] > free.p_kw[g1] + 1.0  # raises its output to compensate
    assert run.first_congestion is not None
    assert run.converged_at is not None and run.converged_at <= 201
    assert run.overflow_kw.max() < 1.0
    assert run.overflow_kw.max() > 0.1  # the paper's proportional signal leaves a residual
    assert result.opf.status == "optimal"
    # the exact optimum moves the same way, further
    assert result.opf.p_kw[g739] < run.setpoints_kw[g739] < free.p_kw[g739]


def test_extinction_replicator_never_uses_zero_start_generator():
    result = extinction()
    gens = list(result.replicator.generators)
    k = gens.index(result.generator)
    assert np.all(result.replicator.trajectory_kw[:, k] == 0.0)
    # without the cheapest generator the others exceed their limits (barrier violated)
    assert result.replicator.setpoints_kw.max() > 0
    assert np.abs(result.smith.setpoints_kw - result.opf.p_kw).max() < 0.1
    assert result.smith.setpoints_kw[k] > 9.9


def graph_for(dynamics: str, sparse: str = "ring") -> str:
    """``sparse`` for dynamics that use a communication graph, else complete (RunSettings
    rejects a graph that would be ignored)."""
    return sparse if DYNAMICS[dynamics].uses_graph else "complete"


def eta_for(dynamics: str) -> float | None:
    """A noise level (EUR/MWh) for the dynamics that need one (logit), else None."""
    return 0.1 if "eta" in DYNAMICS[dynamics].parameters else None


def test_every_dynamics_conserves_mass_and_stays_nonnegative(peak_problem):
    for name in DYNAMICS:
        run = run_snapshot(
            peak_problem, 566, RunSettings(dynamics=name, graph=graph_for(name), x0="capacity",
                                           eta=eta_for(name))  # fmt: skip
        )
        assert np.all(run.trajectory_kw >= 0.0), name
        np.testing.assert_allclose(run.trajectory_kw.sum(axis=1), 57.358, atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    n_buses=st.integers(3, 40),
    n_gens=st.integers(2, 6),
    dynamics=st.sampled_from(sorted(DYNAMICS)),
)
def test_invariants_on_random_feeders(seed, n_buses, n_gens, dynamics):
    rng = np.random.default_rng(seed)
    feeder = random_feeder(rng, n_buses, min(n_gens, n_buses))
    reduced = reduce_feeder(feeder)
    capacity = feeder.generators.pmax_kw.sum()
    load = pd.Series(rng.uniform(0.1, 1.0, len(feeder.loads)), index=feeder.loads.index)
    load *= rng.uniform(0.2, 0.9) * capacity / load.sum()
    problem = build_problem(reduced, single_minute_profiles(1, load, "random"))
    integrator = Integrator(substeps=20, max_iterations=300)
    run = run_snapshot(
        problem,
        1,
        RunSettings(dynamics=dynamics, graph=graph_for(dynamics, "path"), integrator=integrator,
                    eta=eta_for(dynamics)),  # fmt: skip
    )
    assert np.all(run.trajectory_kw >= 0.0)
    np.testing.assert_allclose(run.trajectory_kw.sum(axis=1), load.sum(), rtol=1e-10)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    n=st.integers(2, 8),
    dynamics=st.sampled_from(sorted(d.name for d in DYNAMICS.values() if d.rests_at_optimum)),
    graph=st.sampled_from(["complete", "ring", "path", "star"]),
)
def test_rest_points_are_equal_fitness_states(seed, n, dynamics, graph):
    """Equal fitness on the support (unused ones worse) is a rest point; unequal is not (the
    dynamics whose rest points are the equilibria: not logit, tests/dynamics/test_targets.py)."""
    rng = np.random.default_rng(seed)
    field = DYNAMICS[dynamics]
    adjacency = communication_graph(graph if field.uses_graph else "complete", list(range(n)))
    bounds = np.zeros(n)
    x = rng.dirichlet(np.ones(n))
    used = rng.random(n) < 0.6
    used[rng.integers(n)] = True
    x = np.where(used, x, 0.0)
    x /= x.sum()
    f = np.where(used, 7.0, 7.0 - rng.uniform(0.5, 2.0, n))
    if field.uses_graph and graph != "complete":
        x, f = rng.dirichlet(np.ones(n)), np.full(n, 7.0)  # full support: no graph truncation
    rate = field_rate(field_of(field, bounded=False), x, f, adjacency, bounds, bounds)
    np.testing.assert_allclose(rate, 0.0, atol=1e-12)
    # full support, unequal fitness: the state moves. The fittest strategy gains at least
    # x_min^2 times its smallest fitness lead over a neighbour under every dynamic here
    # (Smith: x_min, BNN and the replicators: x_min^2), so that is the floor asserted.
    x = rng.dirichlet(np.ones(n))
    f = rng.uniform(0, 5, n)
    rate = field_rate(field_of(field, bounded=False), x, f, adjacency, bounds, bounds)
    top = int(np.argmax(f))
    lead = min(f[top] - f[j] for j in np.flatnonzero(adjacency[top]))
    assert np.abs(rate).max() >= 0.5 * x.min() ** 2 * lead > 0.0
    assert abs(np.sum(rate)) < 1e-12


def test_disconnected_communication_graph_is_an_error():
    import networkx as nx

    graph = nx.Graph([("G1", "G114"), ("G578", "G739")])
    graph.add_nodes_from(["G817", "G835"])
    with pytest.raises(ValueError, match="disconnected"):
        communication_graph(graph, ["G1", "G114", "G578", "G739", "G817", "G835"])


def test_generator_trip_others_take_over_within_the_minute(official_problem):
    problem = official_problem.with_outage("G114", 700, 710)
    minutes = np.arange(695, 716)
    day = run_day(problem, minutes=minutes)
    k = list(problem.generators).index("G114")
    off = (minutes >= 700) & (minutes < 710)
    assert np.all(day.setpoints_kw[off, k] == 0.0)
    assert np.all(day.converged)
    np.testing.assert_allclose(day.setpoints_kw.sum(axis=1), day.demand_kw, rtol=1e-10)
    gens = list(problem.generators)
    before = day.setpoints_kw[minutes == 699][0]
    at_trip = day.setpoints_kw[minutes == 700][0]
    # the cheapest generator's 10 kW moved to the others within the trip minute
    assert before[k] > 9.9
    others = [gens.index(g) for g in gens if g != "G114"]
    assert at_trip[others].sum() > before[others].sum() + 9.0
    # back online at minute 710 from zero share: Smith dynamics bring it back into use
    assert day.setpoints_kw[-1, k] > 9.9


def test_outage_that_leaves_too_little_capacity_is_infeasible(official_problem):
    from popdispatch.errors import InfeasibleError

    with pytest.raises(InfeasibleError, match="minute"):
        official_problem.with_outage("G817", 500, 600)


def test_paper_mode_has_rest_points_away_from_the_dc_opf(official_problem):
    """Documented finding (docs/paper-mode.md): with the discontinuous barrier, generators
    sliding on a limit pump mass back into dearer generators; the state below is at rest for
    the paper's Smith dynamics at minute 1205 although the DC-OPF is 2.4-5 kW away."""
    p_kw = np.array([0.101, 10.0, 4.221, 0.925, 11.443, 10.0])
    x = p_kw / p_kw.sum()
    for substeps in (100, 1000):
        never_stop = Integrator(substeps=substeps, tol_kw=1e-12)
        engine = Engine(official_problem, RunSettings(integrator=never_stop))
        trajectory = engine.run_minute(x, 1205, max_iterations=1000).trajectory
        drift = np.abs(trajectory[-100:].mean(axis=0) - trajectory[100:200].mean(axis=0))
        assert drift.max() * 1000 < 0.02
    opf = solve_opf(official_problem, 1205).p_kw
    assert np.abs(trajectory[-1] * 1000 - opf).max() > 2.0


@pytest.mark.slow
def test_base_day_supply_equals_demand_every_minute(official_problem):
    day = run_day(official_problem)
    assert len(day.minutes) == 1440
    assert np.all(day.converged)
    np.testing.assert_allclose(day.setpoints_kw.sum(axis=1), day.demand_kw, rtol=1e-9)
    assert np.all(day.setpoints_kw >= 0.0)


def test_demand_above_capacity_is_reported_with_its_minute(official_problem):
    from popdispatch.errors import InfeasibleError
    from popdispatch.readers import read_profiles

    profiles = read_profiles(official_folder())
    doubled = type(profiles)(profiles.kw * 2.0, profiles.source)
    with pytest.raises(InfeasibleError, match=r"minute \d+ exceeds the available generation"):
        build_problem(official_problem.feeder, doubled)


def test_results_state_their_profile_source(official_problem, peak_problem):
    assert run_snapshot(peak_problem, 566).profile_source.startswith("official minute 566")
    day = run_day(official_problem, minutes=np.arange(1, 4))
    assert day.profile_source.startswith("official profiles: ")


def test_node_controllers_table_matches_the_compiled_broadcast():
    """Each controller, computed on its own (eq. 8), adds up to what the engine broadcasts."""
    from popdispatch.game import NodeControllers, broadcast_signals

    problem = elv_problem(limits=[(505, 666, 28.0)])
    free = solve_opf(elv_problem(), 566)  # unconstrained optimum overloads the path
    flows = problem.flows(free.p_kw / 1000.0, 566)
    controllers = NodeControllers.from_problem(problem)
    table = controllers.table
    assert len(table) == 2 * len(problem.lines)
    values = controllers.signals(flows, 1000.0)
    by_line = values.groupby(table.line).agg(["min", "max"])
    np.testing.assert_allclose(by_line["min"], -by_line["max"])  # penalty and incentive
    assert values.abs().max() > 1.0
    received = dict.fromkeys(problem.generators, 0.0)
    for receivers, value in zip(table.receivers, values, strict=True):
        for generator in receivers:
            received[generator] += value
    compiled = broadcast_signals(flows, problem.limit, problem.down, 1000.0)
    np.testing.assert_allclose([received[g] for g in problem.generators], compiled, atol=1e-9)
    # the sending side (downstream generators push the flow up the path) is penalised
    assert received["G739"] < 0 < received["G1"]
