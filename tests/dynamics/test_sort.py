"""The complete graph's order by fitness: the insertion sort from the last order and its full
fallback (a hand-written merge sort) give numpy's stable argsort."""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.dynamics.pairwise import merge_sort, sort_by_fitness


@pytest.mark.parametrize("n", [0, 1, 2, 3, 7, 64, 1000, 4097])
def test_merge_sort_is_numpys_stable_argsort(n):
    rng = np.random.default_rng(n)
    for ties in (False, True):  # ties: the stable order (by index) must be kept
        f = rng.integers(0, 4, n).astype(float) if ties else rng.normal(size=n)
        order = rng.permutation(n).astype(np.int64)  # whatever order it held before
        merge_sort(f, order)
        np.testing.assert_array_equal(order, np.argsort(f, kind="mergesort"))


def test_the_insertion_sort_falls_back_to_the_full_sort():
    """A reversed order of 200 distinct values needs ~n^2/2 moves (> 8 n + 64): the full sort
    takes over and the result is still the sorted order."""
    f = np.linspace(0.0, 1.0, 200)
    order = np.arange(200, dtype=np.int64)[::-1].copy()
    sort_by_fitness(f, order)
    np.testing.assert_array_equal(order, np.arange(200))
