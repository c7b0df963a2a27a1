"""The issue's 20-scenario spec on a two-worker LocalCluster through the ``sweep`` command,
with the official profiles; results checked against the profile files (plain numpy) and an
equal-incremental-cost economic dispatch (bisection, plain numpy) where no line is limited."""

from __future__ import annotations

import dask.dataframe as dd
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from popdispatch.cli.sweep import sweep, sweep_report
from popdispatch.feeder.generators import paper_fleet
from popdispatch.sweep.store import STEPS, SUMMARY

from helpers import MISSING_OFFICIAL, find_official_folder

OFFICIAL = find_official_folder()
pytestmark = pytest.mark.skipif(OFFICIAL is None, reason=MISSING_OFFICIAL)

ISSUE_SPEC = """
case = "ieee-elv"
steps = "600-660"                    # minutes 600..660
modes = ["exact", "paper"]
limits = [[], ["505:666=28"]]
profile_assignments = { count = 5, seed = 1 }
"""


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    folder = tmp_path_factory.mktemp("elv")
    (folder / "spec.toml").write_text(ISSUE_SPEC)
    out = folder / "out"
    args = [str(folder / "spec.toml"), "--out", str(out), "--profiles", str(OFFICIAL)]
    result = CliRunner().invoke(sweep, [*args, "--workers", "2", "-q"])
    assert result.exception is None, result.output
    return out, result.output


@pytest.fixture(scope="module")
def pool():
    """Profile number -> 1440 kW values, read with numpy."""
    files = OFFICIAL / "Daily_1min_100profiles"
    return {n: np.loadtxt(files / f"load_profile_{n}.txt") for n in range(1, 101)}


def test_twenty_scenarios_one_summary_row_each(swept):
    out, output = swept
    assert "20 scenarios: 0 already in" in output and "20 to run" in output
    summary = pd.read_parquet(out / SUMMARY)
    assert len(summary) == 20 and summary.scenario_id.nunique() == 20
    for column in ("mode", "limits", "assignment", "max_abs_error_kw", "status", "cost_eur"):
        assert column in summary.columns
    assert (summary.status == "converged").all()
    exact = summary[summary["mode"] == "exact"]
    assert (exact.max_abs_error_kw < 1e-3).all()  # exact mode lands on the DC-OPF
    lazy = dd.read_parquet(out / STEPS)
    assert lazy.minute.min().compute() == 600 and lazy.minute.max().compute() == 660
    assert len(lazy) == 20 * 61 * 6


def test_steps_follow_the_assigned_profile_files(swept, pool):
    out, _ = swept
    summary = pd.read_parquet(out / SUMMARY)
    steps = pd.read_parquet(out / STEPS, filters=[("generator", "==", "G1")])
    for row in summary.itertuples():
        demand = sum(pool[int(n)] for n in row.profile_numbers)[599:660]
        mine = steps[steps.scenario_id == row.scenario_id].sort_values("minute")
        np.testing.assert_allclose(mine.demand_kw, demand, rtol=0, atol=1e-9)


def test_summary_agrees_with_the_steps(swept):
    out, _ = swept
    summary = pd.read_parquet(out / SUMMARY).set_index("scenario_id")
    steps = pd.read_parquet(out / STEPS)
    steps["scenario_id"] = steps.scenario_id.astype(str)
    worst = (steps.setpoint_kw - steps.opf_kw).abs().groupby(steps.scenario_id).max()
    np.testing.assert_allclose(summary.max_abs_error_kw, worst[summary.index], rtol=1e-12)
    per_minute = steps.drop_duplicates(["scenario_id", "minute"])
    opf_eur = per_minute.groupby("scenario_id").opf_cost_eur_per_h.sum() / 60.0
    np.testing.assert_allclose(summary.opf_cost_eur, opf_eur[summary.index], rtol=1e-12)
    np.testing.assert_allclose(summary.cost_gap_eur, summary.cost_eur - summary.opf_cost_eur)


def economic_dispatch_kw(demand_kw: float) -> np.ndarray:
    """Equal incremental cost dispatch of the paper's fleet within its limits (no lines):
    ``p_i = clip((lambda - b_i) / (2 c_i), pmin_i, pmax_i)`` in MW, lambda by bisection."""
    fleet = paper_fleet()
    b, c = fleet.b.to_numpy(), fleet.c.to_numpy()
    lo, hi = fleet.pmin_kw.to_numpy() / 1e3, fleet.pmax_kw.to_numpy() / 1e3
    low, high = 0.0, 100.0
    for _ in range(200):
        price = (low + high) / 2
        total = np.clip((price - b) / (2 * c), lo, hi).sum() * 1e3
        low, high = (price, high) if total < demand_kw else (low, price)
    return np.clip((price - b) / (2 * c), lo, hi) * 1e3


def test_unlimited_dcopf_is_the_economic_dispatch(swept):
    out, _ = swept
    steps = pd.read_parquet(out / STEPS)
    summary = pd.read_parquet(out / SUMMARY)
    free = set(summary.scenario_id[(summary.limits == "none") & (summary["mode"] == "exact")])
    mine = steps[steps.scenario_id.astype(str).isin(free) & steps.minute.isin([600, 630, 660])]
    for _, rows in mine.groupby([mine.scenario_id.astype(str), "minute"]):
        expected = economic_dispatch_kw(rows.demand_kw.iloc[0])
        np.testing.assert_allclose(rows.opf_kw, expected, atol=1e-4)
        np.testing.assert_allclose(rows.setpoint_kw, expected, atol=1e-3)


def test_report_and_dry_run_of_a_finished_sweep(swept, tmp_path):
    out, _ = swept
    report = CliRunner().invoke(sweep_report, [str(out), "--out", str(tmp_path / "r")])
    assert report.exception is None
    assert report.output.startswith("20 scenarios: 20 converged")
    assert (tmp_path / "r" / "sweep.png").is_file() and (tmp_path / "r" / "groups.csv").is_file()
    groups = pd.read_csv(tmp_path / "r" / "groups.csv")
    assert len(groups) == 4 and (groups.scenarios == 5).all()
    spec = out.parent / "spec.toml"
    listing = CliRunner().invoke(sweep, [str(spec), "--out", str(out), "--dry-run"])
    lines = listing.output.strip().splitlines()
    assert lines[0].startswith("20 scenarios: 20 already in") and len(lines) == 22
    assert all(line.endswith("\tdone") for line in lines[2:])
