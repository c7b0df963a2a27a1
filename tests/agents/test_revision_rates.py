"""The agents' revision rates: each generator's Newton rate ``(S / P) / (2 c)``
(dynamics/newton.py, computed here by hand from the fleet), capped at ``rate_cap`` except,
with the local step on the complete graph, for a quadratic generator whose output moves no
priced row (capped at ``FREE_RATE_CAP``, as the engine's adaptive steps lift it). On a drawn
case17me fleet whose unpriced DG drained at the cap's pace (a steep DG's range makes the
spread ``S`` large) the agents now reach the DC-OPF (Clarabel) in at most 200 rounds."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.population import FREE_RATE_CAP, build_agents  # noqa: E402
from popdispatch.modes.exact import NEWTON_RATE_CAP  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402

from helpers import (  # noqa: E402
    FLEET17,
    agents_on_a_matpower_fleet,
    assert_converged_on_the_dc_opf,
    random_fleet_problem,
)


def _by_hand(problem, free: bool) -> np.ndarray:
    """``(S / P) / (2 c)``: ``S`` the spread of marginal costs over the ranges, ``P`` the
    demand; capped at the rate cap, or, if ``free``, the unpriced quadratic generators at the
    free cap (``inf`` for a linear one: capped)."""
    top = problem.b + 2 * problem.c * problem.pmax
    spread = top.max() - (problem.b + 2 * problem.c * problem.pmin).min()
    with np.errstate(divide="ignore"):
        newton = spread / problem.demand[0] / (2 * problem.c)
    below_a_limit = (problem.down != 0).any(axis=0) if len(problem.limit) else 0 * newton > 0
    cap = np.full(len(newton), NEWTON_RATE_CAP)
    if free:
        cap[~below_a_limit & (problem.c > 0)] = FREE_RATE_CAP
    return np.minimum(newton, cap)


@pytest.mark.parametrize("seed", [3, 11, 29])
@pytest.mark.parametrize(
    ("graph", "local", "free"),
    [("complete", True, True), ("complete", False, False), ("ring", True, False)],
)
def test_each_generator_revises_at_its_rate(seed, graph, local, free):
    problem = random_fleet_problem(seed, 5, 1)
    dynamics = "smith" if graph == "complete" else "distributed-smith"
    settings = RunSettings(mode="exact", dynamics=dynamics, graph=graph)
    system = build_agents(problem, 1, settings, 1e-4, Faults(), local_step=local)
    found = np.array([g.rule.rate for g in system.generators])
    np.testing.assert_allclose(found, _by_hand(problem, free), rtol=1e-12)
    assert (found > NEWTON_RATE_CAP).any() == free  # the draws have such generators


def test_an_unpriced_dg_draining_a_small_part_of_the_spread_in_under_200_rounds(tmp_path):
    """The drawn case17me fleet on the complete graph: at most 200 rounds (301 with every
    rate capped)."""
    out, opf, setpoints = agents_on_a_matpower_fleet(
        tmp_path, "case17me", FLEET17, (16, 17, 714.7), "complete"
    )
    assert abs(opf.line_price[0]) > 1.0  # the line binds at the optimum (EUR/MWh)
    assert_converged_on_the_dc_opf(out, opf, setpoints, 200)
