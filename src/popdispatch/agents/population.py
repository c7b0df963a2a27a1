"""The population dynamics as agents: today's algorithm of :mod:`popdispatch.agents`.

One agent per generator (:mod:`~popdispatch.agents.generator`: fitness, the pairwise
revision rule, power moved only in offer-accept-commit transactions), one per node
controller (:mod:`~popdispatch.agents.controller`: the mode's line prices), the plant
(:mod:`~popdispatch.agents.plant`: set points to flows) and the source bus
(:mod:`~popdispatch.agents.source`), in the six-phase round of
:mod:`~popdispatch.agents.schedule`. :func:`build_agents` builds them, :func:`run` runs them in
the generic world (:func:`popdispatch.agents.world.run_world`) and judges the end state with
the engine's distance certificate (:func:`popdispatch.online.verdicts`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import networkx as nx
import numpy as np

from popdispatch.agents.controller import PAYOFFS, ControllerAgent, LineEnd, LinePrice
from popdispatch.agents.generator import GeneratorAgent, GeneratorRule
from popdispatch.agents.network import FaultEvent, Faults, LossyNetwork
from popdispatch.agents.plant import Inverters, PlantAgent
from popdispatch.agents.schedule import TICKS_PER_ROUND
from popdispatch.agents.source import SOURCE_ID, SourceAgent
from popdispatch.agents.system import (
    W_PER_MW,
    AgentRun,
    AgentSettings,
    check_events,
    line_states,
    without,
)
from popdispatch.agents.world import WorldOptions, WorldRun, run_world
from popdispatch.constants import KW_PER_MW
from popdispatch.dynamics import communication_graph
from popdispatch.dynamics.pairwise import slow_relays
from popdispatch.errors import OptionError
from popdispatch.game.controllers import NodeControllers
from popdispatch.game.parameters import MinuteInputs, PriceLaw
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import STABLE_STEP
from popdispatch.modes import get_mode
from popdispatch.modes.exact import controller_constants, scales
from popdispatch.online.settings import RunSettings, initial_shares
from popdispatch.online.stiffness import price_loop_rate, stiffness_rate
from popdispatch.warm_start import SHARES, warm_start

#: The name the registry (:mod:`popdispatch.agents.algorithms`) knows this algorithm by.
NAME = "population"
#: The modes its node controllers price (``--mode``).
MODES = ("paper", "exact")
#: The :class:`~popdispatch.agents.system.AgentSettings` fields it reads: all of them.
OPTIONS = frozenset(AgentSettings.__dataclass_fields__)
#: The cap of the revision rate of a quadratic generator whose output moves no priced row, in
#: the agents with the local step on the complete graph (dimensionless, dynamics/newton.py;
#: :meth:`~popdispatch.online.RunSettings.revision_rates`): three times the fixed steps' cap
#: ``rate_cap``, which made a DG whose marginal cost must fall a small part of a spread that a
#: steep DG's range made large drain at the cap's pace. The generator's own step factor keeps
#: its own mode stable at any rate, and uncapped it adds at most ``S / P`` to the coupling
#: between generators that bounds the round step (:func:`local_stiffness_rate`). Not the
#: engine's 1000: in the rounds a fast rate also answers stale news fast, and with 20 % of the
#: messages lost the ELV congestion minute took 411 rounds at 10, 561 at 30, 711 at 100 and
#: oscillated at 1000. Not on a sparse graph, where each generator normalises by its
#: neighbourhood and free flat neighbours left runs unconverged (docs/agents.md, "The local
#: step").
FREE_RATE_CAP = 30.0
#: With the local step on the complete graph a line price moves by at most this part of its
#: proportional weight per round, ``h alpha / C`` (:func:`price_rates`): the price loop's own
#: bound on the round step, ``h = C / (2 alpha)``, with the round step itself set by the
#: coupling between generators (:func:`local_stiffness_rate`).
PRICE_STEP = 0.5
#: Under the prices' own step a limited line above a generator counts in its own step factor
#: for this many rounds after its price was last non-zero
#: (:meth:`~popdispatch.agents.generator.GeneratorAgent._price_slope`): 2 let a case17me
#: fleet oscillate across the line's band, 5 a random fleet whose nearly linear DG crept
#: toward the limit for longer than that and, freed, crossed it by half the limit; the whole
#: run held a linear DG below a line that no longer bound at a crawl (docs/agents.md).
PRICED_MEMORY = 10
#: Under the prices' own step each line above a generator counts at this part of its
#: proportional weight ``C_k`` in the generator's own step factor (:func:`price_slopes`).
OWN_STEP_SLOPE = 0.5


def default_step(problem: DispatchProblem, settings: RunSettings, minute: int,
                 local: bool = False) -> float:  # fmt: skip
    """The default round step, s: in exact mode ``STABLE_STEP / rate``
    (:data:`popdispatch.integrate.STABLE_STEP`, the largest ``h * rate`` the engine's Heun
    steps take; ``rate``: :func:`~popdispatch.online.stiffness.stiffness_rate`, or with the
    ``local`` step of the curvature-scaled field :func:`local_stiffness_rate`); in paper mode
    the engine's own Euler substep (the mode's integrator: ``dt / substeps``)."""
    if not get_mode(settings.mode).bounded:
        stepping = settings.stepping
        return stepping.dt / stepping.substeps
    if local and len(settings.revision_rates(problem)):
        return STABLE_STEP / local_stiffness_rate(problem, settings, minute)
    return STABLE_STEP / stiffness_rate(problem, settings, minute)


def local_stiffness_rate(problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
    """The rate (1/s) that bounds the round step when every generator takes its own step
    factor (:meth:`~popdispatch.agents.generator.GeneratorRule.step_factor`), which keeps
    each generator's own mode, its curvature and the proportional part of the prices above
    it, stable at any step: the rate at which every interior marginal cost relaxes, ``gain D
    S / P`` (the coupling between generators, which no own factor bounds), a round step of
    1.5 of that relaxation time at most. Where the prices do not integrate at their own step
    (:func:`own_price_step`) also the line prices' rate ``2 STABLE_STEP alpha / C``
    (:func:`~popdispatch.online.stiffness.price_loop_rate`)."""
    fp = settings.game_constants(problem)
    demand = float(problem.demand[minute - 1])
    spread, reference = scales(problem)
    field = float(fp.gain) * demand * spread / reference
    if own_price_step(problem, settings):
        return field
    return max(field, price_loop_rate(problem, settings, minute))


def own_price_step(problem: DispatchProblem, settings: RunSettings) -> bool:
    """Whether the line prices integrate at their own step (:func:`price_rates`) and the
    round step is the generators' coupling bound: with the local step on the complete graph,
    where no generator lies below two limited lines. Nested prices add up in the generators
    below them, and the price loops with them: the synthetic 1k feeder (up to 23 limited lines
    above a generator) oscillates at the larger step (docs/agents.md, "The local step")."""
    if not _complete(generator_graph(problem, settings)):
        return False
    return all(len(lines_above(problem, i)) <= 1 for i in range(problem.n_generators))


def price_rates(weight: np.ndarray, rate: np.ndarray, step_s: float) -> np.ndarray:
    """The line prices' rates (EUR/MW per MW per s) under a round step ``step_s`` (s) that
    the price loop does not bound: ``alpha_k`` at most ``C_k / (2 h)``, so that a round moves
    a price by at most half its proportional part, ``h alpha / C <= 1/2``, the step the
    price loop's bound gives (docs/agents.md, "The round step"). The price of a rest point
    does not depend on its rate."""
    return np.minimum(rate, PRICE_STEP * weight / step_s)


@dataclass
class AgentSystem:
    """The agents of one run and what they share: the plant, the controllers by id, the
    generators in the problem's order, the inverters and the simulated network."""

    plant: PlantAgent
    controllers: dict[str, ControllerAgent]
    generators: list[GeneratorAgent]
    inverters: Inverters
    network: LossyNetwork
    graph: nx.Graph
    demand_mw: float
    source: SourceAgent | None = None
    events: list = field(default_factory=list)
    price_cap: float = np.inf  # EUR/MW: a line price beyond it means no dispatch relieves it
    line_names: list[str] = field(default_factory=list)  # "line A-B" per limited line
    prove: Callable[[AgentSystem], float] | None = None  # the distance bound now, MW
    extrapolate: bool = False  # the rest rule projects the geometric tail (exact mode)
    accuracy_mw: float = 0.0  # what a rest must prove to end the run (with ``prove``)
    max_imbalance_mw: float = 0.0  # largest |supply - demand| of the committed state so far
    max_transient_mw: float = 0.0  # largest |supply - demand| of the inverters at a round start

    # -- what the world needs (popdispatch.agents.world.WorldSystem) -------------------------

    def registrations(self) -> list[tuple[object, str]]:
        """Every agent with its id: the plant, the controllers, the generators by name, the
        source bus."""
        return [(self.plant, "plant"), *((a, aid) for aid, a in self.controllers.items()),
                *zip(self.generators, self.graph.nodes, strict=True),
                (self.source, SOURCE_ID)]  # fmt: skip

    @property
    def history(self) -> list[np.ndarray]:
        return self.plant.history

    @property
    def round_ticks(self) -> int:
        return self.plant.round_ticks

    @property
    def step_s(self) -> float:
        return self.generators[0].rule.step_s

    def observe(self, faults_applied: bool) -> None:
        """Track the committed state's imbalance (before and after the round's faults) and
        the inverters' (before them: what the source bus took up during the last round)."""
        self.max_imbalance_mw = max(self.max_imbalance_mw, abs(self.committed_imbalance_mw()))
        if not faults_applied:
            self.max_transient_mw = max(self.max_transient_mw,
                                        abs(self.physical_imbalance_mw()))  # fmt: skip

    def _live_controllers(self) -> list[ControllerAgent]:
        return [c for c in self.controllers.values() if not c.crashed]

    def residual_mw(self) -> float:
        """The live controllers' largest distance from complementary slackness, MW."""
        return max((c.residual_mw() for c in self._live_controllers()), default=0.0)

    def runaway(self) -> str | None:
        return runaway(self, self._live_controllers())

    def drain(self) -> None:
        for gen in self.parties:
            gen.quiet = True  # no new offers; open transactions decided

    def busy(self) -> bool:
        return any(g.busy for g in self.parties if not g.crashed)

    @property
    def agents(self) -> list:
        extra = [self.source] if self.source is not None else []
        return [self.plant, *self.controllers.values(), *self.generators, *extra]

    @property
    def parties(self) -> list[GeneratorAgent]:
        """Everyone who commits power: the generators and the source bus."""
        return [*self.generators, *([self.source] if self.source is not None else [])]

    def apply(self, event: FaultEvent, rnd: int) -> None:
        """Start or end ``event`` at round ``rnd`` (see :class:`FaultEvent`)."""
        if event.kind == "trip":
            if rnd == event.round:
                self.trip(event.agent, rnd)
            return
        agent = (self.controllers.get(event.agent) if event.kind == "controller-crash"
                 else self._generator_or_none(event.agent))  # fmt: skip
        end = None if event.rounds is None else event.round + event.rounds
        if rnd == event.round:
            agent.crashed = True
            self.events.append({"round": rnd, "event": event.kind, "agent": event.agent})
        elif rnd == end:
            agent.crashed = False
            self.events.append({"round": rnd, "event": "restart", "agent": event.agent})

    def _generator_or_none(self, name: str):
        return next((g for g in self.generators if g.aid == name), None)

    def trip(self, name: str, rnd: int) -> None:
        """DG ``name`` trips: its output goes to 0 at once and its agent stops for good; the
        protection reports it, so the others forget it (its transactions, its status) and the
        source bus takes over at once what the committed state now lacks (the tripped output
        and the transactions the trip cut), as its committed position
        (:mod:`popdispatch.agents.source`)."""
        gen = self._generator_or_none(name)
        gen.crashed = gen.tripped = True
        self.inverters.p[gen.index] = 0.0
        for book in (gen.pending_in, gen.pending_out, gen.committed, gen.undelivered,
                     gen.open_offers, gen.reserved, gen.accepted):  # fmt: skip
            book.clear()
        for other in self.parties:
            if other is not gen:
                other.forget(name)
        taken = -self.committed_imbalance_mw()
        self.source.position_mw += taken
        self.events.append({"round": rnd, "event": "trip", "agent": name,
                            "source_takes_kw": taken * KW_PER_MW})  # fmt: skip

    def committed_imbalance_mw(self) -> float:
        """Supply minus demand of the committed state: every set point, plus each committed
        transaction whose receiver has not applied it yet (in flight: among the decisions its
        sender has not seen acknowledged, since a receiver acknowledges what it applied). Zero
        up to rounding if every transaction is applied exactly once at each end."""
        parties = {g.aid: g for g in self.parties}
        in_flight = sum(
            decision.amount_mw for g in parties.values()
            for txid, (aid, decision) in g.undelivered.items()
            if decision.commit and txid not in getattr(parties.get(aid), "applied", ())
        )  # fmt: skip
        planned = sum(g.planned for g in parties.values())
        return float(planned + in_flight - self.demand_mw)

    def physical_imbalance_mw(self) -> float:
        """Supply minus demand of the set points as they are: what the source bus takes up."""
        return float(self.inverters.p.sum() - self.demand_mw)



def controller_prices(system: AgentSystem) -> dict:
    """Each live controller's ``(line, z_up, z_down)`` of its lines (a crashed controller's
    copies froze when it stopped: the survivor's count)."""
    return {aid: [(end.line, end.z_up, end.z_down) for end in c.ends]
            for aid, c in system.controllers.items() if not c.crashed}  # fmt: skip



def initial_setpoints(problem: DispatchProblem, settings: RunSettings, minute: int) -> np.ndarray:
    """Initial set points (MW) as :meth:`popdispatch.online.Engine.run_minute` starts: the
    initial shares, projected onto the limits in bounded modes, times the demand."""
    inputs = MinuteInputs.of(problem, minute)
    x = initial_shares(problem, settings.x0, minute)
    weight = np.empty_like(x)
    warm_start(int(SHARES), get_mode(settings.mode).bounded, x, 0.0, inputs.demand,
               problem.pmin, problem.pmax, inputs.active, weight)  # fmt: skip
    return x * inputs.demand


def game_constants(problem: DispatchProblem, settings: RunSettings):
    """The game's constants (EUR/MW: ``B``, ``m``, ``C``, ``gain``, ``price_rate``) exactly as
    the engine runs them for this problem and settings: read from the engine's own
    :class:`~popdispatch.game.parameters.GameParameters`, so that a mode whose constants
    depend on the problem (scaled ones) needs no copy of that rule here."""
    from popdispatch.online import Engine

    return Engine(problem, settings).params


def generator_graph(problem: DispatchProblem, settings: RunSettings) -> nx.Graph:
    """The communication graph over generator names (complete for dynamics without one)."""
    names = list(problem.generators)
    adjacency = communication_graph(settings.trading_graph, names)
    return nx.relabel_nodes(nx.from_numpy_array(adjacency), dict(enumerate(names)))


def build_agents(problem: DispatchProblem, minute: int, settings: RunSettings,
                 step_s: float, faults: Faults, timeout: int = 1, lag: int = 0,
                 copies: int = 1, engine_limiter: bool = True,
                 stale_rounds: int = 10, local_step: bool = False) -> AgentSystem:  # fmt: skip
    """The agents of one minute (not yet registered anywhere); ``timeout``: rounds an offer
    stays open; ``lag``: rounds from a commit to the inverters' change; ``local_step``: each
    generator scales its pairs' steps by its own factor (GeneratorRule.step_factor), and the
    controllers hasten a still line's price and net a settled line's two prices
    (:mod:`popdispatch.agents.controller`)."""
    if not problem.online[minute - 1].all():
        off = ", ".join(problem.generators[~problem.online[minute - 1]])
        raise OptionError(f"the agents run with every generator online (offline: {off})")
    check_settings(settings)
    mode = get_mode(settings.mode)
    field_code = settings.field
    graph = generator_graph(problem, settings)
    sparse = not _complete(graph)
    # unpriced quadratic generators freed with the local step on the complete graph only
    rates = settings.revision_rates(problem, FREE_RATE_CAP if local_step and not sparse else None)
    fp = game_constants(problem, settings)
    weight, price_rate = line_constants(problem, settings, fp, minute)  # C_k, alpha_k
    own_step = bool(local_step) and mode.bounded and own_price_step(problem, settings)
    demand = float(problem.demand[minute - 1])
    network = LossyNetwork(faults, TICKS_PER_ROUND)
    inverters = Inverters(initial_setpoints(problem, settings, minute))
    names = list(problem.generators)
    generators = []
    for i, name in enumerate(names):
        neighbours = [n for n in names if graph.has_edge(name, n)]
        above = lines_above(problem, i)
        rule = GeneratorRule(
            float(problem.b[i]), float(problem.c[i]), float(problem.pmin[i]),
            float(problem.pmax[i]), float(fp.B), float(fp.m),
            float(fp.gain) if mode.bounded else 1.0, not mode.bounded, int(field_code),
            demand, step_s, float(rates[i]) if len(rates) else 0.0,
            above, price_slopes(above, weight, fp.C, own_step),
            len(neighbours) + 1 if sparse else 1,
            bool(local_step) and mode.bounded, PRICED_MEMORY if own_step else 0,
        )  # fmt: skip
        generators.append(
            GeneratorAgent(
                rule, i, inverters, neighbours, timeout, lag, copies, engine_limiter, network
            )  # fmt: skip
        )
    slow = slow_relay_ids(graph, names, rates) if sparse else frozenset()
    for gen in generators:
        gen.relay = sparse  # relay through blocked generators where the graph is not complete
        gen.slow_relays = slow
        gen.stale_rounds = stale_rounds
    speed = still_line_speed(problem, settings) if local_step else 0.0
    if own_step:
        price_rate = price_rates(weight, price_rate, step_s)
    controllers, line_ends = _controllers(problem, settings, fp, step_s, network, weight,
                                          price_rate, speed, bool(local_step),
                                          own_step)  # fmt: skip
    for controller in controllers.values():  # the generators report a silence first
        controller.stale_rounds = 2 * stale_rounds
    plant = PlantAgent(problem, minute, inverters, line_ends, faults.noise_kw, faults.seed,
                       network)  # fmt: skip
    source = SourceAgent(names, timeout, copies, network)
    _check_ids(names, controllers)
    check_events(faults.events, names, list(controllers))
    cap = mode.price_cap(problem) if mode.bounded else np.inf
    return AgentSystem(plant, controllers, generators, inverters, network, graph, demand,
                       source, price_cap=cap, line_names=_line_names(problem))  # fmt: skip


def price_slopes(above: tuple[int, ...], weight: np.ndarray, C: float,
                 own_step: bool) -> tuple[float, ...]:  # fmt: skip
    """The fall of the prices above a generator per MW it adds, as its own step factor counts
    them (EUR/MW per MW), for each line in ``above``: under the prices' own step
    (``own_step``, :func:`own_price_step`) :data:`OWN_STEP_SLOPE` times the line's own weight
    ``C_k`` (``weight``: each limited line's; the scaled law's ``C sqrt(s_k)``); otherwise half
    the game's ``C`` on every line, the fall of the generator's own half of the net price
    (there the price loop bounds the round step, and the lines' own weights only make the
    factors smaller; docs/agents.md, "The local step")."""
    if own_step:
        return tuple(OWN_STEP_SLOPE * float(weight[k]) for k in above)
    return tuple(0.5 * float(C) for _ in above)


def lines_above(problem: DispatchProblem, generator: int) -> tuple[int, ...]:
    """The limited lines between ``generator`` and the source (indices among the limited
    lines), nearest first: what the node controllers on its path tell it. On a meshed network
    every limited line its output moves (a non-zero distribution factor), each counted as a
    whole line (its factor is at most 1 in size: a step factor on the safe side)."""
    if problem.meshed:
        return tuple(int(k) for k in np.flatnonzero(problem.factor[:, generator]))
    above = []
    k = int(problem.generator_line[generator])
    while k >= 0:
        above.append(k)
        k = int(problem.line_up[k])
    return tuple(above)


def _line_names(problem: DispatchProblem) -> list[str]:
    """``line A-B`` of every limited line (its end buses as the feeder names them)."""
    lines = problem.feeder.lines.iloc[np.asarray(problem.lines, dtype=int)]
    return [f"line {bus_name(a)}-{bus_name(b)}"
            for a, b in zip(lines.from_bus, lines.to_bus, strict=True)]  # fmt: skip


def check_settings(settings: RunSettings) -> None:
    """Refuse run settings the agents cannot honour: a mode other than paper and exact (their
    node controllers price limited lines only), the tree price law (each controller hears only
    its own lines; the tree law needs its neighbours' excesses). The scaled law needs only two
    counts per line, which each controller has from configuration (:func:`line_constants`)."""
    if get_mode(settings.mode).code not in PAYOFFS:
        raise OptionError(f"the agents run paper and exact mode, not {settings.mode}", "--mode")
    if settings.exact.price_law == PriceLaw.TREE:
        raise OptionError(
            "the agents' node controllers run the plain and scaled price laws (each hears only "
            "its own lines; the tree law needs its neighbours' excesses)",
            "--price-law",
        )


def _check_ids(generators: list[str], controllers: dict) -> None:
    """No generator may carry another agent's id (the plant, the source bus, a node
    controller ``C<bus>``): one-line error naming it."""
    others = {"plant": "the plant", SOURCE_ID: "the source bus"}
    others.update({aid: "a node controller" for aid in controllers})
    for name in generators:
        if str(name) in others:
            raise OptionError(f"generator {name!r} has the agent id of {others[str(name)]}: "
                              "rename it in the fleet", "--fleet")  # fmt: skip


def slow_relay_ids(graph: nx.Graph, names: list[str], rates: np.ndarray) -> frozenset[str]:
    """The generators that relay by their revision rates (the engine's
    :func:`~popdispatch.dynamics.pairwise.slow_relays` on ``graph``): a roster the set-up
    gives every generator, like the graph."""
    if len(rates) != len(names):
        return frozenset()
    csr = nx.to_scipy_sparse_array(graph, nodelist=names, format="csr")
    slow = slow_relays(np.asarray(rates, dtype=float), csr.indptr.astype(np.int64),
                       csr.indices.astype(np.int64))  # fmt: skip
    return frozenset(name for name, flag in zip(names, slow, strict=True) if flag)


def _complete(graph: nx.Graph) -> bool:
    n = graph.number_of_nodes()
    return graph.number_of_edges() == n * (n - 1) // 2


def relay_phase_ticks(n_generators: int, delay_max: int) -> int:
    """Ticks per phase that let a relayed message cross the longest chain of relays: at
    most ``n - 1`` hops, each half a tick plus up to ``delay_max`` rounds of
    :data:`TICKS_PER_ROUND` ticks (relays pass messages on as they arrive)."""
    hops = max(n_generators - 1, 1)
    return int(hops * (0.5 + TICKS_PER_ROUND * int(delay_max))) + 1


def bus_name(bus) -> str:
    """An original bus as the source format names it (a whole number read into a float
    column, ``505.0``, as ``505``)."""
    if isinstance(bus, float) and bus.is_integer():
        bus = int(bus)
    return str(bus)


def controller_id(bus) -> str:
    """Agent id of the node controller at original bus ``bus`` (``C505``)."""
    return f"C{bus_name(bus)}"


def line_constants(
    problem: DispatchProblem, settings: RunSettings, fp, minute: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each limited line's proportional weight ``C_k`` (EUR/MW per MW) and price rate
    ``alpha_k`` at ``minute``, as the engine's kernels have them
    (:func:`popdispatch.modes.exact.controller_constants`: under the scaled law from the
    fleet's online tradable generators and those below the line, two counts each controller
    is told; on a mesh from the line's distribution factors, its configuration); ``fp``'s
    ``C`` and ``price_rate`` on every line in paper mode."""
    n_lines = len(problem.limit)
    if not get_mode(settings.mode).bounded or not n_lines:
        return np.full(n_lines, float(fp.C)), np.full(n_lines, float(fp.price_rate))
    return controller_constants(problem, settings.exact.price_law, fp.C, fp.price_rate, minute)


def still_line_speed(problem: DispatchProblem, settings: RunSettings) -> float:
    """The least speed the controllers hasten a still line's overflowing price to, EUR/MW per
    s (:mod:`popdispatch.agents.controller`): exact mode's ``pinned_speed`` times the
    marginal-cost spread ``S``, as the engine's pinned lines; 0 in a mode without prices."""
    if not get_mode(settings.mode).bounded:
        return 0.0
    return float(settings.exact.pinned_speed * scales(problem)[0])


def _controllers(problem, settings: RunSettings, fp, step_s: float, network, weight, rate,
                 speed: float = 0.0, net: bool = False, tell_both: bool = False):  # fmt: skip
    """``({id: controller}, line_ends)`` from the problem's controller table; each line priced
    by the mode's own payoff map (:class:`~popdispatch.agents.controller.LinePrice`) with the
    problem's limit of the line, its proportional weight ``weight[k]`` and price rate
    ``rate[k]`` (:func:`line_constants`: the scaled law and a mesh's lever scale are the plain
    law with per-line constants); ``speed``: the least speed of a still line's price, EUR/MW
    per s (:func:`still_line_speed`); ``net``: the controllers net a settled line's prices;
    ``tell_both``: they tell which lines have both directions priced."""
    table = NodeControllers.from_problem(problem).table
    position = {line: k for k, line in enumerate(problem.lines)}
    payoff = PAYOFFS[get_mode(settings.mode).code]
    n_states = 2 if get_mode(settings.mode).bounded else 0
    ends: dict[str, list[LineEnd]] = {}
    line_ends: list[list[str]] = [[] for _ in problem.lines]
    for row in table.itertuples():
        aid = controller_id(row.bus)
        k = position[row.line]
        price = LinePrice(payoff, float(problem.limit[k]), float(weight[k]), float(rate[k]),
                          n_states)  # fmt: skip
        weights = None
        if problem.meshed:  # each generator's factor to the line
            weights = dict(zip(problem.generators, problem.factor[k].tolist(), strict=True))
        ends.setdefault(aid, []).append(
            LineEnd(k, int(row.orientation), price, list(row.receivers), weights=weights)
        )
        line_ends[k].append(aid)
    for aid, own in ends.items():  # each end knows its partner and the other side
        for end in own:
            partner = next(a for a in line_ends[end.line] if a != aid)
            end.partner = partner
            end.other_receivers = next(e.receivers for e in ends[partner] if e.line == end.line)
    controllers = {aid: ControllerAgent(own, step_s, network, speed=speed, net=net,
                                        tell_both=tell_both)
                   for aid, own in ends.items()}  # fmt: skip
    return controllers, [tuple(e) for e in line_ends]



def _auditor(problem: DispatchProblem, settings: RunSettings, opts: AgentSettings,
             step_s: float):  # fmt: skip
    """The engine that audits a run (its distance certificate and KKT check, with the
    agents' step, rest tolerance and window): a :class:`popdispatch.online.Engine` of
    ``problem`` (without the tripped generators)."""
    from popdispatch.integrate import Integrator
    from popdispatch.online import Engine

    integrator = Integrator(dt=step_s, tol_kw=max(opts.tol_kw, 1e-9), window=opts.window)
    return Engine(problem, replace(settings, integrator=integrator))


def _judged(run: AgentRun, engine, minute: int, tripped: list[str], tol_kw: float) -> AgentRun:
    """``run`` with the engine's verdict (:func:`popdispatch.online.verdicts`): in a mode that
    claims the DC-OPF, converged only when the distance certificate proves the end state
    (set points, each line's prices: the mean of its end controllers' copies) within the
    accuracy; a run at rest without that proof is stalled with the reason (a failing KKT
    condition, else the bound). A source bus still carrying power after a trip is never
    converged."""
    from popdispatch.online import verdicts

    problem = engine.problem
    p_mw = run.setpoints_kw[None] / KW_PER_MW
    z = run.line_states(len(problem.limit))[None]
    if not engine.mode.claims_dc_opf:
        z = np.zeros((1, 0))
    rested = np.array([run.rest_round is not None])
    verdict = verdicts(engine, np.array([minute]), p_mw, z, rested, np.array([run.infeasible]))
    certified, reason = bool(verdict.certified[0]), verdict.reasons[0]
    if engine.mode.claims_dc_opf and abs(run.source_kw) > tol_kw:
        certified = False
        reason = (f"the source bus carries {run.source_kw:.4g} kW that the generators left "
                  f"after the trip of {', '.join(tripped)} cannot take")  # fmt: skip
    bound = None if verdict.bound_kw is None else float(verdict.bound_kw[0])
    accuracy = None if verdict.accuracy_kw is None else float(verdict.accuracy_kw[0])
    return replace(run, certified=certified, stall_reason=reason if rested[0] else None,
                   distance_bound_kw=bound, accuracy_kw=accuracy)  # fmt: skip


def proved_distance_mw(engine, minute: int, tol_mw: float = np.inf):
    """``prove(system)``: the distance bound (MW) the certificate gives the agents' state now
    (the inverters' set points and the live controllers' prices), with ``engine`` (see
    :func:`_auditor`); none (infinite) while the source bus carries more than ``tol_mw`` (MW)
    after a trip, which :func:`_judged` never calls converged."""

    def prove(system: AgentSystem) -> float:
        if system.source is not None and abs(system.source.position_mw) > tol_mw:
            return np.inf
        p_mw = system.inverters.p[None]
        z = line_states(controller_prices(system), len(engine.problem.limit))[None]
        return engine.certificates(np.array([minute]), p_mw, z)[0].distance_mw

    return prove



def refuse(settings: RunSettings, opts: AgentSettings, faults: Faults) -> None:
    """Refuse, before any work, what this algorithm cannot honour (:func:`check_settings`)."""
    check_settings(settings)


def step_for(opts: AgentSettings, problem: DispatchProblem, settings: RunSettings,
             minute: int) -> float:  # fmt: skip
    """The round's Euler step in force, s: the given one, else :func:`default_step`."""
    if opts.step_s is not None:
        return opts.step_s
    return default_step(problem, settings, minute, opts.local_step)


def run(problem: DispatchProblem, minute: int, settings: RunSettings, faults: Faults,
        opts: AgentSettings, on_round=None) -> AgentRun:  # fmt: skip
    """One minute by the population's agents in the generic world, judged by the engine's
    distance certificate (:func:`_judged`; ``opts.tol_kw`` already in force)."""
    step_s = step_for(opts, problem, settings, minute)
    tripped = [e.agent for e in faults.events if e.kind == "trip"]
    engine = _auditor(without(problem, minute, tripped), settings, opts, step_s)
    system = prepared(problem, minute, settings, faults, opts, step_s, engine)
    world = run_world(system, world_options(opts, faults), on_round)
    return _judged(_result(system, world), engine, minute, tripped, opts.tol_kw)


def world_options(opts: AgentSettings, faults: Faults) -> WorldOptions:
    """The world's settings from the agents' (the rest window widened for unpaced rounds)."""
    return WorldOptions(opts.max_rounds, opts.rest_window(faults), opts.tol_kw,
                        opts.drain_rounds)  # fmt: skip


def prepared(problem, minute, settings, faults, opts: AgentSettings, step_s: float,
             engine=None) -> AgentSystem:  # fmt: skip
    """The agents of the minute, paced to the network, with the certificate's ``prove`` when
    an auditing ``engine`` (:func:`_auditor`) in a mode that claims the DC-OPF is given: a
    rest it does not prove within the accuracy runs on
    (:func:`popdispatch.agents.world.simulate`)."""
    system = build_agents(problem, minute, settings, step_s, faults, opts.timeout_for(faults),
                          opts.lag_for(faults), opts.copies_for(faults),
                          opts.engine_limiter_for(faults), opts.stale_for(faults),
                          opts.local_step)  # fmt: skip
    ticks = opts.phase_ticks_for(faults, TICKS_PER_ROUND)
    if system.generators[0].relay:
        ticks = max(ticks, relay_phase_ticks(len(system.generators), faults.delay_max))
    for agent in system.agents:
        agent.phase_ticks = ticks
    if engine is not None and engine.mode.claims_dc_opf:
        system.prove = proved_distance_mw(engine, minute, opts.tol_kw / KW_PER_MW)
        system.accuracy_mw = float(settings.accuracy_mw(problem.demand[minute - 1]))
    system.extrapolate = bool(settings.stepping.extrapolate)
    return system


def _result(system: AgentSystem, world: WorldRun) -> AgentRun:
    """The run from what the world measured and the agents' end state."""
    residual = max((c.residual_mw() for c in system.controllers.values()), default=0.0)
    trajectory = np.array(system.plant.history) * KW_PER_MW
    return AgentRun(
        generators=list(system.graph.nodes),
        trajectory_kw=trajectory,
        setpoints_kw=system.inverters.p * KW_PER_MW,
        rounds=world.rounds,
        rest_round=world.rest_round,
        messages=world.messages,
        scalars_sent=world.scalars_sent,
        lost=world.lost,
        duplicated=world.duplicated,
        max_imbalance_w=system.max_imbalance_mw * W_PER_MW,
        max_transient_w=system.max_transient_mw * W_PER_MW,
        final_imbalance_w=system.physical_imbalance_mw() * W_PER_MW,
        open_transactions=sum(
            len(g.open_offers) + len(g.undelivered) + len(g.reserved) for g in system.parties
        ),
        residual_kw=residual * KW_PER_MW,
        wall_seconds=world.wall_seconds,
        agents=len(system.agents),
        step_s=system.step_s,
        phase_ticks=system.plant.phase_ticks,
        prices=controller_prices(system),
        events=sorted(_events(system), key=lambda e: e["round"]),
        source_kw=system.source.position_mw * KW_PER_MW,
        horizon_reason=world.horizon_reason,
        infeasible=world.infeasible,
    )


def runaway(system: AgentSystem, controllers: list[ControllerAgent]) -> str | None:
    """Why the line prices ran away, if one of ``controllers``' prices passed the mode's cap
    (:meth:`popdispatch.modes.mechanism.Mode.price_cap`: no dispatch relieves the line, as in
    the engine's stopping rule), else None."""
    for controller in controllers:
        for end in controller.ends:
            price = max(end.z_up, end.z_down)
            if price > system.price_cap:
                line = system.line_names[end.line]
                return (f"the line prices ran away: {line}'s price {price:.4g} EUR/MWh passed "
                        f"{system.price_cap:.4g} EUR/MWh, which no dispatch within the limits "
                        "needs (the line limits cannot be met)")
    return None



def _events(system: AgentSystem) -> list[dict]:
    """The run's fault events and what the agents noticed."""
    noticed = [e for a in [*system.generators, *system.controllers.values()] for e in a.events]
    return [*system.events, *noticed]


