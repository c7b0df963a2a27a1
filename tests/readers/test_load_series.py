"""Load time series of any resolution (issue 12): a user's CSV or Parquet table attached to a
feeder's loads by load name or bus id, and SimBench's bundled year.

Yardsticks: per-step totals and per-load values computed here with plain numpy from the same
numbers written to the file; SimBench's totals from simbench's own ``get_absolute_values``."""

from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd
import pytest

from popdispatch.errors import OptionError, ProfileError
from popdispatch.feeder import Feeder, make_fleet
from popdispatch.readers.series import read_load_table
from popdispatch.runs import select_steps


def small_feeder() -> Feeder:
    """Five buses, three loads (two on bus 3), own loads in kW."""
    buses = pd.DataFrame(
        {"x": [0.0, 1, 2, 3, 3], "y": [0.0, 0, 0, 1, -1]},
        index=pd.Index([1, 2, 3, 4, 5], name="bus"),
    )
    lines = pd.DataFrame(
        {"from_bus": [1, 2, 3, 3], "to_bus": [2, 3, 4, 5], "length_km": 0.1, "r_ohm": 0.03,
         "x_ohm": 0.01, "limit_kw": np.inf},
        index=["L12", "L23", "L34", "L35"],
    )  # fmt: skip
    loads = pd.DataFrame(
        {"bus": [2, 3, 3], "p_kw": [6.0, 1.0, 3.0]}, index=pd.Index(["home", "shop", "farm"])
    )
    fleet = make_fleet([(1, 0, 5.0, 0.02, 0, 30), (4, 0, 1.0, 0.01, 0, 10)])
    return Feeder("mine", buses, lines, loads, source_bus=1, generators=fleet)


def quarter_hours(n: int) -> pd.DatetimeIndex:
    return pd.date_range("2024-03-01T00:00", periods=n, freq="15min")


@pytest.fixture
def values() -> np.ndarray:
    return np.random.default_rng(7).uniform(0.0, 5.0, (10, 2))


@pytest.mark.parametrize("suffix", ["csv", "parquet"])
def test_table_by_load_name_and_bus(tmp_path, values, suffix):
    """``home`` by name, bus 3 (shop + farm) shared 1:3 as their own p_kw; 15-minute steps."""
    table = pd.DataFrame(
        {"time": quarter_hours(10).strftime("%Y-%m-%dT%H:%M:%S"), "HOME": values[:, 0],
         "3": values[:, 1]}
    )  # fmt: skip
    path = tmp_path / f"loads.{suffix}"
    table.to_csv(path, index=False) if suffix == "csv" else table.to_parquet(path, index=False)
    profiles = read_load_table(path, small_feeder())
    assert list(profiles.kw.columns) == ["home", "shop", "farm"]
    expected = np.column_stack([values[:, 0], values[:, 1] * 0.25, values[:, 1] * 0.75])
    np.testing.assert_allclose(profiles.kw.to_numpy(), expected, rtol=1e-12)
    np.testing.assert_allclose(profiles.total_kw().to_numpy(), values.sum(axis=1), rtol=1e-12)
    np.testing.assert_allclose(profiles.timeline.hours, 0.25)
    assert profiles.timeline.step_minutes == 15.0
    assert profiles.timeline.label(1) == "2024-03-01T00:00:00"
    assert profiles.timeline.label(10) == "2024-03-01T02:15:00"


def test_time_zone_and_selection(tmp_path, values):
    """Times with an offset keep it; --start/--end pick the steps whose hours hold them."""
    times = pd.date_range("2024-03-01", periods=10, freq="1h", tz="UTC").tz_convert("Europe/Madrid")
    path = tmp_path / "loads.csv"
    frame = pd.DataFrame({"Timestamp": [t.isoformat() for t in times], "home": values[:, 0]})
    frame["shop"], frame["farm"] = values[:, 1], 2 * values[:, 1]
    frame.to_csv(path, index=False)
    profiles = read_load_table(path, small_feeder())
    assert profiles.timeline.label(1) == "2024-03-01T01:00:00+01:00"
    np.testing.assert_allclose(profiles.timeline.hours, 1.0)
    # 03:30 local is inside step 3 (03:00-04:00); 04:10Z is 05:10 local, step 5
    steps = select_steps(profiles, start="2024-03-01T03:30+01:00", end="2024-03-01T04:10Z")
    np.testing.assert_array_equal(steps, [3, 4, 5])
    np.testing.assert_array_equal(select_steps(profiles, (2, 4)), [2, 3, 4])
    assert select_steps(profiles) is None
    with pytest.raises(OptionError, match="outside the series") as exc:
        select_steps(profiles, start="2024-03-02T12:00+01:00")
    assert exc.value.option == "--start"
    with pytest.raises(OptionError, match="before") as exc:
        select_steps(profiles, start="2024-03-01T05:00+01:00", end="2024-03-01T03:00+01:00")
    with pytest.raises(OptionError, match="outside the series' 1-10") as exc:
        select_steps(profiles, (5, 11))
    assert exc.value.option == "--steps"


def test_elv_day_times_of_day():
    """The undated ELV day: minute 1 starts at 00:00, minute 566 at 09:25; HH:MM selects."""
    from popdispatch.feeder.profiles import day_timeline

    timeline = day_timeline()
    assert timeline.labels([1, 566, 1440]) == ["00:00:00", "09:25:00", "23:59:00"]
    assert timeline.step_at("09:25") == 566
    assert timeline.step_minutes == 1.0


def _write(tmp_path, frame: pd.DataFrame):
    path = tmp_path / "bad.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (lambda f: f.assign(time=f.time[::-1].to_numpy()), ["row 2", "times must increase"]),
        (lambda f: f.assign(time=["x"] + list(f.time[1:])), ["row 1", "'x' is not a time"]),
        (lambda f: f.assign(shop=["1.0", "lots"] + list(f.shop[2:])), ["'shop'", "row 2"]),
        (lambda f: f.assign(barn=1.0), ["'barn'", "neither a load nor a bus"]),
        (lambda f: f.drop(columns="farm"), ["no column for load 'farm'", "1 of 3"]),
        (lambda f: f.assign(**{"2": 1.0}), ["'home'", "two columns"]),
        (lambda f: f.assign(shop=float("inf")), ["'shop'", "row 1", "finite number"]),
    ],
)
def test_bad_tables_name_the_cell(tmp_path, values, change, words):
    frame = pd.DataFrame({"time": quarter_hours(10).astype(str), "home": values[:, 0]})
    frame["shop"], frame["farm"] = values[:, 1], values[:, 1]
    path = _write(tmp_path, change(frame))
    with pytest.raises(ProfileError) as exc:
        read_load_table(path, small_feeder())
    message = str(exc.value)
    assert "\n" not in message
    for word in words:
        assert word in message, message


SIMBENCH = importlib.util.find_spec("simbench") is not None
CODE = "1-LV-rural1--0-sw"


@pytest.mark.skipif(not SIMBENCH, reason="needs the optional simbench extra")
def test_simbench_year_totals_equal_simbench_absolute_values():
    import simbench

    from popdispatch.cases.builtin import load_case, simbench_profiles

    net = simbench.get_simbench_net(CODE)
    expected = simbench.get_absolute_values(net, profiles_instead_of_study_cases=True)
    loads_kw = expected[("load", "p_mw")].to_numpy().sum(axis=1) * 1000.0
    sgen_kw = expected[("sgen", "p_mw")].to_numpy().sum(axis=1) * 1000.0  # PV: fixed injection
    expected_kw = loads_kw - sgen_kw
    fleet = make_fleet([(3, 0, 60.0, 0.5, 0, 200)])
    feeder = load_case(f"simbench:{CODE}", fleet=fleet)
    profiles = simbench_profiles(CODE, feeder)
    assert profiles.steps == 35136 == len(expected_kw)
    np.testing.assert_allclose(profiles.total_kw().to_numpy(), expected_kw, rtol=1e-9,
                               atol=1e-9)  # fmt: skip
    injected = profiles.kw[[c for c in profiles.kw.columns if c.startswith("sgen")]]
    np.testing.assert_allclose(-injected.sum(axis=1).to_numpy(), sgen_kw, rtol=1e-12)
    first = net.load.index[0]
    np.testing.assert_allclose(
        profiles.kw[f"load{first}"], expected[("load", "p_mw")][first] * 1000.0, rtol=1e-12
    )
    # German local time: a 15-minute grid in UTC across both clock changes of 2016
    assert profiles.timeline.label(1) == "2016-01-01T00:00:00+01:00"
    assert profiles.timeline.label(35136) == "2016-12-31T23:45:00+01:00"
    assert profiles.timeline.step_minutes == 15.0
