"""``--ac`` and ``--html`` on ``snapshot`` and ``day`` (issues 14 and 17): the command's JSON,
``day.csv`` and the report file carry what the AC check and the report computed.

The AC power flow itself is tested against pandapower in ``tests/ac``; here the numbers that
must agree across the command's outputs are checked against the run's own independent
quantities: the loads the AC check draws equal the run's demand, the generation equals the
set points, and what the source supplies beyond the DC dispatch equals the losses (a DC
dispatch balances the loads exactly).
"""

from __future__ import annotations

import json

import pandas as pd
import pytest

from test_commands import assert_one_line_error, run

#: The AC check's tolerance on kW sums (power-grid-model's 1e-8 p.u. on 0.4 kV, kW scale).
KW = 1e-6


def test_snapshot_ac_and_html(tmp_path):
    report = tmp_path / "snapshot.html"
    args = ["snapshot", "--minute", "566", "--mode", "exact", "--limit", "505:666=28"]
    result = run(*args, "--ac", "--html", str(report), "--json", "-q")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    ac = s["ac"]
    assert ac["minute"] == 566
    assert ac["load_kw"] == pytest.approx(s["demand_kw"], abs=KW)
    setpoints = sum(g["setpoint_kw"] for g in s["generators"])
    assert ac["generation_kw"] == pytest.approx(setpoints, abs=KW)
    assert ac["losses_kw"] > 0
    assert ac["source_extra_kw"] == pytest.approx(ac["losses_kw"] + ac["dc_mismatch_kw"], abs=KW)
    assert 0.9 < ac["v_min_pu"] <= ac["v_max_pu"] < 1.1
    assert ac["max_loading_line"] is not None  # the 505-666 limit is the only rating
    text = report.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>") or text.lstrip().lower().startswith("<html")
    assert "Plotly" in text and len(text) > 3_000_000  # plotly.js embedded (offline page)
    assert '<script src="http' not in text


def test_day_ac_columns_and_summary(tmp_path):
    out = tmp_path / "day"
    result = run("day", "--mode", "exact", "--minutes", "560-569", "--ac", "--out", str(out),
                 "--json", "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    ac = json.loads(result.stdout)["ac"]
    table = pd.read_csv(out / "day.csv")
    assert len(table) == ac["steps"] == 10
    assert table.load_kw.to_numpy() == pytest.approx(table.demand_kw.to_numpy(), abs=KW)
    setpoints = table.filter(like="_setpoint_kw").sum(axis=1).to_numpy()
    assert table.generation_kw.to_numpy() == pytest.approx(setpoints, abs=KW)
    assert ac["losses_kwh"] == pytest.approx(table.losses_kw.sum() / 60, rel=1e-8)
    assert ac["v_min_pu"] == pytest.approx(table.v_min_pu.min(), abs=1e-9)  # CSV: 10 digits
    worst = table.loc[table.v_min_pu.idxmin()]
    assert ac["v_min_minute"] == worst.minute and ac["v_min_bus"] == worst.v_min_bus
    summary = json.loads((out / "summary.json").read_text())
    assert summary["ac"]["losses_kwh"] == pytest.approx(ac["losses_kwh"], rel=1e-12)


def test_text_output_names_the_ac_check():
    result = run("snapshot", "--minute", "566", "--vn-kv", "0.416", "-q")
    assert result.returncode == 0, result.stderr
    assert "AC check: losses" in result.stdout and "p.u. (bus" in result.stdout


def test_html_into_a_missing_folder_is_a_usage_error(tmp_path):
    result = run("day", "--minutes", "1-2", "--html", str(tmp_path / "no" / "r.html"))
    assert_one_line_error(result, 2, "--html", "does not exist")


def test_reproduce_html_writes_both_reports(tmp_path):
    out = tmp_path / "results"
    result = run("reproduce", "--minutes", "560-565", "--html", "--out", str(out), "-q")
    assert result.returncode == 0, result.stderr
    for name in ("base_day.html", "congestion.html"):
        text = (out / name).read_text(encoding="utf-8")
        assert "Plotly" in text and len(text) > 3_000_000, name
    assert (out / "summary.json").exists() and (out / "report.md").exists()
