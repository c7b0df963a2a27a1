"""``popdispatch agents`` through click's test runner (the command is registered in the main
group by cli/commands.py), and on a user's MATPOWER feeder in a subprocess."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
    for key in ("status", "minute", "demand_kw", "generators", "iterations", "rounds",
                "max_abs_error_kw", "messages", "scalars_sent", "lost",
                "max_imbalance_w"):  # fmt: skip
        assert key in s
    opf = solve_opf(congestion_problem, 566).p_kw  # the yardstick, solved here
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    assert np.abs(setpoints - opf).max() < 0.01
    assert s["lost"] == 0 and s["messages"] > 0
    assert s["scalars_sent"] > s["messages"]  # a status alone carries 5
    assert abs(s["max_imbalance_w"]) < 1.0
    assert s["dynamics_status"] == "converged"
    assert s["distance_bound_kw"] <= s["accuracy_kw"]
    assert np.abs(setpoints - opf).max() <= s["accuracy_kw"]


def test_a_run_stopped_early_says_what_it_proved():
    """Exit 1; the JSON and the text say not converged with the bound above the accuracy."""
    result = CliRunner().invoke(agents, [*CONGESTION, "--json", "--max-rounds", "10"])
    assert result.exit_code == 1, result.output
    s = json.loads(result.stdout)
    assert s["dynamics_status"] == "not_converged" and s["converged_iteration"] is None
    assert s["distance_bound_kw"] > s["accuracy_kw"] > 0
    text = CliRunner().invoke(agents, [*CONGESTION, "--max-rounds", "10"]).stdout
    assert f"proved within {s['distance_bound_kw']:.3g} kW of the DC-OPF" in text
    assert f"accuracy {s['accuracy_kw']:.3g} kW" in text


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


# -- a user's feeder, in a subprocess: the case69 with its own fleet ------------------

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import scale_cases  # noqa: E402  (where the MATPOWER cases are: one definition for all)

CASE69 = scale_cases.MATPOWER_DIR / "case69.m"
FLEET69 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,grid,50,0.1,0,5000
27,pv27,10,0.1,0,300
50,bat50,20,0.2,0,500
65,dg65,5,0.1,0,400
"""
needs_case69 = pytest.mark.skipif(
    not CASE69.is_file(), reason=f"{CASE69} not found (set POPDISPATCH_FEEDERS)"
)


def fleet69(folder: Path) -> Path:
    """The issue's fleet for case69, written into ``folder``."""
    path = folder / "fleet69.csv"
    path.write_text(FLEET69)
    return path


def popdispatch_agents(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    """``popdispatch agents --minute 1 --mode exact --net case69.m --fleet fleet69.csv ARGS
    --json -q`` in a subprocess (the environment's PYTHONPATH and cache folder inherited)."""
    script = Path(sys.executable).with_name("popdispatch")
    base = [str(script)] if script.exists() else [sys.executable, "-m", "popdispatch.cli"]
    command = [*base, "agents", "--minute", "1", "--mode", "exact", "--net", str(CASE69),
               "--fleet", str(fleet69(tmp_path)), *args, "--json", "-q"]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=900)


def case69_opf(tmp_path: Path, limit_kw: float):
    """The DC-OPF of the same run (Clarabel)."""
    from popdispatch.runs import FeederSource, load_run

    source = FeederSource(net=CASE69, fleet=fleet69(tmp_path))
    problem, _ = load_run(source, None, 1, [(26, 27, limit_kw)])
    return solve_opf(problem, 1)


@needs_case69
@pytest.mark.parametrize("limit_kw", [100, 200])
def test_case69_with_a_binding_limit_reaches_the_dc_opf(tmp_path, limit_kw):
    """The issue's run: before, ``not_converged`` after 4000 rounds (pv27 at 0 kW, the DC-OPF
    114 kW; at 200 kW the set points never settled) and exit code 0, ``line_prices`` null."""
    result = popdispatch_agents(tmp_path, "--limit", f"26:27={limit_kw}")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    opf = case69_opf(tmp_path, limit_kw)  # the yardstick: Clarabel, solved here
    assert s["status"] == "converged" and s["horizon_reason"] is None
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    assert np.abs(setpoints - opf.p_kw).max() <= 0.01  # kW
    assert opf.p_kw[1] == pytest.approx(limit_kw + 14.0, abs=1e-3)  # pv27 exports the limit
    [line] = s["line_prices"]
    assert (line["from_bus"], line["to_bus"]) == (26, 27)
    assert line["opf_price_eur_per_mwh"] == pytest.approx(opf.line_price[0], abs=1e-6)
    assert line["price_eur_per_mwh"] == pytest.approx(opf.line_price[0], abs=0.05)  # EUR/MWh


@needs_case69
@pytest.mark.parametrize(
    ("args", "words"),
    [(["--max-rounds", "20"], "give more rounds"),
     (["--step-s", "0.002", "--max-rounds", "100", "--dynamics", "distributed-smith",
       "--graph", "ring"], "oscillate")],
    ids=["horizon", "step-too-large"],
)  # fmt: skip
def test_a_run_away_from_the_optimum_exits_1_and_says_why(tmp_path, args, words):
    """Too few rounds, or on a ring a step past the line prices' stability limit (2e-3 s,
    2.4 times ``C / alpha``: the set points flip between 0 and 300 kW; on the complete graph
    the prices integrate at their own step, docs/agents.md): exit 1 after the complete JSON,
    its status ``not_converged`` with the reason, and one line on stderr."""
    result = popdispatch_agents(tmp_path, "--limit", "26:27=100", *args)
    assert result.returncode == 1, result.stderr
    s = json.loads(result.stdout)
    assert s["status"] == "not_converged" and words in s["horizon_reason"]
    assert s["max_abs_error_kw"] > 0.01
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert "the agents did not converge on minute 1 (not_converged)" in lines[0]
    assert words in lines[0]


@needs_case69
def test_line_prices_that_run_away_end_the_run_as_infeasible(tmp_path):
    """Line 1-2 limited to 1000 kW while 2.6 MW of load below it cannot be served from below:
    the prices pass the engine's cap, the agents stop there (not after 4000 rounds) and the
    command exits 1, naming the line (1-3 of the reduced feeder: bus 2 is no key node)."""
    result = popdispatch_agents(tmp_path, "--limit", "1:2=1000")
    assert result.returncode == 1, result.stderr
    s = json.loads(result.stdout)
    assert s["status"] == "infeasible" and s["dynamics_status"] == "infeasible"
    assert "ran away: line 1-3's price" in s["horizon_reason"]
    assert s["rounds"] < 1000
    assert len(result.stderr.strip().splitlines()) == 1 and "infeasible" in result.stderr


def test_voltage_mode_is_refused_in_one_line_before_any_work(tmp_path):
    """The agents price lines only (and the command has no --vmin): exit 2, one line naming
    --mode, no output, before the feeder is read (a feeder file that is not MATPOWER is not
    what is reported)."""
    bad = tmp_path / "bad.m"
    bad.write_text("this is not a MATPOWER case\n")
    script = Path(sys.executable).with_name("popdispatch")
    base = [str(script)] if script.exists() else [sys.executable, "-m", "popdispatch.cli"]
    command = [*base, "agents", "--minute", "1", "--mode", "voltage", "--net", str(bad),
               "--json", "-q"]  # fmt: skip
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2, result.stderr
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--mode" in lines[0] and "paper and exact" in lines[0]
    assert "Traceback" not in result.stderr
