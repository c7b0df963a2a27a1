"""The dispatch problem of a meshed network (any connected one, :mod:`popdispatch.feeder.dcnet`).

The same :class:`~popdispatch.game.problem.DispatchProblem` as a radial feeder's, with the
limited lines' coefficients given as distribution factors: flows on the limited lines are
``load_flow - D p`` with ``D_ki = -PTDF_k,bus(i)`` (MW per MW, injection at generator ``i``'s
bus withdrawn at the slack) and ``load_flow`` the DC flow of the loads, shunts and phase
shifters with the slack supplying everything. On a radial feeder with the slack at the source
``D_ki`` is 1 for a generator below line ``k`` and 0 above it: the paper's rule.

The engine reads ``D`` row by row (its kernels ``mesh_line_flows`` and ``mesh_broadcast``,
:mod:`popdispatch.game.flows`): one multiply-add per limited line and generator.
"""

from __future__ import annotations

import numpy as np

from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FleetError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.game.problem import DispatchProblem, check_capacity, fleet_columns

#: Distribution factors below this (MW per MW) are round-off of the sparse solves (a generator
#: on a line's far side from the slack reads 1e-17, not 0): they are set to 0, so that a DG
#: with no influence on a line hears no price from it.
FACTOR_FLOOR = 1e-12

#: Two generators' distribution factors on a line closer than this (MW per MW) count as equal
#: in :func:`smallest_factor_gap`: round-off, not a lever on the line.
GAP_FLOOR = 1e-9

#: The smallest lever (MW per MW) :func:`lever_scale` divides by: a line that dispatch moves
#: less than this has its price constants raised a thousandfold, no more.
LEVER_FLOOR = 1e-3


def build_mesh_problem(
    net: DcNetwork, bus_demand_mw: np.ndarray | None = None, source: str = "", check: bool = True
) -> DispatchProblem:
    """The engine arrays of ``net``: its fleet, its limited lines (finite ``limit_kw``) with
    their distribution factors, and the demand of each row of ``bus_demand_mw`` (MW, (minutes,
    buses) in the order of ``net.buses``; default one minute, the network's own ``pd_mw``).
    A bus's shunt conductance is demand at every minute (MATPOWER's DC model). ``check``:
    raise :class:`~popdispatch.errors.InfeasibleError` when a minute's demand is outside the
    fleet's range."""
    gens = net.generators
    if not len(gens):
        raise FleetError(f"network {net.name!r} has no generator to dispatch: give a fleet")
    if bus_demand_mw is None:
        bus_demand_mw = net.buses.pd_mw.to_numpy(float)
    demand = np.atleast_2d(np.asarray(bus_demand_mw, float)) + net.buses.gs_mw.to_numpy(float)
    limited = np.flatnonzero(np.isfinite(net.lines.limit_kw.to_numpy(float)))
    model = net.model
    gen_bus = net.buses.index.get_indexer(gens.bus)
    factor = -model.ptdf(limited, gen_bus) if len(limited) else np.zeros((0, len(gens)))
    factor[np.abs(factor) < FACTOR_FLOOR] = 0.0  # round-off of the LU, not a sensitivity
    load_flow = model.flows_mw(-demand.T, limited).T if len(limited) else np.zeros((len(demand), 0))
    n_lines = len(limited)
    problem = DispatchProblem(
        feeder=net,
        **fleet_columns(gens),
        lines=limited,
        limit=net.lines.limit_kw.to_numpy(float)[limited] / KW_PER_MW,
        line_up=np.full(n_lines, -1, np.int64),
        line_preorder=np.arange(n_lines, dtype=np.int64),
        generator_line=np.full(len(gens), -1, np.int64),
        demand=demand.sum(axis=1),
        load_flow=np.ascontiguousarray(load_flow),
        online=np.ones((len(demand), len(gens)), dtype=bool),
        profile_source=source or f"{net.name}: the case's own demand",
        fixed_injection=np.zeros(len(demand)),
        factor=np.ascontiguousarray(factor),
    )
    if check:
        check_capacity(problem)
    return problem


def smallest_factor_gap(factor: np.ndarray) -> float:
    """The smallest difference (MW per MW) between two generators' coefficients on one limited
    line, over the rows of ``factor`` ``(limited lines, generators)``, differences below
    :data:`GAP_FLOOR` ignored; infinite when no line has two different coefficients. Shifting
    output between two generators whose coefficients differ by ``g`` moves the line's flow by
    ``g`` MW per MW, so a line price ``z`` (EUR/MWh) is worth ``g z`` to them: the price that
    balances a marginal-cost gap is that gap over ``g`` (1 on a radial feeder, whose
    coefficients are 0 and 1)."""
    gap = np.inf
    for row in np.asarray(factor, float):
        steps = np.diff(np.sort(row))
        steps = steps[steps > GAP_FLOOR]
        if len(steps):
            gap = min(gap, float(steps.min()))
    return gap


def lever_scale(factor: np.ndarray) -> np.ndarray:
    """Per limited line (rows of ``factor``, ``(limited lines, generators)``), the multiplier of
    its price constants in exact mode (the price rate and the proportional weight ``C``,
    :mod:`popdispatch.modes.exact`): 1 over the line's *lever* ``sigma_k = max_i D_ki - min_i
    D_ki``, the most one MW moved between two generators moves its flow, within
    [:data:`LEVER_FLOOR`, 1]. A price ``z`` on the line changes two generators' fitness
    difference by at most ``sigma_k z`` and their exchange moves the flow by at most
    ``sigma_k`` per MW, so the loop from overflow to price to dispatch to flow has gain
    ``sigma_k^2`` times the radial feeder's (``sigma_k = 1``); the multiplier gives one factor
    back (both factors: the price loop stiffens), keeping rest points and prices unchanged."""
    factor = np.asarray(factor, float)
    if not factor.size:
        return np.ones(len(factor))
    lever = factor.max(axis=1) - factor.min(axis=1)
    return 1.0 / np.clip(lever, LEVER_FLOOR, 1.0)
