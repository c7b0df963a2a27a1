"""A distributed generator as an agent: its own cost, limits and set point, the revision rule.

Each round (:mod:`popdispatch.agents.schedule`) the generator

0. (tick 0, a sparse graph under the curvature-scaled field only) sends its revision rate,
   room and movable mass to its neighbours (:class:`~popdispatch.agents.messages.Standing`);
1. (tick 2) computes its fitness from its own set point and the latest signal of every
   limited line (the engine's kernel :func:`popdispatch.game.fitness.fitness_into`, eqs.
   5-7) and its weights (:attr:`popdispatch.dynamics.law.FlowLaw.reference`: receiver
   weight ``w``, sender weight ``v``, room, movable mass), and sends them with ``f`` to its
   neighbours in the communication graph. Under the curvature-scaled field (exact mode,
   dynamics/newton.py) ``v`` is its revision rate ``r`` (from its own cost curve) where it
   has mass to move and ``w`` is ``r / R`` where it has room, ``R`` the rates of the
   generators inside their limits (``r`` at most ``R`` at a limit): on a sparse graph those
   of its closed neighbourhood,
   which it normalises itself from the standings of tick 0
   (:func:`~popdispatch.dynamics.newton.neighbourhood_weights`); on the complete graph
   those of the whole fleet, which every listener normalises from the statuses it holds;
2. (tick 3) from the latest statuses of its neighbours, sums its pairwise in- and outflow
   (:func:`popdispatch.dynamics.pairwise.graph_flows` on its own star of edges, eqs. 13-14)
   and applies the steppers' flux limiter to its own side: a sender whose outflow over the
   step ``h`` would exceed its movable mass scales its ``v`` so that it exactly empties
   (integrate/steppers.py). It offers each better neighbour
   ``h * D * w_i * v_j^lim * (f_i - f_j)`` MW;
3. (tick 4) accepts the offers that arrived, all scaled by one factor and never past the
   room it has left (counting what it has reserved), reserving the amounts. The factor is
   the steppers' receiver limiter ``room / (h * inflow)`` with the inflow of the limited
   senders, which is what their offers of the round carry (``engine_limiter``, the default
   on a perfect network, where the agents then follow the engine exactly: room at the
   round's status, offers of this round), or ``room / offered`` with the room left now and
   every offer that arrived (lost, late or repeated messages). A receiver filled to its
   room lands on ``Pmax`` exactly, as the engine's shares do (:meth:`GeneratorAgent._set`);
4. (tick 5) commits the offers accepted in time (lowering its own set point by the amount:
   the transaction's decision point) and aborts the others, then sends every decision not
   yet acknowledged (again each round until the receiver acknowledges).

A receiver applies a commit once (by transaction id) and acknowledges every copy; an abort
frees the reservation. Power thus only moves in pairwise transactions: once every decision
has reached its receiver, the set points sum to what they summed to before. With no loss
and no delay every round's transactions are decided within the round and the set points
follow the engine's limited Euler step exactly (``x_out = x + h (inflow - outflow)`` with the
limited weights).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from popdispatch.agents.base import RoundAgent
from popdispatch.agents.messages import (
    Accept,
    Ack,
    Decision,
    Offer,
    Output,
    Relayed,
    Signals,
    Standing,
    Status,
)
from popdispatch.agents.plant import Inverters
from popdispatch.agents.schedule import Phase
from popdispatch.dynamics.fields import Field, field_tag, law_of
from popdispatch.dynamics.newton import neighbourhood_weights
from popdispatch.dynamics.pairwise import graph_flows, receives_relayed, relays_at_limit
from popdispatch.game.fitness import fitness_into
from popdispatch.game.parameters import share_bounds

#: Units in the last place of ``Pmax`` within which a set point counts as at ``Pmax``
#: (:meth:`GeneratorAgent._set`): the rounding of a few accepted amounts added in MW (1 ulp
#: measured); a generator approaching ``Pmax`` smoothly is 1e-9 MW or more away from it.
LIMIT_ULPS = 16


def relays(w: float, mass: float, room: float) -> bool:
    """A generator with receiver weight ``w``, movable ``mass`` and ``room`` (shares) cannot
    take part in a comparison both ways and relays (the engine's rule,
    :func:`popdispatch.dynamics.pairwise.relays_at_limit`)."""
    return bool(relays_at_limit(float(w), float(mass), float(room)))


def receives(status: Status) -> bool:
    """Whether the generator of ``status`` can receive relayed flows (the engine's
    :func:`~popdispatch.dynamics.pairwise.receives_relayed`)."""
    return bool(receives_relayed(float(status.w), float(status.room)))


def _theta(status: Status) -> float:
    """A neighbour's step factor from its status (1 where it sends none)."""
    return 1.0 if status.theta is None else float(status.theta)


def star(n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR adjacency (``indptr``, ``indices``) of the star of node 0 and ``n - 1`` leaves: one
    generator's own edges."""
    indptr = np.array([0, n - 1, *range(n, 2 * n - 1)], dtype=np.int64)
    indices = np.array([*range(1, n), *([0] * (n - 1))], dtype=np.int64)
    return indptr, indices


def complete(n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR adjacency (``indptr``, ``indices``) of the complete graph on ``n`` nodes."""
    indptr = np.arange(n + 1, dtype=np.int64) * (n - 1)
    indices = np.array([j for i in range(n) for j in range(n) if j != i], dtype=np.int64)
    return indptr, indices


class Own(NamedTuple):
    """A generator's status inputs at the round's status tick: fitness ``f`` (EUR/MW),
    receiver weight ``w``, sender weight ``v``, ``room`` below ``Pmax`` and movable ``mass``
    above ``Pmin`` (shares; :attr:`popdispatch.dynamics.law.FlowLaw.reference`)."""

    f: float
    w: float
    v: float
    room: float
    mass: float
    theta: float = 1.0


@dataclass(frozen=True)
class GeneratorRule:
    """What one generator knows of the game: its cost ``b`` (EUR/MWh), ``c`` (EUR/(MW^2 h)),
    limits ``pmin``/``pmax`` (MW), the fitness constants ``B``, ``m`` (EUR/MW, EUR/MW^2) and
    revision ``gain``, whether the barrier applies (paper mode), the dynamic's field code
    (:class:`~popdispatch.dynamics.fields.Field`), the demand ``demand_mw`` (MW), the Euler
    step ``step_s`` (s) and its revision ``rate`` (dimensionless, from its own cost curve:
    :func:`popdispatch.dynamics.newton.revision_rates`; read by the curvature-scaled field
    only).

    The local step (``local_step``, curvature-scaled field only; docs/agents.md, "The local
    step"): ``lines_above`` are the limited lines between the generator and the source (those
    whose price falls as its output rises), ``price_slopes`` the fall of each one's half price
    per MW, in the same order (``C_k / 2``, EUR/MW per MW, ``C_k`` the line's proportional
    weight: the game's ``C`` under the plain law on a radial feeder) and ``fan`` the most
    receivers the own sender weight sums over (1 on the complete graph, the own degree plus
    one on a sparse graph); ``priced_memory``: rounds a line above keeps counting in the own
    factor after its price was last non-zero (0: only while it is)."""

    b: float
    c: float
    pmin: float
    pmax: float
    B: float
    m: float
    gain: float
    barrier: bool
    field: int
    demand_mw: float
    step_s: float
    rate: float = 0.0
    lines_above: tuple[int, ...] = ()
    price_slopes: tuple[float, ...] = ()
    fan: int = 1
    local_step: bool = False
    priced_memory: int = 0

    @property
    def scaled(self) -> bool:
        """Whether the field is the curvature-scaled one, whose receiver weights are
        normalised by the rates of a neighbourhood (dynamics/newton.py)."""
        return self.field == Field.CAPACITY_NEWTON

    @property
    def free(self) -> bool:
        """Whether power this generator trades with another free one changes no fitness
        (local step only): its cost is linear (``c = 0``: its fitness does not move with its
        output) and no limited line lies above it (its output moves no price)."""
        return self.local_step and self.c == 0.0 and not self.lines_above

    def step_factor(self, price_slope: float) -> float:
        """The own step factor ``theta = 1 / (1 + h lam)`` (dimensionless, in (0, 1]): ``lam``
        (1/s) is the fastest rate at which this generator's own fitness gap closes,
        ``gain D fan r (2 c + price_slope)`` with ``price_slope`` the sum of ``C_k / 2`` over
        the priced lines above it (EUR/MW per MW: each moves its half price by ``-C_k / 2``
        per MW it adds). An Euler step of ``theta h`` on the own mode ``y' = -lam y``
        multiplies ``y`` by ``1 / (1 + h lam)``, backward Euler's factor: never past the own
        marginal-cost equality, whatever ``h``. 1 without the local step or outside the
        curvature-scaled field."""
        if not (self.local_step and self.scaled):
            return 1.0
        slope = 2.0 * self.c + price_slope  # EUR/MW per MW
        lam = self.gain * self.demand_mw * self.fan * self.rate * slope
        return 1.0 / (1.0 + self.step_s * lam)


class GeneratorAgent(RoundAgent):
    """One DG (see the module docstring). ``index``: its entry in ``inverters``;
    ``neighbours``: agent ids of its neighbours in the communication graph; ``timeout``:
    rounds an offer stays open (accepted up to its last round's tick 4, decided at the
    latest at its last round's tick 5; 1 = within its own round); ``lag``: rounds between a
    commit and the change of both inverters (0: the sender's at once, the receiver's as the
    decision arrives), so that a decision lost or late a few times still lands at both ends
    at the same tick and the source bus never sees the transaction half done; ``copies``:
    copies of each decision sent per round (a decision lost on the way leaves the
    transaction half done, and the source bus takes up the difference, until a copy
    arrives); ``engine_limiter``: the receiver scales the offers by the steppers' own factor
    ``room / (h * inflow)`` (room at the round's status, inflow of the limited senders: this
    round's offers, as the engine does), else by the room left over all offers received
    (see step 3)."""

    ROUND = Phase

    def __init__(self, rule: GeneratorRule, index: int, inverters: Inverters,
                 neighbours: list[str], timeout: int = 1, lag: int = 0, copies: int = 1,
                 engine_limiter: bool = True, network=None):  # fmt: skip
        super().__init__(network)
        self.rule = rule
        self.timeout = int(timeout)
        self.lag = int(lag)
        self.copies = int(copies)
        self.engine_limiter = bool(engine_limiter)
        self.plant_id: str | None = None  # real time: whom to tell the inverter's output
        self.room_share = np.inf  # room below Pmax at the round's status, share of demand
        self.pending_out: dict[str, tuple[float, int]] = {}  # committed: MW, effective round
        self.pending_in: dict[str, tuple[float, int]] = {}  # received: MW, effective round
        self.index = index
        self.inverters = inverters
        self.neighbours = list(neighbours)
        self.quiet = False  # no new offers (drain)
        self.signals: dict[str, tuple[int, float]] = {}
        self.both_lines: dict[str, bool] = {}  # line: both its directions price the flow
        self.priced_lines: dict[int, int] = {}  # line above -> last round it priced this one
        self.statuses: dict[str, Status] = {}
        self.standings: dict[str, Standing] = {}  # sparse graph, curvature-scaled field
        self.own: Own | None = None
        self.offers_in: list[tuple[str, Offer]] = []
        self.open_offers: dict[str, tuple[str, int, float]] = {}  # txid: receiver, round, MW
        self.accepted: dict[str, float] = {}  # txid: MW, as the receiver accepted
        self.undelivered: dict[str, tuple[str, Decision]] = {}  # decided, not acknowledged
        self.committed: dict[str, float] = {}  # every commit this sender decided, MW
        self.reserved: dict[str, float] = {}  # receiver: txid: MW accepted, undecided
        self.answered: set[str] = set()  # receiver: offers accepted or refused
        self.applied: set[str] = set()  # receiver: decisions applied
        self.relay = False  # relay through blocked generators (a graph that is not complete)
        self.slow_relays: frozenset[str] = frozenset()  # who relays by rate (set-up's roster)
        self.status_round = -1  # the round of the own latest status
        self.heard: dict[tuple[str, str], tuple[Status, tuple]] = {}  # (origin, via): route
        self.forwarded: set[str] = set()  # origins whose status this relay passed on
        self.routes: dict[str, tuple] = {}  # relayed txid: hops to the counterparty
        self.relayed_messages = 0  # messages this generator passed on as a relay
        self.stale_rounds = 10  # rounds of silence after which a line or neighbour is stale
        self.unwatched: set[str] = set()  # lines whose price is older than stale_rounds
        self.events: list[dict] = []  # what this generator noticed (stale prices)
        self.tripped = False

    @property
    def p(self) -> float:
        """The set point this generator's inverter holds, MW."""
        return float(self.inverters.p[self.index])

    @property
    def planned(self) -> float:
        """The set point with every commit this generator knows of applied, MW (what its
        revision rule works with)."""
        later = sum(a for a, _ in self.pending_in.values()) - sum(
            a for a, _ in self.pending_out.values()
        )
        return self.p + later if later else self.p

    def _set(self, p_mw: float) -> None:
        """Set the inverter to ``p_mw`` (MW); a set point within :data:`LIMIT_ULPS` units in
        the last place of ``Pmax`` lands on ``Pmax`` (exact mode).

        The receiver's side of the limiter fills a generator to its room exactly, but the
        agent adds the accepted amounts in MW one by one and lands a few ulps off ``Pmax``
        where the engine's shares land on it. Below it, the room (``~3e-17`` of a share) is
        positive and the receiver weight ``1[x < hi]`` (dynamics/capacity.py) is 1, so next
        round every worse neighbour counts it in its outflow and the senders' limiter
        (steppers.py ``euler_steps``: senders first, from the unlimited flows) scales the
        senders down for mass the generator cannot take: measured 4.3e-5 MW off the engine's
        Euler step on the complete graph, 5.9e-4 MW on the ring.
        """
        r = self.rule
        if not r.barrier and abs(p_mw - r.pmax) <= LIMIT_ULPS * np.spacing(r.pmax):
            p_mw = r.pmax
        self.inverters.p[self.index] = p_mw

    # -- messages as they arrive -------------------------------------------------------------

    @property
    def PHASES(self) -> tuple[Phase, ...]:  # noqa: N802  (RoundAgent's name)
        """The ticks this generator acts at: on a sparse graph under the curvature-scaled
        field also the first, to send its :class:`Standing`."""
        if self.normalises_itself:
            return (Phase.MEASURE, Phase.STATUS, Phase.OFFER, Phase.ACCEPT, Phase.COMMIT)
        return (Phase.STATUS, Phase.OFFER, Phase.ACCEPT, Phase.COMMIT)

    @property
    def normalises_itself(self) -> bool:
        """Whether this generator normalises its own weights (a sparse graph under
        the curvature-scaled field: by its closed neighbourhood, from their standings); on
        the complete graph every listener normalises every receiver weight by the rates of
        all (:meth:`_normalised_weights`)."""
        return self.relay and self.rule.scaled

    def receive(self, content, sender) -> None:
        if isinstance(content, Signals):
            for line, value in content.values.items():
                if content.round >= self.signals.get(line, (-1, 0.0))[0]:
                    self.signals[line] = (content.round, value)
                    self.both_lines[line] = line in content.both
        elif isinstance(content, Standing):
            old = self.standings.get(sender)
            if old is None or content.round >= old.round:
                self.standings[sender] = content
        elif isinstance(content, Status):
            old = self.statuses.get(sender)
            if old is None or content.round >= old.round:
                self.statuses[sender] = content
            self._flood(sender, content, ())
        elif isinstance(content, Relayed):
            self._relayed(content, sender)
        elif isinstance(content, Offer):
            if content.txid not in self.answered:
                self.offers_in.append((sender, content))
        elif isinstance(content, Accept):
            if content.txid in self.open_offers:
                self.accepted[content.txid] = content.amount_mw
        elif isinstance(content, Decision):
            self._apply(content, sender)
        elif isinstance(content, Ack):
            self.undelivered.pop(content.txid, None)

    # -- the relay (docs/agents.md "the relay"; dynamics/pairwise.py relay_flows) -----------

    @property
    def blocked(self) -> bool:
        """Whether this generator relays this round: it cannot take part in a comparison (at
        a limit: no room, or no movable mass), or it relays by rate (``slow_relays``)."""
        return self.own is not None and self._relays(self.aid, self.own)

    def _relays(self, aid: str, status) -> bool:
        """Whether generator ``aid`` of ``status`` relays (blocked, or by rate)."""
        return aid in self.slow_relays or relays(status.w, status.mass, status.room)

    def _flood(self, origin: str, status: Status, route: tuple) -> None:
        """A blocked generator passes every status of this round on to its other
        neighbours, once per origin, the route growing by itself."""
        if not self.relay or origin == self.aid:
            return
        if route:
            self.heard[(origin, route[-1])] = (status, route)
        if not self.blocked or status.round != self.status_round or origin in self.forwarded:
            return
        self.forwarded.add(origin)
        onward = (*route, self.aid)
        for aid in self.neighbours:
            if aid != origin and aid not in route:
                self._forward(Relayed(origin, status, onward), aid)

    def _relayed(self, message: Relayed, sender: str) -> None:
        """A flooded status, or a routed transaction message: pass it on along its path, or,
        if addressed here, remember the way back and take its content."""
        if isinstance(message.content, Status) and not message.path:
            self._flood(message.origin, message.content, tuple(message.route))
            return
        route = (*message.route, sender) if sender != message.origin else tuple(message.route)
        if message.path:
            nxt, rest = message.path[0], tuple(message.path[1:])
            self._forward(Relayed(message.origin, message.content, route, rest), nxt)
            return
        txid = getattr(message.content, "txid", None)
        if txid is not None:
            self.routes.setdefault(txid, (*reversed(route), message.origin))
        self.receive(message.content, message.origin)

    def _forward(self, message: Relayed, aid: str) -> None:
        """Pass a message on at once (a relay does not wait for its next tick)."""
        self.relayed_messages += 1
        self.schedule_instant_task(self.send_message(message, receiver_addr=self.addresses[aid]))

    def _send_tx(self, content, aid: str, txid: str) -> None:
        """Send a transaction message to ``aid``, through the relays if it was relayed."""
        hops = self.routes.get(txid)
        if hops is None or len(hops) == 1:
            self.send(content, aid)
        else:
            self.send(Relayed(self.aid, content, (), tuple(hops[1:])), hops[0])

    def _groups(self) -> list[list[tuple[str, Status, tuple | None]]]:
        """The relay groups this generator belongs to this round, from the flooded statuses:
        each a list of its members ``(id, status, hops to it)`` (itself included, with hops
        None; hops None too where no route came through the group)."""
        rnd = self.status_round
        own = self.own
        me = Status(rnd, own.f, own.w, own.v, own.mass, own.room, self.index)
        status = {self.aid: me}
        direct = {a: s for a, s in self.statuses.items() if s.round == rnd}
        status.update(direct)
        heard = [(o, st, r) for (o, _), (st, r) in self.heard.items() if st.round == rnd]
        for o, st, _ in heard:
            status[o] = st
        parent: dict[str, str] = {}

        def find(a: str) -> str:
            parent.setdefault(a, a)
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        def union(a: str, b: str) -> None:
            parent[find(a)] = find(b)

        comps: set[str] = set()
        members: dict[str, dict[str, Status]] = {}
        for o, st, route in heard:
            for a, b in zip(route, route[1:], strict=False):
                union(a, b)
            if self._relays(o, st):
                union(o, route[0])
            if self.blocked:
                union(self.aid, route[-1])
        for a, st in direct.items():
            if self._relays(a, st) and self.blocked:
                union(self.aid, a)
        for a, st in direct.items():
            if self._relays(a, st):
                comps.add(find(a))
                members.setdefault(find(a), {})[a] = st
        for o, st, route in heard:
            c = find(route[0])
            comps.add(c)
            members.setdefault(c, {})[o] = st
        if self.blocked:
            own = find(self.aid)
            comps.add(own)
            members.setdefault(own, {}).update(direct)
        groups = []
        for c in sorted(comps):  # a set of ids: sorted, or the order hangs on string hashing
            group = members.get(c, {})
            group[self.aid] = me
            groups.append([(a, st, None if a == self.aid else (a,) if a in direct
                            else self._hops_to(a, c, find, heard))
                           for a, st in sorted(group.items())])  # fmt: skip
        return groups

    def _hops_to(self, target: str, comp: str, find, heard) -> tuple | None:
        """The shortest way (relays, then ``target``) by which ``target``'s status came
        through the group ``comp``."""
        routes = [r for o, _, r in heard if o == target and find(r[0]) == comp]
        if not routes:
            return None
        return (*reversed(min(routes, key=len)), target)

    def _relay_flows(self) -> tuple[float, list[tuple[str, float, tuple]]]:
        """This round's relayed inflow (from every worse member of its groups, as a receiver)
        and outflows (to every better member that can receive: ``(receiver, rate, hops)``),
        shares/s, at the pairwise rate ``w_b v_a [f_b - f_a]_+`` of dynamics/pairwise.py
        ``relay_flows``."""
        if not self.relay or self.own is None:
            return 0.0, []
        f0, w0, v0 = self.own.f, self.own.w, self.own.v
        inflow, out = 0.0, []
        me = receives(self.own)
        for group in self._groups():
            for aid, st, hops in group:
                if aid == self.aid:
                    continue
                if me and st.v > 0.0 and f0 > st.f:
                    inflow += (f0 - st.f) * w0 * st.v
                if v0 > 0.0 and st.f > f0 and receives(st) and hops is not None:
                    pair = min(self.own.theta, _theta(st)) if self.rule.local_step else 1.0
                    out.append((aid, (st.f - f0) * st.w * v0 * pair, hops))
        return inflow, out

    def _apply(self, decision: Decision, sender: str) -> None:
        """A sender's decision: recorded once by id (applied at its effective round, or now
        if that has passed), acknowledged every time."""
        if decision.txid not in self.applied:
            self.applied.add(decision.txid)
            self.reserved.pop(decision.txid, None)
            if decision.commit:
                now = self.now()[0]
                if now >= decision.effective_round:
                    self._set(self.p + decision.amount_mw)
                    self._report()
                else:
                    self.pending_in[decision.txid] = (decision.amount_mw, decision.effective_round)
        self._send_tx(Ack(decision.txid), sender, decision.txid)

    # -- the round ---------------------------------------------------------------------------

    def act(self, rnd: int, phase: Phase) -> None:
        if phase == Phase.MEASURE:
            self._standing(rnd)
        elif phase == Phase.STATUS:
            self._status(rnd)
        elif phase == Phase.OFFER:
            self._offer(rnd)
        elif phase == Phase.ACCEPT:
            self._accept(rnd)
        elif phase == Phase.COMMIT:
            self._commit(rnd)

    def _watch_signals(self, rnd: int) -> None:
        """Report each line whose latest price is more than ``stale_rounds`` rounds old (its
        controller is silent; the last price is kept), and when it is fresh again."""
        for line, (heard, _) in self.signals.items():
            stale = rnd - heard > self.stale_rounds
            if stale and line not in self.unwatched:
                self.unwatched.add(line)
                self.events.append({"round": rnd, "event": "stale_price", "agent": self.aid,
                                    "line": int(line), "last_round": heard})  # fmt: skip
            elif not stale and line in self.unwatched:
                self.unwatched.discard(line)
                self.events.append({"round": rnd, "event": "fresh_price", "agent": self.aid,
                                    "line": int(line)})  # fmt: skip

    def forget(self, aid: str) -> None:
        """A neighbour that tripped (the protection's report): drop its status, the offers
        to it and from it, and the decisions it will never acknowledge (the source bus
        carries what they moved, :meth:`popdispatch.agents.population.AgentSystem.trip`)."""
        self.neighbours = [n for n in self.neighbours if n != aid]
        self.statuses.pop(aid, None)
        self.standings.pop(aid, None)

        def other(txid: str) -> str:
            sender, _, receiver = txid.split("/")[:3]
            return receiver if sender == self.aid else sender

        for book in (self.open_offers, self.undelivered, self.reserved, self.accepted,
                     self.committed, self.pending_out, self.pending_in):  # fmt: skip
            for txid in [t for t in book if other(t) == aid]:
                del book[txid]
        self.offers_in = [(s, o) for s, o in self.offers_in if s != aid]

    def _weights(self) -> tuple[float, float, float, float]:
        """``(w, v, room, mass)`` of the field at the planned set point (shares; mass already
        committed away cannot move again): under the curvature-scaled field ``w`` is the
        revision rate where there is room, before its normalisation, ``v`` the rate where
        there is mass to move."""
        r = self.rule
        one = np.ones(1)
        lo, hi = np.empty(1), np.empty(1)
        active = np.ones(1, dtype=np.bool_)
        share_bounds(r.pmin * one, r.pmax * one, active, r.demand_mw, lo, hi)
        x = np.array([self.planned]) / r.demand_mw
        tag = field_tag(r.field)  # the comparison laws' weights read no fitness
        with np.errstate(divide="ignore", invalid="ignore"):  # no room: w is 0 either way
            w, v, room, mass = law_of(tag).reference(tag, x, np.zeros(1), lo, hi, active,
                                                     r.rate * one)  # fmt: skip
        if r.scaled:
            w[0] = r.rate if room[0] > 0.0 else 0.0
            v[0] = r.rate if mass[0] > 0.0 else 0.0
        return float(w[0]), float(v[0]), float(room[0]), float(mass[0])

    def _standing(self, rnd: int) -> None:
        """Sparse graph, curvature-scaled field: rate, room and movable mass to the
        neighbours, from which each normalises its receiver weight at the status tick."""
        _, _, room, mass = self._weights()
        standing = Standing(rnd, self.rule.rate, room, mass)
        for aid in self.neighbours:
            self.send(standing, aid)

    def _own_weights(self, w: float, v: float, room: float, mass: float) -> tuple[float, float]:
        """The own receiver and sender weights normalised by the closed neighbourhood: ``r /
        R`` and ``r``, the rate at a limit at most ``R``, with ``R`` the rates of the closed
        neighbourhood inside their limits, else of those with room (the engine's
        :func:`~popdispatch.dynamics.newton.neighbourhood_weights` on the own star, with the
        neighbours' latest standings)."""
        if w <= 0.0 and v <= 0.0:
            return 0.0, 0.0
        known = [self.standings[aid] for aid in self.neighbours if aid in self.standings]
        rate = np.array([self.rule.rate, *(s.rate for s in known)])
        rooms = np.array([room, *(s.room for s in known)])
        masses = np.array([mass, *(s.mass for s in known)])
        receivers, senders = np.zeros(len(rate)), np.zeros(len(rate))
        receivers[0], senders[0] = w, v
        neighbourhood_weights(*star(len(rate)), rate, receivers, senders, rooms, masses)
        return float(receivers[0]), float(senders[0])

    def _status(self, rnd: int) -> None:
        """Fitness and weights at the own set point; status to the neighbours."""
        self._watch_signals(rnd)
        for book in (self.statuses, self.standings):  # a neighbour silent that long: no part
            for aid in [a for a, st in book.items() if rnd - st.round > self.stale_rounds]:
                del book[aid]
        r = self.rule
        one = np.ones(1)
        p = np.array([self.p])  # the inverter's output: what the lines carry
        signal = np.array(
            [sum(value for _, value in (self.signals[k] for k in sorted(self.signals, key=int)))]
        )
        f = np.empty(1)
        fitness_into(p, r.b * one, r.c * one, r.pmin * one, r.pmax * one, r.B, r.m, r.gain,
                     signal, r.barrier, f)  # fmt: skip
        w, v, room, mass = self._weights()
        if self.normalises_itself:
            w, v = self._own_weights(w, v, room, mass)
        theta = r.step_factor(self._price_slope(rnd))
        self.own = Own(float(f[0]), w, v, room, mass, theta)
        self.status_round = rnd
        self.heard = {}
        self.forwarded = set()
        status = Status(rnd, self.own.f, w, v, mass, room, self.index,
                        theta if r.local_step else None, r.free)  # fmt: skip
        for aid in self.neighbours:
            self.send(status, aid)

    def _price_slope(self, rnd: int) -> float:
        """The fall of the prices above this generator per MW it adds (EUR/MW per MW): its
        rule's slope of each limited line above it whose price is not zero (its proportional
        part moves with this generator's output), now or within the rule's
        ``priced_memory`` rounds: where the round step can take a generator across a line's
        band in one round (docs/agents.md, "The local step"), a price that vanishes just inside
        the limit would free the generator's step exactly when the next step prices it again
        (a two-round oscillation). A line whose controllers last said both its directions
        price the flow counts twice: its half price then moves by the whole ``C_k`` per MW."""
        r = self.rule
        now = [k for k in r.lines_above if self.signals.get(str(k), (0, 0.0))[1] != 0.0]
        self.priced_lines.update({k: rnd for k in now})
        recent = {k for k, last in self.priced_lines.items() if rnd - last <= r.priced_memory}
        return sum(slope * (2.0 if self.both_lines.get(str(k)) else 1.0)
                   for k, slope in zip(r.lines_above, r.price_slopes, strict=True)
                   if k in recent)  # fmt: skip

    def _normalised_weights(self, w: np.ndarray, v: np.ndarray, room: np.ndarray,
                            mass: np.ndarray) -> None:  # fmt: skip
        """Complete graph, curvature-scaled field: every weight of the own star (the whole
        fleet) normalised in place by ``R``, the rates of all generators inside their limits,
        else of those with room, each rate at a limit at most ``R`` (the engine's
        ``newton_weights``; ``w`` holds the rates where there is room, ``v`` where there is
        mass, and the kernel reads a rate only where one of them is set)."""
        neighbourhood_weights(*complete(len(w)), np.maximum(w, v), w, v, room, mass)

    def _offer(self, rnd: int) -> None:
        """Own pairwise in/outflow, the limiter's factors, offers to better neighbours."""
        if self.own is None:
            return
        f0, v0, room0, mass0 = self.own.f, self.own.v, self.own.room, self.own.mass
        known = [self.statuses[aid] for aid in self.neighbours if aid in self.statuses]
        names = [aid for aid in self.neighbours if aid in self.statuses]
        n = len(known) + 1
        f = np.array([f0] + [s.f for s in known])
        w = np.array([self.own.w] + [s.w for s in known])
        v = np.array([v0] + [s.v for s in known])
        if self.rule.scaled and not self.relay:
            self._normalised_weights(w, v, np.array([room0] + [s.room for s in known]),
                                     np.array([mass0] + [s.mass for s in known]))  # fmt: skip
        if self.rule.local_step:  # each pair at the step of its stiffer end
            theta = self.own.theta
            w[1:] *= np.minimum(theta, [_theta(s) for s in known])
            self._free_pairs(f, w, v0, mass0, known)
        inflow, outflow = np.zeros(n), np.zeros(n)
        graph_flows(f, w, v, *star(n), inflow, outflow)
        relay_in, relay_out = self._relay_flows()
        inflow[0] += relay_in
        outflow[0] += sum(rate for _, rate, _ in relay_out)
        h = self.rule.step_s
        # the flux limiter of integrate/steppers.py (euler_steps), own side only: the sender
        # weight scaled so that the outflow empties the movable mass
        lim_v = v0 * (mass0 / (h * outflow[0])) if h * outflow[0] > mass0 else v0
        self.room_share = room0  # the receiver's side of the limiter, in _accept
        if self.quiet:
            return
        demand = self.rule.demand_mw
        amounts = {}
        for t, aid in enumerate(names, start=1):
            gap = f[t] - f0
            if gap > 0.0 and w[t] > 0.0 and lim_v > 0.0:
                amounts[(aid, "")] = h * (gap * w[t] * lim_v) * demand
        hops_of = {}
        for k, (aid, rate, hops) in enumerate(relay_out):
            if lim_v > 0.0:  # rate = gap w_b v0: the limited one scales v0 to lim_v
                amounts[(aid, f"/r{k}")] = h * (rate * (lim_v / v0)) * demand
                hops_of[(aid, f"/r{k}")] = hops
        # what is still offered from earlier rounds is not movable again
        movable = mass0 * demand - sum(amount for _, _, amount in self.open_offers.values())
        total = sum(amounts.values())
        scale = max(movable, 0.0) / total if total > max(movable, 0.0) else 1.0
        for (aid, tag), amount in amounts.items():
            if amount * scale > 0.0:
                txid = f"{self.aid}/{rnd}/{aid}{tag}"
                self.open_offers[txid] = (aid, rnd, amount * scale)
                if tag:
                    self.routes[txid] = hops_of[(aid, tag)]
                self._send_tx(Offer(rnd, txid, amount * scale), aid, txid)

    def _free_pairs(self, f: np.ndarray, w: np.ndarray, v0: float, mass0: float,
                    known: list[Status]) -> None:  # fmt: skip
        """Where this generator and better neighbours are all free (:attr:`GeneratorRule.free`),
        scale their receiver weights in ``w`` (in place; position 0 is this generator) by one
        factor, so that the flows to them alone would empty this generator's movable mass
        ``mass0`` within the round: such a pair's gap is the difference of two constant
        marginal costs, which no trade closes, and the plain step moved the power at a
        constant crawl. The flux limiter then shares the mass among all the receivers, in
        proportion to their flows, and each receiver's side caps it at its room; a gap of 0
        (a tie) moves nothing."""
        if not (self.rule.free and v0 > 0.0 and mass0 > 0.0):
            return
        free = np.array([False, *(s.free for s in known)]) & (f > f[0])
        rate = float(np.sum(w[free] * (f[free] - f[0]))) * v0  # shares/s at factor 1
        h = self.rule.step_s
        if rate > 0.0 and h * rate < mass0:
            w[free] *= mass0 / (h * rate)

    def _accept(self, rnd: int) -> None:
        """Accept the open offers that arrived, all in the same proportion, within the room
        left (counting what is reserved): the receiver's side of the flux limiter."""
        offers, self.offers_in = self.offers_in, []
        valid = []
        for sender, offer in offers:
            if offer.txid in self.answered:
                continue
            self.answered.add(offer.txid)
            if rnd < offer.round + self.timeout:  # else expired: refused, the sender aborts
                valid.append((sender, offer))
        total = sum(offer.amount_mw for _, offer in valid)
        room = self.rule.pmax - self.planned - sum(self.reserved.values())
        if self.rule.barrier:  # paper mode: no upper limit in the revision rule
            room = np.inf
        if self.engine_limiter:  # the steppers' factor, then never past the room left:
            # room over the limited senders' flows (h * inflow), which the offers carry (MW)
            offered = total / self.rule.demand_mw
            scale = self.room_share / offered if offered > self.room_share else 1.0
        else:
            scale = 1.0 if total <= max(room, 0.0) else max(room, 0.0) / total
        for sender, offer in valid:
            amount = min(offer.amount_mw * scale, max(room, 0.0))
            room -= amount
            if amount > 0.0:
                self.reserved[offer.txid] = amount
                self._send_tx(Accept(offer.txid, amount), sender, offer.txid)

    def _commit(self, rnd: int) -> None:
        """Commit the accepted offers, abort the expired ones; (re)send every decision not yet
        acknowledged."""
        for txid, (aid, offered_round, _) in list(self.open_offers.items()):
            amount = self.accepted.pop(txid, None)
            if amount is None and rnd < offered_round + self.timeout - 1:
                continue  # still open
            del self.open_offers[txid]
            effective = rnd + self.lag
            if amount is not None:
                self.pending_out[txid] = (amount, effective)
                self.committed[txid] = amount
                self.undelivered[txid] = (aid, Decision(txid, True, amount, effective))
            else:
                self.undelivered[txid] = (aid, Decision(txid, False, 0.0, effective))
        self._due(rnd)
        for aid, decision in self.undelivered.values():
            for _ in range(self.copies):
                self._send_tx(decision, aid, decision.txid)

    def _due(self, rnd: int) -> None:
        """Change the inverter by every commit whose effective round has come."""
        for pending, sign in ((self.pending_out, -1.0), (self.pending_in, 1.0)):
            for txid, (amount, effective) in list(pending.items()):
                if effective <= rnd:
                    del pending[txid]
                    self._set(self.p + sign * amount)
                    self._report()

    def _report(self) -> None:
        """Real time (TCP): tell the plant the inverter's new output at once (in the simulated
        world the plant reads the inverters)."""
        if self.plant_id is not None:
            output = Output(self.aid, self.p)
            self.schedule_instant_task(
                self.send_message(output, receiver_addr=self.addresses[self.plant_id])
            )

    @property
    def busy(self) -> bool:
        """Whether a transaction of this generator is still open or unacknowledged."""
        return bool(
            self.open_offers or self.undelivered or self.reserved or self.pending_out
            or self.pending_in
        )  # fmt: skip
