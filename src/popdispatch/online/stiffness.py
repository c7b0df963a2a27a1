"""The fastest rate of exact mode's dynamics on one minute and the explicit round step it
allows (docs/agents.md, "The round step"): the step of the rounds of population dynamics run
by messages (:mod:`popdispatch.algorithms.population`)."""

from __future__ import annotations

import numpy as np

from popdispatch.dynamics import communication_graph
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import STABLE_STEP
from popdispatch.modes import get_mode
from popdispatch.modes.exact import controller_constants, scales
from popdispatch.online.settings import RunSettings


def stiffness_rate(problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
    """An estimate of the fastest rate of exact mode's dynamics at ``minute``, 1/s.

    Curvature-scaled field (dynamics/newton.py), the largest of

    - ``kappa D g max_i r_i (2 c_i + C_i)``: a generator's own relaxation rate (``kappa`` the
      revision gain per EUR/MW, ``D`` the minute's demand, MW, ``r_i`` its revision rate,
      ``C_i`` the price weight of the nearest limited line above it,
      :func:`popdispatch.modes.exact.controller_constants`, 0 below none; on a meshed network
      ``C`` times the generator's largest distribution factor to a limited line, in size),
      at least ``kappa D g S / P``, the rate at which every interior marginal cost relaxes;
      ``g`` the most receivers a sender's weights can sum over: 1 on the complete graph, the
      largest degree plus one on a sparse graph;
    - ``2 STABLE_STEP alpha / C`` where a line is limited: a line's price and the set points
      below it, in their proportional and integral regime, move as ``s^2 + a s + b = 0``
      with ``b / a = alpha / C``; Euler's factor ``1 + h s`` of a complex pair has ``|1 + h
      s|^2 = 1 - h a + h^2 b``, below 1 for ``h < C / alpha`` and smallest at ``h = C / (2
      alpha)``, the step this gives.

    Capacity-constrained Smith (``ExactConstants(revision="capacity")``): ``kappa max(S, D
    max_i (2 c_i + C_i))``. Dimensionless constants, so the same on a feeder scaled by 100."""
    fp = settings.game_constants(problem)
    weight, _ = controller_constants(problem, settings.exact.price_law, fp.C, fp.price_rate,
                                     minute)  # fmt: skip
    below = np.zeros(problem.n_generators)
    limited = problem.generator_line >= 0
    below[limited] = weight[problem.generator_line[limited]]
    if problem.meshed and len(problem.limit):  # the line its output moves most, as one line
        # a mesh runs the plain law: C on every line before its lever scale (game/mesh.py
        # lever_scale), which an exchange's own relaxation does not see
        below = float(fp.C) * np.abs(problem.factor).max(axis=0)
    demand = float(problem.demand[minute - 1])
    spread, reference = scales(problem)
    rates = settings.revision_rates(problem)
    if not len(rates):
        own = float(np.max(demand * (2.0 * problem.c + below)))
        return float(fp.gain) * max(spread, own)
    fan = _fan(problem, settings)
    own = float(np.max(rates * (2.0 * problem.c + below)))
    field = float(fp.gain) * demand * fan * max(own, spread / reference)
    return max(field, price_loop_rate(problem, settings, minute))


def price_loop_rate(problem: DispatchProblem, settings: RunSettings, minute: int = 1) -> float:
    """The line prices' part of :func:`stiffness_rate`, 1/s: ``2 STABLE_STEP alpha_k / C_k``
    at its largest over the limited lines (``alpha_k`` a line's price rate, ``C_k`` its
    proportional weight, :func:`popdispatch.modes.exact.controller_constants`),
    else 0: ``alpha / C`` under the plain law and on a mesh (whose lever scale multiplies
    both), ``alpha s_k / (C sqrt(s_k))`` under the scaled law."""
    if not len(problem.limit):
        return 0.0
    fp = settings.game_constants(problem)
    weight, rates = controller_constants(problem, settings.exact.price_law, fp.C,
                                         fp.price_rate, minute)  # fmt: skip
    return 2.0 * STABLE_STEP * float(np.max(rates / weight))


def round_step(problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
    """The largest explicit round step of exact mode at ``minute``, s: ``STABLE_STEP /``
    :func:`stiffness_rate` (:data:`popdispatch.integrate.STABLE_STEP`, the largest ``h *
    rate`` of an explicit step on a real rate); in paper mode (a mode whose barrier keeps the
    limits) the engine's own Euler substep, ``dt / substeps``."""
    if not get_mode(settings.mode).bounded:
        stepping = settings.stepping
        return stepping.dt / stepping.substeps
    return STABLE_STEP / stiffness_rate(problem, settings, minute)


def _fan(problem: DispatchProblem, settings: RunSettings) -> int:
    """The most receivers a sender's weights sum over: 1 on the complete graph, else the
    communication graph's largest degree plus one."""
    adjacency = communication_graph(settings.trading_graph, [str(g) for g in problem.generators])
    n = len(adjacency)
    if (adjacency + np.eye(n) > 0).all():
        return 1
    return int(adjacency.sum(axis=1).max()) + 1
