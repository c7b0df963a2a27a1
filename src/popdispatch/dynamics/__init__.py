"""Mean dynamics as vector fields on the population shares ``x`` (``x_i = p_i / P_d``).

Each dynamic is a :class:`Dynamics` record naming its compiled vector field, so the integrator
never needs to know which one it runs, and adding one never touches the integrator.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from popdispatch.dynamics.capacity import project_to_box
from popdispatch.dynamics.fields import CAPACITY_SMITH, LOCAL_REPLICATOR, REPLICATOR, SMITH
from popdispatch.dynamics.graph import GRAPHS, communication_graph
from popdispatch.dynamics.replicator import local_replicator_rates, replicator_rates
from popdispatch.dynamics.smith import smith_rates


@dataclass(frozen=True)
class Dynamics:
    """A mean dynamic.

    Attributes
    ----------
    name : CLI name.
    rates : compiled vector field ``(x, f, graph, lo, hi) -> (inflow, out_rate, rate_bound)``.
    field : its code for :func:`popdispatch.dynamics.fields.vector_field`.
    uses_graph : whether the communication graph matters (else the complete graph is used).
    extinction : whether a strategy at zero share stays at zero (imitative dynamics).
    equation : the paper's equation number.
    bounded_field : code of the capacity-constrained variant used by the exact mode (None if
        there is none).
    """

    name: str
    rates: Callable
    field: int
    uses_graph: bool
    extinction: bool
    equation: str
    bounded_field: int | None = None


DYNAMICS = {
    d.name: d
    for d in (
        Dynamics("smith", smith_rates, SMITH, False, False, "13", CAPACITY_SMITH),
        Dynamics("replicator", replicator_rates, REPLICATOR, False, True, "9"),
        Dynamics("local-replicator", local_replicator_rates, LOCAL_REPLICATOR, True, True, "12"),
        Dynamics("distributed-smith", smith_rates, SMITH, True, False, "14", CAPACITY_SMITH),
    )
}


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
    "communication_graph",
    "get_dynamics",
    "project_to_box",
]
