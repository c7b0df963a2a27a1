"""Distributed dispatch algorithms on one message network, for comparison: each one module
(initialise / local update / exchange, :mod:`popdispatch.algorithms.base`), one generic round
runner (:mod:`popdispatch.algorithms.runner`) and one counter and clock
(:mod:`popdispatch.algorithms.network`: an in-process synchronous message-passing runtime,
not the mango agents of :mod:`popdispatch.agents`). The registry
(:mod:`popdispatch.algorithms.registry`) has one line per algorithm.
"""

from __future__ import annotations

from popdispatch.algorithms.admm import AdmmParams
from popdispatch.algorithms.consensus_admm import ConsensusAdmmParams
from popdispatch.algorithms.dual import DualParams
from popdispatch.algorithms.network import Faults, Network
from popdispatch.algorithms.population import SmithParams
from popdispatch.algorithms.registry import ALGORITHMS
from popdispatch.algorithms.runner import AlgorithmRun, RunOptions, run_algorithm

__all__ = [
    "ALGORITHMS", "AlgorithmRun", "AdmmParams", "ConsensusAdmmParams", "DualParams", "Faults",
    "Network",
    "RunOptions", "SmithParams", "run_algorithm",
]  # fmt: skip
