"""Exact mode on random fleets (the space a user's fleet spans: curvatures over five decades,
linear generators, Pmin > 0, binding limits), against an exact DC-OPF found by enumerating
active sets (tests/qp_exact.py): every run converges within 200 iterations, and every run that
says ``converged`` is within its stated accuracy of the optimum, with every price law, on the
complete graph and with distributed Smith on connected graphs."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from popdispatch.modes.exact import ExactConstants
from popdispatch.online import RunSettings, run_snapshot

from helpers import random_fleet_problem
from qp_exact import exact_dc_opf

#: The iterations exact mode may take on any fleet.
HORIZON = 200
FLEETS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _check(problem, settings_: RunSettings) -> None:
    optimum = exact_dc_opf(problem)
    assume(optimum is not None)
    run = run_snapshot(problem, 1, settings_)
    assert run.status == "converged", (run.status, run.stall_reason)
    assert run.iterations <= HORIZON
    distance_kw = np.abs(run.setpoints_kw - optimum * 1e3).max()
    assert distance_kw <= run.accuracy_kw
    assert run.distance_bound_kw >= distance_kw - 1e-9  # the certificate is a bound


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
