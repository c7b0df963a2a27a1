"""Vector fields by name: every dynamic names a :class:`Field`, and each field's compiled
weights equal the plain-numpy reference's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from popdispatch.dynamics import DYNAMICS, Dynamics, Field, field_rate
from popdispatch.dynamics.fields import field_weights
from popdispatch.reference import pair_flows, weights


def test_every_dynamic_names_fields_and_nothing_unread():
    names = {f.name for f in dataclasses.fields(Dynamics)}
    assert names == {"name", "field", "uses_graph", "bounded_field"}
    used = {d.field for d in DYNAMICS.values()} | {d.bounded_field for d in DYNAMICS.values()}
    assert used - {None} == set(Field)


@pytest.mark.parametrize("field", list(Field))
def test_compiled_weights_equal_the_reference(field):
    rng = np.random.default_rng(int(field))
    n = 7
    x = rng.dirichlet(np.ones(n))
    lo, hi = x * rng.uniform(0, 1, n), x + rng.uniform(0, 1, n)
    lo[0] = hi[0] = x[0]  # no width: takes no part in the capacity field
    active = rng.random(n) < 0.8
    w, v, room = (np.empty(n) for _ in range(3))
    field_weights(field, x, lo, hi, active, w, v, room)
    for compiled, expected in zip((w, v, room), weights(field, x, lo, hi, active), strict=True):
        np.testing.assert_array_equal(compiled, expected)
    f = rng.normal(0, 1, n)
    complete = np.ones((n, n)) - np.eye(n)
    inflow, outflow = pair_flows(f, *weights(field, x, lo, hi, active)[:2], complete)
    rate = field_rate(field, x, f, complete, lo, hi, active)
    np.testing.assert_allclose(rate, inflow - outflow, rtol=0, atol=1e-14)
