"""Distributed dispatch algorithms on one message network, for comparison: each one module
(initialise / local update / exchange, :mod:`popdispatch.algorithms.base`), one generic round
runner (:mod:`popdispatch.algorithms.runner`) and one counter and clock
(:mod:`popdispatch.algorithms.network`: an in-process synchronous message-passing runtime,
not the mango agents of :mod:`popdispatch.agents`). The registry has one line per algorithm.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

from popdispatch.algorithms.admm import Admm, AdmmParams
from popdispatch.algorithms.dual import DualDecomposition, DualParams
from popdispatch.algorithms.network import Faults, Network
from popdispatch.algorithms.population import PopulationDynamics, SmithParams
from popdispatch.algorithms.runner import AlgorithmRun, RunOptions, run_algorithm


@dataclass(frozen=True)
class Entry:
    """An algorithm of the registry: its class and its default parameters' factory."""

    cls: type
    params: object


ALGORITHMS: dict[str, Entry] = {
    "smith": Entry(PopulationDynamics, SmithParams),
    "distributed-smith": Entry(PopulationDynamics, partial(SmithParams, graph="ring")),
    "dual-decomposition": Entry(DualDecomposition, DualParams),
    "admm": Entry(Admm, AdmmParams),
}

__all__ = [
    "ALGORITHMS", "AlgorithmRun", "AdmmParams", "DualParams", "Faults", "Network",
    "RunOptions", "SmithParams", "run_algorithm",
]  # fmt: skip
