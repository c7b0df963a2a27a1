"""Target flows: the sums of the flow laws whose kernel is 1 (:mod:`popdispatch.dynamics.law`).

Mass moves from every sender ``j`` to every receiver ``i`` at ``w_i v_j`` whatever their
fitness: the receiver weight is a *target* computed from the whole fitness vector (BNN's
excess payoff, the logit choice). On the complete graph, without the pair ``i = j`` (a
strategy trading with itself moves nothing):

    inflow_i  = w_i * (V - v_i),     V = sum_j v_j,
    outflow_j = v_j * (W - w_j),     W = sum_i w_i,        x' = inflow - outflow,

O(n). Both sums are of non-negative terms, so a strategy with no weight neither sends nor
receives. A target needs the whole population, so these laws run on the complete graph only
(:class:`~popdispatch.dynamics.law.Dynamics` ``uses_graph`` false).
"""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True, inline="always")
def target_flows(w, v, inflow, outflow):
    """``inflow``/``outflow`` (see the module docstring) of receiver weights ``w`` and sender
    weights ``v`` on the complete graph."""
    total_w = 0.0
    total_v = 0.0
    for i in range(w.shape[0]):
        total_w += w[i]
        total_v += v[i]
    for i in range(w.shape[0]):
        inflow[i] = w[i] * max(total_v - v[i], 0.0)
        outflow[i] = v[i] * max(total_w - w[i], 0.0)
