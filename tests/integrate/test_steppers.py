"""The steppers' flux-limited stages on their own (popdispatch.integrate.steppers): the limited
Euler stage and the Heun combination on hand-made states, against plain numpy in the test,
called with the arrays the steppers take out of the named records (:class:`Workspace`,
:class:`Term`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.dynamics.fields import Field
from popdispatch.game.parameters import GameParameters, MinuteInputs
from popdispatch.integrate import Term, workspace
from popdispatch.integrate.steppers import (
    HEUN_STEP,
    QUIET_MOTION,
    STEP_FLOOR,
    SWITCH_CAPS,
    SWITCH_TURN,
    euler_steps,
    heun_combination,
    next_step,
    stiffness,
)
from popdispatch.modes import ModeCode, mode_tag

EMPTY = np.zeros(0, dtype=np.int64)
#: Smith on the complete graph (the stages read the field's sums, not the mode).
RULES = Term.of(Field.SMITH, mode_tag(ModeCode.PAPER), True, EMPTY, EMPTY)


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


def _limited(ws, h, x, z, x_out, z_out):
    """One limited Euler step (euler_steps without an evaluation) on the first stage of
    ``ws``, which holds the field at ``x`` already; the game (no lines) is not evaluated."""
    n = len(x)
    vector, lines = np.zeros(n), np.zeros(0)
    params = GameParameters(b=vector, c=vector, pmin=vector, pmax=vector, B=0.0, m=0.0, C=0.0,
                            gain=1.0, price_rate=0.0, limit=lines, generator_line=EMPTY,
                            line_up=EMPTY, line_preorder=EMPTY)  # fmt: skip
    minute = MinuteInputs(demand=1.0, load_flow=lines, lo=vector, hi=vector,
                          active=np.ones(n, dtype=bool), below=lines, tradable=0.0)  # fmt: skip
    one = ws.first
    euler_steps(1, False, h, x, z, RULES, params, minute, *one, ws.first_limited, ws.game,
                ws.counters.evaluations, x_out, z_out)  # fmt: skip


def _fill(ws, point, f, w, v, room):
    stage = ws.first if point == 0 else ws.second
    inflow, outflow = _numpy_flows(f, w, v)
    # the sender weight is the movable mass here, as for (capacity) Smith
    for name, row in zip(("f", "w", "v", "room", "mass", "inflow", "outflow"),
                         (f, w, v, room, v, inflow, outflow), strict=True):  # fmt: skip
        getattr(stage, name)[:] = row
    stage.order[:] = np.argsort(f, kind="mergesort")
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
    _limited(ws, h, x.copy(), z, x_out, z_out)
    # plain numpy: scale senders that would overdraw, then receivers that would overfill with
    # the limited senders' flows
    v2 = np.where(h * outflow > v, v * v / np.where(outflow > 0, h * outflow, 1.0), v)
    into = _numpy_flows(f, w, v2)[0]
    w2 = np.where(h * into > room, w * room / np.where(into > 0, h * into, 1.0), w)
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
    _limited(ws, 0.01, x, np.zeros(0), x_out, np.zeros(0))
    # by hand: inflow = (0, 1/3, 2/3 + 1/3), outflow = (1/3 * (1 + 2), 1/3 * 1, 0)
    np.testing.assert_allclose(inflow, [0, 1 / 3, 1.0], rtol=1e-15)
    np.testing.assert_allclose(outflow, [1.0, 1 / 3, 0], rtol=1e-15)
    np.testing.assert_allclose(x_out, x + 0.01 * np.array([-1.0, 0.0, 1.0]), rtol=0, atol=1e-16)


def test_limited_euler_stage_empties_a_sender_exactly_and_keeps_prices_non_negative():
    f = np.array([0.0, 1.0])
    x, lo, hi = np.array([0.2, 0.8]), np.zeros(2), np.array([1.0, 10.0])
    ws = workspace(2, 0, 2, 1)
    ws.first.z_rate[:] = [-5.0, 3.0]  # price rates of point 0
    _fill(ws, 0, f, np.ones(2), x - lo, hi - x)  # outflow of 0: 0.2 per s
    x_out, z_out = np.empty(2), np.empty(2)
    _limited(ws, 5.0, x, np.array([1.0, 1.0]), x_out, z_out)
    # 5 s would move 1.0 out of a sender holding 0.2: it is scaled to empty exactly
    np.testing.assert_allclose(x_out, [0.0, 1.0], rtol=0, atol=4 * np.finfo(float).eps)
    np.testing.assert_array_equal(z_out, [0.0, 16.0])  # 1 - 25 projected to 0; 1 + 15


def test_limited_euler_stage_with_both_ends_limited_lands_on_both_limits():
    """Sender and receiver both limited: the sender's factor first, the receiver's from the
    limited sender's flow, so the pair is scaled once and both land exactly on their limits.
    (With both factors from the unlimited flows, as until issue 13, the pair was scaled
    twice: 100 s here moved 2e-5 instead of 0.2; docs/agents.md, "Status".)"""
    f = np.array([0.0, 1.0])
    x, lo, hi = np.array([0.2, 0.8]), np.zeros(2), np.array([1.0, 1.0])
    ws = workspace(2, 0, 0, 1)
    _fill(ws, 0, f, np.ones(2), x - lo, hi - x)  # mass 0.2 to move, room 0.2: both limited
    x_out = np.empty(2)
    _limited(ws, 100.0, x, np.zeros(0), x_out, np.zeros(0))
    np.testing.assert_allclose(x_out, [0.0, 1.0], rtol=0, atol=4 * np.finfo(float).eps)
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
    one, two = ws.first, ws.second
    heun_combination(h, x.copy(), np.zeros(0), *one[1:], two.f, two.w, two.v, two.room, two.mass,
                     two.inflow, two.outflow, two.z_rate, two.order, ws.first_limited,
                     ws.second_limited, RULES.field, RULES.graph, x_out, np.zeros(0))  # fmt: skip
    half = 0.5 * h
    out, into = half * (out1 + out2), half * (in1 + in2)
    alpha = np.where(out > v1, v1 / np.where(out > 0, out, 1.0), 1.0)
    if (alpha < 1.0).any():  # receivers from the limited senders' flows
        into = half * (_numpy_flows(f1, w1, alpha * v1)[0] + _numpy_flows(f2, w2, alpha * v2)[0])
    beta = np.where(into > room1, room1 / np.where(into > 0, into, 1.0), 1.0)
    s_in1, s_out1 = _numpy_flows(f1, beta * w1, alpha * v1)
    s_in2, s_out2 = _numpy_flows(f2, beta * w2, alpha * v2)
    expected = x + half * (s_in1 - s_out1 + s_in2 - s_out2)
    scale = half * np.abs(np.concatenate([s_in1, s_out1, s_in2, s_out2])).max() + 1.0
    np.testing.assert_allclose(x_out, expected, rtol=0, atol=64 * n * np.finfo(float).eps * scale)
    _check_domain(x_out, x, lo, hi)


def test_a_rate_measured_across_a_small_jump_does_not_shrink_the_steps_without_end():
    """Across a jump of the field the measured rate grows as ``1 / h``: with a jump below
    :data:`SWITCH_TURN` times the field, each stiffness cap shrank the next step by the same
    factor (a random star on which distributed Smith slid along a relay's switch: steps of
    1e-20 s that no longer advanced the clock). Capping below the step floor counts as a
    switch, so the steps stop at the floor, as the Heun iteration applies it."""
    dt, h, switches = 0.01, 1e-3, 0
    assert SWITCH_TURN > 2.8
    for _ in range(20_000):
        h, switches = next_step(h, 1e-6, 2.8 / h, switches, dt)
        h = max(h, STEP_FLOOR * dt) if switches > SWITCH_CAPS else h
    assert h >= STEP_FLOOR * dt
    assert switches > SWITCH_CAPS


def test_a_steady_linear_rate_is_capped_and_counts_no_switch():
    dt, h, switches = 0.01, 1e-5, 0
    for _ in range(1_000):
        h, switches = next_step(h, 1e-6, 5e4, switches, dt)
    assert h == HEUN_STEP / 5e4
    assert switches == 0


def _measured_rate(h, x, k1, k2, rtol=1e-4, atol=1e-8):
    """:func:`stiffness` of a step of ``h`` whose two stages' fields (shares per s) are ``k1``
    and ``k2``, no prices, the limiter nowhere near."""
    room = np.ones_like(x)
    zero = np.zeros(0)
    return stiffness(h, x, zero, room, room, np.maximum(k1, 0), np.maximum(-k1, 0), zero,
                     np.maximum(k2, 0), np.maximum(-k2, 0), zero, rtol, atol, 1e-4)  # fmt: skip


def test_a_linear_rate_is_measured_and_round_off_at_rest_is_not():
    """A displacement decaying at ``lam`` is measured as ``lam``; a field of round-off (a state
    at rest, each evaluation's field a different few units of the last place) measures no
    rate: read as ``||k2 - k1|| / (h ||k1||)`` it is about ``1 / h`` at any step, which held
    the steps at rest where they were (1e-6 s on the synthetic 1k feeder x100)."""
    rng = np.random.default_rng(3)
    x = np.array([0.3, 0.3, 0.4])
    h, lam = 1e-3, 50.0
    k1 = -lam * np.array([1e-3, -2e-3, 1e-3])
    assert _measured_rate(h, x, k1, k1 * (1 - h * lam)) == pytest.approx(lam, rel=1e-9)
    scale = 1e-8 + 1e-4 * x
    for _ in range(100):
        noise1, noise2 = (rng.normal(0, 1, 3) * 1e-16 for _ in range(2))
        assert h * np.linalg.norm(noise1 / scale) < QUIET_MOTION
        assert _measured_rate(h, x, noise1, noise2) == 0.0
