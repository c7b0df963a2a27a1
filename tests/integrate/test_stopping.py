"""The stopping rule on its own (popdispatch.integrate.stopping): window means, the windows'
agreement with geometric-tail extrapolation, and the rule inside ``integrate`` on a real game
(residual over the last window, horizon, price cap), against plain numpy in the test."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from popdispatch.game.parameters import MinuteInputs
from popdispatch.integrate import Status, integrate
from popdispatch.integrate.stopping import window_mean, windows_agree
from popdispatch.online import Engine, RunSettings, overflow_kw
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

# --- window means and the windows' agreement -------------------------------------------------


def _ring(samples: np.ndarray, size: int) -> tuple[np.ndarray, int]:
    """A ring of ``size`` rows holding ``samples`` (iterations 0..k) the way integrate does."""
    ring = np.zeros((size, samples.shape[1]))
    for k, row in enumerate(samples):
        ring[k % size] = row
    return ring, len(samples) - 1


def test_window_mean_wraps_around_the_ring():
    rng = np.random.default_rng(1)
    samples = rng.random((23, 3))
    ring, last = _ring(samples, 9)  # 3 windows of 3, wrapped twice
    for i in range(3):
        assert window_mean(ring, last, 3, i) == pytest.approx(samples[-3:, i].mean(), abs=1e-15)
        expected = samples[-6:-3, i].mean()
        assert window_mean(ring, last - 3, 3, i) == pytest.approx(expected, abs=1e-15)


def _means_ring(means: list[list[float]], window: int) -> tuple[np.ndarray, int]:
    """Samples constant within each window, the windows' means being ``means`` (oldest first)."""
    samples = np.repeat(np.array(means, dtype=float), window, axis=0)
    return _ring(samples, 3 * window)


@pytest.mark.parametrize("window", [1, 4])
def test_windows_agree_compares_the_last_two_means_per_generator(window):
    tol = 0.01
    ring, last = _means_ring([[0.0, 1.0], [0.5, 1.0], [0.5 + 0.009, 1.0 - 0.009]], window)
    assert windows_agree(ring, last, window, tol, False)
    ring, last = _means_ring([[0.0, 1.0], [0.5, 1.0], [0.5 + 0.009, 1.0 - 0.011]], window)
    assert not windows_agree(ring, last, window, tol, False)  # the second generator moved


def test_windows_agree_uses_means_not_samples():
    """A generator chattering by far more than tol around a fixed mean agrees."""
    window, tol = 4, 1e-6
    chatter = np.array([[1.0], [3.0]] * 6)  # period 2, mean 2 in every window of 4
    ring, last = _ring(chatter, 3 * window)
    assert windows_agree(ring, last, window, tol, False)


@pytest.mark.parametrize(
    ("previous", "step", "agree"),
    [
        (0.008, 0.004, True),  # ratio 0.5: tail 0.004 <= tol
        (0.0044, 0.004, False),  # ratio ~0.91: tail ~0.04 > tol though the step is within tol
        (-0.008, 0.004, True),  # sign change: not a geometric tail, no projection
        (0.0, 0.004, True),  # no previous motion: no projection
    ],
)
def test_extrapolation_of_a_geometric_tail(previous, step, agree):
    window, tol = 3, 0.005
    m0 = 1.0
    ring, last = _means_ring([[m0], [m0 + previous], [m0 + previous + step]], window)
    assert windows_agree(ring, last, window, tol, False)  # the step alone is within tol
    assert windows_agree(ring, last, window, tol, True) == agree


# --- the stopping rule inside integrate (a real game: the congestion snapshot) ---------------


@pytest.fixture(scope="module")
def congested():
    return elv_problem(limits=[CONGESTION_PATH])


def _integrate(engine, integrator, history):
    """integrate() as the engine calls it, from uniform shares projected onto the limits."""
    problem = engine.problem
    minute = MinuteInputs.of(problem, PEAK_MINUTE)
    x = np.full(problem.n_generators, 1.0 / problem.n_generators)
    x = np.clip(x, minute.lo, minute.hi)
    x /= x.sum()
    return integrate(
        x, engine.z, engine.term, engine.params, minute, engine.ws,
        integrator.stepper(engine.price_scale),
        integrator.stop_rule(engine.z_cap), engine.h_try, history,
    )  # fmt: skip


def _run(problem, mode, **integrator_changes):
    """integrate() with history; returns (outcome, history, engine, integrator)."""
    engine = Engine(problem, RunSettings(mode=mode))
    integrator = replace(engine.settings.stepping, **integrator_changes)
    history = np.empty((integrator.max_iterations + 1, problem.n_generators))
    outcome = _integrate(engine, integrator, history)
    return outcome, history[: outcome.iterations + 1], engine, integrator


def _numpy_agree(history, k, window, tol_mw):
    recent = history[k - window + 1 : k + 1].mean(axis=0)
    middle = history[k - 2 * window + 1 : k - window + 1].mean(axis=0)
    return bool(np.all(np.abs(recent - middle) <= tol_mw))


def test_paper_mode_stops_at_the_first_iteration_whose_windows_agree(congested):
    """Paper mode has no controllers (residual 0): the run stops when the window means first
    agree within tol_kw, and its convergence iteration is the first of the last window."""
    outcome, history, _, integrator = _run(congested, "paper")
    steps, window, tol_mw = outcome.iterations, integrator.window, integrator.tol_kw / 1000.0
    assert outcome.status == Status.CONVERGED
    assert 0 <= outcome.converged_at == steps - window
    assert _numpy_agree(history, steps, window, tol_mw)
    assert not any(_numpy_agree(history, k, window, tol_mw) for k in range(2 * window, steps))


def test_exact_mode_stops_only_with_every_residual_of_the_last_window_within_tol(congested):
    """Exact mode: window means agree, the tail projection too, and the overflow (part of the
    residual, evaluated at the start of each iteration) is within the minute's tolerance
    (``max(tol_rel P_d, tol_kw)``) over the last window. (Without the fixed-point stop, which
    ends this run earlier.)"""
    outcome, history, _, integrator = _run(congested, "exact", fixed_point=False)
    demand_mw = float(congested.demand[PEAK_MINUTE - 1])
    steps, window = outcome.iterations, integrator.window
    tol_kw = integrator.tol_mw(demand_mw) * 1000.0
    assert tol_kw == pytest.approx(max(1e-6 * demand_mw * 1000.0, 1e-4))
    assert outcome.status == Status.CONVERGED
    assert 0 <= outcome.converged_at == steps - window and outcome.first_congestion >= 1
    assert steps >= 3 * window  # the extrapolating rule needs three windows
    assert _numpy_agree(history, steps, window, tol_kw / 1000.0)
    starts = history[steps - window : steps]  # states each of the last window's iterations began
    overflow = np.array([overflow_kw(congested, p, PEAK_MINUTE) for p in starts])
    assert overflow.max(initial=0.0) <= tol_kw + 1e-12


def test_not_converged_within_the_horizon(congested):
    outcome, history, _, _ = _run(congested, "paper", max_iterations=7)
    assert (outcome.iterations, outcome.status) == (7, Status.NOT_CONVERGED)
    assert len(history) == 8


def test_a_price_past_its_cap_stops_the_run_as_infeasible(congested):
    engine = Engine(congested, RunSettings(mode="exact"))
    assert np.isfinite(engine.z_cap)
    engine.z_cap = 1e-9
    outcome = _integrate(engine, engine.settings.stepping, np.empty((0, congested.n_generators)))
    assert outcome.status == Status.INFEASIBLE
    assert 1 <= outcome.first_congestion <= outcome.iterations and engine.z.max() > 1e-9
