"""Node controllers as agents (paper section II-B): measure their lines, price them, broadcast.

One agent per key node at an end of a limited line (the rows of
:class:`popdispatch.game.controllers.NodeControllers`). For each line it ends, the controller
keeps the latest measured flow and, at its tick, sends the value for its side of the line to
the generators on that side. The values are the mode's own payoff map
(:func:`popdispatch.modes.exact.payoff`, :func:`popdispatch.modes.paper.payoff`) evaluated on
the line alone (:class:`LinePrice`: the line with one generator on each side, so the map's
broadcast gives the parent side's and the child side's value):

- paper mode: eq. 8 of the flow as seen from each end;
- exact mode: the line's integrated prices ``z_up``, ``z_down``: the net price ``nu`` goes as
  ``-nu / 2`` to the parent side and ``+nu / 2`` to the child side, and the map's rates give
  one Euler step of the prices, ``z <- max(z + h z_rate, 0)``. Each end integrates its own
  copy of the two prices from its own measurements: with perfect sensors and links the copies
  are equal; otherwise only the sum of the two half prices matters for the generators'
  comparisons.

A line whose flow stands still over its limit (the generators that could relieve it all held
at a limit: nothing answers its price until the price crosses one's marginal cost) has its
overflowing price hastened, like the engine's pinned lines (docs/exact-mode.md, "Pinned
lines") but from what the controller alone measures (:class:`StillLine`): once
:data:`STILL_GRACE` fresh measurements in a row found the flow moved by at most
:data:`STILL_FLOW` of the overflow, each further one multiplies the factor on that price's
rate by :data:`STUCK_GROWTH`, up to :data:`popdispatch.modes.exact.PINNED_BOOST` and to the
least speed ``speed`` (EUR/MW per s, :class:`ControllerAgent`). The first measurement that
finds the flow moving ends the spell and takes back the last round's gain (the generators
answered a price before it; the measurement comes a round late). A later still spell grows
the factor at most to the last spell's final factor over ``STUCK_GROWTH ** SPELL_BACKOFF``:
the price loop ringing around its target, which the plain law damps, is fed less each time,
while a price that the overshoot's answer left far below its target (a linear DG below the
line, whose answer is all or nothing) still climbs faster than the plain law. At a rest point
the line is not overflowing, so the hastening changes no rest point.

A line whose flow has settled inside both limits (moved by at most :data:`NET_SETTLED` of its
slack since the measurement before) with both prices positive nets them (:meth:`LineEnd.net`):
both lowered by the same amount, as far as each direction's multiplier ``max(0, z + C
excess)`` allows, so the broadcast at the measured flow is unchanged. On the line's Lagrangian
term ``z_up (f - U) + z_down (-f - U)`` the net ``z_up - z_down`` prices the flow and the sum
costs ``U`` each: among prices with the same net the smallest sum is the better dual point,
and a rest point never has both (the flow cannot be at ``+U`` and ``-U``), so netting changes
no rest point. Left alone, the two prices decay together at ``alpha (U -+ f)`` while the net
holds the flow inside, slow on a small limit. Only once settled: while the flow sweeps
across the band, the two prices move the net at ``2 alpha f``, faster than one price alone
(``alpha (f - U)``), and that corrects an overshoot. With the local step only, as the
hastening.

Under the prices' own step (:func:`popdispatch.agents.population.own_price_step`) the
controllers tell the generators, with each signal, the lines whose two multipliers were both
positive at the measurement it comes from (``Signals.both``,
:meth:`ControllerAgent._both_directions`): the net price then moves by ``2 C`` per MW of flow
instead of ``C``, and the generators below the line count it twice in their own step factors
(:meth:`popdispatch.agents.generator.GeneratorAgent._price_slope`).

A controller that stops (crash): every round each end sends its partner at the other end of
the line a :class:`~popdispatch.agents.messages.Heartbeat`. An end whose partner has been
silent for more than ``stale_rounds`` rounds takes the line over: it also sends the other
side its value (it measures the same flow), until the partner's heartbeats resume. The
generators on the silent end's side keep the last price they heard meanwhile (and report the
silence themselves, :mod:`popdispatch.agents.generator`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from popdispatch.agents.base import RoundAgent
from popdispatch.agents.messages import Heartbeat, Measurement, Signals
from popdispatch.agents.schedule import Phase
from popdispatch.game.parameters import GameParameters, GameWork, MinuteInputs
from popdispatch.modes import ModeCode, exact, paper
from popdispatch.modes.exact import PINNED_BOOST, multiplier

#: The payoff map each mode's controllers evaluate (the agents run these two modes).
PAYOFFS = {ModeCode.EXACT: exact.payoff, ModeCode.PAPER: paper.payoff}
#: A fresh measurement that moved the flow by at most this fraction of the line's overflow
#: finds the flow standing still.
STILL_FLOW = 1e-6
#: Still measurements in a row before a price is hastened: a climb the plain law ends in a few
#: rounds is left alone (on random fleets, hastened from the first still round, such climbs
#: overshot and rang for up to 50 rounds more).
STILL_GRACE = 6
#: The factor on a still line's overflowing price rate grows by this much a round (2 overshot
#: more, and without a limit on later spells kept a case12da fleet oscillating).
STUCK_GROWTH = 1.5
#: A still spell after one that ended grows its factor at most to that one's final factor over
#: ``STUCK_GROWTH`` to this power: about the rounds by which the ended spell overshot (its
#: answer comes a round late and the factor grew meanwhile).
SPELL_BACKOFF = 3
#: A flow inside both limits that moved by at most this fraction of its slack since the
#: measurement before has settled, and its line's two prices are netted (0.3 netted later on
#: random fleets, with more rounds).
NET_SETTLED = 0.1


@dataclass
class StillLine:
    """One line end's hastening of a still line's price (module docstring). ``boost``: the
    factor on the overflowing price's rate; ``flow_mw``, ``round``: the measurement last
    judged; ``still``: still measurements in a row; ``ceiling``: the most the factor may grow
    to in this spell (:data:`PINNED_BOOST` until a spell ends, then that spell's final factor
    over ``STUCK_GROWTH ** SPELL_BACKOFF``; no hastening once it is 1); ``gained``: what the
    factor added to the (up, down) prices in the last step, EUR/MW."""

    boost: float = 1.0
    flow_mw: float = 0.0
    round: int = -1
    still: int = 0
    ceiling: float = PINNED_BOOST
    gained: tuple[float, float] = (0.0, 0.0)

    def judge(self, flow_mw: float, flow_round: int, limit_mw: float) -> bool:
        """Judge a measurement (``flow_round`` as the last one: nothing new, nothing changes);
        returns whether the hastening just ended, its last gain to be taken back."""
        if flow_round == self.round:
            return False
        overflow = abs(flow_mw) - limit_mw
        moved = abs(flow_mw - self.flow_mw)
        still = self.round >= 0 and overflow > 0.0 and moved <= STILL_FLOW * overflow
        self.flow_mw, self.round = flow_mw, flow_round
        self.still = self.still + 1 if still else 0
        ended = self.boost > 1.0 and not still
        if ended:
            self.ceiling = max(1.0, self.boost / STUCK_GROWTH**SPELL_BACKOFF)
        hasten = self.still > STILL_GRACE and self.ceiling > 1.0
        self.boost = min(self.boost * STUCK_GROWTH, self.ceiling) if hasten else 1.0
        return ended


class LinePrice:
    """One limited line as its mode's payoff map sees it, alone: a game with this line and one
    generator on each side (generator 0 above it, 1 below it, no costs, unit gain), so that the
    map's fitness is the broadcast value of each side and its controller rates the line's.

    ``payoff``: the mode's compiled map (:data:`PAYOFFS`); ``limit_mw``: U; ``C``: EUR/MW per
    MW (eq. 8's gain, or the proportional part of the price); ``price_rate``: EUR/MW per MW per
    s. :meth:`evaluate` returns ``(parent side, child side)`` values (EUR/MW) and leaves the
    rates of ``z`` (upward, downward; EUR/MW per s) in :attr:`rate`.
    """

    def __init__(self, payoff, limit_mw: float, C: float, price_rate: float, n_states: int):
        two = np.zeros(2)
        self.payoff = payoff
        self.params = GameParameters(
            b=two, c=two, pmin=two, pmax=two, B=0.0, m=0.0, C=float(C), gain=1.0,
            price_rate=float(price_rate), limit=np.array([float(limit_mw)]),
            generator_line=np.array([-1, 0], dtype=np.int64),
            line_up=np.array([-1], dtype=np.int64), line_preorder=np.array([0], dtype=np.int64),
        )  # fmt: skip
        self.minute = MinuteInputs(1.0, np.zeros(1), two, two, np.ones(2, dtype=np.bool_),
                                   np.zeros(1), 0.0)  # fmt: skip
        self.work = GameWork.empty(1, n_generators=2)
        self.p = np.zeros(2)
        self.values = np.zeros(2)
        self.z = np.zeros(n_states)
        self.rate = np.zeros(n_states)

    def evaluate(self, flow_mw: float, z: tuple[float, ...] = ()) -> tuple[float, float, float]:
        """The values the line's two sides receive at flow ``flow_mw`` (MW, away from the
        source) and prices ``z``, and the distance from complementary slackness (MW; 0 in a
        mode without prices)."""
        self.minute.load_flow[0] = flow_mw  # no generation: the flow is the load flow
        self.z[:] = z
        _, residual = self.payoff(self.p, self.z, self.params, self.minute, self.work,
                                  self.values, self.rate)  # fmt: skip
        return float(self.values[0]), float(self.values[1]), float(residual)


@dataclass
class LineEnd:
    """One limited line as one of its end controllers sees it.

    ``line``: index among the limited lines; ``orientation``: +1 at the parent end (a positive
    flow leaves this node), -1 at the child end; ``price``: the line under the mode's payoff
    map (:class:`LinePrice`, its limit U inside); ``receivers``: generator agent ids on this
    end's side; ``z_up``, ``z_down``: exact-mode prices, EUR/MW; ``partner``: the controller
    at the other end, ``other_receivers`` the generators on its side; ``partner_round``: round
    of its latest heartbeat; ``took_over``: this end sends the other side's value too (the
    partner is silent). ``still``: the hastening of its price while the flow stands still
    (:class:`StillLine`). ``weights``: on a meshed network, each receiver's distribution factor
    to the line (``D_ki``, :mod:`popdispatch.game.mesh`; the grid operator's PTDF row of the
    line): the parent end sends every receiver ``parent + D_ki (child - parent)``, its side's
    value where ``D_ki`` is 0 and the other's where it is 1 (a radial feeder's rule), and the
    child end sends only when it has taken over. ``None`` on a radial feeder.
    """

    line: int
    orientation: int
    price: LinePrice
    receivers: list[str]
    flow_mw: float | None = None
    flow_round: int = -1
    z_up: float = 0.0
    z_down: float = 0.0
    partner: str | None = None
    other_receivers: list[str] = field(default_factory=list)
    partner_round: int = -1
    took_over: bool = False
    weights: dict[str, float] | None = None
    still: StillLine = field(default_factory=StillLine)
    moved_mw: float = float("inf")

    def measure(self, flow_mw: float, flow_round: int) -> None:
        """Keep a measurement newer than the latest (and how far it moved the flow, MW)."""
        if flow_round > self.flow_round:
            if self.flow_mw is not None:
                self.moved_mw = abs(flow_mw - self.flow_mw)
            self.flow_mw, self.flow_round = flow_mw, flow_round

    def net(self) -> None:
        """Net the two prices of a line whose flow has settled inside both limits (module
        docstring): both lowered by ``min(mu_up, mu_down)`` (EUR/MW), the mode's multipliers
        (:func:`popdispatch.modes.exact.multiplier`) at the measured flow, which keeps their
        difference, the broadcast."""
        slack = float(self.price.params.limit[0]) - abs(self.flow_mw)
        if not (slack > 0.0 and self.moved_mw <= NET_SETTLED * slack):
            return
        common = min(self.multipliers())
        self.z_up -= common
        self.z_down -= common

    def multipliers(self) -> tuple[float, float]:
        """``(mu_up, mu_down)``, EUR/MW: the mode's multipliers ``max(0, z + C excess)``
        (:func:`popdispatch.modes.exact.multiplier`) of the line's two directions at the
        latest measurement and the present prices."""
        limit, C = float(self.price.params.limit[0]), float(self.price.params.C)
        return (multiplier(self.z_up, self.flow_mw - limit, C),
                multiplier(self.z_down, -self.flow_mw - limit, C))  # fmt: skip

    @property
    def states(self) -> tuple[float, ...]:
        """The prices the line's map integrates (exact mode: ``z_up``, ``z_down``; none in
        paper mode)."""
        return (self.z_up, self.z_down) if len(self.price.z) else ()


class ControllerAgent(RoundAgent):
    """The node controller of one key node (see the module docstring). ``step_s``: the
    round's Euler step ``h``, s; ``speed``: the least speed a still line's overflowing price
    is hastened to, EUR/MW per s (0: never); ``net``: net a settled line's two prices;
    ``tell_both``: tell the generators which lines have both directions priced (the prices'
    own step, :func:`popdispatch.agents.population.own_price_step`)."""

    ROUND = Phase

    PHASES = (Phase.SIGNAL,)

    def __init__(self, ends: list[LineEnd], step_s: float, network=None,
                 stale_rounds: int = 10, speed: float = 0.0, net: bool = False,
                 tell_both: bool = False):  # fmt: skip
        super().__init__(network)
        self.stale_rounds = int(stale_rounds)
        self.events: list[dict] = []
        self.ends = ends
        self.step_s = step_s
        self.speed = float(speed)
        self.net = bool(net)
        self.tell_both = bool(tell_both)
        self.by_line = {}
        for end in ends:
            self.by_line.setdefault(end.line, []).append(end)

    def receive(self, content, sender) -> None:
        if isinstance(content, Measurement):
            for end in self.by_line.get(content.line, ()):
                end.measure(content.flow_mw, content.round)
        elif isinstance(content, Heartbeat):
            for end in self.by_line.get(content.line, ()):
                end.partner_round = max(end.partner_round, content.round)

    def act(self, rnd: int, phase: Phase) -> None:
        if phase != Phase.SIGNAL:
            return
        values: dict[str, dict[str, float]] = {}
        doubled: set[str] = set()  # lines whose two directions both price the flow
        for end in self.ends:
            if end.partner is not None:
                self.send(Heartbeat(rnd, end.line), end.partner)
                self._watch(end, rnd)
            if end.flow_mw is None:
                continue  # nothing measured yet: nothing to say
            if self._both_directions(end):
                doubled.add(str(end.line))
            own, other = self._price(end)
            if end.weights is not None:
                self._weighted(end, own, other, values)
                continue
            for aid in end.receivers:
                values.setdefault(aid, {})[str(end.line)] = own
            if end.took_over:  # the silent partner's side: the same map, its value
                for aid in end.other_receivers:
                    values.setdefault(aid, {})[str(end.line)] = other
        for aid, by_line in values.items():
            self.send(Signals(rnd, by_line, tuple(sorted(doubled & by_line.keys()))), aid)

    def _both_directions(self, end: LineEnd) -> bool:
        """Whether ``end``'s line has both directions' multipliers ``max(0, z + C excess)``
        positive at its latest measurement, before this round's step (told only when the
        controller tells it, ``tell_both``): the net price ``mu_up - mu_down`` then moves by
        ``2 C`` per MW of flow, each side's half price by ``C``, twice what one direction
        moves it by."""
        return self.tell_both and bool(end.states) and min(end.multipliers()) > 0.0

    @staticmethod
    def _weighted(end: LineEnd, own: float, other: float, values: dict) -> None:
        """A meshed network's line: each receiver's value weighed by its factor (``weights``),
        sent by the parent end, or by the child end when it has taken the line over."""
        if end.orientation < 0 and not end.took_over:
            return
        parent, child = (own, other) if end.orientation > 0 else (other, own)
        for aid, factor in end.weights.items():
            values.setdefault(aid, {})[str(end.line)] = parent + factor * (child - parent)

    def _watch(self, end: LineEnd, rnd: int) -> None:
        """Take the line over when the partner has been silent for more than
        ``stale_rounds`` rounds; hand it back when it speaks again."""
        silent = rnd - max(end.partner_round, 0) > self.stale_rounds
        if silent and not end.took_over:
            end.took_over = True
            self.events.append({"round": rnd, "event": "controller_silent",
                                "agent": end.partner, "line": end.line,
                                "taken_over_by": self.aid})  # fmt: skip
        elif not silent and end.took_over:
            end.took_over = False
            self.events.append({"round": rnd, "event": "controller_back",
                                "agent": end.partner, "line": end.line})  # fmt: skip

    def _price(self, end: LineEnd) -> tuple[float, float]:
        """``(this side's value, the other side's)`` at the latest measurement (EUR/MW), then
        one Euler step of the line's prices, ``z <- max(z + h z_rate, 0)`` (exact mode), and
        their netting if the controller nets."""
        parent, child, _ = end.price.evaluate(end.flow_mw, end.states)
        if end.states:
            h, rate = self.step_s, end.price.rate
            up, down = self._hastened(end, float(rate[0]), float(rate[1]))
            end.z_up = max(end.z_up + h * up, 0.0)
            end.z_down = max(end.z_down + h * down, 0.0)
            if self.net:
                end.net()
        return (parent, child) if end.orientation > 0 else (child, parent)

    def _hastened(self, end: LineEnd, up: float, down: float) -> tuple[float, float]:
        """The rates (EUR/MW per s) of the line's up and down prices, the rising one (the
        overflowing direction's) times the still line's factor but no faster than ``speed``
        unless alone (:class:`StillLine`); a hastening that just ended takes back its last
        gain first."""
        still = end.still
        if self.speed == 0.0:
            return up, down
        if still.judge(end.flow_mw, end.flow_round, float(end.price.params.limit[0])):
            end.z_up = max(end.z_up - still.gained[0], 0.0)
            end.z_down = max(end.z_down - still.gained[1], 0.0)
        rates = [up, down]
        for side, rate in enumerate(rates):
            if rate > 0.0 and still.boost > 1.0:
                rates[side] = rate * max(1.0, min(still.boost, self.speed / rate))
        still.gained = (self.step_s * (rates[0] - up), self.step_s * (rates[1] - down))
        return rates[0], rates[1]

    def residual_mw(self) -> float:
        """Largest distance from complementary slackness over this controller's lines at their
        latest measurements and present prices, MW (the mode's own residual: exact mode any
        overflow and any slack while a price is positive; 0 in paper mode)."""
        worst = 0.0
        for end in self.ends:
            if end.flow_mw is not None:
                worst = max(worst, end.price.evaluate(end.flow_mw, end.states)[2])
        return worst
