"""The registry: one line per algorithm (its class and its default parameters, the
equal-effort tuning's winners, docs/comparison.md)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

from popdispatch.algorithms.admm import Admm, AdmmParams
from popdispatch.algorithms.consensus_admm import ConsensusAdmm, ConsensusAdmmParams
from popdispatch.algorithms.dual import DualDecomposition, DualParams
from popdispatch.algorithms.population import PopulationDynamics, SmithParams


@dataclass(frozen=True)
class Entry:
    """An algorithm of the registry: its class and its default parameters' factory."""

    cls: type
    params: object


ALGORITHMS: dict[str, Entry] = {
    "smith": Entry(PopulationDynamics, SmithParams),
    "distributed-smith": Entry(PopulationDynamics, partial(SmithParams, graph="ring")),
    "smith-paper": Entry(PopulationDynamics, partial(SmithParams, step=1.0, mode="paper")),
    "distributed-smith-paper": Entry(
        PopulationDynamics, partial(SmithParams, step=1.0, graph="ring", mode="paper")
    ),
    "dual-decomposition": Entry(DualDecomposition, DualParams),
    "fast-dual-decomposition": Entry(
        DualDecomposition, partial(DualParams, balance_step=0.5, accelerated=True)
    ),
    "admm": Entry(Admm, AdmmParams),
    "consensus-admm": Entry(ConsensusAdmm, ConsensusAdmmParams),
}
