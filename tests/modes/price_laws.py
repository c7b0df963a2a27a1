"""Exact mode's compiled payoff under each price law, for the price-law tests, and the
synthetic 1k feeder they run on."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from popdispatch.game.parameters import GameParameters, GameWork, PriceLaw
from popdispatch.modes.exact import (
    ExactConstants,
    game_constants,
    payoff,
    scaled_payoff,
    tree_payoff,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import scale_cases  # noqa: E402  (the benchmark's synthetic feeders)

KERNELS = {PriceLaw.PLAIN: payoff, PriceLaw.TREE: tree_payoff, PriceLaw.SCALED: scaled_payoff}


def synthetic_1k():
    """The synthetic 1k feeder, every candidate line limited (68 limited lines, nested)."""
    return scale_cases.synthetic(1000, 10, 1.0)


def law_payoff(problem, law: PriceLaw, p, z, minute):
    """``(fitness, z_rate, game constants)`` of exact mode's compiled payoff under ``law`` at
    set points ``p`` (MW), controller states ``z`` and ``minute`` (MinuteInputs)."""
    fp = game_constants(problem, ExactConstants(price_law=law))
    params = GameParameters.of(problem, fp)
    fitness, z_rate = np.empty(len(p)), np.empty(len(z))
    work = GameWork.empty(len(problem.limit), n_generators=len(p))
    KERNELS[law](p, z, params, minute, work, fitness, z_rate)
    return fitness, z_rate, fp
