"""The feeder as an agent: inverters hold the set points, sensors measure the limited lines.

The plant is physics, not a decision maker: given the generators' set points (their
inverters, :class:`Inverters`) and the loads of the minute, the flow on every limited line is
the engine's own lossless DC flow (on a radial feeder
:func:`popdispatch.game.flows.limited_line_flows`, paper eq. 1d; on a meshed network
:func:`~popdispatch.game.flows.mesh_line_flows`, by the distribution factors); the source bus
takes up whatever supply and demand differ by, at once. At the first tick of each round the
plant's sensors send each limited line's flow to the node controllers at both its ends (with
optional Gaussian noise), and the plant records the set points it sees: the trajectory of
the run.
"""

from __future__ import annotations

import numpy as np

from popdispatch.agents.base import RoundAgent
from popdispatch.agents.messages import Measurement, Output
from popdispatch.agents.schedule import Phase
from popdispatch.constants import KW_PER_MW
from popdispatch.game.flows import limited_line_flows, mesh_line_flows
from popdispatch.game.problem import DispatchProblem


class Inverters:
    """The generators' inverters: the set point each one holds, MW (by generator position).

    A generator agent writes its own entry; an inverter keeps its last set point while its
    agent is down, and a trip sets it to 0 at once.
    """

    def __init__(self, p_mw: np.ndarray):
        self.p = np.array(p_mw, dtype=float)


class PlantAgent(RoundAgent):
    """The feeder of one minute (see the module docstring).

    ``line_ends[k]``: the agent ids of the controllers at the parent and child end of limited
    line ``k``; ``noise_kw``: standard deviation of each measurement, kW; ``seed``: of the
    noise.
    """

    ROUND = Phase

    PHASES = (Phase.MEASURE,)

    def __init__(self, problem: DispatchProblem, minute: int, inverters: Inverters,
                 line_ends: list[tuple[str, str]], noise_kw: float = 0.0, seed: int = 0,
                 network=None):  # fmt: skip
        super().__init__(network)
        self.problem = problem
        self.load_flow = np.ascontiguousarray(problem.load_flow[minute - 1])
        self.inverters = inverters
        self.line_ends = line_ends
        self.noise_mw = noise_kw / KW_PER_MW
        self.rng = np.random.default_rng(seed)
        self.flow = np.zeros(len(problem.limit))
        self.history: list[np.ndarray] = []

    def receive(self, content, sender) -> None:
        if isinstance(content, Output):  # real time: an inverter's reading
            self.inverters.p[self.problem.generators.get_loc(content.generator)] = content.p_mw

    def act(self, rnd: int, phase: Phase) -> None:
        if phase != Phase.MEASURE:
            return
        p = np.ascontiguousarray(self.inverters.p)
        self.history.append(p.copy())
        pr = self.problem
        if pr.meshed:  # the network's DC flows, by the distribution factors
            mesh_line_flows(self.load_flow, p, pr.factor, self.flow)
        else:
            limited_line_flows(self.load_flow, p, pr.generator_line, pr.line_up,
                               pr.line_preorder, self.flow)  # fmt: skip
        for k, ends in enumerate(self.line_ends):
            for aid in ends:
                noise = self.rng.normal(0.0, self.noise_mw) if self.noise_mw else 0.0
                self.send(Measurement(rnd, k, float(self.flow[k] + noise)), aid)
