"""Dual decomposition as agents: a balance price and line prices by projected gradient ascent
on the DC-OPF's dual, each DG best-responding to its locational price.

The rules are :mod:`popdispatch.algorithms.dual`'s (the same functions: best response, the
steps from the cost curves, the price steps, Nesterov's momentum with the joint restart);
here each is run by its own mango agent in the generic world
(:func:`popdispatch.agents.world.run_world`), in a three-tick round:

======  ===========  ==================================================================
tick    who          what
======  ===========  ==================================================================
0       plant        records the set points; sends each line's flow to its controller and
                     the substation's shortfall ``P_d - sum p`` to the coordinator
        DGs          send their cost curve (b, c, Pmin, Pmax) to every price holder they
                     have not heard a price from yet (configuration; repeated until heard)
1       coordinator  once it holds every DG's curve: its step ``alpha`` and start price
                     (sent, round 0's prices); then each round a step on the newest
                     shortfall it has not used, the balance price to every DG
        controllers  likewise: step ``beta_k`` from the curves of its DGs, then a step on
                     the newest flow it has not used, ``nu_k`` to its DGs
2       DGs          best response to the last prices received: the inverter's set point
======  ===========  ==================================================================

Accelerated (``fast-dual-decomposition``): each holder keeps its Nesterov state; each
controller sends the coordinator its restart term every round, the coordinator a restart to
every controller when its own term plus the controllers' latest is negative.

Loss handling: a DG keeps the last prices it received (stale; older or repeated ones are
ignored by their round); a holder whose measurement is lost takes no step that round and
sends its price again; a lost restart term leaves the coordinator its last one. Faults: a
DG's crash (its inverter holds its set point), a trip (output 0 for good), a controller's
crash (its line price frozen at its DGs).

The run is judged by its distance to the project's Clarabel DC-OPF of the minute
(:func:`popdispatch.opf.solve_opf`; with a tripped DG offline and a DG crashed for good held
where its inverter stopped), as ``popdispatch compare`` judges it: ``converged`` only when the
set points of the last ``window`` rounds and the final ones are all within the accuracy
``max(accuracy_kw, accuracy_rel x demand)`` of it, balance supply and demand within it and
overflow no line by more than it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from enum import IntEnum

import networkx as nx
import numpy as np
from mango import json_serializable

from popdispatch.agents.base import RoundAgent
from popdispatch.agents.messages import Measurement
from popdispatch.agents.network import Faults, LossyNetwork
from popdispatch.agents.plant import Inverters, PlantAgent
from popdispatch.agents.system import W_PER_MW, AgentRun, AgentSettings, check_events, without
from popdispatch.agents.world import WorldOptions, WorldRun, run_world
from popdispatch.algorithms.base import COORDINATOR, Minute, balanced_shares, with_held
from popdispatch.algorithms.dual import (
    DualDecomposition,
    DualParams,
    Momentum,
    balance_price_step,
    balance_step_size,
    best_response,
    initial_balance_price,
    line_gradient,
    line_price_step,
    line_step_sizes,
    price_response,
)
from popdispatch.constants import KW_PER_MW
from popdispatch.errors import OptionError
from popdispatch.game.problem import DispatchProblem
from popdispatch.online.settings import RunSettings
from popdispatch.opf import solve_opf

#: The name the registry (:mod:`popdispatch.agents.algorithms`) knows this algorithm by.
NAME = "dual-decomposition"
#: It solves the DC-OPF, as exact mode does (``--mode``).
MODES = ("exact",)
#: The :class:`~popdispatch.agents.system.AgentSettings` fields it reads: the world's.
OPTIONS = frozenset({"max_rounds", "window", "tol_kw", "drain_rounds", "paced"})
#: The snapshot's run options (``popdispatch agents``) it reads: the mode only (exact);
#: the population dynamics' own (``--dynamics``, ``--x0``, ...) given are refused.
RUN_OPTIONS = frozenset({"mode"})
#: The options that set the run settings it does not read.
_SETTING_OPTIONS = {"dynamics": "--dynamics", "graph": "--graph", "x0": "--x0", "eta": "--eta",
                    "fitness": "--constants", "exact": "--constants or --price-law",
                    "integrator": "--constants", "warm_start": "--warm-start",
                    "vmin_pu": "--vmin", "vmax_pu": "--vmax"}  # fmt: skip
#: The plant's agent id.
PLANT_ID = "plant"


class DualPhase(IntEnum):
    """The ticks of a round (see the module docstring)."""

    MEASURE = 0
    PRICE = 1
    RESPOND = 2


# -- messages (mango's JSON codec carries them between processes as well) --------------------


@json_serializable
@dataclass(frozen=True)
class CostCurve:
    """DG -> price holder (configuration): its cost ``b`` (EUR/MWh), ``c`` (EUR/MW^2h) and
    its limits this minute, MW."""

    b: float
    c: float
    pmin_mw: float
    pmax_mw: float


@json_serializable
@dataclass(frozen=True)
class Shortfall:
    """Plant -> coordinator: the substation's measured shortfall ``P_d - sum p``, MW, at the
    start of ``round``."""

    round: int
    shortfall_mw: float


@json_serializable
@dataclass(frozen=True)
class Price:
    """Price holder -> DG: the balance price or line ``line``'s price (``-1``: the balance
    price), EUR/MWh, set in ``round``."""

    round: int
    line: int
    price: float


@json_serializable
@dataclass(frozen=True)
class RestartTerm:
    """Controller -> coordinator (accelerated): its restart term ``grad . (x - x_last)``."""

    round: int
    term: float


@json_serializable
@dataclass(frozen=True)
class Restart:
    """Coordinator -> controller (accelerated): drop the momentum (no scalars)."""

    round: int


# -- the agents -------------------------------------------------------------------------------


class DgAgent(RoundAgent):
    """A DG: its cost curve, its inverter, the last prices it received; it best-responds to
    its locational price ``lambda + sum_k D_ki nu_k`` (``weights``: its ``D_ki`` by
    controller id)."""

    ROUND = DualPhase
    PHASES = (DualPhase.MEASURE, DualPhase.RESPOND)

    def __init__(self, index: int, curve: CostCurve, weights: dict[str, float],
                 inverters: Inverters, network=None):  # fmt: skip
        super().__init__(network)
        self.index, self.curve, self.weights, self.inverters = index, curve, weights, inverters
        self.lam: float | None = None  # None until the first balance price arrives
        self.nu = dict.fromkeys(weights, 0.0)  # line prices start at 0
        self.heard: dict[str, int] = {}  # the newest round heard from each holder

    def receive(self, content, sender) -> None:
        if not isinstance(content, Price) or content.round <= self.heard.get(sender, -1):
            return  # older than what it holds (late or repeated): stale
        self.heard[sender] = content.round
        if content.line < 0:
            self.lam = content.price
        else:
            self.nu[sender] = content.price

    def act(self, rnd: int, phase: DualPhase) -> None:
        if phase == DualPhase.MEASURE:
            for holder in [COORDINATOR, *self.weights]:
                if holder not in self.heard:
                    self.send(self.curve, holder)
        elif self.lam is not None:
            price = self.lam + sum(w * self.nu[k] for k, w in self.weights.items())
            c = self.curve
            self.inverters.p[self.index] = best_response(price, c.b, c.c, c.pmin_mw, c.pmax_mw)


class PriceHolder(RoundAgent):
    """What the coordinator and the line controllers share: the curves of their DGs (by
    name, in the fleet's order), a measurement to step on, and Nesterov's state."""

    ROUND = DualPhase
    PHASES = (DualPhase.PRICE,)

    def __init__(self, dgs: list[str], params: DualParams, network=None):
        super().__init__(network)
        self.dgs, self.params = dgs, params
        self.curves: dict[str, CostCurve] = {}
        self.configured = False
        self.momentum: Momentum | None = None
        self.measured: tuple[int, float] | None = None  # (round, value) not yet used
        self.used = -1  # the round of the last measurement stepped on

    def receive(self, content, sender) -> None:
        if isinstance(content, CostCurve) and sender in self.dgs:
            self.curves[sender] = content
        else:
            self.take(content, sender)

    def take(self, content, sender) -> None:
        """The holder's own messages."""

    def measure(self, rnd: int, value: float) -> None:
        if rnd > self.used and (self.measured is None or rnd > self.measured[0]):
            self.measured = (rnd, value)

    def fresh(self) -> float | None:
        """The newest measurement not yet stepped on (None: lost or late)."""
        if self.measured is None:
            return None
        self.used, value = self.measured
        self.measured = None
        return value

    def curve_arrays(self) -> tuple[np.ndarray, ...]:
        """``(b, c, lo, hi)`` of its DGs in the fleet's order."""
        rows = [self.curves[name] for name in self.dgs]
        return tuple(np.array([getattr(r, f.name) for r in rows]) for f in fields(CostCurve))

    def act(self, rnd: int, phase: DualPhase) -> None:
        if not self.configured:
            if len(self.curves) < len(self.dgs):
                return  # waiting for the DGs' curves
            self.configure()
            self.configured = True
        else:
            value = self.fresh()
            if value is not None:
                self.step(rnd, value)
        self.broadcast(rnd)

    def configure(self) -> None: ...

    def step(self, rnd: int, value: float) -> None: ...

    def broadcast(self, rnd: int) -> None: ...


class CoordinatorAgent(PriceHolder):
    """The substation's coordinator: the balance price ``lambda``, stepped on the measured
    shortfall; accelerated, the joint restart test over the controllers' latest terms."""

    def __init__(self, dgs: list[str], controllers: list[str], demand_mw: float,
                 params: DualParams, network=None):  # fmt: skip
        super().__init__(dgs, params, network)
        self.controllers, self.demand_mw = controllers, demand_mw
        self.lam = 0.0
        self.alpha = 0.0
        self.terms = np.zeros(len(controllers))
        self.term_round = np.full(len(controllers), -1)
        self.restart_all = False

    def take(self, content, sender) -> None:
        if isinstance(content, Shortfall):
            self.measure(content.round, content.shortfall_mw)
        elif isinstance(content, RestartTerm) and sender in self.controllers:
            k = self.controllers.index(sender)
            if content.round > self.term_round[k]:
                self.terms[k], self.term_round[k] = content.term, content.round

    def configure(self) -> None:
        b, c, lo, hi = self.curve_arrays()
        self.alpha = balance_step_size(self.params.balance_step, price_response(c, lo, hi))
        self.lam = initial_balance_price(b, c, lo, hi, self.demand_mw)
        self.momentum = Momentum([self.lam])

    def step(self, rnd: int, shortfall: float) -> None:
        if not self.params.accelerated:
            self.lam = balance_price_step(self.lam, self.alpha, shortfall)
            return
        grad = np.array([shortfall])
        own = self.momentum.ascend(np.array([self.lam]), grad, self.alpha, -np.inf)
        if own + self.terms.sum() < 0.0:
            self.momentum.restart()
            self.restart_all = True
        self.lam = float(self.momentum.extrapolate(-np.inf)[0])

    def broadcast(self, rnd: int) -> None:
        if self.restart_all:
            for name in self.controllers:
                self.send(Restart(rnd), name)
            self.restart_all = False
        for name in self.dgs:
            self.send(Price(rnd, -1, float(self.lam)), name)


class LineControllerAgent(PriceHolder):
    """The node controller of limited line ``line``: its two direction prices ``mu``,
    stepped on the measured flow; ``weights``: its DGs' ``D_ki`` (the DGs its price moves)."""

    def __init__(self, line: int, limit_mw: float, weights: dict[str, float],
                 params: DualParams, network=None):  # fmt: skip
        super().__init__(list(weights), params, network)
        self.line, self.limit_mw, self.weights = line, limit_mw, weights
        self.mu = np.zeros(2)
        self.beta = 0.0
        self.restart = False

    def take(self, content, sender) -> None:
        if isinstance(content, Measurement) and content.line == self.line:
            self.measure(content.round, content.flow_mw)
        elif isinstance(content, Restart) and sender == COORDINATOR:
            self.restart = True

    def configure(self) -> None:
        _, c, lo, hi = self.curve_arrays()
        factor = np.array([[self.weights[name] for name in self.dgs]])
        self.beta = float(line_step_sizes(self.params.line_step, factor,
                                          price_response(c, lo, hi))[0])  # fmt: skip
        self.momentum = Momentum(self.mu)

    def step(self, rnd: int, flow: float) -> None:
        grad = line_gradient(flow, self.limit_mw)
        if not self.params.accelerated:
            self.mu = line_price_step(self.mu, self.beta, grad)
            return
        if self.restart:
            self.momentum.restart()
            self.restart = False
        term = self.momentum.ascend(self.mu, grad, self.beta, 0.0)
        self.send(RestartTerm(rnd, term), COORDINATOR)
        self.mu = self.momentum.extrapolate(0.0)

    def broadcast(self, rnd: int) -> None:
        nu = float(self.mu[0] - self.mu[1])
        for name in self.dgs:
            self.send(Price(rnd, self.line, nu), name)


class SubstationPlant(PlantAgent):
    """The feeder (:class:`~popdispatch.agents.plant.PlantAgent`): records the set points,
    sends each limited line's DC flow (:meth:`Minute.flows`, the in-process runtime's) to its
    controller and the substation's shortfall to the coordinator, with the plant's noise."""

    ROUND = DualPhase
    PHASES = (DualPhase.MEASURE,)

    def __init__(self, minute: Minute, inverters: Inverters, controllers: list[str],
                 noise_kw: float = 0.0, seed: int = 0, network=None):  # fmt: skip
        super().__init__(minute.problem, minute.minute, inverters,
                         [(c,) for c in controllers], noise_kw, seed, network)  # fmt: skip
        self.m = minute

    def _noise(self) -> float:
        return float(self.rng.normal(0.0, self.noise_mw)) if self.noise_mw else 0.0

    def act(self, rnd: int, phase: DualPhase) -> None:
        p = self.inverters.p.copy()
        self.history.append(p)
        flows = self.m.flows(p)
        for k, (aid,) in enumerate(self.line_ends):
            self.send(Measurement(rnd, k, float(flows[k]) + self._noise()), aid)
        self.send(Shortfall(rnd, float(self.m.demand - p.sum()) + self._noise()), COORDINATOR)


# -- the system the world runs -----------------------------------------------------------------


@dataclass
class DualSystem:
    """The agents of one run and the yardstick they are judged by (module docstring)."""

    minute: Minute
    plant: SubstationPlant
    coordinator: CoordinatorAgent
    controllers: dict[str, LineControllerAgent]
    dgs: list[DgAgent]
    inverters: Inverters
    network: LossyNetwork
    graph: nx.Graph
    accuracy_mw: float
    hold: int
    extrapolate: bool = False
    events: list = field(default_factory=list)
    tripped: list[str] = field(default_factory=list)
    held: dict[int, float] = field(default_factory=dict)  # crashed for good: where it stays
    max_imbalance_mw: float = 0.0
    _opf: tuple = (None, None)  # (key, OpfResult) of the yardstick in force

    def __post_init__(self) -> None:
        self.prove = proved_bound_mw

    def registrations(self) -> list[tuple[object, str]]:
        names = self.minute.names
        return [(self.plant, PLANT_ID), (self.coordinator, COORDINATOR),
                *((c, aid) for aid, c in self.controllers.items()),
                *zip(self.dgs, names, strict=True)]  # fmt: skip

    @property
    def agents(self) -> list:
        return [self.plant, self.coordinator, *self.controllers.values(), *self.dgs]

    @property
    def history(self) -> list[np.ndarray]:
        return self.plant.history

    @property
    def round_ticks(self) -> int:
        return self.plant.round_ticks

    @property
    def step_s(self) -> float:
        return 0.0  # no Euler step: a round is one price iteration

    def apply(self, event, rnd: int) -> None:
        """Start or end a fault event at round ``rnd`` (a trip, a DG's or a controller's
        crash, :class:`~popdispatch.agents.network.FaultEvent`)."""
        names = self.minute.names
        if event.kind == "controller-crash":
            agent = self.controllers[event.agent]
        else:
            agent = self.dgs[names.index(event.agent)]
        end = None if event.rounds is None else event.round + event.rounds
        if rnd == event.round:
            agent.crashed = True
            if event.kind == "trip":
                self.inverters.p[agent.index] = 0.0
                self.tripped.append(event.agent)
            elif event.kind == "crash" and end is None:
                self.held[agent.index] = float(self.inverters.p[agent.index])
            self.events.append({"round": rnd, "event": event.kind, "agent": event.agent})
        elif rnd == end:
            agent.crashed = False
            self.events.append({"round": rnd, "event": "restart", "agent": event.agent})

    def observe(self, faults_applied: bool) -> None:
        self.max_imbalance_mw = max(self.max_imbalance_mw, abs(self.shortfall_mw()))

    def shortfall_mw(self) -> float:
        return float(self.minute.demand - self.inverters.p.sum())

    def residual_mw(self) -> float:
        """The dual's gradient still to go at the set points now: the shortfall and the
        largest overflow, MW."""
        return max(abs(self.shortfall_mw()), self.overflow_mw(self.inverters.p))

    def overflow_mw(self, p: np.ndarray) -> float:
        flows = self.minute.flows(p)
        return float(np.max(np.abs(flows) - self.minute.problem.limit, initial=0.0))

    def runaway(self) -> str | None:
        return None  # an infeasible DC-OPF is reported before the agents start

    def drain(self) -> None:
        pass  # nothing is in flight between rounds

    def busy(self) -> bool:
        return False

    def opf(self):
        """The DC-OPF in force (:func:`dc_opf_in_force`), solved once per change."""
        key = (tuple(self.tripped), tuple(sorted(self.held.items())))
        if self._opf[0] != key:
            self._opf = (key, dc_opf_in_force(self.minute, self.tripped, self.held))
        return self._opf[1]

    def distance_mw(self, p: np.ndarray) -> float:
        """``max(distance to the DC-OPF, |shortfall|, overflow)`` of set points ``p``, MW
        (infinite when the DC-OPF in force is infeasible)."""
        opf = self.opf()
        if opf.status != "optimal":
            return np.inf
        distance = float(np.max(np.abs(p - opf.p_kw / KW_PER_MW)))
        return max(distance, abs(float(self.minute.demand - p.sum())), self.overflow_mw(p))


def proved_bound_mw(system: DualSystem) -> float:
    """The largest :meth:`DualSystem.distance_mw` over the last ``hold`` recorded rounds and
    the inverters now (infinite before ``hold`` rounds): within the accuracy, the set points
    held it that long, as ``popdispatch compare`` asks."""
    rows = system.history[-system.hold :]
    if len(rows) < system.hold:
        return np.inf
    return max(system.distance_mw(p) for p in [*rows, system.inverters.p])


def dc_opf_in_force(minute: Minute, tripped: list[str], held: dict[int, float]):
    """The DC-OPF of the minute with the ``tripped`` DGs offline and each DG of ``held``
    (position -> MW) fixed where its inverter stays."""
    return solve_opf(with_held(without(minute.problem, minute.minute, tripped), held),
                     minute.minute)


# -- building, running and judging ------------------------------------------------------------


def controller_ids(problem: DispatchProblem) -> list[str]:
    """Each limited line's controller id: ``C`` and the bus below the line as the source
    format names it (``C666``), or ``C<from>-<to>`` where two limited lines end at one bus."""
    from popdispatch.agents.population import bus_name

    lines = problem.feeder.lines.iloc[np.asarray(problem.lines, dtype=int)]
    original = problem.feeder.original
    ends = list(zip(original.bus_labels(lines.from_bus), original.bus_labels(lines.to_bus),
                    strict=True))  # fmt: skip
    below = [f"C{bus_name(b)}" for _, b in ends]
    if len(set(below)) == len(below):
        return below
    return [f"C{bus_name(a)}-{bus_name(b)}" for a, b in ends]


def build(problem: DispatchProblem, minute: int, params: DualParams, faults: Faults,
          accuracy_mw: float, hold: int) -> DualSystem:  # fmt: skip
    """The agents of one minute (not yet registered anywhere): the DGs start at the uniform
    start (:func:`~popdispatch.algorithms.base.balanced_shares`) until the first prices."""
    m = Minute.of(problem, minute)
    names = m.names
    network = LossyNetwork(faults, len(DualPhase))
    inverters = Inverters(balanced_shares(m.lo, m.hi, m.demand))
    ids = controller_ids(problem)
    factor = problem.down
    weights = [{names[i]: float(factor[k, i]) for i in np.flatnonzero(factor[k])}
               for k in range(len(ids))]  # fmt: skip
    controllers = {aid: LineControllerAgent(k, float(problem.limit[k]), weights[k], params,
                                            network)
                   for k, aid in enumerate(ids)}  # fmt: skip
    dgs = [
        DgAgent(i, CostCurve(float(problem.b[i]), float(problem.c[i]), float(m.lo[i]),
                             float(m.hi[i])),
                {aid: weights[k][name] for k, aid in enumerate(ids) if name in weights[k]},
                inverters, network)
        for i, name in enumerate(names)
    ]  # fmt: skip
    coordinator = CoordinatorAgent(names, ids, m.demand, params, network)
    plant = SubstationPlant(m, inverters, ids, faults.noise_kw, faults.seed, network)
    graph = nx.Graph()
    graph.add_edges_from((COORDINATOR, name) for name in names)
    graph.add_edges_from((aid, name) for aid, w in zip(ids, weights, strict=True) for name in w)
    graph.add_edges_from((PLANT_ID, aid) for aid in [COORDINATOR, *ids])
    if params.accelerated:
        graph.add_edges_from((COORDINATOR, aid) for aid in ids)
    check_ids(names, ids)
    check_events(faults.events, names, ids)
    return DualSystem(m, plant, coordinator, controllers, dgs, inverters, network, graph,
                      accuracy_mw, hold)  # fmt: skip


def check_ids(generators: list[str], controllers: list[str]) -> None:
    """No DG may carry another agent's id (one line naming it)."""
    taken = {PLANT_ID, COORDINATOR, *controllers}
    for name in generators:
        if name in taken:
            raise OptionError(f"generator {name!r} has the agent id of another agent "
                              "(the plant, the coordinator or a line controller): rename it "
                              "in the fleet", "--fleet")  # fmt: skip


def refuse(settings: RunSettings, opts: AgentSettings, faults: Faults, name: str = NAME) -> None:
    """Refuse, before any work, run settings it does not read that differ from the
    defaults (the population dynamics' options), one line naming the option."""
    defaults = RunSettings(mode=MODES[0])
    for setting, option in _SETTING_OPTIONS.items():
        if getattr(settings, setting) != getattr(defaults, setting):
            raise OptionError(f"the {name} agents do not use {option} (population dynamics "
                              "only)", option)  # fmt: skip


def make_run(name: str):
    """``run`` of the registry's algorithm ``name`` (its parameters:
    :data:`popdispatch.algorithms.registry.ALGORITHMS`, the comparison's defaults)."""

    def run(problem: DispatchProblem, minute: int, settings: RunSettings, faults: Faults,
            opts: AgentSettings, on_round=None) -> AgentRun:  # fmt: skip
        from popdispatch.algorithms.registry import ALGORITHMS

        return run_dual(problem, minute, settings, faults, opts, ALGORITHMS[name].params(),
                        on_round)  # fmt: skip

    run.__doc__ = f"One minute by the {name} agents in the generic world (module docstring)."
    return run


run = make_run(NAME)


def run_dual(problem: DispatchProblem, minute: int, settings: RunSettings, faults: Faults,
             opts: AgentSettings, params: DualParams, on_round=None) -> AgentRun:  # fmt: skip
    """One minute by dual decomposition's agents with ``params`` (``opts.tol_kw`` in force);
    infeasible without running when the minute's DC-OPF is."""
    try:
        DualDecomposition.check(problem)
    except OptionError as exc:
        raise OptionError(str(exc), "--algorithm") from None
    demand = float(problem.demand[minute - 1])
    accuracy = float(settings.accuracy_mw(demand))
    system = build(problem, minute, params, faults, accuracy, opts.window)
    paced = opts.phase_ticks_for(faults, len(DualPhase))
    for agent in system.agents:
        agent.phase_ticks = paced
    if system.opf().status != "optimal":
        return _infeasible(system, minute)
    world = run_world(system, WorldOptions(opts.max_rounds, opts.rest_window(faults),
                                           opts.tol_kw, opts.drain_rounds), on_round)  # fmt: skip
    return _judged(system, world)


def _result(system: DualSystem, world: WorldRun | None) -> AgentRun:
    prices = {aid: [(c.line, float(c.mu[0]), float(c.mu[1]))]
              for aid, c in system.controllers.items() if not c.crashed}  # fmt: skip
    return proposal_run(system, world, np.array([c.mu[0] - c.mu[1]
                                                 for c in system.controllers.values()]),
                        prices)  # fmt: skip


def proposal_run(system, world: WorldRun | None, line_prices: np.ndarray,
                 prices: dict | None = None) -> AgentRun:  # fmt: skip
    """The :class:`~popdispatch.agents.system.AgentRun` of an algorithm whose inverters follow
    proposals (dual decomposition, consensus ADMM): the plant's history, the world's counts,
    the imbalance of the applied set points, the controllers' ``line_prices`` (EUR/MWh) and
    their ``prices`` by controller (as the population's run reports them), not yet judged
    (:func:`judged`)."""
    p = system.inverters.p
    history = system.history or [p.copy()]
    return AgentRun(
        generators=list(system.minute.names),
        trajectory_kw=np.array(history) * KW_PER_MW,
        setpoints_kw=p * KW_PER_MW,
        rounds=world.rounds if world else 0,
        rest_round=world.rest_round if world else None,
        messages=world.messages if world else 0,
        lost=world.lost if world else 0,
        duplicated=world.duplicated if world else 0,
        max_imbalance_w=system.max_imbalance_mw * W_PER_MW,
        max_transient_w=system.max_imbalance_mw * W_PER_MW,
        final_imbalance_w=-system.shortfall_mw() * W_PER_MW,
        open_transactions=0,
        residual_kw=system.residual_mw() * KW_PER_MW,
        wall_seconds=world.wall_seconds if world else 0.0,
        agents=len(system.agents),
        step_s=system.step_s,
        phase_ticks=system.plant.phase_ticks,
        prices=prices if prices is not None else {},
        events=sorted(system.events, key=lambda e: e["round"]),
        scalars_sent=world.scalars_sent if world else 0,
        accuracy_kw=system.accuracy_mw * KW_PER_MW,
        line_price_eur_per_mwh=line_prices,
    )  # fmt: skip


def _infeasible(system: DualSystem, minute: int) -> AgentRun:
    why = (f"the DC-OPF of minute {minute} is infeasible: no dispatch within the limits "
           "exists, so the prices would run away")  # fmt: skip
    return replace(_result(system, None), infeasible=True, horizon_reason=why)


def _judged(system: DualSystem, world: WorldRun) -> AgentRun:
    return judged(system, world, _result(system, world), "its price is frozen")


def judged(system: DualSystem, world: WorldRun, run: AgentRun, frozen: str) -> AgentRun:
    """``run``, ``converged`` only when :func:`proved_bound_mw` is within the accuracy at
    the end; otherwise the reason with the distance (``frozen``: what a crashed line
    controller leaves behind, named in the reason)."""
    bound = proved_bound_mw(system)
    certified = bool(bound <= system.accuracy_mw)
    bound_kw = float(bound * KW_PER_MW)
    reason = None
    if not certified:
        where = ("the DC-OPF in force is infeasible" if system.opf().status != "optimal"
                 else f"the set points of the last {system.hold} rounds are up to "
                 f"{bound_kw:.4g} kW from the DC-OPF (or off balance or over a line by that)")
        reason = f"{where}; accuracy {run.accuracy_kw:.3g} kW"  # fmt: skip
    at_rest = world.rest_round is not None
    down = [aid for aid, c in system.controllers.items() if c.crashed]
    hint = (f"line controller {', '.join(down)} is down: {frozen}" if down
            else "give more rounds")  # fmt: skip
    return replace(run, certified=certified, distance_bound_kw=bound_kw,
                   stall_reason=f"at rest, but {reason} ({hint})" if reason and at_rest
                   else None,
                   horizon_reason=(f"not converged after {run.rounds} rounds: {reason} "
                                   f"({hint})" if reason and not at_rest else None))  # fmt: skip
