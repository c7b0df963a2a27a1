"""``--net``, ``--fleet``, ``--root`` and ``--no-ratings``: any radial network on the command line
(issue 12), run for real in subprocesses. Data from ``../shared/feeders`` (or
``$POPDISPATCH_FEEDERS``); skipped with that reason when absent."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from test_commands import assert_one_line_error, gens, run

FEEDERS = Path(
    os.environ.get("POPDISPATCH_FEEDERS", "").strip()
    or Path(__file__).resolve().parents[3] / "shared" / "feeders"
)
CASE33 = FEEDERS / "matpower" / "case33bw.m"
needs_feeders = pytest.mark.skipif(
    not CASE33.is_file(),
    reason="test feeders not found: set POPDISPATCH_FEEDERS to the folder holding "
    "matpower/case33bw.m, or place it at ../shared/feeders beside the checkout",
)

# Merit order b (EUR/MWh): G1 10 < G18 20 < G33 25 < G25 30; c small enough not to reorder.
FLEET = """bus,name,a,b,c,pmin_kw,pmax_kw
1,G1,0,10,0.01,0,10000
18,G18,0,20,0.02,0,1500
25,G25,0,30,0.01,0,1500
33,G33,0,25,0.03,0,1000
"""


@pytest.fixture
def fleet(tmp_path: Path) -> Path:
    path = tmp_path / "fleet.csv"
    path.write_text(FLEET)
    return path


@needs_feeders
def test_feeder_reads_a_matpower_network():
    summary = json.loads(run("feeder", "--net", str(CASE33), "--json", "-q").stdout)
    assert (summary["case"], summary["buses"], summary["original_lines"]) == ("case33bw", 33, 32)
    assert summary["loads"] == 32
    assert [g["name"] for g in summary["generators"]] == ["G1"]  # the case's own source


@needs_feeders
def test_opf_on_a_network_with_a_fleet_and_a_binding_limit(fleet):
    # case33bw's loads total 3715 kW; bus 1 has no load, so line 1-2 carries G1's output.
    # Limited to 2000 kW, the merit order gives G1 2000, G18 its 1500, G33 the last 215,
    # G25 (dearest) nothing.
    result = run(
        "opf", "--minute", "1", "--net", str(CASE33), "--fleet", str(fleet),
        "--limit", "1:2=2000", "--json", "-q",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["status"] == "optimal"
    assert summary["demand_kw"] == pytest.approx(3715.0)
    p = {name: g["p_kw"] for name, g in gens(summary).items()}
    expected = {"G1": 2000.0, "G18": 1500.0, "G33": 215.0, "G25": 0.0}
    for name, kw in expected.items():
        assert p[name] == pytest.approx(kw, abs=1e-3), name


@needs_feeders
@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--net", "CASE", "--opendss", "."], "--net"),
        (["--root", "1"], "--root"),
        (["--net", "CASE", "--profiles", ".", "--loads", "CASE"], "--loads"),
    ],
)
def test_network_options_misused_are_usage_errors(args, option):
    args = [str(CASE33) if a == "CASE" else a for a in args]
    result = run("opf", "--minute", "1", *args)
    assert_one_line_error(result, 2, "error")
    assert option.lstrip("-") in result.stderr


def test_unknown_network_format_is_a_usage_error(tmp_path: Path):
    net = tmp_path / "grid.xlsx"
    net.write_text("")
    assert_one_line_error(run("feeder", "--net", str(net)), 2, "unknown network format", ".m")


def test_cases_lists_the_built_in_cases_with_their_sizes():
    result = run("cases", "--json", "-q")
    assert result.returncode == 0, result.stderr
    cases = {c["name"]: c for c in json.loads(result.stdout)["cases"]}
    # Baran & Wu's published totals and the ELV's official minute-566 peak.
    assert (cases["case33bw"]["buses"], cases["case33bw"]["lines"]) == (33, 32)
    assert cases["case33bw"]["total_load_kw"] == pytest.approx(3715.0)
    assert cases["ieee-elv"]["total_load_kw"] == pytest.approx(57.358, abs=1e-3)


def test_case_option_reads_a_built_in_case_and_refuses_unknown_names():
    summary = json.loads(run("feeder", "--case", "case33bw", "--json", "-q").stdout)
    assert (summary["buses"], summary["original_lines"], summary["loads"]) == (33, 32, 32)
    assert_one_line_error(run("feeder", "--case", "nope"), 2, "unknown case 'nope'", "case33bw")
    unpriced = run("opf", "--minute", "1", "--case", "kerber-landnetz-freileitung-1")
    assert_one_line_error(unpriced, 1, "give a fleet")
