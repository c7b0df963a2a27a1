"""Vector fields by name: every dynamic names a :class:`Field`, and each field's compiled
weights equal the plain-numpy reference's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from popdispatch.dynamics import DYNAMICS, Dynamics, Field, field_rate
from popdispatch.dynamics.fields import rated_field_weights
from popdispatch.reference import pair_flows, weights


def test_every_dynamic_names_fields_and_nothing_unread():
    names = {f.name for f in dataclasses.fields(Dynamics)}
    assert names == {"name", "field", "uses_graph", "bounded_field"}
    used = {d.field for d in DYNAMICS.values()} | {d.bounded_field for d in DYNAMICS.values()}
    # exact mode's curvature-scaled revision replaces the bounded fields (RunSettings.field)
    assert used - {None} | {Field.CAPACITY_NEWTON} == set(Field)


@pytest.mark.parametrize("field", list(Field))
def test_compiled_weights_equal_the_reference(field):
    rng = np.random.default_rng(int(field))
    n = 7
    x = rng.dirichlet(np.ones(n))
    lo, hi = x * rng.uniform(0, 1, n), x + rng.uniform(0, 1, n)
    lo[0] = hi[0] = x[0]  # no width: takes no part in the capacity field
    active = rng.random(n) < 0.8
    rates = 10.0 ** rng.uniform(-3, 2, n)  # revision rates (read by the curvature-scaled field)
    w, v, room, mass = (np.empty(n) for _ in range(4))
    rated_field_weights(int(field), x, lo, hi, active, rates, w, v, room, mass)
    expected = weights(field, x, lo, hi, active, rates)
    for compiled, value in zip((w, v, room, mass), expected, strict=True):
        np.testing.assert_allclose(compiled, value, rtol=1e-15, atol=0)
    f = rng.normal(0, 1, n)
    complete = np.ones((n, n)) - np.eye(n)
    inflow, outflow = pair_flows(f, *expected[:2], complete)
    rate = field_rate(field, x, f, complete, lo, hi, active, rates)
    np.testing.assert_allclose(rate, inflow - outflow, rtol=0, atol=1e-13)


def test_a_strategy_a_few_ulp_below_its_upper_limit_is_at_it():
    """Capacity-constrained Smith: room of at most ROOM_ULPS units in the last place of ``hi``
    is no room (no receiver weight), so round-off left by the limiter's landing does not make
    a full generator a receiver; a strategy a little further below still is one."""
    from popdispatch.dynamics.capacity import ROOM_ULPS, capacity_smith_weights

    hi = np.array([0.7, 0.7, 0.7, 0.5])
    ulp = np.spacing(0.7)
    x = np.array([0.7 - 2 * ulp, 0.7 - ROOM_ULPS * ulp, 0.7 - 2 * ROOM_ULPS * ulp, 0.1])
    lo = np.zeros(4)
    w, v, room = np.empty(4), np.empty(4), np.empty(4)
    capacity_smith_weights(x, lo, hi, np.ones(4, dtype=bool), w, v, room)
    np.testing.assert_array_equal(w, [0.0, 0.0, 1.0, 1.0])
    np.testing.assert_array_equal(room[:2], [0.0, 0.0])
    assert room[2] == hi[2] - x[2] > 0.0
    np.testing.assert_array_equal(v, x - lo)  # the senders' side is untouched
