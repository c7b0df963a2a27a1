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
    result = CliRunner().invoke(
        agents, [*CONGESTION, "--json", "--loss", "0.2", "--seed", "3", "--max-rounds", "30"]
    )
    assert result.exit_code == 0, result.output
    s = json.loads(result.output)
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
