"""Paper mode: the paper's rule (eqs. 5-8).

Barrier for generator limits (eq. 7) and a congestion signal proportional to the present
overflow (eq. 8). Memoryless (no controller states); leaves a residual overflow, and its
discontinuous barrier has rest points away from the DC-OPF (docs/paper-mode.md).
"""

from __future__ import annotations

import numba as nb

from popdispatch.game.controllers import overflow_signal
from popdispatch.game.fitness import fitness_into
from popdispatch.game.flows import (
    broadcast,
    limited_line_flows,
    mesh_broadcast,
    mesh_line_flows,
)
from popdispatch.modes.mechanism import Mode, ModeCode, ModeTag


@nb.njit(cache=True, inline="always")
def payoff(p, z, params, minute, work, fitness, z_rate):
    """Eqs. 5-8 into ``fitness``; ``z`` and ``z_rate`` are empty. Returns ``(congestion,
    residual)``: the largest signal magnitude (EUR/MW) and 0 (no controllers to settle)."""
    flow, parent_side, child_side = work.flow, work.parent_side, work.child_side
    limit, C = params.limit, params.C
    limited_line_flows(minute.load_flow, p, params.generator_line, params.line_up,
                       params.line_preorder, flow)  # fmt: skip
    controller_values(flow, limit, C, parent_side, child_side)
    broadcast(parent_side, child_side, params.generator_line, params.line_up,
              params.line_preorder, work.path, fitness)  # fmt: skip
    return barrier_fitness(p, params, fitness)


@nb.njit(cache=True, inline="always")
def controller_values(flow, limit, C, parent_side, child_side):
    """Eq. 8 at both ends of every limited line: the parent-end controller's value (which
    measures ``flow``) into ``parent_side``, the child-end one's (``-flow``) into
    ``child_side``."""
    for k in range(flow.shape[0]):
        parent_side[k] = overflow_signal(flow[k], limit[k], C)
        child_side[k] = overflow_signal(-flow[k], limit[k], C) if parent_side[k] != 0.0 else 0.0


@nb.njit(cache=True, inline="always")
def barrier_fitness(p, params, fitness):
    """Eqs. 5-7 from the signals already in ``fitness``; returns ``(congestion, 0)``."""
    congestion = 0.0
    for i in range(p.shape[0]):
        congestion = max(congestion, abs(fitness[i]))
    fitness_into(p, params.b, params.c, params.pmin, params.pmax, params.B, params.m, 1.0,
                 fitness, True, fitness)  # fmt: skip
    return congestion, 0.0


@nb.njit(cache=True, inline="always")
def mesh_payoff(p, z, params, minute, work, fitness, z_rate):
    """:func:`payoff` on a meshed network: the flows ``load_flow - D p`` and each line's two
    eq.-8 values weighed by every generator's distribution factor ``D_ki`` (``params.factor``,
    :func:`~popdispatch.game.flows.mesh_broadcast`): ``s_i = sum_k parent_k + D_ki (child_k -
    parent_k)``, the side's value on a radial feeder."""
    flow = work.flow
    mesh_line_flows(minute.load_flow, p, params.factor, flow)
    controller_values(flow, params.limit, params.C, work.parent_side, work.child_side)
    mesh_broadcast(work.parent_side, work.child_side, params.factor, fitness)
    return barrier_fitness(p, params, fitness)


MODE = Mode("paper", ModeCode.PAPER, lambda problem: 0, bounded=False)


class PaperTag(ModeTag):
    """Paper mode's payoff (:func:`payoff`)."""

    __slots__ = ()
    kernel = staticmethod(payoff)


class PaperMeshTag(ModeTag):
    """Paper mode's payoff on a meshed network (:func:`mesh_payoff`)."""

    __slots__ = ()
    kernel = staticmethod(mesh_payoff)
