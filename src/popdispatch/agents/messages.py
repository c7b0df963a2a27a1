"""What the agents say to each other: one small record per message kind. Powers in MW.

Every record is ``json_serializable`` (mango's JSON codec), so the same messages cross a TCP
connection between processes; in mango's simulated world they are handed over as objects.
``round`` is the revision round the message belongs to (one Euler step of the dynamics);
``txid`` names a pairwise transaction (``"<sender>/<round>/<receiver>"``).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, is_dataclass

from mango import json_serializable


@json_serializable
@dataclass(frozen=True)
class Measurement:
    """Plant -> node controller: the flow of limited line ``line`` (index among the limited
    lines), MW, positive away from the source, as measured at the start of ``round``."""

    round: int
    line: int
    flow_mw: float


@json_serializable
@dataclass(frozen=True)
class Signals:
    """Node controller -> generator: the controller's value for each of its lines whose side
    the generator is on (``{line: EUR/MW}``; paper eq. 8 or the exact mode's half price);
    ``both``: those of the lines whose two directions' multipliers were both positive at the
    measurement the values come from (told under the prices' own step only), on which the
    half price moves by the whole ``C`` per MW of flow instead of ``C / 2``."""

    round: int
    values: dict
    both: tuple = ()  # lines as text, as in values


@json_serializable
@dataclass(frozen=True)
class Standing:
    """Generator -> neighbour, at the start of ``round`` on a communication graph that is not
    complete, under the curvature-scaled field (dynamics/newton.py): its revision ``rate``
    (dimensionless), its ``room`` below ``Pmax`` and its movable ``mass`` above ``Pmin``
    (shares). Each receiver normalises its weight by the rates of its closed neighbourhood
    inside their limits (``neighbourhood_weights``), which it learns from these."""

    round: int
    rate: float
    room: float
    mass: float


@json_serializable
@dataclass(frozen=True)
class Status:
    """Generator -> neighbour: fitness ``f`` (EUR/MW), receiver weight ``w``, sender weight
    ``v``, movable ``mass`` and ``room`` (shares) at the start of ``round`` (the pairwise-flow
    inputs, dynamics/pairwise.py; mass and room tell who relays).

    Under the curvature-scaled field ``v`` is the generator's revision rate where it has mass
    to move, and ``w`` its rate where it has room, normalised: on a sparse graph by the
    receiver itself (from its neighbours' :class:`Standing`), on the complete graph by every
    listener, who holds every status of the round and so the common normalisation
    (:meth:`popdispatch.agents.generator.GeneratorAgent._receiver_weights`)."""

    round: int
    f: float
    w: float
    v: float
    mass: float = 0.0
    room: float = 0.0
    index: int = -1  # the generator's position among the generators
    theta: float | None = None  # its own step factor (GeneratorRule.step_factor); None: 1
    free: bool = False  # a linear cost and no limited line above (GeneratorRule.free)


@json_serializable
@dataclass(frozen=True)
class Offer:
    """Sender -> better neighbour: move ``amount_mw`` to it (before the receiver's limiter)."""

    round: int
    txid: str
    amount_mw: float


@json_serializable
@dataclass(frozen=True)
class Accept:
    """Receiver -> sender: ``amount_mw`` (at most the offer) is reserved for ``txid``."""

    txid: str
    amount_mw: float


@json_serializable
@dataclass(frozen=True)
class Decision:
    """Sender -> receiver: ``txid`` is committed with ``amount_mw`` or aborted (``amount_mw``
    0). Both inverters change at the last tick of round ``effective_round`` (the receiver's
    on arrival if that is later). Repeated until acknowledged."""

    txid: str
    commit: bool
    amount_mw: float
    effective_round: int


@json_serializable
@dataclass(frozen=True)
class Ack:
    """Receiver -> sender: the decision on ``txid`` is applied (idempotent)."""

    txid: str


@json_serializable
@dataclass(frozen=True)
class Output:
    """Generator -> plant, real time only: the output its inverter now holds, MW (a physical
    reading; in the simulated world the plant reads the inverters directly)."""

    generator: str
    p_mw: float


@json_serializable
@dataclass(frozen=True)
class Heartbeat:
    """Node controller -> the controller at the other end of limited line ``line``: alive
    at ``round`` (a silent partner's lines are taken over, docs/agents.md)."""

    round: int
    line: int


@json_serializable
@dataclass(frozen=True)
class Relayed:
    """A message passed on by relays (generators that cannot take part in a comparison,
    dynamics/pairwise.py ``relay_flows``): ``content`` from ``origin``.

    ``route``: the relays it went through so far, in order (a flooded status: each blocked
    generator passes every status it hears on to its other neighbours, once per origin and
    round); ``path``: the relays still to go before its addressee (a routed offer, accept,
    decision or acknowledgement of a relayed transaction; empty for a flood).
    """

    origin: str
    content: object
    route: tuple = ()
    path: tuple = ()


ALL_MESSAGES = (
    Measurement,
    Signals,
    Standing,
    Status,
    Offer,
    Accept,
    Decision,
    Ack,
    Output,
    Relayed,
    Heartbeat,
)


def scalars(content) -> int:
    """The real numbers a message carries (its payload: every ``float`` in its fields, in a
    dict's values and in a relayed message's content); rounds, indices, flags and names are
    its envelope and are not counted. The measure of communication that algorithms of
    different message shapes share (``scalars_sent``)."""
    if isinstance(content, float):
        return 1
    if isinstance(content, dict):
        return sum(scalars(value) for value in content.values())
    if isinstance(content, tuple | list):
        return sum(scalars(value) for value in content)
    if is_dataclass(content) and not isinstance(content, type):
        return sum(scalars(getattr(content, f.name)) for f in fields(content))
    return 0
