"""Exact mode's scaled price law (modes/exact.py, docs/exact-mode.md "Per-line scaling"): the
compiled rates and broadcast equal a plain-numpy construction of the per-line diagonal
preconditioner ``N / N_k`` from the problem's dense below-matrix, and the law is chosen by
name."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from price_laws import law_payoff

from popdispatch.game.parameters import MinuteInputs, PriceLaw, tradable_below, tradable_count
from popdispatch.modes.exact import (
    ExactConstants,
    scaled_weights,
)


def dense_scaled(problem, p, z, fp, minute) -> tuple[np.ndarray, np.ndarray]:
    """The scaled law from its definition with the dense (lines x generators) matrix
    ``problem.down``: ``N_k`` the tradable (online, ``hi > lo``) generators below line ``k``,
    ``N`` all tradable ones, the line's factor ``s_k = N / N_k`` (1 where ``N_k = 0``);
    rates ``price_rate * s_k * excess``; price ``nu_k = max(0, z+ + sqrt(s_k) C e+) - max(0, z- +
    sqrt(s_k) C e-)``; fitness ``gain * (sum_k nu_k (D_ki - 1/2) - (b_i + 2 c_i p_i))`` (EUR/MW).
    Returns ``(fitness, z_rate)``."""
    n = len(problem.limit)
    response = (minute.hi > minute.lo).astype(float)
    r_k = problem.down @ response
    s = np.where(r_k > 0, response.sum() / np.where(r_k > 0, r_k, 1.0), 1.0)
    flow = problem.load_flow[0] - problem.down @ p
    up, down = flow - problem.limit, -flow - problem.limit
    rate = fp.price_rate * np.concatenate([s * up, s * down])
    weight = np.sqrt(s) * fp.C
    nu = np.maximum(0, z[:n] + weight * up) - np.maximum(0, z[n:] + weight * down)
    signal = (problem.down - 0.5).T @ nu
    fitness = fp.gain * (signal - (problem.b + 2 * problem.c * p))
    return fitness, rate


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scaled_rates_equal_the_dense_preconditioner(problem, seed):
    rng = np.random.default_rng(seed)
    n = len(problem.limit)
    p = problem.pmin + (problem.pmax - problem.pmin) * rng.uniform(0, 1, problem.n_generators)
    p *= problem.demand[0] / p.sum()
    z = np.where(rng.uniform(0, 1, 2 * n) < 0.3, rng.uniform(0, 50, 2 * n), 0.0)
    minute = MinuteInputs.of(problem, 1)
    if seed == 2:  # a generator that cannot trade (Pmin = Pmax) leaves every R_k it was in
        hi, below = minute.hi.copy(), minute.below.copy()
        hi[3] = minute.lo[3]
        tradable_below(problem.generator_line, problem.line_up, problem.line_preorder,
                       minute.lo, hi, below)  # fmt: skip
        minute = minute._replace(hi=hi, below=below, tradable=tradable_count(minute.lo, hi))
    fitness, rate, fp = law_payoff(problem, PriceLaw.SCALED, p, z, minute)
    expected_fitness, expected_rate = dense_scaled(problem, p, z, fp, minute)
    np.testing.assert_allclose(rate, expected_rate, rtol=1e-9, atol=1e-9 * fp.price_rate)
    np.testing.assert_allclose(fitness, expected_fitness, rtol=1e-9, atol=1e-9 * fp.gain)
    if seed != 2:  # the weights the KKT check reads are the kernel's (minute 1 as it is)
        r_k = problem.down @ (minute.hi > minute.lo)
        s = np.where(r_k > 0, problem.n_generators / np.maximum(r_k, 1), 1.0)
        weights = scaled_weights(problem, np.array([0]), fp.C)[0]
        np.testing.assert_allclose(weights, np.sqrt(s) * fp.C)
    # the preconditioner is not the identity here: lines with few generators below move faster
    response = (minute.hi > minute.lo).astype(float)
    assert (problem.down @ response < 0.5 * response.sum()).any()


def test_the_engine_compiles_the_scaled_kernel_by_its_name(problem):
    """With adaptive steps the kernel that hastens the pinned pairs; with fixed Euler steps
    (which the agents follow) the law's own."""
    from popdispatch.integrate import Integrator
    from popdispatch.modes.exact import ExactScaledPinnedTag, ExactScaledTag
    from popdispatch.online import Engine, RunSettings

    assert ExactConstants(price_law="SCALED").price_law is PriceLaw.SCALED
    settings = RunSettings(mode="exact", exact=ExactConstants(price_law="scaled"))
    assert type(Engine(problem, settings).term.mode) is ExactScaledPinnedTag
    euler = replace(settings, integrator=Integrator(method="euler", dt=1e-4, substeps=1))
    assert type(Engine(problem, euler).term.mode) is ExactScaledTag


def test_a_pinned_pairs_scaled_rates_equal_the_numpy_statement():
    """Along a scaled-law run of the nested pair (tests/test_fleet_outliers.py: the one
    generator between two nested lines at its Pmin, 1680 iterations before its pair was
    hastened under this law): the compiled rates are the law's (:func:`dense_scaled`) plus
    the pair's gain on half the gap of the lines' rates ``alpha s_k e_k`` and the pinned and
    stuck lines' gains on their own (``popdispatch.reference.pinned_rates``); a gain is not
    zero on some of the states."""
    from popdispatch.game.parameters import GameParameters, GameWork
    from popdispatch.modes.exact import pinned_scaled_payoff
    from popdispatch.online import Engine, RunSettings
    from popdispatch.online.settings import initial_shares
    from popdispatch.reference import pinned_rates

    from helpers import random_fleet_problem

    problem = random_fleet_problem(3376343775, 5, 2)
    settings = RunSettings(mode="exact", exact=ExactConstants(price_law="scaled"))
    engine = Engine(problem, settings)
    speed = settings.engine_pinned_speed(problem)
    assert speed > 0
    run = engine.run_minute(initial_shares(problem, settings.x0, 1), 1, max_iterations=8)
    minute = MinuteInputs.of(problem, 1)
    fp = settings.game_constants(problem)
    params = GameParameters.of(problem, fp, pinned_speed=speed, stuck_lines=True)
    n = len(problem.limit)
    response = (minute.hi > minute.lo).astype(float)
    r_k = problem.down @ response
    s = np.where(r_k > 0, response.sum() / np.where(r_k > 0, r_k, 1.0), 1.0)
    gained = 0
    rng = np.random.default_rng(5)
    # one work for all states: its counts are kept from state to state
    work = GameWork.empty(n, n_generators=problem.n_generators)
    for p in run.trajectory:
        z = rng.uniform(0.0, 30.0, 2 * n)
        fitness, z_rate = np.empty(len(p)), np.empty(2 * n)
        pinned_scaled_payoff(p, z, params, minute, work, fitness, z_rate)
        expected_fitness, plain_rate = dense_scaled(problem, p, z, fp, minute)
        flow = problem.load_flow[0] - problem.down @ p
        excess = np.concatenate([flow - problem.limit, -flow - problem.limit])
        expected = pinned_rates(problem, 1, p, z, excess, plain_rate, fp.price_rate *
                                np.tile(s, 2), speed, expected_fitness / fp.gain)  # fmt: skip
        np.testing.assert_allclose(z_rate, expected, rtol=1e-9, atol=1e-9 * fp.price_rate)
        np.testing.assert_allclose(fitness, expected_fitness, rtol=1e-9, atol=1e-9 * fp.gain)
        gained += not np.allclose(expected, plain_rate, rtol=1e-12, atol=0.0)
    assert gained > 0


def test_voltage_mode_refuses_the_scaled_law():
    """Voltage mode has no scaled kernel: asking for one is an option error, not a silent
    plain law."""
    from popdispatch.errors import OptionError
    from popdispatch.modes import ModeCode, mode_tag

    with pytest.raises(OptionError, match="exact mode only"):
        mode_tag(ModeCode.VOLTAGE, PriceLaw.SCALED)
