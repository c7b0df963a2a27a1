"""The dispatch as a system of agents in mango's simulated world, and its result.

:func:`run_agents` builds one agent per generator, one per node controller and the plant
(:func:`build_agents`), registers them in a mango :class:`~mango.SimulationWorld` whose
communication simulation is the seeded :class:`~popdispatch.agents.network.LossyNetwork`,
places the generators on the communication graph as a mango topology, and steps the clock
round by round until the set points come to rest (or ``max_rounds``). Then no new offers are
made and the clock runs on until every transaction is decided and acknowledged (the drain),
and the run is compared with nothing: callers compare it with the DC-OPF or the engine.
"""

from __future__ import annotations

import asyncio
import time
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
from popdispatch.constants import KW_PER_MW
from popdispatch.dynamics import communication_graph, get_dynamics
from popdispatch.errors import OptionError
from popdispatch.game.controllers import NodeControllers
from popdispatch.game.parameters import MinuteInputs, PriceLaw
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import STABLE_STEP
from popdispatch.integrate.stopping import windows_agree
from popdispatch.modes import get_mode
from popdispatch.modes.exact import price_weights, scales
from popdispatch.online.settings import RunSettings, initial_shares
from popdispatch.warm_start import SHARES, warm_start

#: Watts per MW.
W_PER_MW = 1.0e6
#: Paper mode's rest tolerance, kW (it claims a rest point of its dynamics, no accuracy).
PAPER_TOL_KW = 1e-3


@dataclass(frozen=True)
class AgentSettings:
    """How the agents run, beyond the dynamics' :class:`~popdispatch.online.RunSettings`.

    Attributes
    ----------
    step_s : the round's Euler step ``h``, s (None: :func:`default_step`).
    max_rounds : horizon, rounds.
    window : rounds over which the set points must move less than ``tol_kw`` to be at rest
        (and every controller's residual, modes/exact.py, be within ``tol_kw``: a price may
        still be decaying on a slack line while the set points wait at their limits).
    tol_kw : rest tolerance, kW (None: :meth:`tol_for`, the engine's).
    drain_rounds : most rounds after rest to decide and acknowledge every transaction.
    timeout : rounds an offer stays open (None: ``2 * delay_max + 1`` of the faults, so that
        an offer and its acceptance can both arrive as late as the network delays them).
    lag : rounds from a commit to the change of both inverters (see :meth:`lag_for`).
    paced : rounds paced to the network's latency (default): each phase lasts one tick more
        than the longest simulated delay, so agents act on this round's messages only (a
        synchronizer); a round then takes ``1 + 6 * delay_max`` times the simulated time of
        an unpaced one, and delays cost time, not staleness. Unpaced, agents act on the
        latest messages they have, however old (docs/agents.md: exact mode does not settle).
    decision_copies : copies of each commit or abort sent per round (see :meth:`copies_for`).
    engine_limiter : receivers scale offers by the engine's limiter factor (None: no, they
        accept ``room / offered``; see :mod:`popdispatch.agents.generator`). With it the
        agents follow the engine's Euler trajectory exactly; without it a receiver scales
        by the room it has left now over every offer that arrived (late or repeated ones).
    """

    step_s: float | None = None
    max_rounds: int = 4000
    window: int = 10
    tol_kw: float | None = None
    drain_rounds: int = 200
    timeout: int | None = None
    lag: int | None = None
    paced: bool = True
    decision_copies: int | None = None
    engine_limiter: bool | None = None
    stale_rounds: int = 10

    def tol_for(self, problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
        """The rest tolerance in force, kW: the given one, else the engine's in a mode that
        claims the DC-OPF (``settings.stepping``: a tenth of the accuracy's floor or its
        relative part, ``max(accuracy_rel P_d, accuracy_kw / 10)``, so that the rest is what
        the distance certificate then proves), else :data:`PAPER_TOL_KW`."""
        if self.tol_kw is not None:
            return float(self.tol_kw)
        if not get_mode(settings.mode).claims_dc_opf:
            return PAPER_TOL_KW
        return settings.stepping.tol_mw(float(problem.demand[minute - 1])) * KW_PER_MW

    def stale_for(self, faults: Faults) -> int:
        """Rounds of silence after which a price or a neighbour's status counts as stale
        (``stale_rounds``, plus ``delay_max`` in unpaced rounds, where messages may be that
        late): at 30 % loss ten rounds in a row are lost with probability 6e-6."""
        return self.stale_rounds + (0 if self.paced else int(faults.delay_max))

    def engine_limiter_for(self, faults: Faults) -> bool:
        """Whether receivers use the engine's limiter factor (None: no; set it to follow the
        engine's Euler trajectory exactly, tests/agents/test_equality.py)."""
        return bool(self.engine_limiter)

    def lag_for(self, faults: Faults) -> int:
        """Rounds from a commit to the inverters' change (None: 0; a lag holds the inverters
        behind the planned set points the revision rule works with, and on the congestion
        minute with delays it stalled the run 3.4 kW from the DC-OPF, docs/agents.md)."""
        return self.lag if self.lag is not None else 0

    def copies_for(self, faults: Faults) -> int:
        """Copies of each decision per round (None: 1 on a lossless network, else 3: a lost
        decision leaves a transaction half done and the source bus, then the lines, carry
        the difference, which the exact mode's line prices amplify)."""
        if self.decision_copies is not None:
            return self.decision_copies
        return 3 if faults.loss else 1

    def timeout_for(self, faults: Faults) -> int:
        """Rounds an offer stays open (see the attribute; 1 in paced rounds)."""
        if self.timeout is not None:
            return self.timeout
        return 1 if self.paced else 2 * int(faults.delay_max) + 1

    def phase_ticks_for(self, faults: Faults) -> int:
        """Ticks per phase: 1, or in paced rounds one more than the longest simulated delay
        (``delay_max`` unpaced rounds), so that every message of a phase is in before the
        next phase acts."""
        return 1 + TICKS_PER_ROUND * int(faults.delay_max) if self.paced else 1

    def rest_window(self, faults: Faults) -> int:
        """Rounds of rest required: ``window`` times ``1 + delay_max`` (a late network can
        hold every transaction up for ``delay_max`` rounds; ``window`` in paced rounds)."""
        return self.window * (1 if self.paced else 1 + int(faults.delay_max))

    def step_for(self, problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
        """The Euler step in force, s: the given one, else :func:`default_step`."""
        if self.step_s is not None:
            return self.step_s
        return default_step(problem, settings, minute)


def stiffness_rate(problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
    """An estimate of the fastest rate of exact mode's dynamics at ``minute``, 1/s
    (docs/agents.md, "The round step").

    Curvature-scaled field (dynamics/newton.py), the largest of

    - ``kappa D g max_i r_i (2 c_i + C_i)``: a generator's own relaxation rate (``kappa`` the
      revision gain per EUR/MW, ``D`` the minute's demand, MW, ``r_i`` its revision rate,
      ``C_i`` the price weight of the nearest limited line above it,
      :func:`popdispatch.modes.exact.price_weights`, 0 below none), at least ``kappa D g S /
      P``, the rate at which every interior marginal cost relaxes; ``g`` the most receivers a
      sender's weights can sum over: 1 on the complete graph (``sum_i r_i / R = 1``), the
      largest degree plus one on a sparse graph (each neighbour's weight ``r_i / R_i`` is at
      most 1, and a sender relays to one best receiver per group it belongs to);
    - ``2 STABLE_STEP alpha / C`` where a line is limited: a line's price and the set points
      below it, in their proportional and integral regime, move as ``s^2 + a s + b = 0``
      with ``b / a = alpha / C`` whatever the generators; Euler's factor ``1 + h s`` of a
      complex pair has ``|1 + h s|^2 = 1 - h a + h^2 b``, below 1 for ``h < C / alpha`` and
      smallest at ``h = C / (2 alpha)``, the step this gives.

    Capacity-constrained Smith (``ExactConstants(revision="capacity")``): ``kappa max(S, D
    max_i (2 c_i + C_i))``. Dimensionless constants, so the same on a feeder scaled by 100.
    Counts one priced line above a generator: limits nested several deep along one path (the
    synthetic feeders with every line limited) are stiffer than this."""
    fp = settings.game_constants(problem)
    row = np.array([minute - 1])
    weight = np.broadcast_to(price_weights(problem, settings.exact.price_law, fp.C, row),
                             (1, len(problem.limit)))[0]  # fmt: skip
    below = np.zeros(problem.n_generators)
    limited = problem.generator_line >= 0
    below[limited] = weight[problem.generator_line[limited]]
    demand = float(problem.demand[minute - 1])
    spread, reference = scales(problem)
    rates = settings.revision_rates(problem)
    if not len(rates):
        own = float(np.max(demand * (2.0 * problem.c + below)))
        return float(fp.gain) * max(spread, own)
    graph = generator_graph(problem, settings)
    fan = 1 if _complete(graph) else max(d for _, d in graph.degree) + 1
    own = float(np.max(rates * (2.0 * problem.c + below)))
    field = float(fp.gain) * demand * fan * max(own, spread / reference)
    price = 2.0 * STABLE_STEP * float(fp.price_rate) / float(fp.C) if len(problem.limit) else 0.0
    return max(field, price)


def default_step(problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
    """The default round step, s: in exact mode ``STABLE_STEP / rate``
    (:data:`popdispatch.integrate.STABLE_STEP`, the largest ``h * rate`` the engine's Heun
    steps take; ``rate``: :func:`stiffness_rate`); in paper mode the engine's own Euler
    substep (the mode's integrator: ``dt / substeps``)."""
    if not get_mode(settings.mode).bounded:
        stepping = settings.stepping
        return stepping.dt / stepping.substeps
    return STABLE_STEP / stiffness_rate(problem, settings, minute)


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


@dataclass(frozen=True)
class AgentRun:
    """A run of the agents. Powers in kW, imbalances in W.

    ``trajectory_kw``: set points at the start of every round (rows), as the plant saw them;
    ``setpoints_kw``: after the drain; ``rest_round``: the round the set points came to rest
    (None if never); ``messages``: every message sent (lost ones and duplicate copies
    included); ``scalars_sent``: the real numbers those messages carried
    (:func:`popdispatch.agents.messages.scalars`); ``lost``: of them lost; ``duplicated``:
    messages the network delivered twice; ``max_imbalance_w``: largest |supply - demand| of the
    committed state at any round; ``max_transient_w``: largest |supply - demand| of the
    inverters as they were at a measurement (taken up by the source bus while a commit is in
    flight); ``final_imbalance_w``: of the inverters after the drain; ``open_transactions``:
    undecided or unacknowledged transactions left after the drain; ``prices``: exact mode,
    each controller's ``(line, z_up, z_down)`` EUR/MW; ``step_s``: the round's Euler step;
    ``phase_ticks``: ticks per phase (paced rounds); ``events``: the faults and what the
    agents noticed (trips, crashes and restarts, stale prices, controllers taken over), each
    ``{"round", "event", "agent", ...}``; ``source_kw``: the source bus's committed position
    left after the drain (power a trip moved to it that the generators could not take
    back); ``stall_reason``: why a run at rest is
    not at the DC-OPF (exact mode's KKT check, :func:`popdispatch.online.kkt_violations`, on
    the set points and the controllers' prices), None otherwise; ``horizon_reason``: why a run
    never came to rest (:func:`horizon_reason`, :func:`runaway`), None otherwise;
    ``infeasible``: the line prices ran away (:func:`runaway`).
    """

    generators: list[str]
    trajectory_kw: np.ndarray
    setpoints_kw: np.ndarray
    rounds: int
    rest_round: int | None
    messages: int
    lost: int
    duplicated: int
    max_imbalance_w: float
    max_transient_w: float
    final_imbalance_w: float
    open_transactions: int
    residual_kw: float
    wall_seconds: float
    agents: int
    step_s: float
    phase_ticks: int = 1
    prices: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    source_kw: float = 0.0
    scalars_sent: int = 0

    stall_reason: str | None = None
    horizon_reason: str | None = None
    infeasible: bool = False
    certified: bool = False
    distance_bound_kw: float | None = None
    accuracy_kw: float | None = None

    @property
    def status(self) -> str:
        """As the engine's snapshot: ``converged`` (in exact mode the distance certificate
        proves every set point within ``accuracy_kw`` of the DC-OPF; in paper mode, at rest),
        ``stalled`` (at rest without that proof: ``stall_reason``), ``infeasible`` (the line
        prices ran away: ``horizon_reason``) or ``not_converged`` (never at rest and not
        proved: ``horizon_reason``)."""
        if self.infeasible:
            return "infeasible"
        if self.certified:
            return "converged"
        return "not_converged" if self.rest_round is None else "stalled"

    @property
    def reason(self) -> str | None:
        """Why the run is not ``converged`` (None if it is)."""
        if self.status == "converged":
            return None
        return self.horizon_reason if self.rest_round is None else self.stall_reason

    def line_states(self, n_lines: int) -> np.ndarray:
        """Exact mode's line prices at the end, EUR/MW: ``z_up`` of every limited line, then
        ``z_down``, each the mean of its live end controllers' copies (0 in paper mode)."""
        return line_states(self.prices, n_lines)

    @property
    def messages_per_agent_round(self) -> float:
        return self.messages / max(self.agents * max(self.rounds, 1), 1)


def line_states(prices: dict, n_lines: int) -> np.ndarray:
    """``z_up`` of every limited line, then ``z_down`` (EUR/MW), each the mean of the copies
    in ``prices`` (per controller, ``(line, z_up, z_down)`` of each line it ends)."""
    z, ends = np.zeros(2 * n_lines), np.zeros(n_lines)
    for copies in prices.values():
        for line, z_up, z_down in copies:
            z[line] += z_up
            z[n_lines + line] += z_down
            ends[line] += 1
    return z / np.concatenate([ends, ends]).clip(min=1)


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
    dynamics = get_dynamics(settings.dynamics)
    kind = settings.graph if dynamics.uses_graph else "complete"
    adjacency = communication_graph(kind, names)
    return nx.relabel_nodes(nx.from_numpy_array(adjacency), dict(enumerate(names)))


def build_agents(problem: DispatchProblem, minute: int, settings: RunSettings,
                 step_s: float, faults: Faults, timeout: int = 1, lag: int = 0,
                 copies: int = 1, engine_limiter: bool = True,
                 stale_rounds: int = 10) -> AgentSystem:  # fmt: skip
    """The agents of one minute (not yet registered anywhere); ``timeout``: rounds an offer
    stays open; ``lag``: rounds from a commit to the inverters' change."""
    if not problem.online[minute - 1].all():
        off = ", ".join(problem.generators[~problem.online[minute - 1]])
        raise OptionError(f"the agents run with every generator online (offline: {off})")
    check_settings(settings)
    mode = get_mode(settings.mode)
    field_code = settings.field
    rates = settings.revision_rates(problem)
    fp = game_constants(problem, settings)
    demand = float(problem.demand[minute - 1])
    network = LossyNetwork(faults)
    inverters = Inverters(initial_setpoints(problem, settings, minute))
    graph = generator_graph(problem, settings)
    names = list(problem.generators)
    generators = []
    for i, name in enumerate(names):
        rule = GeneratorRule(
            float(problem.b[i]), float(problem.c[i]), float(problem.pmin[i]),
            float(problem.pmax[i]), float(fp.B), float(fp.m),
            float(fp.gain) if mode.bounded else 1.0, not mode.bounded, int(field_code),
            demand, step_s, float(rates[i]) if len(rates) else 0.0,
        )  # fmt: skip
        neighbours = [n for n in names if graph.has_edge(name, n)]
        generators.append(
            GeneratorAgent(
                rule, i, inverters, neighbours, timeout, lag, copies, engine_limiter, network
            )  # fmt: skip
        )
    relay = not _complete(graph)
    for gen in generators:
        gen.relay = relay
        gen.stale_rounds = stale_rounds
    controllers, line_ends = _controllers(problem, settings, fp, step_s, network)
    for controller in controllers.values():  # the generators report a silence first
        controller.stale_rounds = 2 * stale_rounds
    plant = PlantAgent(problem, minute, inverters, line_ends, faults.noise_kw, faults.seed,
                       network)  # fmt: skip
    source = SourceAgent(names, timeout, copies, network)
    _check_ids(names, controllers)
    _check_events(faults.events, names, controllers)
    cap = mode.price_cap(problem) if mode.bounded else np.inf
    return AgentSystem(plant, controllers, generators, inverters, network, graph, demand,
                       source, price_cap=cap, line_names=_line_names(problem))  # fmt: skip


def _line_names(problem: DispatchProblem) -> list[str]:
    """``line A-B`` of every limited line (its end buses as the feeder names them)."""
    lines = problem.feeder.lines.iloc[np.asarray(problem.lines, dtype=int)]
    return [f"line {bus_name(a)}-{bus_name(b)}"
            for a, b in zip(lines.from_bus, lines.to_bus, strict=True)]  # fmt: skip


def check_settings(settings: RunSettings) -> None:
    """Refuse run settings the agents cannot honour: a mode other than paper and exact (their
    node controllers price limited lines only), a price law other than plain (they hear only
    their own lines; the tree law needs its neighbours' excesses, the scaled law the count of
    tradable generators below each line)."""
    if get_mode(settings.mode).code not in PAYOFFS:
        raise OptionError(f"the agents run paper and exact mode, not {settings.mode}", "--mode")
    if settings.exact.price_law != PriceLaw.PLAIN:
        raise OptionError(
            "the agents' node controllers run the plain price law (each hears only its own "
            "lines; the tree law needs its neighbours' excesses, the scaled law the count of "
            "tradable generators below each line)",
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


def _check_events(events, generators: list[str], controllers: dict) -> None:
    """Every fault names an agent of its kind (one-line error naming it)."""
    for event in events:
        known = list(controllers) if event.kind == "controller-crash" else generators
        if event.agent not in known:
            what = "node controller" if event.kind == "controller-crash" else "generator"
            raise OptionError(f"{event.kind}: no {what} {event.agent!r} (known: "
                              f"{', '.join(map(str, known))})", "--" + event.kind)  # fmt: skip


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


def _controllers(problem, settings: RunSettings, fp, step_s: float, network):
    """``({id: controller}, line_ends)`` from the problem's controller table; each line priced
    by the mode's own payoff map (:class:`~popdispatch.agents.controller.LinePrice`) with the
    problem's limit of the line."""
    table = NodeControllers.from_problem(problem).table
    position = {line: k for k, line in enumerate(problem.lines)}
    payoff = PAYOFFS[get_mode(settings.mode).code]
    n_states = 2 if get_mode(settings.mode).bounded else 0
    ends: dict[str, list[LineEnd]] = {}
    line_ends: list[list[str]] = [[] for _ in problem.lines]
    for row in table.itertuples():
        aid = controller_id(row.bus)
        k = position[row.line]
        price = LinePrice(payoff, float(problem.limit[k]), float(fp.C), float(fp.price_rate),
                          n_states)  # fmt: skip
        ends.setdefault(aid, []).append(
            LineEnd(k, int(row.orientation), price, list(row.receivers))
        )
        line_ends[k].append(aid)
    for aid, own in ends.items():  # each end knows its partner and the other side
        for end in own:
            partner = next(a for a in line_ends[end.line] if a != aid)
            end.partner = partner
            end.other_receivers = next(e.receivers for e in ends[partner] if e.line == end.line)
    controllers = {aid: ControllerAgent(own, step_s, network) for aid, own in ends.items()}
    return controllers, [tuple(e) for e in line_ends]


def run_agents(
    problem: DispatchProblem,
    minute: int,
    settings: RunSettings | None = None,
    faults: Faults | None = None,
    agent_settings: AgentSettings | None = None,
    on_round=None,
) -> AgentRun:
    """One minute of dispatch by the agents in mango's simulated world (module docstring).

    ``on_round(system, rnd)``: called after every round's measurement (fault injection,
    probes); it may crash, restart or trip agents of ``system``.
    """
    settings = settings or RunSettings()
    faults = faults or Faults()
    agent_settings = agent_settings or AgentSettings()
    agent_settings = replace(agent_settings,
                             tol_kw=agent_settings.tol_for(problem, settings, minute))
    step_s = agent_settings.step_for(problem, settings, minute)
    tripped = [e.agent for e in faults.events if e.kind == "trip"]
    engine = _auditor(without(problem, minute, tripped), settings, agent_settings, step_s)
    run = _run(problem, minute, settings, faults, agent_settings, step_s, on_round, engine)
    return _judged(run, engine, minute, tripped, agent_settings.tol_kw)


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


def proved_distance_mw(engine, minute: int):
    """``prove(system)``: the distance bound (MW) the certificate gives the agents' state now
    (the inverters' set points and the live controllers' prices), with ``engine`` (see
    :func:`_auditor`)."""

    def prove(system: AgentSystem) -> float:
        p_mw = system.inverters.p[None]
        z = line_states(controller_prices(system), len(engine.problem.limit))[None]
        return engine.certificates(np.array([minute]), p_mw, z)[0].distance_mw

    return prove


def without(problem: DispatchProblem, minute: int, names: list[str]) -> DispatchProblem:
    """``problem`` with the generators ``names`` offline in ``minute`` (tripped: the DC-OPF a
    run with trips must reach)."""
    if not names:
        return problem
    online = problem.online.copy()
    online[minute - 1, problem.generators.get_indexer(names)] = False
    return replace(problem, online=online)


def _run(problem, minute, settings, faults, agent_settings, step_s, on_round,
         engine=None) -> AgentRun:  # fmt: skip
    """Build the agents and run them in mango's simulated world; with an auditing ``engine``
    (:func:`_auditor`) in a mode that claims the DC-OPF, a rest the certificate does not
    prove within the accuracy runs on (see :func:`_simulate`)."""
    system = build_agents(problem, minute, settings, step_s, faults,
                          agent_settings.timeout_for(faults), agent_settings.lag_for(faults),
                          agent_settings.copies_for(faults),
                          agent_settings.engine_limiter_for(faults),
                          agent_settings.stale_for(faults))  # fmt: skip
    ticks = agent_settings.phase_ticks_for(faults)
    if system.generators[0].relay:
        ticks = max(ticks, relay_phase_ticks(len(system.generators), faults.delay_max))
    for agent in system.agents:
        agent.phase_ticks = ticks
    if engine is not None and engine.mode.claims_dc_opf:
        system.prove = proved_distance_mw(engine, minute)
        system.accuracy_mw = float(settings.accuracy_mw(problem.demand[minute - 1]))
    system.extrapolate = bool(settings.stepping.extrapolate)
    window = agent_settings.rest_window(faults)
    return asyncio.run(_simulate(system, agent_settings, window, on_round))


async def _simulate(system: AgentSystem, opts: AgentSettings, window: int, on_round) -> AgentRun:
    """Step the world round by round until the set points come to rest (or the horizon),
    then drain. With ``system.prove``, a rest whose proved distance bound is above the
    accuracy runs on for another window as long as each rest proves at least half the bound
    of the one before (the engine's rule, :func:`popdispatch.online.run_snapshot`): the rest
    window can stop a run whose last watts still move."""
    from mango import AgentAddress, create_world, graph_topology, per_node

    world = create_world(communication_sim=system.network, record_messages=False)
    world.register(system.plant, suggested_aid="plant")
    for aid, agent in system.controllers.items():
        world.register(agent, suggested_aid=aid)
    for gen, name in zip(system.generators, system.graph.nodes, strict=True):
        world.register(gen, suggested_aid=name)
    world.register(system.source, suggested_aid=SOURCE_ID)
    topology = graph_topology(system.graph.copy())
    for name, node in zip(system.graph.nodes, per_node(topology), strict=True):
        node.add(world.agents[name])
    addresses = {aid: AgentAddress(world.addr, aid) for aid in world.agents}
    for agent in system.agents:
        agent.addresses = addresses
    start = time.perf_counter()
    rest_round = unrest = None
    infeasible = False
    max_imbalance = max_transient = 0.0
    last_event = max((_last_round(e) for e in system.network.faults.events), default=-1)
    check_after = last_event + window  # no rest declared before the last fault
    last_bound = np.inf
    async with world:
        rnd, quiet = 0, False
        while True:
            max_imbalance = max(max_imbalance, abs(system.committed_imbalance_mw()))
            max_transient = max(max_transient, abs(system.physical_imbalance_mw()))
            for event in system.network.faults.events:
                system.apply(event, rnd)
            max_imbalance = max(max_imbalance, abs(system.committed_imbalance_mw()))
            if on_round is not None:
                on_round(system, rnd)
            if not quiet:
                rest_round, unrest, infeasible = _verdict(system, rnd, opts, window,
                                                          rnd > check_after)  # fmt: skip
                if rest_round is not None and system.prove is not None and rnd < opts.max_rounds:
                    bound = system.prove(system)
                    if bound > system.accuracy_mw and bound < 0.5 * last_bound:
                        rest_round, last_bound, check_after = None, bound, rnd + window
                quiet = rest_round is not None or unrest is not None
                for gen in system.parties if quiet else ():
                    gen.quiet = True  # the drain: no new offers, open transactions decided
            busy = any(g.busy for g in system.parties if not g.crashed)
            if (quiet and not busy) or rnd >= opts.max_rounds + opts.drain_rounds:
                break
            await world.step_until(system.plant.round_ticks)
            _raise_agent_errors(system)
            rnd += 1
    wall = time.perf_counter() - start
    prices = controller_prices(system)
    residual = max((c.residual_mw() for c in system.controllers.values()), default=0.0)
    trajectory = np.array(system.plant.history) * KW_PER_MW
    return AgentRun(
        generators=list(system.graph.nodes),
        trajectory_kw=trajectory,
        setpoints_kw=system.inverters.p * KW_PER_MW,
        rounds=len(trajectory) - 1,
        rest_round=rest_round,
        messages=system.network.sent,
        scalars_sent=system.network.scalars,
        lost=system.network.lost,
        duplicated=system.network.duplicated,
        max_imbalance_w=max_imbalance * W_PER_MW,
        max_transient_w=max_transient * W_PER_MW,
        final_imbalance_w=system.physical_imbalance_mw() * W_PER_MW,
        open_transactions=sum(
            len(g.open_offers) + len(g.undelivered) + len(g.reserved) for g in system.parties
        ),
        residual_kw=residual * KW_PER_MW,
        wall_seconds=wall,
        agents=len(system.agents),
        step_s=system.generators[0].rule.step_s,
        phase_ticks=system.plant.phase_ticks,
        prices=prices,
        events=sorted(_events(system), key=lambda e: e["round"]),
        source_kw=system.source.position_mw * KW_PER_MW,
        horizon_reason=unrest,
        infeasible=infeasible,
    )


def _verdict(system: AgentSystem, rnd: int, opts: AgentSettings, window: int,
             due: bool) -> tuple[int | None, str | None, bool]:  # fmt: skip
    """``(rest round, reason, infeasible)`` of a run at round ``rnd``: at rest (the set points
    still over ``window`` rounds and every live controller's residual within ``tol_kw``, once
    ``due``: after the last fault), or why it stops without: a line price past the cap
    (:func:`runaway`; infeasible), the horizon (:func:`horizon_reason`); all None and False
    while it runs on."""
    tol = opts.tol_kw / KW_PER_MW
    live = [c for c in system.controllers.values() if not c.crashed]
    residual = max((c.residual_mw() for c in live), default=0.0)
    if due and residual <= tol and _at_rest(system.plant.history, window, tol,
                                            system.extrapolate):
        return len(system.plant.history) - 1, None, False
    ran_away = runaway(system, live)
    if ran_away is not None:
        return None, ran_away, True
    if rnd >= opts.max_rounds:
        step = system.generators[0].rule.step_s
        return None, horizon_reason(system.plant.history, window, tol, step, residual), False
    return None, None, False


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


def _last_round(event: FaultEvent) -> int:
    """The round a fault event last changes something (its start or its restart)."""
    return event.round + (event.rounds or 0)


def _events(system: AgentSystem) -> list[dict]:
    """The run's fault events and what the agents noticed."""
    noticed = [e for a in [*system.generators, *system.controllers.values()] for e in a.events]
    return [*system.events, *noticed]


def _raise_agent_errors(system: AgentSystem) -> None:
    """Re-raise the first error an agent's tick met (mango would only log it)."""
    for agent in system.agents:
        if agent.error is not None:
            raise RuntimeError(f"agent {agent.aid} failed: {agent.error!r}") from agent.error


def horizon_reason(history: list[np.ndarray], window: int, tol_mw: float, step_s: float,
                   residual_mw: float = 0.0) -> str:  # fmt: skip
    """Why set points ``history`` (MW per round) with the controllers' largest residual
    ``residual_mw`` (MW) are not at rest. Over the last :data:`CYCLE_ROUNDS` rounds (or
    ``window``, if longer) their path is at least :data:`CYCLE_PATH` times the range they
    stay in (an oscillation: the round step ``step_s`` is past the stability limit of the
    Euler rule on this problem), or they still move, or a line is still away from
    complementary slackness (more rounds needed)."""
    rounds = len(history) - 1
    recent = np.array(history[-max(window, CYCLE_ROUNDS) - 1 :]) * KW_PER_MW
    path = float(np.abs(np.diff(recent, axis=0)).max(axis=1).sum()) if len(recent) else 0.0
    spread = float(np.ptp(recent, axis=0).max()) if len(recent) else 0.0
    tol_kw = tol_mw * KW_PER_MW
    if spread > tol_kw and path >= CYCLE_PATH * spread:
        return (f"not at rest after {rounds} rounds: the set points oscillate (a path of "
                f"{path:.4g} kW over the last {len(recent) - 1} rounds within a range of "
                f"{spread:.4g} kW); the round step {step_s:.4g} s is past the stability limit "
                "of the Euler rule on this problem (give a smaller step)")
    recent = recent[-window - 1 :]
    moved = float(np.abs(recent - recent[-1]).max()) if len(recent) else 0.0
    return (f"not at rest after {rounds} rounds (at rest: within {tol_kw:g} kW): the set "
            f"points still moved {moved:.4g} kW over the last {len(recent) - 1} rounds and a "
            f"line is {residual_mw * KW_PER_MW:.4g} kW from complementary slackness (give "
            "more rounds)")


#: Rounds over which :func:`horizon_reason` looks for an oscillation.
CYCLE_ROUNDS = 30
#: Path over range of the set points (:func:`horizon_reason`) from which they oscillate:
#: about 1 when they move one way; 27 on the synthetic 1k feeder's complete graph at the
#: default step (6 kW a round within 6.7 kW), 9 when case69 flips between 0 and 300 kW
#: every three rounds (a step 13 times its default).
CYCLE_PATH = 3.0


def _at_rest(history: list[np.ndarray], window: int, tol_mw: float, extrapolate: bool) -> bool:
    """The engine's stopping rule on the rounds (:func:`popdispatch.integrate.stopping.
    windows_agree`): the mean set points of the last ``window`` rounds differ from those of
    the ``window`` before by at most ``tol_mw``, and with ``extrapolate`` (exact mode) so
    does the geometric tail still to go."""
    need = (3 if extrapolate else 2) * window
    if len(history) < need:
        return False
    ring = np.ascontiguousarray(history[-need:], dtype=float)
    return bool(windows_agree(ring, need - 1, window, tol_mw, extrapolate))
