"""What every agent of the dispatch shares: a tick each clock second, an outbox, a crash switch.

An agent acts at whole ticks (:mod:`popdispatch.agents.schedule`) on what its inbox has
brought so far, and queues what it says in an outbox that is sent at the end of the tick
through mango (``Agent.send_message``), to the addresses the builder gave it. A crashed agent
neither acts nor hears (its process is gone); a restarted one resumes with what it kept.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any

from mango import Agent, AgentAddress

from popdispatch.agents.clock import tick_of

#: Clock seconds per tick.
TICK_S = 1.0


class RoundAgent(Agent):
    """Base of the plant, controller and generator agents (see the module docstring).

    ``network``: the simulated network's :class:`~popdispatch.agents.network.LossyNetwork`
    (its ``copies`` decides duplicates), ``None`` on a real network.
    """

    def __init__(self, network=None):
        super().__init__()
        self.network = network
        self.addresses: dict[str, AgentAddress] = {}
        self.outbox: list[tuple[Any, str]] = []
        self.crashed = False
        self.error: BaseException | None = None  # what stopped this agent's ticks, if any
        self.phase_ticks = 1  # ticks per phase (rounds paced to the network's latency)
        self.t0 = 0.0  # clock time of round 0's first tick, s
        self.tick_s = TICK_S  # clock seconds per tick
        self.wall_clock = False  # real time (TCP): ticks at absolute deadlines, no drift
        self.missed_ticks = 0  # real time: deadlines already past when the agent got to them
        self.loss = 0.0  # real time: probability that this agent's outgoing message is dropped
        self.drop = None  # real time: the seeded random.Random of those drops
        self.sent = 0  # real time: messages this agent sent (dropped ones included)
        self.dropped = 0

    #: The algorithm's round: its phases, one tick each (:mod:`popdispatch.agents.clock`).
    ROUND: type[IntEnum]
    #: The ticks of a round this agent acts at (each its own periodic task: an agent that
    #: woke at every tick only to find nothing to do cost the simulation a third of its time);
    #: empty: every phase of ``ROUND``.
    PHASES: tuple[IntEnum, ...] = ()

    def on_ready(self) -> None:
        phases = self.PHASES or tuple(self.ROUND)
        if self.wall_clock:
            for phase in phases:
                self.schedule_instant_task(self._deadlines(phase))
            return
        start = self.context.current_timestamp
        for phase in phases:
            self.schedule_timestamp_task(
                self._start(), start + phase * self.phase_ticks * self.tick_s
            )

    async def _start(self) -> None:
        self.schedule_periodic_task(self._tick, delay=self.round_ticks * self.tick_s)

    async def _deadlines(self, phase: IntEnum) -> None:
        """Real time: this phase's tick of every round at its absolute time from ``t0``."""
        clock = self.context.clock
        k = 0
        while True:
            due = self.t0 + (k * self.round_ticks + phase * self.phase_ticks) * self.tick_s
            k += 1
            if due < clock.time - 0.5 * self.tick_s:
                self.missed_ticks += 1  # started late or fell behind: that tick is gone
                continue
            if due > clock.time:
                await clock.sleep(due - clock.time)
            await self._tick()

    @property
    def round_ticks(self) -> int:
        """Ticks per round."""
        return len(self.ROUND) * self.phase_ticks

    async def _tick(self) -> None:
        if self.crashed:
            return
        rnd, phase = self.now()
        try:
            self.act(rnd, phase)
        except Exception as exc:  # mango logs and drops it; the run must not go on quietly
            self.error = exc
            self.crashed = True
            return
        outbox, self.outbox = self.outbox, []
        for content, aid in outbox:
            copies = self.network.copies() if self.network is not None else 1
            for _ in range(copies):
                self.sent += 1
                if self.drop is not None and self.drop.random() < self.loss:
                    self.dropped += 1  # fault injection over TCP: lost on the way
                    continue
                await self.send_message(content, receiver_addr=self.addresses[aid])

    def now(self) -> tuple[int, IntEnum]:
        """``(round, phase)`` of the clock now."""
        elapsed = (self.context.current_timestamp - self.t0) / self.tick_s
        rnd, phase = tick_of(elapsed, len(self.ROUND), self.phase_ticks)
        return rnd, self.ROUND(phase)

    def send(self, content: Any, aid: str) -> None:
        """Queue ``content`` for agent ``aid`` (sent at the end of this tick)."""
        self.outbox.append((content, aid))

    def handle_message(self, content: Any, meta: dict) -> None:
        if not self.crashed:
            self.receive(content, meta.get("sender_id"))

    def act(self, rnd: int, phase: IntEnum) -> None:
        """What the agent does at tick ``phase`` of round ``rnd``."""

    def receive(self, content: Any, sender: str | None) -> None:
        """What the agent does with a message as it arrives."""
