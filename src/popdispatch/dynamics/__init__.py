"""Mean dynamics as vector fields on the population shares ``x`` (``x_i = p_i / P_d``).

Every dynamic is a pairwise-comparison flow (:mod:`popdispatch.dynamics.pairwise`) fixed by
its receiver and sender weights. Each is a :class:`Dynamics` record naming its compiled
weights, so the integrator never needs to know which one it runs, and adding one never touches
the integrator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from popdispatch.dynamics.capacity import project_to_box
from popdispatch.dynamics.fields import Field, rated_field_weights
from popdispatch.dynamics.graph import GRAPHS, communication_graph
from popdispatch.dynamics.pairwise import pairwise_flows, sort_by_fitness


@dataclass(frozen=True)
class Dynamics:
    """A mean dynamic.

    Attributes
    ----------
    name : CLI name.
    field : its vector field (weights in :func:`popdispatch.dynamics.fields.field_weights`).
    uses_graph : whether the communication graph matters (else the complete graph is used).
    bounded_field : the capacity-constrained variant used by the exact mode (None if there is
        none: imitative dynamics, whose zero shares stay at zero).
    """

    name: str
    field: Field
    uses_graph: bool
    bounded_field: Field | None = None


DYNAMICS = {
    d.name: d
    for d in (
        Dynamics("smith", Field.SMITH, False, Field.CAPACITY_SMITH),  # eq. 13
        Dynamics("replicator", Field.REPLICATOR, False),  # eq. 9
        Dynamics("local-replicator", Field.LOCAL_REPLICATOR, True),  # eq. 12
        Dynamics("distributed-smith", Field.SMITH, True, Field.CAPACITY_SMITH),  # eq. 14
    )
}


def field_rate(
    field: Field,
    x: np.ndarray,
    f: np.ndarray,
    adjacency: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    active: np.ndarray | None = None,
    rate: np.ndarray | None = None,
) -> np.ndarray:
    """``x'`` of the field ``field`` at shares ``x`` and fitness ``f``, on a dense 0/1
    ``adjacency``, with the compiled kernels (``rate``: the per-generator revision rates of
    the curvature-scaled field)."""
    n = len(x)
    x, f = np.asarray(x, dtype=float), np.asarray(f, dtype=float)
    active = np.ones(n, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    rate = np.ones(n) if rate is None else np.asarray(rate, dtype=float)
    w, v, room, mass, inflow, outflow = (np.empty(n) for _ in range(6))
    rated_field_weights(int(field), x, np.asarray(lo, float), np.asarray(hi, float), active, rate,
                        w, v, room, mass)  # fmt: skip
    complete = bool((adjacency + np.eye(n) > 0).all())
    csr = sparse.csr_matrix(adjacency)
    order = np.arange(n, dtype=np.int64)
    if complete:
        sort_by_fitness(f, order)
    indptr, indices = csr.indptr.astype(np.int64), csr.indices.astype(np.int64)
    pairwise_flows(f, w, v, mass, room, complete, indptr, indices, order, inflow, outflow)
    return inflow - outflow


def get_dynamics(name: str) -> Dynamics:
    """Look up a dynamic by name (see :data:`DYNAMICS`)."""
    try:
        return DYNAMICS[name]
    except KeyError:
        raise ValueError(f"unknown dynamics {name!r} (known: {', '.join(DYNAMICS)})") from None


__all__ = [
    "DYNAMICS",
    "GRAPHS",
    "Dynamics",
    "Field",
    "communication_graph",
    "field_rate",
    "get_dynamics",
    "project_to_box",
]
