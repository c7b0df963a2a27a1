"""Node controllers as agents (paper section II-B): measure their lines, price them, broadcast.

One agent per key node at an end of a limited line (the rows of
:class:`popdispatch.game.controllers.NodeControllers`). For each line it ends, the controller
keeps the latest measured flow and, at its tick, sends its value to the generators on its
side of the line:

- paper mode: eq. 8, :func:`popdispatch.game.controllers.overflow_signal` of the flow as seen
  from its node (the parent end sees ``flow``, the child end ``-flow``);
- exact mode: the line's integrated prices (modes/exact.py): with ``z_up``, ``z_down`` and the
  excesses ``e_up = flow - U``, ``e_down = -flow - U``, the net price
  ``nu = max(0, z_up + C e_up) - max(0, z_down + C e_down)`` goes as ``+nu / 2`` to the child
  side and ``-nu / 2`` to the parent side; then ``z <- max(z + h * price_rate * e, 0)``
  (one Euler step of the controller-state map). Each end integrates its own copy of the two
  prices from its own measurements: with perfect sensors and links the copies are equal;
  otherwise only the sum of the two half prices matters for the generators' comparisons.

A controller that stops (crash): every round each end sends its partner at the other end of
the line a :class:`~popdispatch.agents.messages.Heartbeat`. An end whose partner has been
silent for more than ``stale_rounds`` rounds takes the line over: it also sends the other
side its half (the negation of its own: it measures the same flow), until the partner's
heartbeats resume. The generators on the silent end's side keep the last price they heard
meanwhile (and report the silence themselves, :mod:`popdispatch.agents.generator`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from popdispatch.agents.base import RoundAgent
from popdispatch.agents.messages import Heartbeat, Measurement, Signals
from popdispatch.agents.schedule import Phase
from popdispatch.game.controllers import overflow_signal
from popdispatch.modes.exact import line_price


@dataclass
class LineEnd:
    """One limited line as one of its end controllers sees it.

    ``line``: index among the limited lines; ``orientation``: +1 at the parent end (a positive
    flow leaves this node), -1 at the child end; ``limit_mw``: U; ``receivers``: generator
    agent ids on this end's side; ``z_up``, ``z_down``: exact-mode prices, EUR/MW;
    ``partner``: the controller at the other end, ``other_receivers`` the generators on its
    side; ``partner_round``: round of its latest heartbeat; ``took_over``: this end sends the
    other side's half too (the partner is silent).
    """

    line: int
    orientation: int
    limit_mw: float
    receivers: list[str]
    flow_mw: float | None = None
    flow_round: int = -1
    z_up: float = 0.0
    z_down: float = 0.0
    partner: str | None = None
    other_receivers: list[str] = field(default_factory=list)
    partner_round: int = -1
    took_over: bool = False


class ControllerAgent(RoundAgent):
    """The node controller of one key node (see the module docstring).

    ``exact``: the exact mode's prices instead of eq. 8; ``C``: EUR/MW^2 (eq. 8's gain, or the
    proportional part of the price); ``price_rate``: EUR/MW per MW per s; ``step_s``: the
    round's Euler step ``h``, s.
    """

    PHASES = (Phase.SIGNAL,)

    def __init__(self, ends: list[LineEnd], exact: bool, C: float, price_rate: float,
                 step_s: float, network=None, stale_rounds: int = 10):  # fmt: skip
        super().__init__(network)
        self.stale_rounds = int(stale_rounds)
        self.events: list[dict] = []
        self.ends = ends
        self.exact = exact
        self.C = C
        self.price_rate = price_rate
        self.step_s = step_s
        self.by_line = {}
        for end in ends:
            self.by_line.setdefault(end.line, []).append(end)

    def receive(self, content, sender) -> None:
        if isinstance(content, Measurement):
            for end in self.by_line.get(content.line, ()):
                if content.round > end.flow_round:
                    end.flow_mw, end.flow_round = content.flow_mw, content.round
        elif isinstance(content, Heartbeat):
            for end in self.by_line.get(content.line, ()):
                end.partner_round = max(end.partner_round, content.round)

    def act(self, rnd: int, phase: Phase) -> None:
        if phase != Phase.SIGNAL:
            return
        values: dict[str, dict[str, float]] = {}
        for end in self.ends:
            if end.partner is not None:
                self.send(Heartbeat(rnd, end.line), end.partner)
                self._watch(end, rnd)
            if end.flow_mw is None:
                continue  # nothing measured yet: nothing to say
            value = self._price(end) if self.exact else self._overflow(end)
            for aid in end.receivers:
                values.setdefault(aid, {})[str(end.line)] = value
            if end.took_over:  # the silent partner's half: the same law from its side
                other = -value if self.exact else self._overflow(end, -1)
                for aid in end.other_receivers:
                    values.setdefault(aid, {})[str(end.line)] = other
        for aid, by_line in values.items():
            self.send(Signals(rnd, by_line), aid)

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

    def _overflow(self, end: LineEnd, side: int = 1) -> float:
        """Paper eq. 8 as seen from this node (``side`` -1: from the other end)."""
        return overflow_signal(side * end.orientation * end.flow_mw, end.limit_mw, self.C)

    def _price(self, end: LineEnd) -> float:
        """Exact mode: this end's half of the net price (modes/exact.py ``line_price``), then
        one Euler step of the prices."""
        excess_up = end.flow_mw - end.limit_mw
        excess_down = -end.flow_mw - end.limit_mw
        nu = line_price(end.z_up, end.z_down, excess_up, excess_down, self.C)
        h, rate = self.step_s, self.price_rate
        end.z_up = max(end.z_up + h * (rate * excess_up), 0.0)
        end.z_down = max(end.z_down + h * (rate * excess_down), 0.0)
        return -0.5 * nu if end.orientation > 0 else 0.5 * nu

    def residual_mw(self) -> float:
        """Largest distance from complementary slackness over this controller's lines, MW
        (as modes/exact.py: any overflow, and any slack while a price is positive)."""
        worst = 0.0
        for end in self.ends:
            if end.flow_mw is None:
                continue
            for excess, price in ((end.flow_mw - end.limit_mw, end.z_up),
                                  (-end.flow_mw - end.limit_mw, end.z_down)):  # fmt: skip
                worst = max(worst, abs(excess) if price > 0.0 else max(excess, 0.0))
        return worst
