"""Warm starts between minutes on their own (popdispatch.warm_start), against hand-computed
and plain-numpy expectations, plus property tests whose tolerances follow from the functions'
own arithmetic (a few roundings per element and sum; see each test).

The functions are numba-compiled and update ``x`` in place; they are called as the day loop
calls them.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.dynamics.capacity import project_to_box
from popdispatch.warm_start import (
    SETPOINTS,
    SHARES,
    continue_setpoints,
    redistribute_offline,
    warm_start,
)

EPS = np.finfo(float).eps


# --- redistribute_offline ---------------------------------------------------------------------


def test_offline_mass_goes_to_online_generators_in_proportion_to_their_shares():
    x = np.array([0.2, 0.3, 0.5])
    redistribute_offline(x, np.array([True, False, True]))
    np.testing.assert_allclose(x, [0.2 / 0.7, 0.0, 0.5 / 0.7], rtol=2 * EPS)


def test_offline_mass_is_spread_evenly_when_online_generators_hold_nothing():
    x = np.array([0.0, 1.0, 0.0, 0.0])
    redistribute_offline(x, np.array([True, False, True, False]))
    np.testing.assert_array_equal(x, [0.5, 0.0, 0.5, 0.0])


def test_nothing_changes_when_no_offline_generator_holds_mass():
    x = np.array([0.2, 0.0, 0.8])
    redistribute_offline(x, np.array([True, False, True]))
    np.testing.assert_array_equal(x, [0.2, 0.0, 0.8])


@settings(deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=2, max_size=10), st.data())
def test_redistribution_property(raw, data):
    n = len(raw)
    active = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    if not active.any():
        active[0] = True
    x = np.array(raw)
    if x.sum() == 0:
        x[0] = 1.0
    x /= x.sum()
    before = x.copy()
    redistribute_offline(x, active)
    assert np.all(x[~active] == 0.0)
    # one division per element after one sum of n terms: n + 1 roundings
    assert abs(x.sum() - 1.0) <= 2 * (n + 1) * EPS
    if before[active].sum() > 0 and before[~active].sum() > 0:
        expected = before[active] / before[active].sum()  # plain numpy
        np.testing.assert_allclose(x[active], expected, rtol=2 * (n + 1) * EPS)


# --- share continuation: projection onto {lo <= x <= hi, sum x = 1} ---------------------------


def test_projection_by_hand():
    # x - s clipped to the box sums to 1 at s = -0.05 (first generator capped at 0.4)
    y = project_to_box(np.array([0.5, 0.5, 0.0]), np.zeros(3), np.array([0.4, 1.0, 1.0]))
    np.testing.assert_allclose(y, [0.4, 0.55, 0.05], rtol=0, atol=8 * EPS)


@settings(deadline=None)
@given(st.integers(2, 10), st.integers(0, 2**32 - 1))
def test_projection_property(n, seed):
    rng = np.random.default_rng(seed)
    lo = rng.dirichlet(np.ones(n)) * rng.uniform(0, 1)  # sum lo <= 1 <= sum hi
    hi = lo + rng.dirichlet(np.ones(n)) * rng.uniform(1 - lo.sum(), 2)
    x = rng.dirichlet(np.ones(n)) * rng.uniform(0.5, 1.5)  # off the simplex too
    y = project_to_box(x, lo, hi)
    assert np.all(y >= lo) and np.all(y <= hi)  # clipped by min/max: exact
    # bisection on the shift ends at adjacent floats: each free share is off by a few ulps of
    # the shift's scale (at most max|x| + max hi + 1, the initial bracket)
    scale = np.abs(x).max() + hi.max() + 1.0
    assert abs(y.sum() - 1.0) <= 4 * n * EPS * scale
    # a projection: the free shares all moved by the same shift, fixed ones are beyond it
    free = (y > lo) & (y < hi)
    shift = x - y
    if free.any():
        s = shift[free].mean()
        np.testing.assert_allclose(shift[free], s, rtol=0, atol=4 * EPS * scale)
        assert np.all(x[y == lo] - lo[y == lo] <= s + 4 * EPS * scale)
        assert np.all(x[y == hi] - hi[y == hi] >= s - 4 * EPS * scale)


def test_share_warm_start_projects_in_bounded_modes_only():
    x = np.array([0.5, 0.5, 0.0])
    pmin, pmax, active = np.zeros(3), np.array([4.0, 10.0, 10.0]), np.ones(3, dtype=bool)
    unbounded = x.copy()
    warm_start(SHARES, False, unbounded, 8.0, 10.0, pmin, pmax, active, np.empty(3))
    np.testing.assert_array_equal(unbounded, x)  # paper mode: the shares just continue
    bounded = x.copy()
    warm_start(SHARES, True, bounded, 8.0, 10.0, pmin, pmax, active, np.empty(3))
    np.testing.assert_allclose(bounded, [0.4, 0.55, 0.05], rtol=0, atol=8 * EPS)


# --- set-point continuation ---------------------------------------------------------------------


def _continue(p_old, demand, pmin, pmax, active=None):
    n = len(p_old)
    active = np.ones(n, dtype=bool) if active is None else np.asarray(active)
    old_demand = float(np.sum(p_old))
    x = np.asarray(p_old, dtype=float) / old_demand
    continue_setpoints(x, old_demand, demand, np.asarray(pmin, float), np.asarray(pmax, float),
                       active, np.empty(n))  # fmt: skip
    return x * demand


def test_demand_step_shared_by_trading_generators_in_proportion_to_their_weight():
    # weights (p - Pmin)(Pmax - p): 5*5 = 25, 2*8 = 16; the third rests at Pmax and stays
    p = _continue([5.0, 2.0, 10.0], 18.0, [0, 0, 0], [10, 10, 10])
    np.testing.assert_allclose(p, [5 + 25 / 41, 2 + 16 / 41, 10.0], rtol=0, atol=64 * EPS)


def test_demand_step_water_filled_at_a_limit():
    # weights 4.75, 25: step 4 would carry the first to 10.139 > Pmax; it stops at 10 and the
    # rest (4 - 0.5 - 3.361...) goes to the second: final [10, 8.5, 0]
    p = _continue([9.5, 5.0, 0.0], 18.5, [0, 0, 0], [10, 10, 10])
    np.testing.assert_allclose(p, [10.0, 8.5, 0.0], rtol=0, atol=64 * EPS)


def test_demand_step_by_headroom_when_no_generator_is_trading():
    p = _continue([0.0, 10.0, 10.0], 25.0, [0, 0, 0], [10, 10, 10])
    np.testing.assert_allclose(p, [5.0, 10.0, 10.0], rtol=0, atol=64 * EPS)
    # a decrease by the room above Pmin: 0, 10, 4 share -2
    p = _continue([2.0, 10.0, 4.0], 14.0, [2, 0, 0], [10, 10, 4])
    np.testing.assert_allclose(p, [2.0, 10 - 20 / 14, 4 - 8 / 14], rtol=0, atol=64 * EPS)


def test_offline_generator_continues_at_zero():
    p = _continue([3.0, 3.0, 4.0], 11.0, [1, 1, 1], [10, 10, 10], [True, True, False])
    # the offline one holds 4 at the old demand: clipped to 0, so the step is 11 - 6 = 5, shared
    # in proportion to (3 - 1)(10 - 3) = 14 each
    np.testing.assert_allclose(p, [5.5, 5.5, 0.0], rtol=0, atol=64 * EPS)


def test_setpoint_warm_start_without_previous_demand_projects_shares():
    x = np.array([0.5, 0.5, 0.0])
    pmin, pmax, active = np.zeros(3), np.array([4.0, 10.0, 10.0]), np.ones(3, dtype=bool)
    warm_start(SETPOINTS, True, x, 0.0, 10.0, pmin, pmax, active, np.empty(3))
    np.testing.assert_allclose(x, [0.4, 0.55, 0.05], rtol=0, atol=8 * EPS)


@settings(deadline=None)
@given(st.integers(2, 10), st.integers(0, 2**32 - 1), st.floats(0.0, 1.0))
def test_setpoint_continuation_property(n, seed, where):
    rng = np.random.default_rng(seed)
    pmin = rng.uniform(0, 2, n)
    pmax = pmin + rng.uniform(0.5, 10, n)
    p_old = pmin + rng.uniform(0, 1, n) * (pmax - pmin)
    resting = rng.random(n) < 0.3
    p_old[resting] = np.where(rng.random(n) < 0.5, pmin, pmax)[resting]
    demand = pmin.sum() + where * (pmax - pmin).sum()
    p = _continue(p_old, demand, pmin, pmax)
    # p is clipped by min/max, then x = p / demand and x * demand: two roundings of each p
    assert np.all(p >= pmin * (1 - 2 * EPS)) and np.all(p <= pmax * (1 + 2 * EPS))
    # the step is placed in at most n + 1 rounds of n additions each, every term <= max pmax
    tol = 2 * (n + 1) * n * EPS * pmax.max() + 2 * n * EPS * demand
    assert abs(p.sum() - demand) <= tol
    step = demand - p_old.sum()
    weight = (p_old - pmin) * (pmax - p_old)
    trading = weight > 0
    room = (pmax - p_old) if step > 0 else (p_old - pmin)
    if trading.any() and abs(step) <= room[trading].sum() - tol:
        # the trading generators absorb the step: those resting at a limit stay, up to the
        # rounding residual of the first pass, which the headroom pass then spreads: within a
        # few tol (measured 2.6 tol: n=2, seed=28010, where=0.75)
        np.testing.assert_allclose(p[~trading], p_old[~trading], rtol=0, atol=4 * tol)
        moved = p - p_old
        assert np.all(moved[trading] * step >= -tol)  # every trading one moves with the step


# --- the demand step in merit order (exact mode's day loop) -------------------------------------


def _economic_dispatch(demand, b, c, pmin, pmax):
    """The yardstick: min sum(b p + c p^2) s.t. sum p = demand, pmin <= p <= pmax, by Clarabel
    (an interior-point QP solver, independent of the bisection under test)."""
    import clarabel
    from scipy import sparse

    n = len(b)
    eye = sparse.eye(n)
    A = sparse.vstack([sparse.csr_matrix(np.ones((1, n))), -eye, eye]).tocsc()
    rhs = np.concatenate([[demand], -pmin, pmax])
    cones = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(2 * n)]
    options = clarabel.DefaultSettings()
    options.verbose = False
    options.tol_gap_abs = options.tol_gap_rel = options.tol_feas = 1e-12
    P = sparse.csc_matrix(sparse.diags(2.0 * c))
    solution = clarabel.DefaultSolver(P, b.astype(float), A, rhs, cones, options).solve()
    assert str(solution.status) == "Solved"
    return np.clip(np.asarray(solution.x), pmin, pmax)


def _merit(p_old, demand, b, c, pmin, pmax):
    old_demand = float(np.sum(p_old))
    x = np.asarray(p_old, dtype=float) / old_demand
    n = len(x)
    continue_setpoints(x, old_demand, demand, pmin, pmax, np.ones(n, dtype=bool), np.empty(n),
                       b, c)  # fmt: skip
    return x * demand


def test_merit_order_step_by_hand():
    b, c = np.array([2.0, 2.0, 3.0]), np.array([0.5, 1.0, 1.0])
    pmin, pmax = np.zeros(3), np.array([10.0, 10.0, 10.0])
    # marginal costs b + 2 c p at the start: 4, 4, 3. The price rises from 3 (the third
    # first) and then moves all three: p_i = max(p_i, (L - b_i) / (2 c_i)) with
    # (L - 2) + (L - 2) / 2 + (L - 3) / 2 = 2 L - 4.5 = 4.5, so L = 4.5
    p = _merit([2.0, 1.0, 0.0], 4.5, b, c, pmin, pmax)
    price = 4.5
    np.testing.assert_allclose(p, [price - 2, (price - 2) / 2, (price - 3) / 2], atol=64 * EPS)


@settings(deadline=None, max_examples=60)
@given(st.integers(2, 10), st.integers(0, 2**32 - 1), st.floats(0.02, 0.98), st.floats(0.02, 0.98))
def test_merit_order_step_lands_on_the_economic_dispatch(n, seed, before, after):
    """From the economic dispatch of one demand, the step lands on that of the next (no
    lines: what exact mode's day loop starts each minute from)."""
    rng = np.random.default_rng(seed)
    b = rng.uniform(1.0, 5.0, n)
    c = rng.uniform(0.005, 0.05, n)
    pmin = np.where(rng.random(n) < 0.3, rng.uniform(0.0, 2.0, n), 0.0)
    pmax = pmin + rng.uniform(1.0, 20.0, n)
    demand = [pmin.sum() + f * (pmax - pmin).sum() for f in (before, after)]
    p_old = _economic_dispatch(demand[0], b, c, pmin, pmax)
    p = _merit(p_old, demand[1], b, c, pmin, pmax)
    # Clarabel at 1e-12: its set points within about 1e-9 MW of the optimum
    np.testing.assert_allclose(p, _economic_dispatch(demand[1], b, c, pmin, pmax), atol=1e-7)
    assert abs(p.sum() - demand[1]) <= 64 * n * EPS * demand[1]
