"""The generic world the agents of any algorithm run in (mango's simulated world).

:func:`run_world` registers a built system's agents under their ids
(:meth:`WorldSystem.registrations`), places its participants on its communication graph as a
mango topology, gives every agent every address, and steps the clock round by round: at the
start of each round it applies the fault events, calls the probe, and judges the round
(:func:`verdict`: at rest, ran away, or the horizon). Once judged it drains (no new work
started, :meth:`WorldSystem.drain`) until nothing is in flight (:meth:`WorldSystem.busy`) or
``drain_rounds`` pass. What it measures is the same for every algorithm (:class:`WorldRun`):
rounds, messages, the scalars they carried, losses. An algorithm is one module that builds a
:class:`WorldSystem` and reads the result (:mod:`popdispatch.agents.algorithms`).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import networkx as nx
import numpy as np

from popdispatch.agents.network import FaultEvent, LossyNetwork
from popdispatch.constants import KW_PER_MW
from popdispatch.integrate.stopping import windows_agree


class WorldSystem(Protocol):
    """What the world needs of an algorithm's built agents.

    ``network``: the simulated network (faults, counts); ``graph``: the communication graph
    over the participants' ids (a mango topology); ``prove``: in a mode that claims the
    DC-OPF, the distance bound (MW) the state proves now, else None; ``accuracy_mw``: what a
    rest must prove to end the run; ``extrapolate``: the rest rule projects the geometric
    tail (exact mode)."""

    network: LossyNetwork
    graph: nx.Graph
    prove: Callable | None
    accuracy_mw: float
    extrapolate: bool

    @property
    def agents(self) -> list: ...

    def registrations(self) -> list[tuple[object, str]]:
        """Every agent with the id it registers under."""

    @property
    def history(self) -> list[np.ndarray]:
        """The set points (MW) at the start of every round so far."""

    @property
    def round_ticks(self) -> int:
        """Clock ticks per round."""

    @property
    def step_s(self) -> float:
        """The round's step of the algorithm, s (named in a horizon reason)."""

    def apply(self, event: FaultEvent, rnd: int) -> None:
        """Start or end a fault event at round ``rnd``."""

    def observe(self, faults_applied: bool) -> None:
        """The algorithm's own bookkeeping at a round's start (before and after faults)."""

    def residual_mw(self) -> float:
        """The largest distance from the algorithm's own optimality condition still to go
        (the live controllers' complementary slackness), MW."""

    def runaway(self) -> str | None:
        """Why the run cannot end at rest (prices ran away: infeasible), else None."""

    def drain(self) -> None:
        """Start no new work; finish what is in flight."""

    def busy(self) -> bool:
        """Whether work is still in flight (undecided or unacknowledged)."""


@dataclass(frozen=True)
class WorldOptions:
    """The world's own settings: ``max_rounds`` (horizon), ``window`` (rounds of rest),
    ``tol_kw`` (rest tolerance, kW), ``drain_rounds`` (most rounds of drain)."""

    max_rounds: int
    window: int
    tol_kw: float
    drain_rounds: int


@dataclass(frozen=True)
class WorldRun:
    """What the world measured: ``rounds`` (the rounds the set points were recorded after:
    ``len(history) - 1``), ``rest_round`` (None if never), ``horizon_reason`` and
    ``infeasible`` (why it never came to rest), ``messages`` (every send, lost ones and
    duplicates included), ``scalars_sent`` (the real numbers they carried,
    :func:`popdispatch.agents.messages.scalars`), ``lost``, ``duplicated``, and
    ``wall_seconds`` (the clock loop's own time)."""

    rounds: int
    rest_round: int | None
    horizon_reason: str | None
    infeasible: bool
    messages: int
    scalars_sent: int
    lost: int
    duplicated: int
    wall_seconds: float


def run_world(system: WorldSystem, opts: WorldOptions, on_round=None) -> WorldRun:
    """Run ``system`` in mango's simulated world (module docstring); ``on_round(system,
    rnd)``: called at every round's start, after the faults (fault injection, probes)."""
    return asyncio.run(simulate(system, opts, on_round))


async def simulate(system: WorldSystem, opts: WorldOptions, on_round=None) -> WorldRun:
    """:func:`run_world` inside a running event loop. With ``system.prove``, a rest whose
    proved distance bound is above the accuracy runs on for another window as long as each
    rest proves at least half the bound of the one before (the engine runs on while the
    bound falls by 1 %, :func:`popdispatch.online.run_snapshot`; the agents' rounds cost
    messages, so they ask more of each window; a system's ``rest_progress``, when it has one,
    replaces :data:`REST_PROGRESS`), or as long as the bound, falling at its rate since the
    rest before, would reach the accuracy within the horizon (:class:`Falling`): the rest
    window can stop a run whose last watts still move. A run the certificate proves within
    the accuracy every ``window`` rounds stops there, at rest or not (:func:`proved`)."""
    from mango import AgentAddress, create_world, graph_topology, per_node

    world = create_world(communication_sim=system.network, record_messages=False)
    for agent, aid in system.registrations():
        world.register(agent, suggested_aid=aid)
    topology = graph_topology(system.graph.copy())
    for name, node in zip(system.graph.nodes, per_node(topology), strict=True):
        node.add(world.agents[name])
    addresses = {aid: AgentAddress(world.addr, aid) for aid in world.agents}
    for agent in system.agents:
        agent.addresses = addresses
    start = time.perf_counter()
    rest_round = unrest = None
    infeasible = False
    window = opts.window
    last_event = max((_last_round(e) for e in system.network.faults.events), default=-1)
    check_after = last_event + window  # no rest declared before the last fault
    last_bound, last_rest = np.inf, 0
    async with world:
        rnd, quiet = 0, False
        while True:
            system.observe(False)
            for event in system.network.faults.events:
                system.apply(event, rnd)
            system.observe(True)
            if on_round is not None:
                on_round(system, rnd)
            if not quiet:
                rest_round, unrest, infeasible = verdict(system, rnd, opts, rnd > check_after)
                if rest_round is not None and system.prove is not None and rnd < opts.max_rounds:
                    bound = system.prove(system)
                    progress = getattr(system, "rest_progress", REST_PROGRESS)
                    falling = Falling(bound, last_bound, rnd - last_rest)
                    if falling.goes_on(system.accuracy_mw, opts.max_rounds - rnd, progress):
                        rest_round, check_after = None, rnd + window
                        last_bound, last_rest = bound, rnd
                elif proved(system, rnd, window,
                            rnd > check_after and unrest is None and opts.tol_kw > 0.0):
                    rest_round = len(system.history) - 1
                quiet = rest_round is not None or unrest is not None
                if quiet:
                    system.drain()
            if (quiet and not system.busy()) or rnd >= opts.max_rounds + opts.drain_rounds:
                break
            await world.step_until(system.round_ticks)
            _raise_agent_errors(system)
            rnd += 1
    network = system.network
    return WorldRun(
        rounds=len(system.history) - 1,
        rest_round=rest_round,
        horizon_reason=unrest,
        infeasible=infeasible,
        messages=network.sent,
        scalars_sent=network.scalars,
        lost=network.lost,
        duplicated=network.duplicated,
        wall_seconds=time.perf_counter() - start,
    )


#: The factor each further rest's proved bound must fall below, times the one before, for a
#: run at rest above the accuracy to go on (:func:`simulate`) whatever its horizon.
REST_PROGRESS = 0.5


@dataclass(frozen=True)
class Falling:
    """The distance bounds (MW) proved at two rests of a run, ``rounds`` apart: ``bound`` now,
    ``before`` at the rest before (``inf`` at the first)."""

    bound: float
    before: float
    rounds: int

    def rounds_to(self, accuracy_mw: float) -> float:
        """Rounds until the bound is within ``accuracy_mw`` if it keeps falling by the same
        factor every ``rounds`` (0 within it already; ``inf`` if it did not fall)."""
        if self.bound <= accuracy_mw:
            return 0.0
        if not self.bound < self.before:
            return np.inf
        ratio = self.bound / self.before
        return self.rounds * np.log(accuracy_mw / self.bound) / np.log(ratio)

    def goes_on(self, accuracy_mw: float, remaining: int, progress: float) -> bool:
        """Whether a run at rest above ``accuracy_mw`` goes on: its bound fell below
        ``progress`` times the one before, or at its rate it would reach the accuracy within
        the ``remaining`` rounds of its horizon (a slow tail the rest window caught still
        creeping, not a stall)."""
        if self.bound <= accuracy_mw:
            return False
        return self.bound < progress * self.before or self.rounds_to(accuracy_mw) <= remaining


def proved(system: WorldSystem, rnd: int, window: int, due: bool) -> bool:
    """Whether the state proves itself within the accuracy before it is at rest: every
    ``window`` rounds, once ``due`` (after the last fault, the run still going, a rest
    tolerance above 0: with 0 the run goes to its horizon), the distance
    certificate (``system.prove``) of the set points and prices now. Such a run has reached
    what ``converged`` claims, and further rounds would only move it within the accuracy."""
    if not due or system.prove is None or rnd % window:
        return False
    return bool(system.prove(system) <= system.accuracy_mw)


def verdict(system: WorldSystem, rnd: int, opts: WorldOptions,
            due: bool) -> tuple[int | None, str | None, bool]:  # fmt: skip
    """``(rest round, reason, infeasible)`` of a run at round ``rnd``: at rest (the set points
    still over ``window`` rounds and the system's residual within ``tol_kw``, once ``due``:
    after the last fault), or why it stops without: :meth:`WorldSystem.runaway`
    (infeasible), the horizon (:func:`horizon_reason`); all None and False while it runs
    on."""
    tol = opts.tol_kw / KW_PER_MW
    residual = system.residual_mw()
    history = system.history
    if due and residual <= tol and _at_rest(history, opts.window, tol, system.extrapolate):
        return len(history) - 1, None, False
    ran_away = system.runaway()
    if ran_away is not None:
        return None, ran_away, True
    if rnd >= opts.max_rounds:
        reason = horizon_reason(history, opts.window, tol, system.step_s, residual)
        return None, reason, False
    return None, None, False


def _last_round(event: FaultEvent) -> int:
    """The round a fault event last changes something (its start or its restart)."""
    return event.round + (event.rounds or 0)


def _raise_agent_errors(system: WorldSystem) -> None:
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

