"""Population dynamics by messages under the paper's rule (``smith-paper``,
``distributed-smith-paper``): the rounds follow the paper's dynamics to the paper mode's rest,
measured against the engine's paper mode on the same minute (a separate implementation: numba
kernels, flux-limited Euler substeps), and that rest is reported for what it is: away from
the DC-OPF (an independent Clarabel solve), never converged."""

from __future__ import annotations

import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import compare_cases  # noqa: E402

from popdispatch.algorithms import RunOptions, run_algorithm  # noqa: E402
from popdispatch.algorithms.population import paper_signals  # noqa: E402
from popdispatch.online import RunSettings, run_snapshot  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

ELV = "ieee-elv 566, 505:666=28"


@cache
def _elv():
    build, minute = compare_cases.CASES[ELV]
    return build(), minute


@cache
def _paper_run(name: str):
    problem, minute = _elv()
    return run_algorithm(name, problem, minute, options=RunOptions(max_rounds=8000))


def test_smith_by_messages_rests_where_the_engines_paper_mode_rests():
    """Smith on the complete graph under eqs. 5-8 ends within 0.05 kW of the engine's
    paper-mode set points (its chatter about the rest is about 0.01 kW a round), keeps supply
    equal to demand every round, and the rest is the paper mode's: farther from the DC-OPF
    than the accuracy, with the residual overflow eq. 8 leaves; not converged."""
    problem, minute = _elv()
    engine = run_snapshot(problem, minute, RunSettings(mode="paper"))
    assert engine.status == "converged"
    run = _paper_run("smith-paper")
    assert np.abs(run.setpoints_kw - engine.setpoints_kw).max() <= 0.05
    assert np.abs(run.imbalance_kw).max() <= 1e-9
    opf = solve_opf(problem, minute).p_kw
    distance = np.abs(run.setpoints_kw - opf).max()
    assert run.status == "not_converged"
    assert distance > run.tol_kw
    assert abs(distance - np.abs(engine.setpoints_kw - opf).max()) <= 0.05
    assert run.overflow_kw[-1] > run.tol_kw  # eq. 8 acts only on an overflow


def test_distributed_smith_by_messages_approaches_the_paper_rest_on_a_ring():
    """On the ring the relay carries the mass more slowly: after 8000 rounds within 0.3 kW
    of the engine's paper-mode rest, not converged, balanced every round."""
    problem, minute = _elv()
    engine = run_snapshot(problem, minute, RunSettings(mode="paper"))
    run = _paper_run("distributed-smith-paper")
    assert np.abs(run.setpoints_kw - engine.setpoints_kw).max() <= 0.3
    assert np.abs(run.imbalance_kw).max() <= 1e-9
    assert run.status == "not_converged"


@pytest.mark.parametrize("limit", [0.02, 0.5, 3.0])
def test_paper_signals_are_eq_8_at_both_ends(limit):
    """Eq. 8 by hand: ``-C (|flow| - U)`` signed towards the overloaded end, 0 inside."""
    C = 1000.0
    for flow in np.linspace(-4.0, 4.0, 33):
        parent, child = paper_signals(float(flow), limit, C)
        if abs(flow) <= limit:
            assert parent == child == 0.0
        else:
            over = (abs(flow) - limit) * C
            assert parent == pytest.approx(-np.sign(flow) * over)
            assert child == pytest.approx(np.sign(flow) * over)


def test_compare_runs_the_paper_mode_only_when_named():
    """The default list is the methods that claim the DC-OPF; the paper's rule runs when
    named, and its row says it has not reached the DC-OPF."""
    import json

    from popdispatch.cli.compare import ALGORITHM_NAMES, DEFAULT_ALGORITHMS

    assert "smith-paper" in ALGORITHM_NAMES and "smith-paper" not in DEFAULT_ALGORITHMS
    done = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", "compare", "--algorithms", "smith-paper",
         "--minute", "566", "--limit", "505:666=28", "--max-rounds", "300", "--json", "-q"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)["algorithms"]
    assert [r["algorithm"] for r in rows] == ["smith-paper"]
    assert rows[0]["converged"] == "0/1" and rows[0]["final_distance_kw"] > 1e-3
