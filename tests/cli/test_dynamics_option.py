"""``--dynamics bnn|logit`` and ``--eta`` from the command line (in a subprocess): BNN and logit
reach the engine and give what the library gives for the same settings; exact-mode logit is
reported stalled with its distance to the DC-OPF (Clarabel's), never converged; ``--eta``
is refused with one line wherever it is missing, meaningless or not a positive number, and
BNN where it cannot run (exact mode, a sparse graph), before any work."""

from __future__ import annotations

import json

import numpy as np
import pytest

from test_commands import assert_one_line_error, run


def snapshot(*args: str) -> dict:
    result = run("snapshot", "--minute", "566", *args, "--json", "-q")
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


@pytest.mark.parametrize(
    "options", [("--dynamics", "bnn"), ("--dynamics", "logit", "--eta", "0.1")]
)
def test_bnn_and_logit_run_from_the_command_line_as_in_the_library(options):
    from popdispatch.online import RunSettings, run_snapshot
    from popdispatch.scenarios import elv_problem

    s = snapshot(*options)
    assert s["dynamics"] == options[1] and s["status"] == "converged"
    kw = {"eta": float(options[3])} if len(options) > 2 else {}
    expected = run_snapshot(elv_problem(), 566, RunSettings(dynamics=options[1], **kw))
    got = np.array([g["setpoint_kw"] for g in s["generators"]])
    np.testing.assert_allclose(got, expected.setpoints_kw, rtol=0, atol=1e-9)
    assert s["iterations"] == expected.iterations


def test_exact_logit_is_stalled_with_its_distance_to_the_dc_opf():
    s = snapshot("--dynamics", "logit", "--eta", "1", "--mode", "exact")
    assert s["status"] == "stalled" and s["converged_iteration"] is None
    assert "own equilibrium" in s["stall_reason"]
    error = max(abs(g["setpoint_kw"] - g["opf_kw"]) for g in s["generators"])
    assert 0.1 < error <= s["distance_bound_kw"]


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--dynamics", "logit"], ["--eta", "noise level"]),
        (["--eta", "0.1"], ["--eta", "smith dynamics have none"]),
        (["--dynamics", "bnn", "--eta", "0.1"], ["--eta", "bnn"]),
        (["--dynamics", "logit", "--eta", "0"], ["--eta"]),
        (["--dynamics", "logit", "--eta", "nan"], ["--eta", "finite"]),
        (["--dynamics", "logit", "--eta", "inf"], ["--eta", "finite"]),
        (["--dynamics", "logit", "--eta", "x"], ["--eta"]),
        (["--dynamics", "bnn", "--mode", "exact"], ["--mode", "bnn", "mean fitness"]),
        (["--dynamics", "logit", "--eta", "1", "--graph", "ring"], ["--graph", "logit"]),
    ],
)
def test_bad_dynamics_options_are_one_line_usage_errors(args, words):
    for command in (["snapshot", "--minute", "566"], ["day", "--steps", "1-2"]):
        assert_one_line_error(run(*command, *args, "-q"), 2, *words)
