"""``--constants`` (issue 12): the game's constants reach the engine.

Yardstick: our DC-OPF (Clarabel) of the same minute without the line limit. With the line
price's proportional gain ``C`` and its integral rate ``price_rate`` both zero, exact mode's
node controllers never price the limited lines, so the dynamics land on the unconstrained
economic dispatch and overflow the limit; with the defaults they respect it.
"""

from __future__ import annotations

import json

import pytest

from test_commands import assert_one_line_error, gens, run

LIMIT = ["--minute", "566", "--limit", "505:666=28"]


def test_zero_line_gains_ignore_the_limit():
    free = json.loads(run("opf", "--minute", "566", "--json", "-q").stdout)
    result = run(
        "snapshot", *LIMIT, "--mode", "exact", "--constants", "C=0,price_rate=0", "--json", "-q"
    )
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    setpoints = {name: g["setpoint_kw"] for name, g in gens(s).items()}
    for name, g in gens(free).items():
        assert setpoints[name] == pytest.approx(g["p_kw"], abs=1e-3), name
    assert s["max_overflow_kw"] > 5.0  # 34.86 kW on a 28 kW path
    priced = json.loads(run("snapshot", *LIMIT, "--mode", "exact", "--json", "-q").stdout)
    assert priced["status"] == "converged"
    assert priced["max_overflow_kw"] < 1e-3


@pytest.mark.parametrize(
    ("value", "words"),
    [("Q=1", ["--constants", "unknown constant", "price_rate"]), ("B=-1", ["--constants", "B=-1"])],
)
def test_bad_constants_are_usage_errors(value, words):
    assert_one_line_error(run("snapshot", "--minute", "566", "--constants", value), 2, *words)
