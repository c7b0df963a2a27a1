"""The message network every algorithm runs on: explicit messages, one counter, one clock.

An in-process, synchronous message-passing runtime (not the mango agents of
:mod:`popdispatch.agents`): a round is one tick of the common clock; a message sent in round
``r`` is delivered at the start of round ``r + 1 + delay``. The network counts every message
sent (lost ones too: they were on the wire), its scalars and its bytes, each agent's messages
and distinct partners, and what each agent reveals; it loses, delays and duplicates messages
with seeded draws (:class:`Faults`) and can crash an agent (it then sends nothing and
receives nothing).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

#: Bytes of a message's header on the wire: sender, receiver, kind and round (4 bytes each).
HEADER_BYTES = 16
#: Bytes of one scalar (float64).
SCALAR_BYTES = 8


@dataclass(frozen=True)
class Faults:
    """What the network does to messages.

    Attributes
    ----------
    loss : probability that a message is lost (0-1).
    delay_max : largest extra delay of a message, rounds (uniform over ``0..delay_max``).
    duplicate : probability that a message is delivered twice (the copy one round later).
    seed : seed of every draw.
    crash : ``(agent, round)``: that agent stops at the start of that round, for good (a DG's
        inverter holds its last set point); ``None``: no crash.
    """

    loss: float = 0.0
    delay_max: int = 0
    duplicate: float = 0.0
    seed: int = 0
    crash: tuple[str, int] | None = None

    @property
    def perfect(self) -> bool:
        return self.loss == 0.0 and self.delay_max == 0 and self.duplicate == 0.0

    def label(self) -> str:
        parts = [f"loss {self.loss:g}"] if self.loss else []
        parts += [f"delay <= {self.delay_max}"] if self.delay_max else []
        parts += [f"duplicates {self.duplicate:g}"] if self.duplicate else []
        parts += [f"{self.crash[0]} crashes at round {self.crash[1]}"] if self.crash else []
        return ", ".join(parts) or "perfect network"


class Message(NamedTuple):
    """One message: ``values`` are its scalars (floats on the wire); ``sent`` its round."""

    sender: str
    receiver: str
    kind: str
    values: tuple[float, ...]
    sent: int
    key: tuple = ()  # a transaction's identity (not counted as payload: it is in the header)
    via: tuple[str, ...] = ()  # the agents that relayed it, in order


@dataclass
class Counters:
    """What went over the wire."""

    messages: int = 0
    scalars: int = 0
    bytes: int = 0
    lost: int = 0
    duplicated: int = 0
    sent_by: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    partners: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))
    reveals: dict[str, set[str]] = field(default_factory=lambda: defaultdict(set))


class Network:
    """Carries messages between named agents under :class:`Faults`, counting them."""

    def __init__(self, faults: Faults | None = None):
        self.faults = faults or Faults()
        self.counters = Counters()
        self.round = 0
        self._rng = np.random.default_rng(self.faults.seed)
        self._queue: dict[int, list[Message]] = defaultdict(list)

    def crashed(self, agent: str) -> bool:
        crash = self.faults.crash
        return crash is not None and crash[0] == agent and self.round >= crash[1]

    def send(self, sender: str, receiver: str, kind: str, values, reveals: str = "",
             key: tuple = (), via: tuple[str, ...] = ()) -> None:  # fmt: skip
        """Send ``values`` (scalars) from ``sender`` to ``receiver`` (relayed by the agents
        ``via``, one message and one round per hop, each hop lost on its own); ``reveals``
        names what the sender discloses by it (a cost curve, a set point, a price ...)."""
        f = self.faults
        if f.crash is not None and self.crashed(sender):
            return
        values = _scalars(values)
        c = self.counters
        if reveals:
            c.reveals[sender].add(reveals)
        size = HEADER_BYTES + SCALAR_BYTES * len(values)
        delay = 0
        a = sender
        for b in (*via, receiver) if via else (receiver,):
            c.messages += 1
            c.scalars += len(values)
            c.bytes += size
            c.sent_by[a] += 1
            c.partners[a].add(b)
            c.partners[b].add(a)
            if (f.loss and self._rng.random() < f.loss) or (b != receiver and self.crashed(b)):
                c.lost += 1
                return
            delay += 1 + (int(self._rng.integers(0, f.delay_max + 1)) if f.delay_max else 0)
            a = b
        message = Message(sender, receiver, kind, values, self.round, key, via and tuple(via))
        self._queue[self.round + delay].append(message)
        if f.duplicate and self._rng.random() < f.duplicate:
            c.duplicated += 1
            self._queue[self.round + delay + 1].append(message)

    def deliver(self, round_: int) -> dict[str, list[Message]]:
        """Start round ``round_``: the messages due, by receiver (none to a crashed agent)."""
        self.round = round_
        inbox: dict[str, list[Message]] = defaultdict(list)
        crash = self.faults.crash
        for message in self._queue.pop(round_, []):
            if crash is None or not self.crashed(message.receiver):
                inbox[message.receiver].append(message)
        return inbox


def _scalars(values) -> tuple[float, ...]:
    """A message's payload as a tuple of Python floats (from a sequence, an array or a
    number)."""
    if isinstance(values, np.ndarray):
        return tuple(values.ravel().tolist())
    if isinstance(values, (list, tuple)):
        return tuple(map(float, values))
    return (float(values),)
