"""Random assignment of the official profiles to the ELV's loads, checked against the profile
files read with plain numpy."""

from __future__ import annotations

import numpy as np

from popdispatch.sweep.assign import assigned_profiles, assignment_numbers

from helpers import official_folder


def test_numbers_are_distinct_seeded_and_in_range():
    a = assignment_numbers(1, 0, 55, 100)
    assert len(set(a)) == 55 and a.min() >= 1 and a.max() <= 100
    assert np.array_equal(a, assignment_numbers(1, 0, 55, 100))
    assert not np.array_equal(a, assignment_numbers(1, 1, 55, 100))
    assert not np.array_equal(a, assignment_numbers(2, 0, 55, 100))


def test_assigned_profiles_follow_the_files():
    folder = official_folder()
    profiles, numbers = assigned_profiles(str(folder), 1, 3)
    assert profiles.kw.shape == (1440, 55) and len(set(numbers)) == 55
    assert list(profiles.kw.columns[:2]) == ["LOAD1", "LOAD2"]
    expected = np.column_stack(
        [np.loadtxt(folder / "Daily_1min_100profiles" / f"load_profile_{n}.txt") for n in numbers]
    )
    np.testing.assert_array_equal(profiles.kw.to_numpy(), expected)
    assert numbers == list(assignment_numbers(1, 3, 55, 100))
