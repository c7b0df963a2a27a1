"""Paper mode: the paper's rule (eqs. 5-8).

Barrier for generator limits (eq. 7) and a congestion signal proportional to the present
overflow (eq. 8). Memoryless (no controller states); leaves a residual overflow, and its
discontinuous barrier has rest points away from the DC-OPF (docs/paper-mode.md).
"""

from __future__ import annotations

import numba as nb

from popdispatch.game.controllers import overflow_signal
from popdispatch.game.fitness import fitness_into
from popdispatch.game.flows import broadcast, limited_line_flows
from popdispatch.modes.mechanism import Mode, ModeCode, ModeTag


@nb.njit(cache=True, inline="always")
def payoff(p, z, params, minute, work, fitness, z_rate):
    """Eqs. 5-8 into ``fitness``; ``z`` and ``z_rate`` are empty. Returns ``(congestion,
    residual)``: the largest signal magnitude (EUR/MW) and 0 (no controllers to settle)."""
    flow, parent_side, child_side = work.flow, work.parent_side, work.child_side
    limit, C = params.limit, params.C
    limited_line_flows(minute.load_flow, p, params.generator_line, params.line_up,
                       params.line_preorder, flow)  # fmt: skip
    for k in range(flow.shape[0]):
        parent_side[k] = overflow_signal(flow[k], limit[k], C)
        child_side[k] = overflow_signal(-flow[k], limit[k], C) if parent_side[k] != 0.0 else 0.0
    broadcast(parent_side, child_side, params.generator_line, params.line_up,
              params.line_preorder, work.path, fitness)  # fmt: skip
    congestion = 0.0
    for i in range(p.shape[0]):
        congestion = max(congestion, abs(fitness[i]))
    fitness_into(p, params.b, params.c, params.pmin, params.pmax, params.B, params.m, 1.0,
                 fitness, True, fitness)  # fmt: skip
    return congestion, 0.0


MODE = Mode("paper", ModeCode.PAPER, lambda problem: 0, bounded=False)


class PaperTag(ModeTag):
    """Paper mode's payoff (:func:`payoff`)."""

    __slots__ = ()
    kernel = staticmethod(payoff)
