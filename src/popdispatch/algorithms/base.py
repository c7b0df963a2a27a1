"""What every algorithm module provides to the round runner, and the facts they share.

An algorithm is one class with the three steps of a round (PowerModelsADA's shape):
``__init__`` initialises its agents on a problem's minute (and sends the configuration
messages), ``local_update(inbox, round)`` lets every agent act on the messages delivered this
round, ``exchange(round)`` sends the round's messages. ``applied_mw()`` is what the inverters
follow now (MW per generator): the population's set points, or the current proposal of an
iterative method.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from popdispatch.algorithms.network import Message, Network
from popdispatch.game.problem import DispatchProblem


@dataclass(frozen=True)
class Minute:
    """The data of one minute the agents act on (MW, EUR): each generator's bounds that
    minute (0 when offline), the demand, the loads-only flows of the limited lines."""

    problem: DispatchProblem
    minute: int
    lo: np.ndarray
    hi: np.ndarray
    demand: float
    load_flow: np.ndarray

    @classmethod
    def of(cls, problem: DispatchProblem, minute: int) -> Minute:
        online = problem.online[minute - 1]
        return cls(problem, minute, np.where(online, problem.pmin, 0.0),
                   np.where(online, problem.pmax, 0.0), float(problem.demand[minute - 1]),
                   problem.line_load_flow[minute - 1].copy())  # fmt: skip

    @cached_property
    def names(self) -> list[str]:
        return [str(g) for g in self.problem.generators]

    @cached_property
    def position(self) -> dict[str, int]:
        """Each generator's index, by name."""
        return {name: i for i, name in enumerate(self.names)}

    def flows(self, p: np.ndarray) -> np.ndarray:
        """Flows on the limited lines (MW, + towards the loads below) at set points ``p``."""
        return self.load_flow - self.problem.down @ p


def balanced_start(minute: Minute) -> np.ndarray:
    """The uniform start of ``minute`` (:func:`balanced_shares`), MW."""
    return balanced_shares(minute.lo, minute.hi, minute.demand)


def balanced_shares(lo: np.ndarray, hi: np.ndarray, demand: float) -> np.ndarray:
    """Equal shares of the demand (MW) clipped to each DG's range ``[lo, hi]``, the rest
    spread over the DGs with room (the uniform start, kept within limits): sum = demand where
    the fleet allows."""
    n = len(lo)
    p = np.clip(np.full(n, demand / n), lo, hi)
    for _ in range(n):
        gap = demand - p.sum()
        free = (hi - p > 1e-15) if gap > 0 else (p - lo > 1e-15)
        if abs(gap) <= 1e-15 * max(demand, 1.0) or not free.any():
            break
        p[free] = np.clip(p[free] + gap / free.sum(), lo[free], hi[free])
    return p


def with_held(problem: DispatchProblem, held: dict[int, float]) -> DispatchProblem:
    """``problem`` with each generator of ``held`` (position -> MW) fixed at that output, as
    an inverter whose agent stopped holds it: the yardstick's DC-OPF after a crash."""
    if not held:
        return problem
    pmin, pmax = problem.pmin.copy(), problem.pmax.copy()
    for i, p_mw in held.items():
        pmin[i] = pmax[i] = p_mw
    return replace(problem, pmin=pmin, pmax=pmax)


def controller_name(problem: DispatchProblem, k: int) -> str:
    """The node controller of limited line ``k``: ``C`` and the line's reduced number."""
    return f"C{int(problem.lines[k])}"


#: The agent that holds the balance (the substation's coordinator, where one is needed).
COORDINATOR = "coordinator"


class Algorithm:
    """Base of the algorithm modules (see the module docstring)."""

    #: What it does when a message is lost (stale values), for the docs and the table.
    loss_handling = ""
    #: Rounds one iteration of the method takes (the messages' round trips).
    rounds_per_iteration = 1

    def __init__(self, minute: Minute, network: Network, params):
        self.m, self.net, self.params = minute, network, params

    @classmethod
    def check(cls, problem: DispatchProblem) -> None:
        """:class:`~popdispatch.errors.OptionError` (``--algorithms``) where the algorithm
        cannot run ``problem``, before any work; every problem by default."""

    def local_update(self, inbox: dict[str, list[Message]], round_: int) -> None:
        raise NotImplementedError

    def exchange(self, round_: int) -> None:
        raise NotImplementedError

    def applied_mw(self) -> np.ndarray:
        raise NotImplementedError

    def held_mw(self, i: int) -> float:
        """The set point (MW) generator ``i``'s inverter holds for good once its agent has
        crashed: the applied one, unless the algorithm still has changes committed."""
        return float(self.applied_mw()[i])

    def agents(self) -> list[str]:
        raise NotImplementedError

    def send_cost_curves(self, receivers_of) -> None:
        """Configuration (round 0): each generator sends its cost curve and limits (b, c,
        Pmin, Pmax) to the agents ``receivers_of(i)`` names."""
        problem = self.m.problem
        for i, name in enumerate(self.m.names):
            curve = (problem.b[i], problem.c[i], self.m.lo[i], self.m.hi[i])
            for receiver in receivers_of(i):
                self.net.send(name, receiver, "curve", curve, reveals="cost curve")
