"""Payoff mechanisms, one module per mode: the registry and the enum agree, and each mode's
compiled payoff map equals the eqs.-5-8 composition on a dense matrix."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from popdispatch.game.controllers import broadcast_signals
from popdispatch.game.fitness import FitnessParameters, generator_fitness
from popdispatch.game.parameters import GameParameters, GameWork, MinuteInputs
from popdispatch.modes import MODES, ModeCode
from popdispatch.reference import game
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem


@pytest.fixture(scope="module")
def problem():
    return elv_problem(limits=[CONGESTION_PATH])


def test_one_module_per_mode_and_one_enum_member_each():
    assert sorted(m.code for m in MODES.values()) == sorted(ModeCode)
    for name, mode in MODES.items():
        module = importlib.import_module(f"popdispatch.modes.{name}")
        assert module.MODE is mode and callable(module.payoff)
        assert mode.code.name == name.upper()


def _payoff(problem, mode, p, z, fp):
    params = GameParameters.of(problem, fp)
    minute = MinuteInputs.of(problem, PEAK_MINUTE)
    fitness, z_rate = np.empty(len(p)), np.empty(len(z))
    work = GameWork.empty(len(problem.limit), n_generators=problem.n_generators)
    payoff = importlib.import_module(f"popdispatch.modes.{mode.name}").payoff
    congestion, residual = payoff(p, z, params, minute, work, fitness, z_rate)
    return fitness, z_rate, congestion, residual


def test_paper_payoff_is_the_fitness_kernel_plus_eq_8_signals(problem):
    fp = FitnessParameters()
    p = problem.pmax * 0.9  # overloads the congested path
    fitness, _, congestion, residual = _payoff(problem, MODES["paper"], p, np.zeros(0), fp)
    flow = problem.load_flow[PEAK_MINUTE - 1] - problem.down @ p
    signal = broadcast_signals(flow, problem.limit, problem.down, fp.C)
    expected = generator_fitness(p, problem.b, problem.c, problem.pmin, problem.pmax, fp.B,
                                 fp.m, signal)  # fmt: skip
    np.testing.assert_allclose(fitness, expected, rtol=1e-12)
    assert congestion == pytest.approx(np.abs(signal).max()) and congestion > 0
    assert residual == 0.0


@pytest.mark.parametrize("name", sorted(MODES))
def test_payoff_maps_equal_the_dense_reference(problem, name):
    mode, fp = MODES[name], FitnessParameters()
    rng = np.random.default_rng(5)
    p = problem.pmax * rng.uniform(0.2, 1.1, problem.n_generators)
    z = rng.uniform(0.0, 50.0, mode.controller_states(problem))
    got = _payoff(problem, mode, p, z, fp)
    expected = game(mode.code, p, z, problem, PEAK_MINUTE, fp)
    np.testing.assert_allclose(got[0], expected[0], rtol=1e-12)
    np.testing.assert_allclose(got[1], expected[1], rtol=1e-12)
    assert got[2] == pytest.approx(expected[2], rel=1e-12)
    assert got[3] == pytest.approx(expected[3], rel=1e-12)


def test_mode_defaults_live_with_the_mode():
    exact, paper = MODES["exact"], MODES["paper"]
    assert exact.integrator_options["method"] == "heun"
    assert paper.integrator_options.get("method", "euler") == "euler"
    assert (exact.warm_start, paper.warm_start) == ("merit", "shares")
    assert exact.claims_dc_opf and not paper.claims_dc_opf
