"""``--constants`` (issue 12): the paper's constants reach the engine (paper mode).

Yardsticks: the paper's eq. 8 makes the congestion signal proportional to ``C``, so with
``C=0`` a line limit cannot change the dispatch: the run with the 505:666=28 limit must equal
the run without it, set point by set point; with the paper's ``C`` the same limit must change
it (less overflow). ``B`` shifts every fitness alike (eq. 5), so Smith dynamics, which compare
fitness differences (eq. 11), rest at the same set points for any ``B`` that keeps fitness
positive.
"""

from __future__ import annotations

import json

import pytest

from test_commands import assert_one_line_error, gens, run

PEAK = ["snapshot", "--minute", "566", "--mode", "paper", "--json", "-q"]
LIMIT = ["--limit", "505:666=28"]


def _setpoints(*args: str) -> tuple[dict[str, float], dict]:
    result = run(*PEAK, *args)
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    return {name: g["setpoint_kw"] for name, g in gens(summary).items()}, summary


def test_zero_congestion_gain_makes_a_limit_inert():
    free, _ = _setpoints("--constants", "C=0")
    limited, s = _setpoints(*LIMIT, "--constants", "C=0")
    for name, kw in free.items():
        assert limited[name] == pytest.approx(kw, abs=1e-9), name
    paper, s_paper = _setpoints(*LIMIT)
    assert max(abs(paper[n] - free[n]) for n in free) > 1.0  # the paper's C acts
    assert s_paper["max_overflow_kw"] < s["max_overflow_kw"]


def test_bias_b_leaves_smith_dynamics_in_place():
    base, _ = _setpoints()
    doubled, _ = _setpoints("--constants", "B=2000")
    for name, kw in base.items():
        assert doubled[name] == pytest.approx(kw, abs=1e-6), name


@pytest.mark.parametrize(
    ("value", "words"),
    [("Q=1", ["--constants", "unknown constant", "price_rate"]), ("B=-1", ["--constants", "B=-1"])],
)
def test_bad_constants_are_usage_errors(value, words):
    assert_one_line_error(run("snapshot", "--minute", "566", "--constants", value), 2, *words)


def test_exact_mode_refuses_the_papers_constants():
    """Exact mode's constants are dimensionless (ExactConstants): the paper's EUR/MW ones would
    be silently ignored there, so the command refuses them before any work."""
    result = run("snapshot", "--minute", "566", "--mode", "exact", "--constants", "gain=5")
    assert_one_line_error(result, 2, "--constants", "exact mode")
