"""The agents' node controllers under the scaled price law (each line's price rate times
``s_k = N / N_k`` and its proportional weight times ``sqrt(s_k)``, from the two counts each
controller is given at configuration): the agents follow the engine's Euler trajectory under
that law, and on a fleet whose cheap DG sits at its Pmax below a limited line, where the
plain law's price must travel the whole marginal-cost gap driven by a small overflow, they
reach the DC-OPF (Clarabel) in fewer than 200 rounds (as the plain law does with its still
line hastened)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents  # noqa: E402
from popdispatch.constants import KW_PER_MW  # noqa: E402
from popdispatch.integrate import Integrator  # noqa: E402
from popdispatch.modes.exact import ExactConstants  # noqa: E402
from popdispatch.online import Engine, RunSettings, initial_shares  # noqa: E402
from popdispatch.scenarios import PEAK_MINUTE  # noqa: E402

from helpers import agents_on_a_matpower_fleet, assert_converged_on_the_dc_opf  # noqa: E402

SCALED = ExactConstants(price_law="scaled")


def test_agents_follow_engine_euler_under_the_scaled_law(congestion_problem):
    h, rounds = 0.002, 40
    settings = RunSettings(dynamics="smith", mode="exact", exact=SCALED)
    opts = AgentSettings(step_s=h, max_rounds=rounds, tol_kw=0.0, engine_limiter=True,
                         local_step=False)  # fmt: skip
    run = run_agents(congestion_problem, PEAK_MINUTE, settings, Faults(), opts)
    integrator = Integrator(method="euler", dt=h, substeps=1, max_iterations=rounds,
                            tol_kw=1e-12, window=5)  # fmt: skip
    engine = Engine(congestion_problem, RunSettings("smith", "exact", exact=SCALED,
                                                    integrator=integrator))  # fmt: skip
    x0 = initial_shares(congestion_problem, "uniform", PEAK_MINUTE)
    engine = engine.run_minute(x0, PEAK_MINUTE).trajectory
    agents = run.trajectory_kw / KW_PER_MW
    n = min(len(engine), len(agents))
    assert n >= 10
    assert np.abs(engine[n - 1] - engine[0]).max() * KW_PER_MW > 0.1
    np.testing.assert_allclose(agents[:n], engine[:n], rtol=0.0, atol=1e-9)  # MW


#: MATPOWER's case16am with a drawn fleet: g3 (b 14.4 EUR/MWh, nearly linear) at its Pmax
#: below line 14-15 limited to 200.6 kW, where the DC-OPF prices the line at 19,297 EUR/MWh
#: (the source's steep curve sets the balance price) and the overflow at the start is 27 kW.
FLEET16 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,src,48.98171251,775.338378,0,57400
14,g0,8.85419043,0.231838187,0,6383.096365
3,g1,44.25426463,139.601085,0,2387.095935
8,g2,25.08181119,343.575232,2512.000089,5206.391829
15,g3,14.39123713,0.288754917,0,2328.002886
"""


@pytest.mark.parametrize("law", ["scaled", "plain"])
@pytest.mark.parametrize("graph", ["complete", "ring"])
def test_a_dg_pinned_below_a_limited_line_in_under_200_rounds(tmp_path, graph, law):
    """The scaled law's constants, or the plain law's with the still line's hastened price
    (tests/agents/test_still_lines.py), bring the case16am fleet to the DC-OPF in at most 200
    rounds (the plain law alone took 261 and 281)."""
    out, opf, setpoints = agents_on_a_matpower_fleet(
        tmp_path, "case16am", FLEET16, (14, 15, 200.6), graph, "--price-law", law
    )
    assert opf.line_price.min() < -1e4  # the line's price travels far (EUR/MWh)
    assert_converged_on_the_dc_opf(out, opf, setpoints, 200)

