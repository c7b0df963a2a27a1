"""The distance certificate (popdispatch.online.certificate) against an exact DC-OPF found by
enumerating active sets (tests/qp_exact.py): whatever the end state and the prices, the bound
it proves is at least the true distance; at an exact optimum with its own prices it proves the
optimum to round-off."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from popdispatch.online.certificate import Batch, certify_minutes

from helpers import random_fleet_problem
from qp_exact import exact_dc_opf


def _certify(problem, p, mu, accuracy=1e-6):
    return certify_minutes(problem, np.array([1]), p[None], mu[None], np.array([accuracy]))[0]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(2, 5), st.integers(0, 2),
       st.floats(1e-9, 0.5), st.floats(0.0, 1.0))  # fmt: skip
def test_the_bound_is_never_below_the_true_distance(seed, n_gens, n_limits, scale, price_scale):
    problem = random_fleet_problem(seed, n_gens, n_limits)
    optimum = exact_dc_opf(problem)
    assume(optimum is not None)
    rng = np.random.default_rng(seed + 1)
    batch = Batch.of(problem, np.array([1]))
    lo, hi = batch.lo[0], batch.hi[0]
    # an end state: the optimum with mass moved between random pairs (balance kept)
    p = optimum.copy()
    for _ in range(3):
        i, j = rng.choice(len(p), 2, replace=False)
        move = min(scale * float(rng.random()) * max(hi.max(), 1e-3), p[j] - lo[j], hi[i] - p[i])
        p[i] += move
        p[j] -= move
    mu = rng.exponential(1.0, batch.A.shape[0]) * price_scale * 50.0
    mu[rng.random(len(mu)) < 0.5] = 0.0
    certificate = _certify(problem, p, mu)
    distance = np.abs(p - optimum)
    assert (certificate.bound_mw >= distance - 1e-9 * max(1.0, hi.max())).all(), (
        certificate, p, optimum)  # fmt: skip


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(2, 5), st.integers(0, 2))
def test_the_exact_optimum_proves_itself_to_round_off(seed, n_gens, n_limits):
    """At the optimum, with the controllers' prices near the optimal line duals (here: none,
    the polish finds them), every generator is proved within 1e-9 of the demand."""
    problem = random_fleet_problem(seed, n_gens, n_limits)
    optimum = exact_dc_opf(problem)
    assume(optimum is not None)
    batch = Batch.of(problem, np.array([1]))
    excess = batch.e0[0] + batch.A @ optimum
    mu = np.where(excess > -1e-9, 1.0, 0.0)  # a price on each line at its limit
    demand = float(problem.demand[0])
    certificate = _certify(problem, optimum, mu, accuracy=1e-12 * demand)
    assert certificate.reason is None
    assert certificate.distance_mw <= 1e-7 * demand


def test_an_end_state_beyond_a_limit_without_a_kkt_point_near_it_proves_nothing():
    problem = random_fleet_problem(3, 4, 1)
    optimum = exact_dc_opf(problem)
    assert optimum is not None
    batch = Batch.of(problem, np.array([1]))
    line = int(np.argmax(np.abs(problem.down).sum(axis=1)))
    below = np.flatnonzero(problem.down[line])
    p = optimum.copy()
    p[below] = batch.lo[0][below]  # the generators below the limited line at their minimum
    p[0] += optimum[below].sum() - p[below].sum()  # the source makes up for them
    excess = batch.e0[0] + batch.A @ p
    if excess.max() <= 1e-6:
        return  # that line was not binding: nothing beyond a limit to show
    certificate = _certify(problem, p, np.zeros(batch.A.shape[0]), accuracy=1e-9)
    assert certificate.distance_mw >= np.abs(p - optimum).max() - 1e-12
