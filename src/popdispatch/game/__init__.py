"""The population game: fitness (eqs. 5-7), node controllers and congestion signals (eq. 8)."""

from popdispatch.game.controllers import NodeControllers, broadcast_signals, overflow_signal
from popdispatch.game.fitness import FitnessParameters, barrier, generator_fitness
from popdispatch.game.problem import DispatchProblem, build_problem

__all__ = [
    "DispatchProblem",
    "FitnessParameters",
    "NodeControllers",
    "barrier",
    "broadcast_signals",
    "build_problem",
    "generator_fitness",
    "overflow_signal",
]
