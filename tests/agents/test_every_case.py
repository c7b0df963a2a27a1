"""The agents on every case of the engine's scale study (benchmarks/scale_cases.py, the cases of
tests/test_exact_mode.py::test_every_case_converges_to_the_dc_opf_in_200_iterations): the
built-in and MATPOWER networks with and without a binding limit, the synthetic 1k feeder with
every line limited and the same times 100. On a perfect network they follow the engine's Euler
steps (exact and paper mode, complete graph and a ring) and, in exact mode, come to rest at the
DC-OPF solved here by Clarabel, its set points and its line prices (docs/agents.md)."""

from __future__ import annotations

import functools
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.population import build_agents, controller_id, default_step  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents  # noqa: E402
from popdispatch.constants import KW_PER_MW  # noqa: E402
from popdispatch.errors import OptionError  # noqa: E402
from popdispatch.integrate import Integrator  # noqa: E402
from popdispatch.modes.exact import scales  # noqa: E402
from popdispatch.online import Engine, RunSettings, initial_shares  # noqa: E402
from popdispatch.online.kkt import net_prices  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import scale_cases  # noqa: E402  (the engine's case list: one definition for all)

CASES = list(scale_cases.all_cases(sizes=(1000,)))
IDS = [f"{name}-{limits}" for name, limits, _ in CASES]
NETWORKS = [case for case in CASES if not case[0].startswith("synthetic")]
NETWORK_IDS = [f"{name}-{limits}" for name, limits, _ in NETWORKS]
#: The dynamics each graph runs: Smith on the complete graph, distributed Smith on a ring.
GRAPHS = {"complete": "smith", "ring": "distributed-smith"}
#: Rounds compared with the engine's Euler steps.
ROUNDS = 20
#: Accuracy of a line price at rest, as a share of the marginal-cost spread (EUR/MWh).
PRICE_RTOL = 1e-3
#: "To the watt": largest |supply - demand| of any committed state, W.
BALANCE_W = 1.0


@functools.cache
def case(name: str, limits: str):
    """``(problem, DC-OPF)`` of a case of the study (built once per session)."""
    if scale_cases.matpower_missing(name):
        pytest.skip(scale_cases.matpower_missing(name))
    build = next(b for n, lim, b in CASES if (n, lim) == (name, limits))
    problem = build()
    return problem, solve_opf(problem, 1)


def settings_for(mode: str, graph: str) -> RunSettings:
    return RunSettings(dynamics=GRAPHS[graph], mode=mode, graph=graph)


def engine_euler_mw(problem, settings: RunSettings, h: float, rounds: int) -> np.ndarray:
    """The engine's set points (MW) after each Euler step of ``h`` seconds (one step per
    iteration) of minute 1, from uniform shares."""
    integrator = Integrator(method="euler", dt=h, substeps=1, max_iterations=rounds,
                            tol_kw=1e-12, window=5)  # fmt: skip
    engine = Engine(problem, replace(settings, integrator=integrator))
    return engine.run_minute(initial_shares(problem, "uniform", 1), 1).trajectory


#: The cases paper mode's rounds are compared on (exact mode: every case): the paper's feeder
#: free and congested, a binding limit on a Kerber and a MATPOWER feeder, the deep synthetic
#: limits and their scaling by 100 (paper mode's code is the same on the others).
PAPER_CASES = {("ieee-elv", "none"), ("ieee-elv", "binding"), ("kerber-dorfnetz", "binding"),
               ("matpower:case69", "binding"), ("synthetic-1k", "every line"),
               ("synthetic-1k x100", "every line")}  # fmt: skip
EULER_RUNS = [(name, limits, graph, mode) for name, limits, _ in CASES for graph in GRAPHS
              for mode in ("exact", "paper")
              if mode == "exact" or (name, limits) in PAPER_CASES]  # fmt: skip


@pytest.mark.parametrize(("name", "limits", "graph", "mode"), EULER_RUNS,
                         ids=["-".join(run) for run in EULER_RUNS])  # fmt: skip
def test_agents_follow_the_engine_euler_steps(name, limits, graph, mode):
    """Perfect network, the default round step of the plain Euler rounds (no local step): the
    agents' set points after every round are the engine's Euler steps (summation orders
    apart)."""
    problem, _ = case(name, limits)
    settings = settings_for(mode, graph)
    h = default_step(problem, settings, 1)
    opts = AgentSettings(max_rounds=ROUNDS, tol_kw=0.0, engine_limiter=True, local_step=False)
    run = run_agents(problem, 1, settings, Faults(), opts)
    assert run.step_s == h
    engine = engine_euler_mw(problem, settings, h, ROUNDS)
    agents = run.trajectory_kw / KW_PER_MW
    n = min(len(engine), len(agents))
    assert n >= 4  # the engine may stop earlier, at a fixed point
    demand = float(problem.demand[0])
    atol = 1e-9 * max(1.0, demand)  # MW
    # the trajectory moves, so equality is not the trivial one of a state at rest
    assert np.abs(engine[n - 1] - engine[0]).max() > 1e3 * atol
    np.testing.assert_allclose(agents[:n], engine[:n], rtol=0.0, atol=atol)


def accuracy_kw(settings: RunSettings, problem) -> float:
    """The accuracy a converged minute proves, kW (max(0.001 kW, 1e-6 of the demand))."""
    return float(settings.accuracy_mw(problem.demand[0])) * KW_PER_MW


@pytest.mark.parametrize("graph", list(GRAPHS))
@pytest.mark.parametrize(("name", "limits", "build"), NETWORKS, ids=NETWORK_IDS)
def test_agents_reach_the_dc_opf_on_every_network(name, limits, build, graph):
    """Exact mode, default settings: converged (the distance certificate proves the end
    state within the accuracy) and within that accuracy of Clarabel's DC-OPF, the binding
    line priced at the DC-OPF's dual."""
    problem, opf = case(name, limits)
    assert opf.status == "optimal"
    settings = settings_for("exact", graph)
    run = run_agents(problem, 1, settings, Faults())
    assert run.status == "converged", run.reason
    accuracy = accuracy_kw(settings, problem)
    assert run.accuracy_kw == pytest.approx(accuracy)
    assert run.distance_bound_kw <= accuracy
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= accuracy
    weight = settings.game_constants(problem).C
    prices = net_prices(problem, np.array([1]), run.setpoints_kw[None] / KW_PER_MW,
                        run.line_states(len(problem.limit))[None], weight)[0][0]  # fmt: skip
    if limits == "binding":
        assert np.abs(opf.line_price).max() > 1e-6  # the limit binds
    spread = scales(problem)[0]
    np.testing.assert_allclose(prices, opf.line_price, rtol=0.0, atol=PRICE_RTOL * spread)
    assert abs(run.max_imbalance_w) < BALANCE_W and run.open_transactions == 0


def test_a_step_past_the_stability_limit_is_reported_not_converged():
    """The synthetic feeder's limits nest up to 23 deep: on the complete graph the plain Euler
    rounds' default step (no local step; one priced line above a generator) is past the Euler
    rule's stability limit. The run says so instead of resting (docs/agents.md, "The round
    step")."""
    problem, opf = case("synthetic-1k", "every line")
    run = run_agents(problem, 1, settings_for("exact", "complete"), Faults(),
                     AgentSettings(max_rounds=60, local_step=False))  # fmt: skip
    assert run.status == "not_converged"
    assert "oscillate" in run.reason and "smaller step" in run.reason
    assert np.abs(run.setpoints_kw - opf.p_kw).max() > 1.0  # kW: far from the optimum


@pytest.mark.extended
def test_the_synthetic_feeder_on_a_ring_reaches_the_dc_opf_with_the_local_step():
    """The synthetic 1k feeder (68 limited lines, 23 deep, 9 binding) on the ring: with the
    plain Euler rounds the curvature-scaled field's stiffness bounded the step to about 7e-5 s
    and 6000 rounds left it 0.038 kW away; with each generator's local step the round step is
    the line prices' (4.2e-4 s) and the run converges (measured: 1591 rounds, docs/agents.md,
    "The local step"): proved within the accuracy, and within it of Clarabel's DC-OPF, supply
    = demand."""
    problem, opf = case("synthetic-1k", "every line")
    settings = settings_for("exact", "ring")
    run = run_agents(problem, 1, settings, Faults(), AgentSettings(max_rounds=3000))
    accuracy = accuracy_kw(settings, problem)
    assert run.status == "converged", run.reason
    assert run.distance_bound_kw <= accuracy
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= accuracy
    assert abs(run.max_imbalance_w) < BALANCE_W


def test_the_synthetic_feeder_on_a_ring_says_honestly_how_far_it_is():
    """Before it converges (100 rounds of the run above) the ring run reports what holds: no
    `converged` without a proof, the bound it reports never below its true distance, supply =
    demand."""
    problem, opf = case("synthetic-1k", "every line")
    settings = settings_for("exact", "ring")
    run = run_agents(problem, 1, settings, Faults(), AgentSettings(max_rounds=100))
    distance = np.abs(run.setpoints_kw - opf.p_kw).max()
    yardstick_kw = 1e-8 * float(problem.demand[0]) * KW_PER_MW  # Clarabel's own tolerance
    assert run.distance_bound_kw is not None
    assert run.distance_bound_kw >= distance - yardstick_kw
    if run.status == "converged":
        assert run.distance_bound_kw <= accuracy_kw(settings, problem)
    else:
        assert distance > 0.0 and run.reason
    assert abs(run.max_imbalance_w) < BALANCE_W


@pytest.mark.parametrize("taken", ["plant", "source", "controller"])
def test_a_generator_with_another_agents_id_is_refused(taken):
    """A fleet generator named like the plant, the source bus or a node controller would
    share its agent id: refused in one line naming it."""
    problem, _ = case("matpower:case69", "binding")
    parent_bus = problem.feeder.lines.iloc[problem.lines[0]].from_bus
    name = controller_id(parent_bus) if taken == "controller" else taken
    clash = replace(problem, generators=pd.Index([name, *problem.generators[1:]]))
    with pytest.raises(OptionError, match=f"generator '{name}' has the agent id") as error:
        build_agents(clash, 1, RunSettings(mode="exact"), 1e-4, Faults())
    assert error.value.option == "--fleet" and "\n" not in str(error.value)
