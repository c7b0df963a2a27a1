"""The one fitness kernel (eqs. 5-7) on its own: by hand, the barrier, the exact mode's gain,
and that the plain-numpy reference's fitness is this kernel (no second implementation)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.game.fitness import FitnessParameters, barrier, barrier_at, generator_fitness

B, M = 1000.0, 400.0
b = np.array([10.0, 20.0, 30.0])
c = np.array([0.5, 1.0, 2.0])
pmin = np.array([1.0, 1.0, 1.0])
pmax = np.array([5.0, 5.0, 5.0])


def test_fitness_by_hand_inside_below_and_above_the_limits():
    p = np.array([2.0, 0.5, 6.0])  # inside, below Pmin, above Pmax
    signal = np.array([-3.0, 0.0, 7.0])
    f = generator_fitness(p, b, c, pmin, pmax, B, M, signal)
    expected = [
        1000.0 - (10.0 + 2 * 0.5 * 2.0) - 3.0,  # eq. 5 + signal
        1000.0 - (20.0 + 2 * 1.0 * 0.5) + 400.0 * 0.5,  # + m p below Pmin (eq. 7)
        1000.0 - (30.0 + 2 * 2.0 * 6.0) + 7.0 - 400.0 * 6.0,  # - m p above Pmax
    ]
    np.testing.assert_array_equal(f, expected)


def test_exact_mode_form_has_no_barrier_and_scales_by_the_gain():
    p = np.array([2.0, 0.5, 6.0])
    signal = np.array([1.0, 2.0, 3.0])
    f = generator_fitness(p, b, c, pmin, pmax, B, M, signal, 100.0, False)
    np.testing.assert_allclose(f, 100.0 * (B - (b + 2 * c * p) + signal), rtol=1e-15)


@settings(deadline=None)  # the first example compiles the kernel
@given(st.lists(st.floats(-10.0, 10.0), min_size=3, max_size=3))
def test_barrier_is_eq_7_per_generator(values):
    p = np.array(values)
    expected = np.where(p < pmin, M * p, np.where(p > pmax, -M * p, 0.0))
    np.testing.assert_array_equal(barrier(p, pmin, pmax, M), expected)
    assert [barrier_at(v, lo, hi, M) for v, lo, hi in zip(p, pmin, pmax, strict=True)] == list(
        expected
    )


def test_reference_uses_the_same_kernel(monkeypatch):
    """reference.py keeps only its naive parts; its fitness is generator_fitness itself."""
    import popdispatch.reference as reference

    calls = []

    def spy(*args):
        calls.append(args)
        return generator_fitness(*args)

    monkeypatch.setattr(reference, "generator_fitness", spy)
    from popdispatch.modes import ModeCode
    from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

    problem = elv_problem(limits=[CONGESTION_PATH])
    p = problem.pmax * 0.5
    for mode in ModeCode:
        z = np.zeros(2 * len(problem.limit))
        reference.game(mode, p, z, problem, PEAK_MINUTE, FitnessParameters())
    assert len(calls) == len(ModeCode)


def test_fitness_constants_must_be_finite_and_non_negative():
    with pytest.raises(ValueError, match="gain"):
        FitnessParameters(gain=-1.0)
