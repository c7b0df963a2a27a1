"""Flow laws by name: the registry builds every field from the laws' modules, each law's
compiled weights and sums equal its plain-numpy statement and the dense all-pairs sum of the
reference, and a field no law names has no kernels (no fallback)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from numba.core.errors import TypingError

from popdispatch.dynamics import DYNAMICS, Dynamics, Field, Kernel, field_rate
from popdispatch.dynamics.fields import LAWS, MODULES, field_of, field_tag, field_weights, law_of
from popdispatch.dynamics.law import FieldTag
from popdispatch.reference import pair_flows, weights

#: The logit's parameters in the tests: noise level (fitness units) and revision rate (1/s).
LOGIT = {"eta": 0.7, "gain": 3.0}


def test_the_registry_builds_every_field_from_the_laws_modules():
    assert [law.name for law in LAWS] == [f.name for f in Field]
    assert [law for module in MODULES for law in module.LAWS] == list(LAWS)
    # the codes of the fields the agents pass at run time are kept
    kept = ("SMITH", "REPLICATOR", "LOCAL_REPLICATOR", "CAPACITY_SMITH", "CAPACITY_NEWTON")
    assert [int(Field[name]) for name in kept] == [0, 1, 2, 3, 4]
    assert {"smith", "distributed-smith", "replicator", "local-replicator", "bnn",
            "logit"} <= set(DYNAMICS)  # fmt: skip
    names = {f.name for f in dataclasses.fields(Dynamics)}
    assert names == {"name", "law", "uses_graph", "scope", "bounded_law", "refusal",
                     "rests_at_optimum", "parameters"}  # fmt: skip
    used = {d.law for d in DYNAMICS.values()} | {d.bounded_law for d in DYNAMICS.values()}
    # exact mode's curvature-scaled revision replaces capacity Smith (RunSettings.field)
    assert used - {None} | {law_of(Field.CAPACITY_NEWTON)} == set(LAWS)
    for dynamics in DYNAMICS.values():
        assert (dynamics.bounded_law is None) == bool(dynamics.refusal), dynamics.name
        assert field_of(dynamics, bounded=False) == Field[dynamics.law.name]


def random_state(seed: int, n: int = 7):
    rng = np.random.default_rng(seed)
    x = rng.dirichlet(np.ones(n))
    lo, hi = x * rng.uniform(0, 1, n), x + rng.uniform(0, 1, n)
    lo[0] = hi[0] = x[0]  # no width: takes no part in the fields with limits
    active = rng.random(n) < 0.8
    active[1] = True
    x = np.where(active, x, 0.0)
    rates = 10.0 ** rng.uniform(-3, 2, n)  # revision rates (read by the curvature-scaled field)
    return rng, x, lo, hi, active, rates


@pytest.mark.parametrize("field", list(Field), ids=lambda f: f.name)
def test_compiled_weights_and_flows_equal_the_reference(field):
    rng, x, lo, hi, active, rates = random_state(int(field))
    n = len(x)
    f = rng.normal(0, 1, n)
    tag = field_tag(field, **LOGIT)
    expected = weights(tag, x, f, lo, hi, active, rates)
    complete = np.ones((n, n)) - np.eye(n)
    kernel = law_of(field).kernel
    inflow, outflow = pair_flows(f, *expected[:2], complete, expected[3], expected[2], kernel)
    rate = field_rate(field, x, f, complete, lo, hi, active, rates, **LOGIT)
    np.testing.assert_allclose(rate, inflow - outflow, rtol=0, atol=1e-13)
    assert abs(rate.sum()) < 1e-13  # mass moves between strategies only


@pytest.mark.parametrize("field", list(Field), ids=lambda f: f.name)
def test_compiled_weights_equal_the_laws_numpy_statement(field):
    from popdispatch.dynamics import fields

    rng, x, lo, hi, active, rates = random_state(100 + int(field))
    f = rng.normal(0, 1, len(x))
    tag = field_tag(field, **LOGIT)
    compiled = _compiled_weights(fields, tag, x, f, lo, hi, active, rates)
    for got, want in zip(compiled, weights(tag, x, f, lo, hi, active, rates), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)


def _compiled_weights(fields, tag, x, f, lo, hi, active, rates):
    import numba as nb

    @nb.njit
    def run(tag, x, f, lo, hi, active, rates, w, v, room, mass):
        fields.weights(tag, x, f, lo, hi, active, rates, w, v, room, mass)

    out = tuple(np.empty(len(x)) for _ in range(4))
    run(tag, x, f, lo, hi, active, rates, *out)
    return out


class UnknownTag(FieldTag):
    """A field record no law names."""

    __slots__ = ()


def test_a_field_no_law_names_has_no_kernels():
    """The compiled stubs have no implementation for a record class no law names (numba
    refuses to type the call), and the run-time weights raise for codes they do not know:
    never another law's weights instead."""
    x = np.full(3, 1 / 3)
    with pytest.raises(TypingError):
        field_rate(UnknownTag(99), x, np.zeros(3), np.ones((3, 3)) - np.eye(3), x * 0, x * 0 + 1)
    w, v, room = (np.empty(3) for _ in range(3))
    with pytest.raises(ValueError, match="no run-time weights"):
        field_weights(int(Field.BNN), x, x * 0, x * 0 + 1, np.ones(3, dtype=bool), w, v, room)
    field_weights(int(Field.CAPACITY_SMITH), x, x * 0, x * 0 + 1, np.ones(3, dtype=bool), w, v,
                  room)  # fmt: skip
    np.testing.assert_array_equal(v, x)


def test_a_law_with_parameters_needs_them():
    with pytest.raises(ValueError, match="eta"):
        field_tag(Field.LOGIT, gain=1.0)
    assert field_tag(Field.LOGIT, eta=2.0, gain=1.0, other=5.0)[1:] == (2.0, 1.0)
    assert law_of(field_tag(Field.BOX_LOGIT, **LOGIT)).kernel == Kernel.TARGET


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


def _pairwise_rate(w, v, f, adjacency):
    """``x'`` of a product-form pairwise law, written out pair by pair: ``w_i v_j [f_i -
    f_j]_+`` from ``j`` to each neighbour ``i``."""
    gain = adjacency * w[:, None] * v[None, :] * np.maximum(f[:, None] - f[None, :], 0.0)
    return gain.sum(axis=1) - gain.sum(axis=0)


def test_a_generator_at_a_limit_trades_at_most_at_the_rate_of_those_inside():
    """The curvature-scaled field: a flat generator at its upper limit (rate 500) sending to
    two steep ones inside (rates 2 and 3) has sender weight ``R = 5``, not its own rate, so
    their marginal costs move at no more than their own Newton rates; a flat one at its lower
    limit is a receiver of weight 1. The weights by hand, the flows pair by pair."""
    x = np.array([0.4, 0.3, 0.3, 0.0])
    lo = np.array([0.0, 0.0, 0.0, 0.0])
    hi = np.array([0.4, 0.8, 0.8, 0.5])
    rates = np.array([500.0, 2.0, 3.0, 400.0])
    f = np.array([-3.0, -1.0, -2.0, 0.5])
    complete = np.ones((4, 4)) - np.eye(4)
    w = np.array([0.0, 2.0 / 5.0, 3.0 / 5.0, 1.0])  # receivers: r / R, at a limit min(r, R) / R
    v = np.array([5.0, 2.0, 3.0, 0.0])  # senders: r, at a limit min(r, R)
    got = field_rate(Field.CAPACITY_NEWTON, x, f, complete, lo, hi, np.ones(4, bool), rates)
    np.testing.assert_allclose(got, _pairwise_rate(w, v, f, complete), rtol=1e-13, atol=0)
    tag = field_tag(Field.CAPACITY_NEWTON)
    reference = weights(tag, x, f, lo, hi, np.ones(4, bool), rates)
    np.testing.assert_allclose(reference[:2], (w, v), rtol=1e-14)


def test_on_a_graph_each_generator_at_a_limit_is_capped_by_its_own_neighbourhood():
    """On the path 0 - 1 - 2 - 3 (0 at its upper limit, 3 at its lower one, 1 and 2 inside):
    generator 0's closed neighbourhood has only 1 inside, so its sender weight is ``r_1``;
    3's has only 2, so its receiver weight is ``min(r_3, r_2) / r_2``; the compiled kernel
    and the plain-numpy statement agree with the values by hand."""
    from popdispatch.dynamics.newton import neighbourhood_weights, reference_local

    path = np.diag(np.ones(3), 1) + np.diag(np.ones(3), -1)
    indptr = np.array([0, 1, 3, 5, 6])
    indices = np.array([1, 0, 2, 1, 3, 2])
    rates = np.array([500.0, 2.0, 3.0, 400.0])
    room = np.array([0.0, 0.5, 0.5, 0.5])
    mass = np.array([0.4, 0.3, 0.3, 0.0])
    w0 = np.where(room > 0, rates, 0.0)
    v0 = np.where(mass > 0, rates, 0.0)
    want_w = np.array([0.0, 2.0 / 5.0, 3.0 / 5.0, 1.0])
    want_v = np.array([2.0, 2.0, 3.0, 0.0])
    w, v = w0.copy(), v0.copy()
    neighbourhood_weights(indptr, indices, rates, w, v, room, mass)
    np.testing.assert_allclose(w, want_w, rtol=1e-14)
    np.testing.assert_allclose(v, want_v, rtol=1e-14)
    for got, want in zip(reference_local(path, rates, w0, v0, room, mass), (want_w, want_v),
                         strict=True):  # fmt: skip
        np.testing.assert_allclose(got, want, rtol=1e-14)
