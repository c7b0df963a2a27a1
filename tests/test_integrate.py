"""The integrator's pieces on their own (popdispatch.integrate): the stopping rule and the
flux-limited Euler and Heun stages, each against a plain-numpy computation in the test.

The kernels are numba-compiled; they are called with the argument layout the engine uses
(``workspace`` rows, ``rules`` tuple), since that is what the engine passes today.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.integrate import (
    INFEASIBLE,
    _heun_combination,
    _limited_stage,
    _window_mean,
    _windows_agree,
    integrate,
    workspace,
)
from popdispatch.online import Engine, RunSettings, overflow_kw
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

EMPTY = np.zeros(0, dtype=np.int64)
#: ``rules`` of a complete graph (field and game codes are not read by the stages).
RULES = (0, 0, True, EMPTY, EMPTY)


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
        assert _window_mean(ring, last, 3, i) == pytest.approx(samples[-3:, i].mean(), abs=1e-15)
        expected = samples[-6:-3, i].mean()
        assert _window_mean(ring, last - 3, 3, i) == pytest.approx(expected, abs=1e-15)


def _means_ring(means: list[list[float]], window: int) -> tuple[np.ndarray, int]:
    """Samples constant within each window, the windows' means being ``means`` (oldest first)."""
    samples = np.repeat(np.array(means, dtype=float), window, axis=0)
    return _ring(samples, 3 * window)


@pytest.mark.parametrize("window", [1, 4])
def test_windows_agree_compares_the_last_two_means_per_generator(window):
    tol = 0.01
    ring, last = _means_ring([[0.0, 1.0], [0.5, 1.0], [0.5 + 0.009, 1.0 - 0.009]], window)
    assert _windows_agree(ring, last, window, tol, False)
    ring, last = _means_ring([[0.0, 1.0], [0.5, 1.0], [0.5 + 0.009, 1.0 - 0.011]], window)
    assert not _windows_agree(ring, last, window, tol, False)  # the second generator moved


def test_windows_agree_uses_means_not_samples():
    """A generator chattering by far more than tol around a fixed mean agrees."""
    window, tol = 4, 1e-6
    chatter = np.array([[1.0], [3.0]] * 6)  # period 2, mean 2 in every window of 4
    ring, last = _ring(chatter, 3 * window)
    assert _windows_agree(ring, last, window, tol, False)


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
    assert _windows_agree(ring, last, window, tol, False)  # the step alone is within tol
    assert _windows_agree(ring, last, window, tol, True) == agree


# --- the stopping rule inside integrate (a real game: the congestion snapshot) ---------------


@pytest.fixture(scope="module")
def congested():
    return elv_problem(limits=[CONGESTION_PATH])


def _run(problem, mode, **integrator_changes):
    """integrate() as the engine calls it, with history; returns (result, history, engine)."""
    engine = Engine(problem, RunSettings(mode=mode))
    integrator = replace(engine.settings.stepping, **integrator_changes)
    x = np.full(problem.n_generators, 1.0 / problem.n_generators)
    minute_problem = engine._minute_problem(PEAK_MINUTE)
    lo, hi = minute_problem[1], minute_problem[2]
    x = np.clip(x, lo, hi)
    x /= x.sum()
    history = np.empty((integrator.max_iterations + 1, len(x)))
    demand = float(problem.demand[PEAK_MINUTE - 1])
    result = integrate(
        x, engine.z, demand, engine.rules, minute_problem, engine.ws,
        engine._kernel_settings(integrator), engine.h_try, history,
    )  # fmt: skip
    return result, history[: result[0] + 1], engine, integrator


def _numpy_agree(history, k, window, tol_mw):
    recent = history[k - window + 1 : k + 1].mean(axis=0)
    middle = history[k - 2 * window + 1 : k - window + 1].mean(axis=0)
    return bool(np.all(np.abs(recent - middle) <= tol_mw))


def test_paper_mode_stops_at_the_first_iteration_whose_windows_agree(congested):
    """Paper mode has no controllers (residual 0): the run stops when the window means first
    agree within tol_kw, and its convergence iteration is the first of the last window."""
    (steps, converged_at, _, _), history, _, integrator = _run(congested, "paper")
    window, tol_mw = integrator.window, integrator.tol_kw / 1000.0
    assert 0 <= converged_at == steps - window
    assert _numpy_agree(history, steps, window, tol_mw)
    assert not any(_numpy_agree(history, k, window, tol_mw) for k in range(2 * window, steps))


def test_exact_mode_stops_only_with_every_residual_of_the_last_window_within_tol(congested):
    """Exact mode: window means agree, the tail projection too, and the overflow (part of the
    residual, evaluated at the start of each iteration) is within tol_kw over the last window."""
    (steps, converged_at, first, _), history, _, integrator = _run(congested, "exact")
    window, tol_kw = integrator.window, integrator.tol_kw
    assert 0 <= converged_at == steps - window and first >= 1
    assert steps >= 3 * window  # the extrapolating rule needs three windows
    assert _numpy_agree(history, steps, window, tol_kw / 1000.0)
    starts = history[steps - window : steps]  # states each of the last window's iterations began
    overflow = np.array([overflow_kw(congested, p, PEAK_MINUTE) for p in starts])
    assert overflow.max(initial=0.0) <= tol_kw + 1e-12


def test_not_converged_within_the_horizon(congested):
    (steps, converged_at, _, _), history, _, _ = _run(congested, "paper", max_iterations=7)
    assert (steps, converged_at) == (7, -1) and len(history) == 8


def test_a_price_past_its_cap_stops_the_run_as_infeasible(congested):
    engine = Engine(congested, RunSettings(mode="exact"))
    assert np.isfinite(engine.z_cap)
    (steps, converged_at, first, _), _, engine, _ = _run_capped(congested, 1e-9)
    assert converged_at == INFEASIBLE
    assert 1 <= first <= steps and engine.z.max() > 1e-9


def _run_capped(problem, z_cap):
    engine = Engine(problem, RunSettings(mode="exact"))
    engine.z_cap = z_cap
    integrator = engine.settings.stepping
    x = np.full(problem.n_generators, 1.0 / problem.n_generators)
    minute_problem = engine._minute_problem(PEAK_MINUTE)
    x = np.clip(x, minute_problem[1], minute_problem[2])
    x /= x.sum()
    result = integrate(
        x, engine.z, float(problem.demand[PEAK_MINUTE - 1]), engine.rules, minute_problem,
        engine.ws, engine._kernel_settings(integrator), engine.h_try, np.empty((0, len(x))),
    )  # fmt: skip
    return result, None, engine, integrator


# --- flux-limited stages on hand-made states -------------------------------------------------


def _numpy_flows(f, w, v):
    """inflow_i = w_i sum_j [f_i - f_j]_+ v_j, outflow_j = v_j sum_i [f_i - f_j]_+ w_i"""
    gap = np.maximum(f[:, None] - f[None, :], 0.0)  # gap[i, j] = [f_i - f_j]_+
    return w * (gap @ v), v * (gap.T @ w)


def _state(rng, n):
    """Shares on the simplex with box limits, the capacity-Smith weights, fitness, raw flows."""
    x = rng.dirichlet(np.ones(n))
    lo = x * rng.uniform(0.0, 1.0, n)
    hi = x + rng.uniform(0.0, 1.0, n)
    at_lo, at_hi = rng.random(n) < 0.25, rng.random(n) < 0.25
    lo[at_lo] = x[at_lo]  # some strategies rest at a limit
    hi[at_hi & ~at_lo] = x[at_hi & ~at_lo]
    room = np.maximum(hi - x, 0.0)
    w = (room > 0).astype(float)
    v = np.maximum(x - lo, 0.0)
    f = rng.normal(0, 1, n)
    return x, lo, hi, f, w, v, room


def _fill(ws, point, f, w, v, room):
    vectors, _, _, order, _, _ = ws
    base = 7 * point
    inflow, outflow = _numpy_flows(f, w, v)
    for k, row in enumerate((f, w, v, room, inflow, outflow), start=1):
        vectors[base + k][:] = row
    order[point][:] = np.argsort(f, kind="mergesort")
    return inflow, outflow


def _check_domain(x_out, x, lo, hi):
    n = len(x)
    assert abs(x_out.sum() - x.sum()) <= 8 * n * np.finfo(float).eps
    assert np.all(x_out >= lo - 4 * np.finfo(float).eps)
    assert np.all(x_out <= hi + 4 * np.finfo(float).eps)


@settings(deadline=None)  # the first example compiles the kernel
@given(st.integers(2, 12), st.integers(0, 2**32 - 1), st.floats(1e-4, 50.0))
def test_limited_euler_stage_matches_numpy_and_stays_in_the_domain(n, seed, h):
    rng = np.random.default_rng(seed)
    x, lo, hi, f, w, v, room = _state(rng, n)
    ws = workspace(n, 0, 0, 1)
    inflow, outflow = _fill(ws, 0, f, w, v, room)
    x_out, z, z_out = np.empty(n), np.zeros(0), np.zeros(0)
    _limited_stage(0, h, x.copy(), z, RULES, ws, x_out, z_out)
    # plain numpy: scale senders that would overdraw, receivers that would overfill
    v2 = np.where(h * outflow > v, v * v / np.where(outflow > 0, h * outflow, 1.0), v)
    w2 = np.where(h * inflow > room, w * room / np.where(inflow > 0, h * inflow, 1.0), w)
    in2, out2 = _numpy_flows(f, w2, v2)
    expected = x + h * (in2 - out2)
    scale = h * (np.abs(in2) + np.abs(out2)).max(initial=0.0) + 1.0
    np.testing.assert_allclose(x_out, expected, rtol=0, atol=64 * n * np.finfo(float).eps * scale)
    _check_domain(x_out, x, lo, hi)


def test_limited_euler_stage_is_plain_euler_away_from_the_limits():
    f = np.array([0.0, 1.0, 2.0])
    x, lo, hi = np.full(3, 1 / 3), np.zeros(3), np.ones(3)
    w, v, room = np.ones(3), x - lo, hi - x
    ws = workspace(3, 0, 0, 1)
    inflow, outflow = _fill(ws, 0, f, w, v, room)
    x_out = np.empty(3)
    _limited_stage(0, 0.01, x, np.zeros(0), RULES, ws, x_out, np.zeros(0))
    # by hand: inflow = (0, 1/3, 2/3 + 1/3), outflow = (1/3 * (1 + 2), 1/3 * 1, 0)
    np.testing.assert_allclose(inflow, [0, 1 / 3, 1.0], rtol=1e-15)
    np.testing.assert_allclose(outflow, [1.0, 1 / 3, 0], rtol=1e-15)
    np.testing.assert_allclose(x_out, x + 0.01 * np.array([-1.0, 0.0, 1.0]), rtol=0, atol=1e-16)


def test_limited_euler_stage_empties_a_sender_exactly_and_keeps_prices_non_negative():
    f = np.array([0.0, 1.0])
    x, lo, hi = np.array([0.2, 0.8]), np.zeros(2), np.array([1.0, 10.0])
    ws = workspace(2, 0, 2, 1)
    ws[1][0][:] = [-5.0, 3.0]  # price rates of point 0
    _fill(ws, 0, f, np.ones(2), x - lo, hi - x)  # outflow of 0: 0.2 per s
    x_out, z_out = np.empty(2), np.empty(2)
    _limited_stage(0, 5.0, x, np.array([1.0, 1.0]), RULES, ws, x_out, z_out)
    # 5 s would move 1.0 out of a sender holding 0.2: it is scaled to empty exactly
    np.testing.assert_allclose(x_out, [0.0, 1.0], rtol=0, atol=4 * np.finfo(float).eps)
    np.testing.assert_array_equal(z_out, [0.0, 16.0])  # 1 - 25 projected to 0; 1 + 15


def test_limited_euler_stage_with_both_ends_limited_stays_inside():
    """Sender and receiver both limited: both weights scale, the pair's flow is the product of
    both scalings, so the stage lands inside the domain, short of both limits."""
    f = np.array([0.0, 1.0])
    x, lo, hi = np.array([0.2, 0.8]), np.zeros(2), np.ones(2)
    ws = workspace(2, 0, 0, 1)
    _fill(ws, 0, f, np.ones(2), x - lo, hi - x)
    x_out = np.empty(2)
    _limited_stage(0, 100.0, x, np.zeros(0), RULES, ws, x_out, np.zeros(0))
    moved = 100.0 * (0.2 * 0.2 / 20.0) * (1.0 * 0.2 / 20.0)  # h * v2 * w2 * gap
    np.testing.assert_allclose(x_out, [0.2 - moved, 0.8 + moved], rtol=1e-14)
    _check_domain(x_out, x, lo, hi)


@settings(deadline=None)  # the first example compiles the kernel
@given(st.integers(2, 12), st.integers(0, 2**32 - 1), st.floats(1e-4, 50.0))
def test_heun_combination_matches_numpy_and_stays_in_the_domain(n, seed, h):
    rng = np.random.default_rng(seed)
    x, lo, hi, f1, w1, v1, room1 = _state(rng, n)
    ws = workspace(n, 0, 0, 1)
    in1, out1 = _fill(ws, 0, f1, w1, v1, room1)
    x1 = x + 0.1 * (rng.dirichlet(np.ones(n)) - x)  # some second evaluation point
    f2, w2, v2 = rng.normal(0, 1, n), (rng.random(n) < 0.8).astype(float), np.maximum(x1 - lo, 0)
    in2, out2 = _fill(ws, 1, f2, w2, v2, np.maximum(hi - x1, 0.0))
    x_out = np.empty(n)
    _heun_combination(h, x.copy(), np.zeros(0), RULES, ws, x_out, np.zeros(0))
    half = 0.5 * h
    out, into = half * (out1 + out2), half * (in1 + in2)
    alpha = np.where(out > v1, v1 / np.where(out > 0, out, 1.0), 1.0)
    beta = np.where(into > room1, room1 / np.where(into > 0, into, 1.0), 1.0)
    s_in1, s_out1 = _numpy_flows(f1, beta * w1, alpha * v1)
    s_in2, s_out2 = _numpy_flows(f2, beta * w2, alpha * v2)
    expected = x + half * (s_in1 - s_out1 + s_in2 - s_out2)
    scale = half * np.abs(np.concatenate([s_in1, s_out1, s_in2, s_out2])).max() + 1.0
    np.testing.assert_allclose(x_out, expected, rtol=0, atol=64 * n * np.finfo(float).eps * scale)
    _check_domain(x_out, x, lo, hi)
