"""The compiled voltage mode against the plain-numpy reference (popdispatch.reference), whose
voltage rows are written from the unscaled LinDistFlow model (``v^2 = v0^2 + S p``, rows
divided by the bus scales), not read from the engine's pre-scaled ``load_flow`` columns."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pandapower", reason="case33bw comes from pandapower's networks")

from popdispatch.game.parameters import GameParameters, GameWork, MinuteInputs  # noqa: E402
from popdispatch.modes import ModeCode, get_mode  # noqa: E402
from popdispatch.modes.voltage import payoff  # noqa: E402
from popdispatch.online import Engine, RunSettings, initial_shares  # noqa: E402
from popdispatch.reference import ReferenceMinute, game  # noqa: E402
from popdispatch.scenarios import VOLTAGE_LIMITS, voltage_problems  # noqa: E402

SETTINGS = RunSettings(mode="exact", vmin_pu=VOLTAGE_LIMITS[0], vmax_pu=VOLTAGE_LIMITS[1])


@pytest.fixture(scope="module")
def problem():
    return voltage_problems()[1]


def test_reference_game_equals_the_compiled_voltage_payoff(problem):
    fp = SETTINGS.game_constants(problem)
    rng = np.random.default_rng(11)
    n_states = get_mode("voltage").controller_states(problem)
    for _ in range(5):
        p = problem.pmax * rng.uniform(0.0, 1.0, problem.n_generators)
        z = rng.uniform(0.0, 5.0, n_states) * (rng.random(n_states) < 0.5)
        got_f, got_rate = np.empty(len(p)), np.empty(n_states)
        work = GameWork.empty(len(problem.limit), n_generators=problem.n_generators)
        got = payoff(p, z, GameParameters.of(problem, fp), MinuteInputs.of(problem, 1), work,
                     got_f, got_rate)  # fmt: skip
        f, rate, congestion, residual = game(ModeCode.VOLTAGE, p, z, problem, 1, fp)
        np.testing.assert_allclose(got_f, f, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(got_rate, rate, rtol=1e-12, atol=1e-12)
        assert got == pytest.approx((congestion, residual), rel=1e-12)


def test_engine_equals_the_reference_on_a_voltage_run(problem):
    """Same set points at every iteration, same stop, and the run reaches the binding voltage
    limits (the voltage rows are exercised).

    Tolerances: the two sum in different orders (dense matrices here), 1e-11 MW apart up to
    iteration 2; from there the adaptive steps of the two take different decisions (a step
    accepted in one is rejected in the other) and the difference grows to 4.9e-7 MW by
    iteration 6 (measured), so each iteration is held to the voltage mode's Heun error control,
    ``rtol * demand`` (1.1e-5 MW), and the end state to the stopping tolerance ``tol_mw``.
    Both stop converged; with those differences the stopping rule's window means agree within
    its tolerance an iteration or a window apart (17 against 20, measured), so the stops are
    held to one window."""
    engine = Engine(problem, SETTINGS)
    x0 = initial_shares(problem, SETTINGS.x0, 1)
    run = engine.run_minute(x0, 1)
    reference = ReferenceMinute(problem, SETTINGS, 1)
    ref, _, z, status, converged_at = reference.run(run.trajectory[0] / reference.demand)
    integrator, demand = SETTINGS.stepping, float(problem.demand[0])
    assert run.status == status
    assert abs(run.converged_at - converged_at) <= integrator.window
    np.testing.assert_allclose(run.trajectory[:3], ref[:3], rtol=0, atol=1e-9)
    rows = min(len(ref), len(run.trajectory))
    np.testing.assert_allclose(run.trajectory[:rows], ref[:rows], rtol=0,
                               atol=integrator.rtol * demand)  # fmt: skip
    np.testing.assert_allclose(run.trajectory[-1], ref[-1], rtol=0,
                               atol=integrator.tol_mw(demand))  # fmt: skip
    assert np.ptp(run.trajectory, axis=0).max() > 1e-3  # things moved
    assert np.abs(z[2 * len(problem.limit) :]).max() > 1.0  # voltage prices rose
