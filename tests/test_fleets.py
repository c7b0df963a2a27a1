"""Exact mode on random fleets (the space a user's fleet spans: curvatures over five decades,
linear generators, Pmin > 0, binding limits), against an exact DC-OPF found by enumerating
active sets (tests/qp_exact.py): on the complete graph every run converges within 200
iterations with every price law, and so does distributed Smith on random connected graphs;
every ``converged`` run is within its stated accuracy of the optimum, and the certificate's
bound is never below the true distance."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from popdispatch.modes.exact import ExactConstants
from popdispatch.online import RunSettings, run_snapshot

from helpers import random_fleet_problem
from qp_exact import exact_dc_opf, roundoff_kw

#: The iterations exact mode may take on any fleet.
HORIZON = 200
FLEETS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _check(problem, settings_: RunSettings, drawn: bool = True) -> None:
    """Converged within the accuracy of the exact optimum in at most :data:`HORIZON`
    iterations, the certificate's bound never below the true distance (``drawn``: a
    hypothesis draw, which an infeasible problem rejects; else the problem must be
    feasible)."""
    optimum = exact_dc_opf(problem)
    if drawn:
        assume(optimum is not None)
    assert optimum is not None
    run = run_snapshot(problem, 1, settings_)
    distance_kw = np.abs(run.setpoints_kw - optimum * 1e3).max()
    # the certificate is a bound
    assert run.distance_bound_kw >= distance_kw - roundoff_kw(problem)
    assert run.status == "converged", (run.status, run.stall_reason)
    assert run.iterations <= HORIZON
    assert distance_kw <= run.accuracy_kw


@pytest.mark.parametrize("law", ["plain", "tree", "scaled"])
@FLEETS
@given(st.integers(0, 2**32 - 1), st.integers(2, 5), st.integers(0, 2))
def test_random_fleets_converge_within_the_accuracy_in_200_iterations(law, seed, n_gens, n_limits):
    problem = random_fleet_problem(seed, n_gens, n_limits)
    exact = ExactConstants(price_law=law)
    _check(problem, RunSettings(mode="exact", exact=exact))


@FLEETS
@given(st.integers(0, 2**32 - 1), st.integers(3, 5), st.integers(0, 2), st.floats(0.0, 1.0))
def test_distributed_smith_on_a_random_connected_graph(seed, n_gens, n_limits, density):
    problem = random_fleet_problem(seed, n_gens, n_limits)
    rng = np.random.default_rng(seed)
    tree = nx.random_labeled_tree(n_gens, seed=int(rng.integers(2**31)))  # connected ...
    graph = nx.relabel_nodes(tree, dict(enumerate(problem.generators)))
    names = list(problem.generators)
    for a in range(n_gens):  # ... plus random chords
        for b in range(a + 1, n_gens):
            if rng.random() < density * 0.5:
                graph.add_edge(names[a], names[b])
    settings_ = RunSettings(mode="exact", dynamics="distributed-smith", graph=graph)
    _check(problem, settings_)


def test_distributed_smith_reaches_the_optimum_behind_a_generator_at_its_limit():
    """A generator whose only neighbour sits at a limit trades through the relay: on this
    tree (drawn by the property test above) the two generators trading through the relay keep
    exchanging microwatts within the accuracy, so the rest rule never fires; the certificate,
    asked every few iterations, proves the state within the accuracy in at most 200."""
    seed, n_gens = 259727, 5
    problem = random_fleet_problem(seed, n_gens, 1)
    rng = np.random.default_rng(seed)
    tree = nx.random_labeled_tree(n_gens, seed=int(rng.integers(2**31)))
    graph = nx.relabel_nodes(tree, dict(enumerate(problem.generators)))
    _check(problem, RunSettings(mode="exact", dynamics="distributed-smith", graph=graph),
           drawn=False)
