"""``popdispatch agents`` through click's test runner (the command is registered in the main
group by cli/commands.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.cli.agents import agents  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

CONGESTION = ["--minute", "566", "--limit", "505:666=28", "--mode", "exact", "-q"]


def test_json_has_snapshot_and_message_keys(congestion_problem):
    result = CliRunner().invoke(agents, [*CONGESTION, "--json"])
    assert result.exit_code == 0, result.output
    s = json.loads(result.output)
    for key in ("status", "minute", "demand_kw", "generators", "iterations",
                "max_abs_error_kw", "messages", "lost", "max_imbalance_w"):  # fmt: skip
        assert key in s
    opf = solve_opf(congestion_problem, 566).p_kw  # the yardstick, solved here
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    assert np.abs(setpoints - opf).max() < 0.01
    assert s["lost"] == 0 and s["messages"] > 0
    assert abs(s["max_imbalance_w"]) < 1.0


def test_loss_is_reported():
    """30 rounds are too few to converge (exit 1, after the complete JSON)."""
    result = CliRunner().invoke(
        agents, [*CONGESTION, "--json", "--loss", "0.2", "--seed", "3", "--max-rounds", "30"]
    )
    assert result.exit_code == 1, result.output
    s = json.loads(result.stdout)
    assert s["status"] == "not_converged" and "not at rest after 30 rounds" in s["horizon_reason"]
    assert 0.1 < s["lost"] / s["messages"] < 0.3
    assert abs(s["max_imbalance_w"]) < 1.0 and abs(s["final_imbalance_w"]) < 1.0


@pytest.mark.parametrize(
    ("args", "option"),
    [(["--loss", "1.5"], "--loss"), (["--delay-max", "-1"], "--delay-max")],
)
def test_bad_fault_options_are_usage_errors(args, option):
    result = CliRunner().invoke(agents, [*CONGESTION, *args])
    assert result.exit_code == 2
    assert option in result.output


def test_fault_options_reach_the_json(congestion_problem):
    result = CliRunner().invoke(agents, [*CONGESTION, "--json", "--controller-crash",
                                         "C666@20", "--crash", "G1@5+5"])  # fmt: skip
    assert result.exit_code == 0, result.output
    s = json.loads(result.output)
    assert {(f["kind"], f["agent"]) for f in s["faults"]} == {
        ("controller-crash", "C666"),
        ("crash", "G1"),
    }
    kinds = {e["event"] for e in s["events"]}
    assert {"crash", "restart", "controller-crash", "stale_price"} <= kinds
    assert abs(s["max_imbalance_w"]) < 1.0 and s["source_kw"] == 0.0


def test_a_trip_is_compared_with_the_dc_opf_without_it():
    args = ["--minute", "566", "--mode", "exact", "-q", "--json", "--trip", "G578@20"]
    result = CliRunner().invoke(agents, args)
    assert result.exit_code == 0, result.output
    s = json.loads(result.output)
    g578 = next(g for g in s["generators"] if g["name"] == "G578")
    assert g578["setpoint_kw"] == 0.0 and g578["opf_kw"] == pytest.approx(0.0, abs=1e-6)
    assert s["max_abs_error_kw"] < 0.01 and abs(s["max_imbalance_w"]) < 1.0


@pytest.mark.parametrize(
    ("args", "option"),
    [(["--trip", "G578@3+2"], "--trip"), (["--controller-crash", "C1@3"], "--controller-crash"),
     (["--crash", "G1"], "--crash")],
)  # fmt: skip
def test_bad_agent_faults_are_usage_errors(args, option, capsys):
    from popdispatch.cli import main

    assert main(["agents", *CONGESTION, *args]) == 2
    assert option in capsys.readouterr().err


def test_options_before_a_subcommand_are_refused_not_ignored(capsys):
    """``agents --mode exact launch ...`` ran ``launch`` with its own defaults (the group's
    options never reach it): now a usage error naming the options, before any work."""
    from popdispatch.cli import main

    assert main(["agents", "--mode", "exact", "-q", "launch", "--minute", "566"]) == 2
    err = capsys.readouterr().err
    assert "--mode, -q given before 'launch'" in err
    assert len(err.strip().splitlines()) == 1
