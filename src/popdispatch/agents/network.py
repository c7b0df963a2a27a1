"""The simulated network: loss, delay and duplication, seeded (a mango communication simulation).

mango's :class:`~mango.simulation.SimulationWorld` asks its communication simulation, for every
message sent, whether it arrives and after how long; this module answers with a seeded
:class:`random.Random`, so a run is repeatable. Time is counted in *ticks* (1 s of simulated
clock each): a round has the algorithm's ``ticks_per_round`` ticks
(:mod:`popdispatch.agents.clock`) and agents act on whole ticks, so every message takes half
a tick (it is in the receiver's inbox before the receiver's next tick) plus a random whole
number of rounds up to ``delay_max`` (whole rounds: arrivals then fall on few instants, and
mango's world steps once per instant). Duplication is decided by the sender's outbox
(:meth:`LossyNetwork.copies`): mango's package result is one delivery per send, so a
duplicated packet is sent twice, each copy with its own loss and delay draw (hence also
reordered).
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from mango import CommunicationSimulation, CommunicationSimulationResult, PackageResult

from popdispatch.agents.clock import HOP_TICKS
from popdispatch.agents.messages import scalars
from popdispatch.errors import OptionError

#: The agent faults a run can be given (:class:`FaultEvent`).
FAULT_KINDS = ("trip", "crash", "controller-crash")


@dataclass(frozen=True)
class FaultEvent:
    """A fault of one agent at the start of round ``round``: ``trip`` (a DG's output to 0 at
    once, for good), ``crash`` (a DG's agent stops; its inverter holds the last set point) or
    ``controller-crash`` (a node controller stops); ``rounds``: rounds until it restarts
    (None: never; a trip never restarts)."""

    kind: str
    agent: str
    round: int
    rounds: int | None = None

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise OptionError(f"unknown fault {self.kind!r} (known: {', '.join(FAULT_KINDS)})",
                              "--" + str(self.kind))  # fmt: skip
        if self.round < 0 or (self.rounds is not None and self.rounds < 1):
            raise OptionError(f"{self.kind} of {self.agent}: round >= 0 and rounds >= 1 "
                              f"required, got {self.round} and {self.rounds}",
                              "--" + self.kind)  # fmt: skip

    @classmethod
    def parse(cls, kind: str, text: str) -> FaultEvent:
        """``AGENT@ROUND`` or ``AGENT@ROUND+ROUNDS`` (restart after ROUNDS rounds)."""
        agent, at, when = text.partition("@")
        start, plus, length = when.partition("+")
        try:
            if not (agent and at and start.isdigit() and (not plus or length.isdigit())):
                raise ValueError
            return cls(kind, agent, int(start), int(length) if plus else None)
        except ValueError:
            raise OptionError(f"{kind} {text!r}: expected AGENT@ROUND or AGENT@ROUND+ROUNDS",
                              "--" + kind) from None  # fmt: skip


@dataclass(frozen=True)
class Faults:
    """Communication faults of a simulated run.

    Attributes
    ----------
    loss : probability that a message is lost, 0-1 (each message independently).
    delay_max : largest extra delay, in rounds (each message: a whole number of rounds drawn
        uniformly from 0 to ``delay_max``).
    duplicate : probability that a message is delivered twice (each copy delayed on its own).
    noise_kw : standard deviation of the flow measurement noise, kW (plant sensors).
    seed : seed of every random draw of the run.
    events : agent faults (:class:`FaultEvent`: trips, crashes) at given rounds.
    """

    loss: float = 0.0
    delay_max: int = 0
    duplicate: float = 0.0
    noise_kw: float = 0.0
    seed: int = 0
    events: tuple = ()

    def __post_init__(self) -> None:
        for name, option in (("loss", "--loss"), ("duplicate", "--duplicate")):
            value = getattr(self, name)
            if not 0.0 <= value < 1.0:
                raise OptionError(f"{name} must be in [0, 1), got {value}", option)
        if int(self.delay_max) != self.delay_max or self.delay_max < 0:
            raise OptionError(
                f"delay_max must be a whole number of rounds >= 0, got {self.delay_max}",
                "--delay-max",
            )
        if not self.noise_kw >= 0.0:
            raise OptionError(f"noise must be >= 0 kW, got {self.noise_kw}", "--noise-kw")

    @property
    def perfect(self) -> bool:
        """No loss, no extra delay, no duplicates, no noise."""
        return not (self.loss or self.delay_max or self.duplicate or self.noise_kw)


class LossyNetwork(CommunicationSimulation):
    """mango communication simulation of :class:`Faults` (seeded loss and whole-tick delays),
    counting what it was asked to carry."""

    def __init__(self, faults: Faults, ticks_per_round: int):
        self.faults = faults
        self.ticks_per_round = int(ticks_per_round)  # the unit of ``delay_max``
        self.rng = random.Random(faults.seed)
        self.sent = 0
        self.scalars = 0  # real numbers carried by the sent messages (messages.scalars)
        self.lost = 0
        self.duplicated = 0

    def calculate_communication(self, current_time, messages) -> CommunicationSimulationResult:
        results = []
        extra_max = int(self.faults.delay_max) * self.ticks_per_round
        for package in messages:
            self.sent += 1
            self.scalars += scalars(package.content[0])
            reached = self.rng.random() >= self.faults.loss
            self.lost += not reached
            extra = (
                self.rng.randint(0, int(self.faults.delay_max)) * self.ticks_per_round
                if extra_max
                else 0
            )
            results.append(PackageResult(reached=reached, delay_s=HOP_TICKS + extra))
        return CommunicationSimulationResult(package_results=results)

    def copies(self) -> int:
        """How many copies of the next message the network delivers attempts for (1 or 2)."""
        if self.faults.duplicate and self.rng.random() < self.faults.duplicate:
            self.duplicated += 1
            return 2
        return 1
