"""The verdict on AC voltages against the voltage limits (popdispatch.ac.limits), against plain
arithmetic on hand-made and random step tables."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from popdispatch.ac.limits import KEEP_TOL_PU, has_bounds, limits_summary, miss_columns
from popdispatch.report.text import voltage_limits_text


def steps_table(v_min, v_max, minutes=None) -> pd.DataFrame:
    n = len(v_min)
    index = pd.Index(minutes if minutes is not None else np.arange(1, n + 1), name="minute")
    return pd.DataFrame({"v_min_pu": v_min, "v_min_bus": [f"b{k}" for k in range(n)],
                         "v_max_pu": v_max, "v_max_bus": list(range(100, 100 + n))},
                        index)  # fmt: skip


def test_a_day_that_misses_both_limits():
    steps = steps_table([0.951, 0.9485, 0.94999], [1.0, 1.052, 1.04], minutes=[7, 8, 9])
    out = limits_summary(steps, 0.95, 1.05)
    assert out["below_vmin_pu"] == pytest.approx(0.0015, abs=1e-15)
    assert (out["below_vmin_bus"], out["below_vmin_minute"]) == ("b1", 8)
    assert out["above_vmax_pu"] == pytest.approx(0.002, abs=1e-15)
    assert (out["above_vmax_bus"], out["above_vmax_minute"]) == (101, 8)
    # minute 9 misses vmin by 1e-5 p.u.: within the tolerance
    assert out["steps"] == 3 and out["steps_outside"] == 1 and out["kept"] is False
    text = voltage_limits_text(out)
    assert "miss the limits at 1 of 3 steps" in text
    assert "up to 0.0015 p.u. below vmin 0.95 (bus b1, minute 8)" in text
    assert "up to 0.002 p.u. above vmax 1.05 (bus 101, minute 8)" in text


def test_one_step_that_keeps_its_only_limit():
    steps = steps_table([0.95], [1.0])
    out = limits_summary(steps, 0.95, 2.0)  # vmax 2: no upper bound
    assert out["vmax_pu"] is None and out["above_vmax_pu"] is None
    assert out["below_vmin_pu"] == 0.0 and out["below_vmin_bus"] is None and out["kept"]
    assert voltage_limits_text(out) == (
        "\nAC voltages keep the limits (tolerance 1e-05 p.u.): vmin 0.95 kept"
    )
    assert list(miss_columns(steps, 0.95, 2.0).columns) == ["below_vmin_pu"]


def test_no_limits():
    assert not has_bounds(0.0, 2.0) and not has_bounds(float("nan"), float("nan"))
    assert has_bounds(0.9, 2.0) and has_bounds(0.0, 1.1)
    assert voltage_limits_text(None) == ""


@given(
    st.lists(st.tuples(st.floats(0.8, 1.2), st.floats(0.0, 0.2)), min_size=1, max_size=20),
    st.floats(0.85, 1.0),
    st.floats(1.0, 1.15),
)
def test_against_plain_arithmetic(values, vmin, vmax):
    low = np.array([v for v, _ in values])
    high = low + np.array([d for _, d in values])
    steps = steps_table(low, high)
    out = limits_summary(steps, vmin, vmax)
    below, above = np.maximum(vmin - low, 0.0), np.maximum(high - vmax, 0.0)
    assert out["below_vmin_pu"] == below.max() and out["above_vmax_pu"] == above.max()
    outside = int(np.sum(np.maximum(below, above) > KEEP_TOL_PU))
    assert out["steps_outside"] == outside and out["kept"] == (outside == 0)
    if below.max() > 0.0:
        assert out["below_vmin_minute"] == int(np.argmax(below)) + 1
    misses = miss_columns(steps, vmin, vmax)
    assert np.array_equal(misses["below_vmin_pu"], below)
    assert np.array_equal(misses["above_vmax_pu"], above)
