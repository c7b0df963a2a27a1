"""With no delay, no loss and no noise on the simulated synchronous clock, the agents follow
the mean-dynamics engine's Euler trajectory (issue 15, first "Done when")."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.network import Faults
from popdispatch.agents.system import AgentSettings, run_agents
from popdispatch.constants import KW_PER_MW
from popdispatch.integrate import Integrator
from popdispatch.online import Engine, RunSettings, initial_shares
from popdispatch.scenarios import PEAK_MINUTE

CASES = [
    # mode, dynamics, graph, Euler step h (s), rounds
    ("exact", "smith", "complete", 0.005, 40),
    ("exact", "distributed-smith", "ring", 0.005, 40),
    ("paper", "smith", "complete", 5e-4, 60),
    ("paper", "local-replicator", "ring", 2e-3, 60),
]


def engine_euler_mw(problem, settings: RunSettings, h: float, rounds: int) -> np.ndarray:
    """The engine's set points (MW) after each Euler step of ``h`` seconds (one step per
    iteration), from the settings' initial shares."""
    integrator = Integrator(method="euler", dt=h, substeps=1, max_iterations=rounds,
                            tol_kw=1e-12, window=5)  # fmt: skip
    engine = Engine(problem, RunSettings(settings.dynamics, settings.mode, settings.graph,
                                         integrator=integrator))  # fmt: skip
    x0 = initial_shares(problem, "uniform", PEAK_MINUTE)
    return engine.run_minute(x0, PEAK_MINUTE).trajectory


@pytest.mark.parametrize(("mode", "dynamics", "graph", "h", "rounds"), CASES)
def test_agents_follow_engine_euler(congestion_problem, mode, dynamics, graph, h, rounds):
    settings = RunSettings(dynamics=dynamics, mode=mode, graph=graph)
    opts = AgentSettings(step_s=h, max_rounds=rounds, tol_kw=0.0, engine_limiter=True,
                         local_step=False)  # the plain Euler rounds: the engine's steps
    run = run_agents(congestion_problem, PEAK_MINUTE, settings, Faults(), opts)
    engine = engine_euler_mw(congestion_problem, settings, h, rounds)
    agents = run.trajectory_kw / KW_PER_MW
    n = min(len(engine), len(agents))
    assert n >= 10
    # the trajectory moves (kW), so equality is not the trivial one of a state at rest
    assert np.abs(engine[n - 1] - engine[0]).max() * KW_PER_MW > 0.1
    np.testing.assert_allclose(agents[:n], engine[:n], rtol=0.0, atol=1e-9)  # MW
    assert run.messages > 0 and run.lost == 0
