"""Mean dynamics as vector fields on the population shares ``x`` (``x_i = p_i / P_d``).

Every dynamic is one module stating its flow law (:mod:`popdispatch.dynamics.law`: mass moves
from ``j`` to ``i`` at ``g_ij w_i v_j K(f_i, f_j)``, ``K`` a fitness comparison or 1), listed in
the registry :data:`popdispatch.dynamics.fields.MODULES`:

- :mod:`~popdispatch.dynamics.smith`: Smith and distributed Smith (pairwise comparison);
- :mod:`~popdispatch.dynamics.replicator`: replicator and local replicator (imitation);
- :mod:`~popdispatch.dynamics.capacity`, :mod:`~popdispatch.dynamics.newton`: Smith inside
  the generator limits, plain or curvature-scaled (exact mode);
- :mod:`~popdispatch.dynamics.bnn`: Brown-von Neumann-Nash (excess payoff, a target);
- :mod:`~popdispatch.dynamics.logit`: logit with noise ``eta`` (perturbed best response).

The integrator, its flux limiter and the plain-numpy reference read the laws, never a
particular dynamic (docs/dynamics.md).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from scipy import sparse

from popdispatch.dynamics.capacity import project_to_box
from popdispatch.dynamics.fields import NAMED, Field, field_tag, law_flows, order_for
from popdispatch.dynamics.fields import local_weights as _local
from popdispatch.dynamics.fields import weights as _weights
from popdispatch.dynamics.graph import GRAPHS, communication_graph
from popdispatch.dynamics.law import Dynamics, FlowLaw, Kernel
from popdispatch.dynamics.pairwise import graph_of

#: The dynamics people name (``--dynamics``), by name.
DYNAMICS: dict[str, Dynamics] = {d.name: d for d in NAMED}


@nb.njit(cache=True)
def _field_rate(tag, graph, x, f, lo, hi, active, rate, w, v, room, mass, order, inflow, outflow):
    _weights(tag, x, f, lo, hi, active, rate, w, v, room, mass)
    _local(tag, graph, rate, w, v, room, mass)
    order_for(tag, graph, f, order)
    law_flows(tag, graph, f, w, v, mass, room, order, inflow, outflow)


def field_rate(
    field: Field | tuple,
    x: np.ndarray,
    f: np.ndarray,
    adjacency: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    active: np.ndarray | None = None,
    rate: np.ndarray | None = None,
    **parameters: float,
) -> np.ndarray:
    """``x'`` (shares/s) of the field ``field`` (a :class:`Field`, or its record) at shares
    ``x`` and fitness ``f`` (EUR/MW), on a dense 0/1 ``adjacency``, by the engine's own
    compiled kernels (``rate``: the per-generator revision rates of the curvature-scaled
    field; ``parameters``: the law's, e.g. ``eta`` and ``gain`` of the logit, in fitness units
    and 1/s)."""
    n = len(x)
    x, f = np.asarray(x, dtype=float), np.asarray(f, dtype=float)
    active = np.ones(n, dtype=bool) if active is None else np.asarray(active, dtype=bool)
    rate = np.ones(n) if rate is None else np.asarray(rate, dtype=float)
    tag = field_tag(field, **parameters)
    complete = bool((adjacency + np.eye(n) > 0).all())
    csr = sparse.csr_matrix(adjacency)
    graph = graph_of(complete, csr.indptr.astype(np.int64), csr.indices.astype(np.int64), rate)
    w, v, room, mass, inflow, outflow = (np.empty(n) for _ in range(6))
    _field_rate(tag, graph, x, f, np.asarray(lo, float), np.asarray(hi, float), active, rate, w,
                v, room, mass, np.arange(n, dtype=np.int64), inflow, outflow)  # fmt: skip
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
    "FlowLaw",
    "Kernel",
    "communication_graph",
    "field_rate",
    "get_dynamics",
    "project_to_box",
]
