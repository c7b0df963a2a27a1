"""Infeasible minutes do not throw results away (issue 10, items 3 and 6), run for real in
subprocesses like ``test_commands.py``.

A day runs every minute asked for and names those whose DC-OPF is infeasible; their DC-OPF
values are null, the dynamics' are still reported, comparisons use the same minutes on both
sides; checks apply only to the minutes asked for; errors name the minute and its capacity;
no output ever shows ``nan``; set points outside their limits are flagged.
"""

from __future__ import annotations

import json
import math

import pandas as pd
import pytest

from helpers import official_folder
from test_commands import assert_one_line_error, gens, run

#: Default (synthetic, shipped) profiles: with G739 off from minute 600 only minute 1123 of
#: 1100-1130 has more demand (55.622 kW) than the 55 kW left online.
SHORT_MINUTES = ("--minutes", "1100-1130", "--event", "739:off@600")


def no_nan(text: str) -> None:
    assert "nan" not in text.lower().replace("nano", ""), text
    assert "NaN" not in text


def test_day_with_an_infeasible_minute_is_complete_json():
    """The issue's acceptance command: one JSON object, 566 named, the other minutes compared."""
    folder = official_folder()
    result = run("day", "--mode", "exact", "--profiles", str(folder), "--limit", "505:666=27",
                 "--minutes", "560-570", "--json", "-q")  # fmt: skip
    assert_one_line_error(result, 1, "infeasible at 1 of 11 minutes (566)")
    no_nan(result.stdout)
    summary = json.loads(result.stdout)  # exactly one object
    assert summary["status"] == "infeasible"
    assert summary["infeasible_minutes"] == [566]
    assert (summary["minutes"], summary["compared_minutes"]) == (11, 10)
    assert summary["minutes_within_0_1_kw"] == 10
    assert summary["max_abs_error_kw"] < 1e-3  # over the 10 feasible minutes
    # energies and costs over the same 10 minutes on both sides
    assert summary["opf_cost"] == pytest.approx(summary["cost"], rel=1e-6)
    for bus, energy in summary["energy_kwh"].items():
        assert energy == pytest.approx(summary["opf_energy_kwh"][bus], abs=1e-4)
    # the dynamics' own day, all 11 minutes, is still there
    assert summary["cost_all_minutes"] > summary["cost"]
    assert summary["max_overflow_kw"] > 0.1  # minute 566 cannot meet the 27 kW limit


def test_capacity_short_minute_is_run_named_and_flagged(tmp_path):
    out = tmp_path / "day"
    result = run("day", *SHORT_MINUTES, "--out", str(out), "--json", "-q")
    assert_one_line_error(result, 1, "1 of 31 minutes (1123)")
    no_nan(result.stdout)
    summary = json.loads(result.stdout)
    assert summary["infeasible_minutes"] == [1123]
    assert summary["compared_minutes"] == 30
    assert summary["opf_cost"] is not None
    # paper mode's barrier lets G578 (Pmax 5 kW) take part of the missing power: flagged
    assert summary["minutes_outside_limits_by_generator"]["G578"] >= 1
    assert summary["minutes_outside_limits"] >= 1
    assert summary["max_outside_limits_kw"] > 0.5  # G578 at 5.82 kW at minute 1123
    table = pd.read_csv(out / "day.csv")  # the whole day is written
    assert list(table.minute) == list(range(1100, 1131))
    row = table.set_index("minute").loc[1123]
    assert not row.opf_feasible and row.outside_limits
    assert math.isnan(row.G578_opf_kw)
    assert row.G578_setpoint_kw > 5.1  # what the dynamics did is still reported
    assert json.loads((out / "summary.json").read_text()) == summary


def test_day_text_names_the_infeasible_minutes_and_compares_like_with_like():
    result = run("day", *SHORT_MINUTES, "-q")
    assert result.returncode == 1
    text = result.stdout
    no_nan(text)
    assert "DC-OPF infeasible at 1 minute: 1123" in text
    assert "over the 30 minutes with a DC-OPF (of 31)" in text
    assert "events: 739:off@600" in text
    assert "limits: none" in text
    assert "* set points outside their limits in" in text and "by up to" in text


def test_checks_apply_only_to_the_minutes_asked_for():
    # G739 off from minute 600 leaves too little capacity at minute 1123 only: 1-100 is fine
    result = run("day", "--minutes", "1-100", "--event", "739:off@600", "--json", "-q")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["infeasible_minutes"] == []
    assert summary["status"] == "converged"


def test_no_generator_online_names_the_minute_and_its_capacity():
    events = [f"--event={bus}:off@10" for bus in (1, 114, 578, 739, 817, 835)]
    result = run("day", "--minutes", "1-100", *events, "-q")
    assert_one_line_error(result, 1, "minute 10", "capacity 0.000 kW")
    assert result.stdout == ""


def test_infeasible_snapshot_prints_what_is_known(tmp_path):
    out = tmp_path / "snap"
    result = run("snapshot", "--minute", "566", "--limit", "505:666=0", "--json", "-q",
                 "--out", str(out))  # fmt: skip
    assert_one_line_error(result, 1, "minute 566 is infeasible", "line limits",
                          "--limit 505:666=0 kW on 505-578")  # fmt: skip
    no_nan(result.stdout)
    summary = json.loads(result.stdout)
    assert summary["status"] == "infeasible"
    assert summary["opf_cost"] is None and summary["max_abs_error_kw"] is None
    g114 = gens(summary)["G114"]
    assert g114["opf_kw"] is None
    assert g114["pmax_kw"] == 10.0
    assert g114["setpoint_kw"] > 10.5 and g114["outside_limits"] is True
    assert "G114" in summary["generators_outside_limits"]
    assert gens(summary)["G739"]["outside_limits"] is False
    assert (out / "trajectory.csv").is_file()  # a complete run is written


def test_infeasible_snapshot_and_opf_text_say_what_is_not_known():
    snap = run("snapshot", "--minute", "566", "--limit", "505:666=0", "-q")
    assert snap.returncode == 1
    no_nan(snap.stdout)
    assert "DC-OPF: infeasible: line limits: --limit 505:666=0 kW on 505-578, " in snap.stdout
    assert "iteration -" not in snap.stdout
    assert "G114         114        26.925        10.000 *" in snap.stdout
    assert "* set point outside its limits: G1" in snap.stdout
    assert "limits: 505:666=0 kW (21 lines)" in snap.stdout
    opf = run("opf", "--minute", "566", "--limit", "505:666=0", "-q")
    assert opf.returncode == 1
    no_nan(opf.stdout)
    assert "infeasible: line limits: --limit 505:666=0 kW on 505-578," in opf.stdout
    assert "online capacity 65.000 kW" in opf.stdout
