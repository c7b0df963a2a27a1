"""Time series on the command line (issue 12): ``--loads`` tables of any resolution, step
selection by number or time, timestamps in every output, energies weighted by step length, the
ELV read through OpenDSSDirect on its official profiles, fleets by OpenDSS bus name.

Yardsticks: the table's own numbers (row sums, 15-minute weights) computed here with numpy, and
the built-in ieee-elv case (read by pandapower) for the OpenDSS read of the same feeder.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch.cases import ieee_elv

from helpers import official_folder
from test_commands import assert_one_line_error, gens, run
from test_networks import CASE33, FEEDERS, needs_feeders

STEPS = 8


@pytest.fixture(scope="module")
def table(tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    """Eight quarter hours of seeded random kW for the 55 ELV loads (total under 65 kW)."""
    names = list(ieee_elv().loads.index)
    rng = np.random.default_rng(12)
    frame = pd.DataFrame(rng.uniform(0.0, 1.0, (STEPS, len(names))), columns=names)
    frame.insert(0, "time", pd.date_range("2024-01-01", periods=STEPS, freq="15min"))
    path = tmp_path_factory.mktemp("series") / "loads.csv"
    frame.assign(time=frame.time.dt.strftime("%Y-%m-%dT%H:%M:%S")).to_csv(path, index=False)
    return path, frame


def test_day_on_a_quarter_hour_table(table, tmp_path):
    path, frame = table
    out = tmp_path / "out"
    result = run(
        "day", "--loads", str(path), "--mode", "exact", "--start", "2024-01-01T00:20",
        "--end", "2024-01-01T01:35", "--out", str(out), "--json", "-q",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    # 00:20 lies in step 2 (00:15-00:30), 01:35 in step 7 (01:30-01:45)
    assert (s["first_step"], s["last_step"], s["steps"]) == (2, 7, 6)
    assert (s["first_minute"], s["last_minute"], s["minutes"]) == (2, 7, 6)
    assert (s["first_time"], s["last_time"]) == ("2024-01-01T00:15:00", "2024-01-01T01:30:00")
    assert s["step_minutes"] == 15.0
    day = pd.read_csv(out / "day.csv")
    loads = frame.drop(columns="time").to_numpy()[1:7]
    np.testing.assert_allclose(day.demand_kw, loads.sum(axis=1), rtol=1e-9)
    assert list(day.time) == list(frame.time.dt.strftime("%Y-%m-%dT%H:%M:%S")[1:7])
    assert list(day.step) == list(range(2, 8))
    # a quarter hour weighs 0.25 h: energy = sum of kW x 0.25, and the whole fleet's energy is
    # the demand's energy (power balance)
    for bus, kwh in s["energy_kwh"].items():
        assert kwh == pytest.approx(day[f"G{bus}_setpoint_kw"].sum() * 0.25, abs=1e-6)
        assert s["opf_energy_kwh"][bus] == pytest.approx(day[f"G{bus}_opf_kw"].sum() * 0.25)
    assert sum(s["opf_energy_kwh"].values()) == pytest.approx(loads.sum() * 0.25, rel=1e-9)
    assert s["cost_eur"] == pytest.approx(day.cost_eur_per_h.sum() * 0.25, rel=1e-9)
    assert s["opf_cost_eur"] == pytest.approx(day.opf_cost_eur_per_h.sum() * 0.25, rel=1e-9)
    assert s["max_abs_error_kw"] < 1e-3


def test_snapshot_of_one_step_carries_its_time(table):
    path, frame = table
    result = run("opf", "--step", "3", "--loads", str(path), "--json", "-q")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert (s["minute"], s["step"], s["time"]) == (3, 3, "2024-01-01T00:30:00")
    demand = frame.drop(columns="time").to_numpy()[2].sum()
    assert s["demand_kw"] == pytest.approx(demand, rel=1e-12)
    assert sum(g["p_kw"] for g in s["generators"]) == pytest.approx(demand, rel=1e-6)
    text = run("opf", "--step", "3", "--loads", str(path), "-q")
    assert "minute 3 (time 2024-01-01T00:30:00)" in text.stdout


def test_steps_outside_the_table_are_usage_errors(table):
    path, _ = table
    assert_one_line_error(
        run("opf", "--minute", "9", "--loads", str(path), "-q"), 2, "--minute", "1-8"
    )
    assert_one_line_error(
        run("day", "--steps", "3-9", "--loads", str(path), "-q"), 2, "--steps", "1-8"
    )
    assert_one_line_error(
        run("day", "--start", "2025-01-01T00:00", "--loads", str(path), "-q"), 2, "--start"
    )


def test_elv_day_keeps_minutes_and_gains_times_of_day():
    result = run("opf", "--minute", "566", "--json", "-q")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert (s["minute"], s["step"], s["time"]) == (566, 566, "09:25:00")


@needs_feeders
def test_a_network_without_profiles_is_one_step():
    assert_one_line_error(run("opf", "--minute", "2", "--net", str(CASE33)), 2, "--minute", "1")


OPENDSS = importlib.util.find_spec("opendssdirect") is not None
needs_opendss = pytest.mark.skipif(not OPENDSS, reason="needs the opendss extra (opendssdirect)")

FLEET = """bus,name,a_eur_per_h,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,G1,0,5.0,0.02,0,10
114,G114,0,1.0,0.01,0,10
578,G578,0,3.0,0.025,0,5
739,G739,0,4.0,0.01,0,10
817,G817,0,2.5,0.015,0,20
835,G835,0,2.0,0.02,0,10
"""


@needs_opendss
def test_elv_master_through_opendssdirect_runs_on_its_official_profiles(tmp_path):
    folder = official_folder()
    fleet = tmp_path / "fleet.csv"
    fleet.write_text(FLEET)
    common = ["--profiles", str(folder), "--mode", "exact", "--minutes", "560-562", "--json", "-q"]
    dss = run("day", "--net", str(folder / "Master.dss"), "--fleet", str(fleet), *common)
    built_in = run("day", *common)
    assert dss.returncode == 0, dss.stderr
    assert built_in.returncode == 0, built_in.stderr
    a, b = json.loads(dss.stdout), json.loads(built_in.stdout)
    assert a["status"] == b["status"] == "converged"
    assert a["first_time"] == "09:19:00"
    for bus, kwh in b["opf_energy_kwh"].items():
        assert a["opf_energy_kwh"][bus] == pytest.approx(kwh, abs=1e-6), bus


@needs_opendss
@pytest.mark.skipif(
    not (FEEDERS / "opendss" / "ieee13" / "IEEE13Nodeckt.dss").is_file(),
    reason="test feeders not found (../shared/feeders/opendss/ieee13)",
)
def test_fleet_by_opendss_bus_name(tmp_path):
    """A DG on the regulator bus ``RG60`` (a name, case as the user writes it) and one on 675;
    the JSON's bus ids are the OpenDSS names (ratings off: the feeder's NormAmps would make
    this made-up dispatch infeasible)."""
    fleet = tmp_path / "fleet13.csv"
    fleet.write_text(
        "bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw\n"
        "sourcebus,grid,50,0.1,0,5000\nRG60,reg,10,0.1,0,1000\n675,pv,5,0.1,0,500\n"
    )
    master = FEEDERS / "opendss" / "ieee13" / "IEEE13Nodeckt.dss"
    result = run(
        "opf",
        "--minute",
        "1",
        "--net",
        str(master),
        "--fleet",
        str(fleet),
        "--no-ratings",
        "--json",
        "-q",
    )
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    buses = {g["name"]: g["bus"] for g in s["generators"]}
    # OpenDSS names its buses: every one a string in the JSON, "675" too (one type per network)
    assert buses == {"grid": "sourcebus", "reg": "rg60", "pv": "675"}
    p = {name: g["p_kw"] for name, g in gens(s).items()}
    # merit order without limits: pv full, reg full, the grid the rest of the demand
    assert p["pv"] == pytest.approx(500, abs=1e-3)
    assert p["reg"] == pytest.approx(1000, abs=1e-3)
    assert p["grid"] == pytest.approx(s["demand_kw"] - 1500, abs=1e-3)


SIMBENCH = importlib.util.find_spec("simbench") is not None
SB_FLEET = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
3,grid,60,0.5,0,400
6,pv6,5,2,0,40
10,pv10,6,2,0,78
"""


@pytest.mark.skipif(not SIMBENCH, reason="needs the optional simbench extra")
def test_simbench_case_runs_on_its_year_across_the_clock_change(tmp_path):
    """27 March 2016, German time: 01:45+01:00 is followed by 03:00+02:00 (a quarter hour
    later); the demand of those steps is simbench's own absolute values."""
    import simbench

    from popdispatch.cases.builtin import simbench_net

    fleet = tmp_path / "fleet.csv"
    fleet.write_text(SB_FLEET)
    result = run(
        "day", "--case", "simbench:1-LV-rural1--0-sw", "--fleet", str(fleet), "--mode", "exact",
        "--start", "2016-03-27T01:45", "--end", "2016-03-27T03:00", "--out", str(tmp_path / "o"),
        "--json", "-q",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert (s["first_time"], s["last_time"]) == (
        "2016-03-27T01:45:00+01:00",
        "2016-03-27T03:00:00+02:00",
    )
    assert s["steps"] == 2 and s["step_minutes"] == 15.0 and s["status"] == "converged"
    net = simbench_net("1-LV-rural1--0-sw")
    p_mw = simbench.get_absolute_values(net, profiles_instead_of_study_cases=True)[("load", "p_mw")]
    expected_kw = p_mw.to_numpy().sum(axis=1)[s["first_step"] - 1 : s["last_step"]] * 1000.0
    day = pd.read_csv(tmp_path / "o" / "day.csv")
    np.testing.assert_allclose(day.demand_kw, expected_kw, rtol=1e-6)
    ambiguous = run(
        "day", "--case", "simbench:1-LV-rural1--0-sw", "--fleet", str(fleet),
        "--start", "2016-10-30T02:30", "-q",
    )  # fmt: skip
    assert_one_line_error(ambiguous, 2, "--start", "ambiguous", "UTC offset")
