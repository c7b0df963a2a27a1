"""Consensus ADMM (``consensus-admm``): the DC-OPF split into a cost term per DG, the balance
at the coordinator and a limit per line controller, each on its copy of the set points it
touches. It reaches the DC-OPF (an independent Clarabel solve) on radial feeders, with linear
costs that dual decomposition refuses, under message loss and with a crashed DG; the message
count of one iteration is the one counted by hand. On a meshed network:
``test_meshed_compare.py``."""

from __future__ import annotations

import sys
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import compare_cases  # noqa: E402

from popdispatch.algorithms import (  # noqa: E402
    Faults,
    RunOptions,
    run_algorithm,
)
from popdispatch.algorithms.network import HEADER_BYTES, SCALAR_BYTES  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

ELV, C33 = "ieee-elv 566, 505:666=28", "case33bw, one binding limit"


@cache
def _problem(label):
    build, minute = compare_cases.CASES[label]
    return build(), minute


def _check(run, problem, minute, opf_kw=None):
    """Converged means within the run's accuracy of an independent DC-OPF, balanced, every
    set point within its range every round; not converged means away from it."""
    opf_kw = solve_opf(problem, minute).p_kw if opf_kw is None else opf_kw
    distance = np.abs(run.setpoints_kw - opf_kw).max()
    imbalance = abs(run.setpoints_kw.sum() - problem.demand[minute - 1] * 1e3)
    if run.status == "converged":
        assert distance <= run.tol_kw and imbalance <= run.tol_kw
    else:
        assert max(distance, imbalance, run.overflow_kw[-1]) > run.tol_kw
    lo, hi = problem.pmin * 1e3, problem.pmax * 1e3
    assert np.all(run.trajectory_kw >= lo - 1e-9) and np.all(run.trajectory_kw <= hi + 1e-9)


@pytest.mark.parametrize("label", [ELV, C33])
def test_reaches_the_dc_opf_of_a_radial_feeder(label):
    problem, minute = _problem(label)
    run = run_algorithm("consensus-admm", problem, minute, options=RunOptions(max_rounds=6000))
    assert run.status == "converged", run.summary()
    _check(run, problem, minute)
    assert (np.abs(solve_opf(problem, minute).line_price) > 1e-3).any()  # the limit binds


def test_linear_costs_that_dual_decomposition_refuses():
    """A linear DG (``c = 0``) has a unique proximal step: consensus ADMM reaches the DC-OPF."""
    from popdispatch.algorithms.dual import DualDecomposition
    from popdispatch.errors import OptionError

    problem, minute = _problem(C33)
    c = problem.c.copy()
    c[1] = 0.0
    linear = replace(problem, c=c)
    with pytest.raises(OptionError):
        DualDecomposition.check(linear)
    run = run_algorithm("consensus-admm", linear, minute, options=RunOptions(max_rounds=6000))
    assert run.status == "converged", run.summary()
    _check(run, linear, minute)


@pytest.mark.parametrize("loss", [0.1, 0.3])
def test_lossy_network_converged_only_at_the_dc_opf(loss):
    problem, minute = _problem(C33)
    run = run_algorithm("consensus-admm", problem, minute, Faults(loss=loss, seed=2),
                        options=RunOptions(max_rounds=6000))  # fmt: skip
    _check(run, problem, minute)
    assert run.status == "converged", run.summary()


def test_a_crashed_dg_holds_its_set_point_and_the_rest_reach_the_dc_opf_around_it():
    problem, minute = _problem(C33)
    crash_round, i = 15, 2
    run = run_algorithm("consensus-admm", problem, minute,
                        Faults(crash=(str(problem.generators[i]), crash_round)),
                        options=RunOptions(max_rounds=6000))  # fmt: skip
    held = run.trajectory_kw[crash_round, i]
    assert np.all(run.trajectory_kw[crash_round:, i] == held)
    pmin, pmax = problem.pmin.copy(), problem.pmax.copy()
    pmin[i] = pmax[i] = held / 1e3
    opf = solve_opf(replace(problem, pmin=pmin, pmax=pmax), minute)
    assert run.status == "converged", run.summary()
    _check(run, problem, minute, opf.p_kw)


def test_one_iteration_sends_the_messages_counted_by_hand():
    """Per iteration each DG sends its consensus value and applied set point (two scalars)
    to the coordinator and to each line whose distribution factor on it is not 0, and each
    of those holders sends it one value back: 2 (n + nnz(D)) messages, 3 (n + nnz(D))
    scalars; plus n cost curves (four scalars) at configuration."""
    problem, minute = _problem(C33)
    n, nnz = problem.n_generators, int(np.count_nonzero(problem.down))
    run = run_algorithm("consensus-admm", problem, minute, options=RunOptions(max_rounds=4))
    pairs = n + nnz
    # round 0: configuration and the first consensus values; rounds 1-4: two iterations
    assert run.messages[0] == n + pairs
    assert run.scalars[0] == 4 * n + 2 * pairs
    assert run.messages[4] - run.messages[0] == 2 * 2 * pairs
    assert run.scalars[4] - run.scalars[0] == 2 * 3 * pairs
    assert run.bytes == (n + 5 * pairs) * HEADER_BYTES + (4 * n + 8 * pairs) * SCALAR_BYTES


def test_the_penalty_is_exact_modes_scales():
    """:func:`penalty` (what the coordinator agent computes from the DGs' curves) is
    ``rho_scale S / P`` of exact mode's :func:`~popdispatch.modes.exact.scales`, to the bit,
    also where the spread is zero (equal marginal costs)."""
    from popdispatch.algorithms.consensus_admm import penalty
    from popdispatch.modes.exact import scales

    problem = compare_cases.case33bw()
    flat = replace(problem, b=np.full_like(problem.b, 30.0), c=np.zeros_like(problem.c))
    for p in (problem, flat):
        spread, demand = scales(p)
        assert penalty(2.5, p.b, p.c, p.pmin, p.pmax, float(np.max(p.demand))) == \
            2.5 * spread / demand  # fmt: skip
