"""The target laws, BNN and logit (dynamics/bnn.py, dynamics/logit.py): their rest points and
extinction behaviour against their definitions, the logit's box target against Brent's method
and its optimality conditions, mass and limits kept by the engine over the whole input space,
and exact mode's verdict on a logit run (never converged to the DC-OPF)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from popdispatch.dynamics import Field, field_rate
from popdispatch.dynamics.logit import box_target, reference_box_target
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem
from popdispatch.integrate import Integrator
from popdispatch.online import RunSettings, run_day, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.scenarios import PEAK_MINUTE, elv_problem

from helpers import random_feeder


def complete(n: int) -> np.ndarray:
    return np.ones((n, n)) - np.eye(n)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 9), log_eta=st.floats(-3, 3))
def test_box_target_is_the_perturbed_best_response_in_the_box(seed, n, log_eta):
    """``clip(exp((f - lambda) / eta), lo, hi)`` summing to the mass: equal to Brent's root
    of the total, inside the box, and optimal: every strategy strictly inside its limits has
    the same ``f_i - eta ln T_i`` (the multiplier), one at its upper limit no less, one at its
    lower limit no more."""
    rng = np.random.default_rng(seed)
    eta = 10.0**log_eta
    f = rng.normal(0, 5, n) * rng.choice([1e-3, 1.0, 1e3])
    lo = rng.uniform(0, 0.1, n) * (rng.random(n) < 0.5)
    hi = lo + rng.uniform(0.01, 1.0, n)
    mass = rng.uniform(lo.sum(), hi.sum())
    part = np.ones(n)
    target = np.empty(n)
    box_target(f, lo, hi, part, eta, mass, target)
    assert abs(target.sum() - mass) <= 1e-12 * max(mass, 1.0)
    assert (target >= lo).all() and (target <= hi).all()
    # lambda is known to a few ulp of its size, a share to that over eta
    precision = 16 * np.finfo(float).eps * (np.abs(f).max() + eta) / eta
    np.testing.assert_allclose(target, reference_box_target(f, lo, hi, part > 0, eta, mass),
                               rtol=1e-12 + precision, atol=1e-15)  # fmt: skip
    inside = (target > lo * (1 + 1e-12) + 1e-300) & (target < hi * (1 - 1e-12))
    level = f - eta * np.log(np.maximum(target, 1e-300))
    if inside.any():
        lam = level[inside].mean()
        tol = 1e-12 * max(1.0, np.abs(f).max()) + 4 * eta * precision
        np.testing.assert_allclose(level[inside], lam, atol=tol)
        assert (level[target >= hi] >= lam - tol).all()
        assert (level[(target <= lo) & (lo > 0)] <= lam + tol).all()


def test_without_limits_the_box_target_is_the_logit_choice():
    f = np.array([3.0, 1.0, -2.0, 2.5])
    target = np.empty(4)
    box_target(f, np.zeros(4), np.full(4, 10.0), np.ones(4), 0.8, 1.0, target)
    choice = np.exp(f / 0.8) / np.exp(f / 0.8).sum()
    np.testing.assert_allclose(target, choice, rtol=1e-12)


@pytest.mark.parametrize("field", [Field.LOGIT, Field.BOX_LOGIT])
def test_logit_rests_at_its_choice_and_not_at_a_nash_state(field):
    """``x = L(f)`` is a rest point; equal fitness on a support with worse unused strategies
    (a Nash state, a rest point of Smith and BNN) is not."""
    f = np.array([1.0, 0.4, -0.3, 0.9])
    eta, n = 0.5, 4
    x = np.exp(f / eta) / np.exp(f / eta).sum()
    box = (np.zeros(n), np.ones(n))
    rate = field_rate(field, x, f, complete(n), *box, eta=eta, gain=2.0)
    np.testing.assert_allclose(rate, 0.0, atol=1e-15)
    nash_x, nash_f = np.array([0.5, 0.5, 0.0, 0.0]), np.array([1.0, 1.0, 0.0, 0.0])
    for dynamics_field in (Field.SMITH, Field.BNN):
        assert np.abs(field_rate(dynamics_field, nash_x, nash_f, complete(n), *box)).max() == 0
    moved = field_rate(field, nash_x, nash_f, complete(n), *box, eta=eta, gain=2.0)
    assert moved[2] > 0.0 and moved[3] > 0.0  # every strategy gets a share (no extinction)


ESCAPES = [(Field.BNN, True), (Field.LOGIT, True), (Field.SMITH, True), (Field.REPLICATOR, False)]


@pytest.mark.parametrize(("field", "escapes"), ESCAPES)
def test_a_better_strategy_at_zero_share_escapes_extinction_unless_imitated(field, escapes):
    """Extinction: strategy 0 holds nothing and is the fittest; BNN (it is above the mean),
    logit (every strategy is chosen) and Smith move mass to it, the replicator never does."""
    x, f = np.array([0.0, 0.3, 0.7]), np.array([5.0, 1.0, 2.0])
    rate = field_rate(field, x, f, complete(3), np.zeros(3), np.ones(3), eta=1.0, gain=1.0)
    assert (rate[0] > 0.0) == escapes
    assert abs(rate.sum()) < 1e-15


def _drawn_problem(seed: int, n_gens: int):
    """The property test's feeder and load of one draw."""
    rng = np.random.default_rng(seed)
    feeder = random_feeder(rng, 20, n_gens)
    capacity = feeder.generators.pmax_kw.sum()
    load = pd.Series(rng.uniform(0.1, 1.0, len(feeder.loads)), index=feeder.loads.index)
    load *= rng.uniform(0.2, 0.9) * capacity / load.sum()
    return build_problem(reduce_feeder(feeder), single_minute_profiles(1, load, "random"))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**31),
    n_gens=st.integers(2, 6),
    case=st.sampled_from([("paper", "bnn"), ("paper", "logit"), ("exact", "logit")]),
    log_eta=st.floats(-3, 3),
    dt=st.sampled_from([0.01, 1.0]),
)
@example(seed=38616, n_gens=4, case=("exact", "logit"), log_eta=-2.28125, dt=0.01)  # overflowed
def test_bnn_and_logit_conserve_mass_and_keep_the_simplex_and_the_box(seed, n_gens, case, log_eta,
                                                                      dt):  # fmt: skip
    """Random feeders, noise levels over six decades (1e-3 to 1e3 EUR/MWh) and steps up to
    100 times the iteration, with no error control but the rejection of a step whose result
    is not finite (exact mode's Heun steps of 0.01 s overflowed on the example): every
    iteration's set points sum to the demand and stay non-negative (paper mode), inside the
    generator limits (exact mode)."""
    mode, dynamics = case
    problem = _drawn_problem(seed, n_gens)
    method = "euler" if mode == "paper" else "heun"
    substeps = 20 if dt < 1 else 1
    loose = Integrator(method=method, dt=dt, substeps=substeps, rtol=1e6, atol=1e6,
                       max_iterations=60)  # fmt: skip
    eta = 10.0**log_eta if dynamics == "logit" else None
    run = run_snapshot(problem, 1, RunSettings(dynamics=dynamics, mode=mode, eta=eta,
                                               x0="capacity", integrator=loose))  # fmt: skip
    demand_kw = problem.demand[0] * 1000
    np.testing.assert_allclose(run.trajectory_kw.sum(axis=1), demand_kw, rtol=1e-10)
    assert np.isfinite(run.trajectory_kw).all()
    assert (run.trajectory_kw >= -1e-12 * demand_kw).all()
    if mode == "exact":
        pmin, pmax = problem.pmin * 1000, problem.pmax * 1000
        assert (run.trajectory_kw >= pmin - 1e-9 * demand_kw).all()
        assert (run.trajectory_kw <= pmax + 1e-9 * demand_kw).all()


def test_a_state_that_overflows_is_stalled_with_the_reason():
    """Exact-mode logit (eta 5e-3 EUR/MWh) by fixed Euler steps of 0.01 s: the prices ring up
    to overflow (the Heun steps of the property test above are rejected instead). The run and
    the day say so, never a dispatch: stalled, the bound infinite, the reason the steps."""
    problem = _drawn_problem(38616, 4)
    euler = Integrator(method="euler", dt=0.01, substeps=1, max_iterations=30)
    settings = RunSettings(dynamics="logit", mode="exact", eta=10.0**-2.28125, x0="capacity",
                           integrator=euler)  # fmt: skip
    run = run_snapshot(problem, 1, settings)
    assert not np.isfinite(run.setpoints_kw).all()
    assert run.status == "stalled" and run.converged_at is None
    assert run.distance_bound_kw == np.inf
    assert "overflowed" in run.stall_reason and "euler steps of 0.01 s" in run.stall_reason
    day = run_day(problem, settings)
    assert day.status == "stalled" and not day.converged.any()
    assert "overflowed" in day.stall_reasons[1]


@pytest.fixture(scope="module")
def peak():
    return elv_problem()


def test_exact_logit_is_never_converged_to_the_dc_opf(peak):
    """At minute 566 the DC-OPF has one generator inside its limits and the logit inside the
    box lands on it (the certificate proves 1e-8 kW): still stalled, never converged, and the
    reason gives the bound; a larger noise rests visibly away, with its bound."""
    opf = solve_opf(peak, PEAK_MINUTE).p_kw
    close = run_snapshot(peak, PEAK_MINUTE, RunSettings(dynamics="logit", mode="exact", eta=0.1))
    assert close.status == "stalled" and close.converged_at is None
    assert close.distance_bound_kw <= close.accuracy_kw
    assert np.abs(close.setpoints_kw - opf).max() <= close.distance_bound_kw + 1e-9
    assert "own equilibrium" in close.stall_reason and "bounded by" in close.stall_reason
    far = run_snapshot(peak, PEAK_MINUTE, RunSettings(dynamics="logit", mode="exact", eta=5.0))
    assert far.status == "stalled"
    gap = np.abs(far.setpoints_kw - opf).max()
    assert 1.0 < gap <= far.distance_bound_kw + 1e-9


def test_exact_logit_day_reports_every_minute_stalled(peak):
    day = run_day(elv_problem(), RunSettings(dynamics="logit", mode="exact", eta=1.0),
                  minutes=np.array([PEAK_MINUTE, PEAK_MINUTE]))  # fmt: skip
    assert not day.converged.any()
    assert day.status == "stalled"
    assert set(day.stall_reasons) == {PEAK_MINUTE}
    assert (day.distance_bound_kw > 0.0).all()


def test_paper_logit_and_bnn_converge_to_their_rest(peak):
    """Paper mode claims only the dynamics' own rest: logit and BNN come to rest (converged)
    on minute 566 and keep supply equal to demand."""
    for options in ({"dynamics": "bnn"}, {"dynamics": "logit", "eta": 0.1}):
        run = run_snapshot(peak, PEAK_MINUTE, RunSettings(**options))
        assert run.status == "converged", options
        np.testing.assert_allclose(run.setpoints_kw.sum(), run.demand_kw, rtol=1e-12)
