"""Consensus ADMM as agents: one agent per term of the DC-OPF (each DG its cost and range, the
coordinator the balance, each limited line's controller its limit), each with its copy of the
set points it touches, agreeing on them by general-form consensus ADMM.

The rules are :mod:`popdispatch.algorithms.consensus_admm`'s (the same functions and
:class:`~popdispatch.algorithms.consensus_admm.Holder`: the penalty from the cost curves, the
DG's prox, the projection onto the balance or a line's slab, the price update, the average,
the silence rule); here each term is its own mango agent in the generic world
(:func:`popdispatch.agents.world.run_world`). Round ``w`` of the world is the in-process
runtime's round ``w + 1`` (odd: x-updates, even: averages), in a three-tick round:

======  ===========  ==================================================================
tick    who          what
======  ===========  ==================================================================
0       plant        records the set points the inverters hold (it sends nothing: the
                     algorithm needs no measurement)
        DGs          send their cost curve (b, c, Pmin, Pmax ratings) to the coordinator
                     until they hold the penalty (configuration)
1       coordinator  once it holds every DG's curve: the penalty ``rho``, to each DG that
                     sent its curve since (all of them at first)
2       holders      odd rounds: price update by the last ``z`` heard, x-update, ``x + u``
                     to each DG of the copy still counted (one scalar each)
        DGs          odd rounds: the prox of its cost at ``z - u`` (once it holds the
                     penalty): the inverter's set point; even rounds: the average ``z``
                     of its own ``x + u`` and the last each holder sent, sent with its
                     applied set point to each holder
======  ===========  ==================================================================

Loss handling: a DG averages the last value each holder sent (stale), a holder steps from the
last ``z`` it heard (older or repeated messages are ignored by their round); a DG not heard
for ``silent_rounds`` rounds (a crash: its inverter holds its set point) is fixed by its
holders at the set point it last reported applying. A tripped DG's agent tells its holders
once (its output is 0, for good), and they fix its copy at 0. A crashed line controller's
last ``x + u`` stays at its DGs (stale).

The run is judged as dual decomposition's agents are
(:func:`popdispatch.agents.dual_decomposition.judged`): ``converged`` only when the set
points of the last ``window`` rounds and the final ones are all within the accuracy
``max(accuracy_kw, accuracy_rel x demand)`` of the project's Clarabel DC-OPF in force
(:func:`popdispatch.opf.solve_opf`), balance supply and demand within it and overflow no
line by more than it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum

import networkx as nx
import numpy as np
from mango import json_serializable

from popdispatch.agents.base import RoundAgent
from popdispatch.agents.dual_decomposition import (
    MODES,
    OPTIONS,
    PLANT_ID,
    RUN_OPTIONS,
    CostCurve,
    DualSystem,
    check_ids,
    controller_ids,
    judged,
    proposal_run,
)
from popdispatch.agents.dual_decomposition import refuse as _refuse
from popdispatch.agents.network import Faults, LossyNetwork
from popdispatch.agents.plant import Inverters
from popdispatch.agents.system import AgentRun, AgentSettings, check_events
from popdispatch.agents.world import WorldOptions, WorldRun, run_world
from popdispatch.algorithms.base import COORDINATOR, Minute, balanced_start
from popdispatch.algorithms.consensus_admm import (
    ConsensusAdmmParams,
    Holder,
    consensus_value,
    onto_slab,
    penalty,
    prox_cost,
    slab_of_line,
)
from popdispatch.game.problem import DispatchProblem
from popdispatch.online.settings import RunSettings

#: The name the registry (:mod:`popdispatch.agents.algorithms`) knows this algorithm by.
NAME = "consensus-admm"
__all__ = ["MODES", "NAME", "OPTIONS", "RUN_OPTIONS", "refuse", "run"]


class AdmmPhase(IntEnum):
    """The ticks of a round (see the module docstring)."""

    RECORD = 0
    PENALTY = 1
    UPDATE = 2


# -- messages (mango's JSON codec carries them between processes as well) --------------------


@json_serializable
@dataclass(frozen=True)
class Penalty:
    """Coordinator -> DG (configuration): the penalty ``rho``, EUR/MW per MW."""

    rho: float


@json_serializable
@dataclass(frozen=True)
class Consensus:
    """DG -> holder: its consensus value ``z`` and applied set point (MW), sent in round
    ``round`` (the in-process runtime's numbering); ``gone``: it tripped (output 0 for good)."""

    round: int
    z_mw: float
    applied_mw: float
    gone: bool = False


@json_serializable
@dataclass(frozen=True)
class Proposal:
    """Holder -> DG: its ``x + u`` of the DG's set point (MW), sent in round ``round``."""

    round: int
    value_mw: float


# -- the agents -------------------------------------------------------------------------------


class AdmmDgAgent(RoundAgent):
    """A DG: its cost curve and range this minute (``lo``, ``hi``, MW), its own term
    (a :class:`Holder` of its one set point), its consensus value ``z`` and the last
    ``x + u`` each other holder (``holders``: the coordinator, then its lines' controllers)
    sent it; its inverter follows its x-updates."""

    ROUND = AdmmPhase
    PHASES = (AdmmPhase.RECORD, AdmmPhase.UPDATE)

    def __init__(self, index: int, curve: CostCurve, lo: float, hi: float,
                 holders: list[str], z0: float, inverters: Inverters,
                 network=None):  # fmt: skip
        super().__init__(network)
        self.index, self.curve, self.lo, self.hi = index, curve, lo, hi
        self.holders, self.inverters = holders, inverters
        self.own = Holder("", np.array([0]), np.array([z0]))
        self.z = self.p = z0
        self.heard: dict[str, tuple[float, int]] = {h: (z0, -1) for h in holders}
        self.rho: float | None = None
        self.tripped = False  # its inverter tripped: it tells its holders, then stops

    def receive(self, content, sender) -> None:
        if isinstance(content, Penalty) and sender == COORDINATOR:
            self.rho = content.rho
        elif isinstance(content, Proposal) and self._newer(sender, content.round):
            self.heard[sender] = (content.value_mw, content.round)

    def _newer(self, holder: str, sent: int) -> bool:
        """Whether a proposal sent in round ``sent`` by one of its holders is newer than the
        one it holds (older or repeated ones are stale; a stranger's are ignored)."""
        return holder in self.heard and sent > self.heard[holder][1]

    def act(self, rnd: int, phase: AdmmPhase) -> None:
        if phase == AdmmPhase.RECORD:
            if self.tripped:
                for holder in self.holders:
                    self.send(Consensus(rnd + 1, 0.0, 0.0, gone=True), holder)
                self.crashed = True
            elif self.rho is None:
                self.send(self.curve, COORDINATOR)
            return
        r = rnd + 1
        if r % 2 == 1:
            if self.rho is None:
                return  # no penalty yet: its inverter holds the start
            c, rho = self.curve, self.rho
            self.own.z[0] = self.z
            self.own.step(lambda v, free: prox_cost(v, c.b, c.c, self.lo, self.hi, rho))
            self.p = float(self.own.x[0])
            self.inverters.p[self.index] = self.p
            return
        self.z = float(consensus_value(self.own, [value for value, _ in self.heard.values()]))
        for holder in self.holders:
            self.send(Consensus(r, self.z, self.p), holder)


class AdmmHolderAgent(RoundAgent):
    """The coordinator's or a line controller's term: its copy of the set points of ``dgs``
    (names, in the fleet's order; positions ``members``) in a :class:`Holder`, projected onto
    ``lo <= a.y <= hi`` (MW): the balance or the line's slab."""

    ROUND = AdmmPhase
    PHASES = (AdmmPhase.UPDATE,)

    def __init__(self, dgs: list[str], members: np.ndarray, z0: np.ndarray, a: np.ndarray,
                 slab: tuple[float, float], silent_rounds: int, network=None):  # fmt: skip
        super().__init__(network)
        self.dgs, self.a, self.slab, self.silent_rounds = dgs, a, slab, silent_rounds
        self.slot = {name: k for k, name in enumerate(dgs)}
        self.holder = Holder("", members, z0)
        self.gone: set[str] = set()

    def receive(self, content, sender) -> None:
        if isinstance(content, Consensus) and sender in self.slot and sender not in self.gone:
            slot = self.slot[sender]
            if content.gone:
                self.gone.add(sender)
                self.holder.free[slot] = False
                self.holder.applied[slot] = 0.0
            else:
                self.holder.hear(slot, content.round, content.z_mw, content.applied_mw)
        else:
            self.take(content, sender)

    def take(self, content, sender) -> None:
        """The holder's own messages."""

    def act(self, rnd: int, phase: AdmmPhase) -> None:
        r = rnd + 1
        if phase != AdmmPhase.UPDATE or r % 2 == 0 or not self.dgs:
            return
        h, (lo, hi) = self.holder, self.slab
        h.forget_silent(r, self.silent_rounds)
        h.step(lambda v, free: onto_slab(v, free, self.a, lo, hi))
        values = h.proposals()
        for slot in np.flatnonzero(h.free):
            self.send(Proposal(r, float(values[slot])), self.dgs[slot])


class AdmmCoordinatorAgent(AdmmHolderAgent):
    """The substation's coordinator: the balance term, and the penalty from the DGs' curves
    and the reference demand (MW, the problem's largest)."""

    PHASES = (AdmmPhase.PENALTY, AdmmPhase.UPDATE)

    def __init__(self, dgs: list[str], z0: np.ndarray, demand_mw: float,
                 reference_demand_mw: float, params: ConsensusAdmmParams,
                 network=None):  # fmt: skip
        n = len(dgs)
        super().__init__(dgs, np.arange(n), z0, np.ones(n), (demand_mw, demand_mw),
                         params.silent_rounds, network)  # fmt: skip
        self.rho_scale, self.reference_demand_mw = params.rho_scale, reference_demand_mw
        self.curves: dict[str, CostCurve] = {}
        self.asking: set[str] = set()
        self.rho: float | None = None

    def take(self, content, sender) -> None:
        if isinstance(content, CostCurve) and sender in self.slot:
            self.curves[sender] = content
            self.asking.add(sender)

    def act(self, rnd: int, phase: AdmmPhase) -> None:
        if phase != AdmmPhase.PENALTY:
            super().act(rnd, phase)
            return
        if self.rho is None and len(self.curves) == len(self.dgs):
            b, c, pmin, pmax = (np.array([getattr(self.curves[n], f) for n in self.dgs])
                                for f in ("b", "c", "pmin_mw", "pmax_mw"))  # fmt: skip
            self.rho = penalty(self.rho_scale, b, c, pmin, pmax, self.reference_demand_mw)
        if self.rho is not None:
            for name in sorted(self.asking, key=self.slot.get):
                self.send(Penalty(float(self.rho)), name)
            self.asking.clear()


class RecordingPlant(RoundAgent):
    """The feeder: records the set points the inverters hold at each round's first tick."""

    ROUND = AdmmPhase
    PHASES = (AdmmPhase.RECORD,)

    def __init__(self, inverters: Inverters, network=None):
        super().__init__(network)
        self.inverters = inverters
        self.history: list[np.ndarray] = []

    def act(self, rnd: int, phase: AdmmPhase) -> None:
        self.history.append(self.inverters.p.copy())


# -- the system the world runs -----------------------------------------------------------------


@dataclass
class AdmmSystem(DualSystem):
    """Dual decomposition's system (the same yardstick and judgment) with consensus ADMM's
    agents; a trip is told to the holders by the DG's agent (module docstring). ADMM
    converges linearly, often slowly at the end: the rest rule projects the geometric tail
    still to go (``extrapolate``, as exact mode's), and a rest above the accuracy goes on
    while each window's proved bound falls by 1 % (``rest_progress``, the engine's rule)."""

    extrapolate: bool = True
    rest_progress: float = 0.99

    def apply(self, event, rnd: int) -> None:
        if event.kind != "trip":
            super().apply(event, rnd)
            return
        if rnd == event.round:
            agent = self.dgs[self.minute.names.index(event.agent)]
            agent.tripped = True
            self.inverters.p[agent.index] = 0.0
            self.tripped.append(event.agent)
            self.events.append({"round": rnd, "event": event.kind, "agent": event.agent})


def build(problem: DispatchProblem, minute: int, params: ConsensusAdmmParams, faults: Faults,
          accuracy_mw: float, hold: int) -> AdmmSystem:  # fmt: skip
    """The agents of one minute (not yet registered anywhere): ``z`` and the inverters at
    the uniform start (:func:`~popdispatch.algorithms.base.balanced_start`), ``u`` at 0."""
    m = Minute.of(problem, minute)
    names = m.names
    network = LossyNetwork(faults, len(AdmmPhase))
    z0 = balanced_start(m)
    inverters = Inverters(z0)
    ids = controller_ids(problem)
    factor = problem.down
    members = [np.flatnonzero(factor[k]) for k in range(len(ids))]
    controllers = {
        aid: AdmmHolderAgent([names[i] for i in members[k]], members[k], z0,
                             factor[k, members[k]],
                             slab_of_line(m.load_flow[k], problem.limit[k]),
                             params.silent_rounds, network)
        for k, aid in enumerate(ids)
    }  # fmt: skip
    dgs = [
        AdmmDgAgent(i, CostCurve(float(problem.b[i]), float(problem.c[i]),
                                  float(problem.pmin[i]), float(problem.pmax[i])),
                    float(m.lo[i]), float(m.hi[i]),
                    [COORDINATOR, *(ids[k] for k in np.flatnonzero(factor[:, i]))],
                    float(z0[i]), inverters, network)
        for i in range(len(names))
    ]  # fmt: skip
    coordinator = AdmmCoordinatorAgent(names, z0, m.demand, float(np.max(problem.demand)),
                                       params, network)  # fmt: skip
    plant = RecordingPlant(inverters, network)
    graph = nx.Graph()
    graph.add_edges_from((COORDINATOR, name) for name in names)
    graph.add_edges_from((aid, names[i]) for aid, ks in zip(ids, members, strict=True)
                         for i in ks)  # fmt: skip
    graph.add_node(PLANT_ID)
    check_ids(names, ids)
    check_events(faults.events, names, ids)
    return AdmmSystem(m, plant, coordinator, controllers, dgs, inverters, network, graph,
                      accuracy_mw, hold)  # fmt: skip


# -- running and judging ------------------------------------------------------------------------


def refuse(settings: RunSettings, opts: AgentSettings, faults: Faults) -> None:
    """As dual decomposition's (:func:`popdispatch.agents.dual_decomposition.refuse`): the
    population dynamics' options are refused, one line naming the option."""
    _refuse(settings, opts, faults, NAME)


def run(problem: DispatchProblem, minute: int, settings: RunSettings, faults: Faults,
        opts: AgentSettings, on_round=None) -> AgentRun:  # fmt: skip
    """One minute by consensus ADMM's agents with the comparison's parameters
    (:data:`popdispatch.algorithms.registry.ALGORITHMS`); infeasible without running when the
    minute's DC-OPF is."""
    from popdispatch.algorithms.registry import ALGORITHMS

    return run_admm(problem, minute, settings, faults, opts, ALGORITHMS[NAME].params(),
                    on_round)  # fmt: skip


def run_admm(problem: DispatchProblem, minute: int, settings: RunSettings, faults: Faults,
             opts: AgentSettings, params: ConsensusAdmmParams,
             on_round=None) -> AgentRun:  # fmt: skip
    """One minute by consensus ADMM's agents with ``params`` (``opts.tol_kw`` in force)."""
    demand = float(problem.demand[minute - 1])
    accuracy = float(settings.accuracy_mw(demand))
    system = build(problem, minute, params, faults, accuracy, opts.window)
    paced = opts.phase_ticks_for(faults, len(AdmmPhase))
    for agent in system.agents:
        agent.phase_ticks = paced
    if system.opf().status != "optimal":
        return _infeasible(system, minute)
    world = run_world(system, WorldOptions(opts.max_rounds, opts.rest_window(faults),
                                           opts.tol_kw, opts.drain_rounds), on_round)  # fmt: skip
    return judged(system, world, _result(system, world), "its last proposals stay at its DGs")


def _result(system: AdmmSystem, world: WorldRun | None) -> AgentRun:
    return proposal_run(system, world, np.array([line_price(c, system.coordinator.rho)
                                                 for c in system.controllers.values()]))


def line_price(controller: AdmmHolderAgent, rho: float | None) -> float:
    """Line ``k``'s price read from its controller's term, EUR/MWh: at a fixed point its
    consensus duals ``rho u_k`` are ``nu_k a`` (the slab's normal), so ``nu_k = rho u_k.a /
    a.a`` over the DGs it still counts (the sign of dual decomposition's ``mu_up -
    mu_down``); 0 before the penalty is set or without DGs."""
    h = controller.holder
    a = np.where(h.free, controller.a, 0.0)
    norm = float(a @ a)
    if rho is None or norm == 0.0:
        return 0.0
    return float(rho * (h.u @ a) / norm)


def _infeasible(system: AdmmSystem, minute: int) -> AgentRun:
    why = (f"the DC-OPF of minute {minute} is infeasible: no dispatch within the limits "
           "exists, so the consensus cannot settle")  # fmt: skip
    return replace(_result(system, None), infeasible=True, horizon_reason=why)
