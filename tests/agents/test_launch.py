"""``agents launch``: one OS process per agent over TCP on localhost; the congestion minute
reaches the DC-OPF (solved here) within 0.01 kW and no process outlives the launcher."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import psutil
import pytest
from click.testing import CliRunner

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.cli.agents import agents  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402


def _agents() -> list[psutil.Process]:
    """Agent processes of the launches this test process started, directly or through a
    launcher (others on the machine, e.g. another test worker's, do not count)."""
    found = []
    for proc in psutil.Process().children(recursive=True):
        try:
            command = " ".join(proc.cmdline())
        except (psutil.NoSuchProcess, psutil.ZombieProcess):
            continue
        if "popdispatch.agents.launch --id" in command:
            found.append(proc)
    return found


def _children() -> int:
    """Agent processes of this test's launches still running."""
    return len(_agents())


def test_launched_congestion_minute_reaches_dc_opf(congestion_problem):
    args = ["launch", "--minute", "566", "--limit", "505:666=28", "--rounds", "160", "--json",
            "--startup-s", "300",
            "-q"]  # fmt: skip
    result = CliRunner().invoke(agents, args)
    assert result.exit_code == 0, result.output
    s = json.loads(result.output)
    # every round the plant was asked for happened or is reported missed (real time: a
    # loaded machine can make a process miss a tick)
    assert s["processes"] == 12 and s["rounds"] + s["missed_ticks"] >= 160
    opf = solve_opf(congestion_problem, 566).p_kw
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    assert np.abs(setpoints - opf).max() < 0.01, f"{s['missed_ticks']} ticks missed"  # kW
    assert _children() == 0


def test_launched_minute_with_loss_over_tcp(congestion_problem):
    """Fault injection over TCP: every process drops 10 % of its messages (seeded draws, but
    real message timing, so not a repeatable run); the launched congestion minute goes from
    uniform shares (up to 9 kW from the DC-OPF) to within 0.5 kW of it in 300 rounds.
    Measured: 1.3e-4 kW and 0.043 kW in two runs (late messages act like the simulation's
    unpaced delays, which keep 0.13 kW; docs/agents.md). The simulated minute with 10 % loss
    is within 0.01 kW from round 151 (benchmarks/fault_table.py)."""
    args = ["launch", "--minute", "566", "--limit", "505:666=28", "--rounds", "300", "--json",
            "--startup-s", "300", "--loss", "0.1", "--seed", "1", "-q"]  # fmt: skip
    result = CliRunner().invoke(agents, args)
    assert result.exit_code == 0, result.output
    s = json.loads(result.output)
    assert 0.07 < s["lost"] / s["messages"] < 0.13
    opf = solve_opf(congestion_problem, 566).p_kw
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    assert np.abs(setpoints - opf).max() < 0.5  # kW
    assert _children() == 0


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_stopping_the_launcher_leaves_no_process(stop):
    """SIGINT (Ctrl-C) or SIGTERM (a closed terminal, a CI timeout) to the launcher during
    start-up: it exits non-zero (130 as the CLI reports interruptions, 143 for SIGTERM, or a
    KeyboardInterrupt) and every agent process is gone."""
    code = (
        "from popdispatch.agents.launch import launch\n"
        "launch(566, [[505, 666, 28.0]], rounds=40, startup_s=60)\n"
    )
    # a terminal's Ctrl-C: SIGINT at its default, whatever this process inherited (a shell
    # that starts a job in the background without job control ignores it, and so would the
    # launcher)
    launcher = subprocess.Popen([sys.executable, "-c", code], stderr=subprocess.PIPE,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 120
    while _children() < 12 and time.time() < deadline:
        time.sleep(0.5)
    started = _agents()
    assert len(started) == 12
    os.kill(launcher.pid, stop)
    launcher.wait(timeout=60)
    assert launcher.returncode != 0
    _, alive = psutil.wait_procs(started, timeout=10)  # orphans: the launcher is gone
    assert not alive
