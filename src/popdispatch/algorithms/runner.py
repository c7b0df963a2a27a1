"""The one round runner: any algorithm of the registry on one minute, over one network, with
one message counter and one clock, measured against the DC-OPF every round.

Each round ``r = 1, 2, ...``: the network delivers the messages due, the algorithm's agents
act on them (``local_update``) and send (``exchange``); the runner then reads the set points
the inverters apply (``applied_mw``) and measures them against the yardstick, the project's
Clarabel DC-OPF of the minute (from a DG's crash on: the DC-OPF with that DG held at the set
point its inverter keeps, its value at the end of the crash round). A run is ``converged``
only when its applied set points are within ``tol`` (``max(accuracy_kw, accuracy_rel x
demand)`` kW) of the DC-OPF, balance supply and demand within ``tol`` and overflow no line
by more than ``tol``, for ``hold`` rounds in a row (the distance to the known optimum is the
certificate); else ``not_converged`` at the horizon, with the distance it ended at."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from popdispatch.algorithms.base import Minute, with_held
from popdispatch.algorithms.network import Faults, Network
from popdispatch.algorithms.registry import ALGORITHMS
from popdispatch.constants import KW_PER_MW
from popdispatch.game.problem import DispatchProblem
from popdispatch.opf import OpfResult, generation_cost, solve_opf


@dataclass(frozen=True)
class RunOptions:
    """max_rounds: horizon; hold: rounds the accuracy must hold; accuracy_kw, accuracy_rel:
    the tolerance ``max(accuracy_kw, accuracy_rel x demand)`` kW."""

    max_rounds: int = 3000
    hold: int = 10
    accuracy_kw: float = 1e-3
    accuracy_rel: float = 1e-6


@dataclass(frozen=True)
class AlgorithmRun:
    """One run: per round (index 0 = the start) the distance to the DC-OPF, cost gap,
    largest overflow and imbalance of the applied set points, cumulative messages and
    scalars; and the run's totals."""

    algorithm: str
    status: str
    converged_round: int | None
    tol_kw: float
    distance_kw: np.ndarray
    cost_gap: np.ndarray
    overflow_kw: np.ndarray
    imbalance_kw: np.ndarray
    messages: np.ndarray
    scalars: np.ndarray
    bytes: int
    lost: int
    duplicated: int
    agents: int
    messages_per_agent_round: float
    partners_mean: float
    partners_max: int
    reveals: dict[str, list[str]]
    loss_handling: str
    rounds_per_iteration: int
    setpoints_kw: np.ndarray
    opf_kw: np.ndarray
    trajectory_kw: np.ndarray  # (rounds + 1, generators): the applied set points

    @property
    def rounds(self) -> int:
        return len(self.distance_kw) - 1

    def summary(self) -> dict:
        """The run's totals as a JSON-ready dict (units in the keys)."""
        at = self.converged_round if self.converged_round is not None else self.rounds
        return {
            "algorithm": self.algorithm, "status": self.status,
            "converged_round": self.converged_round, "rounds": self.rounds,
            "rounds_per_iteration": self.rounds_per_iteration,
            "messages": int(self.messages[at]), "scalars": int(self.scalars[at]),
            "messages_total": int(self.messages[-1]), "bytes_total": self.bytes,
            "lost": self.lost, "duplicated": self.duplicated, "agents": self.agents,
            "messages_per_agent_round": self.messages_per_agent_round,
            "partners_mean": self.partners_mean, "partners_max": self.partners_max,
            "final_distance_kw": float(self.distance_kw[-1]),
            "final_cost_gap": float(self.cost_gap[-1]),
            "max_overflow_kw": float(self.overflow_kw[-1]),
            "final_imbalance_kw": float(self.imbalance_kw[-1]),
            "max_abs_imbalance_kw": float(np.abs(self.imbalance_kw).max()),
            "tol_kw": self.tol_kw, "reveals": self.reveals, "loss_handling": self.loss_handling,
        }  # fmt: skip


class Yardstick:
    """The DC-OPF of the minute; after a crash, with the crashed DG held where it stopped."""

    def __init__(self, problem: DispatchProblem, minute: int):
        self.problem, self.minute = problem, minute
        self.opf: OpfResult = solve_opf(problem, minute)
        if self.opf.status != "optimal":
            raise ValueError(f"the DC-OPF of minute {minute} is infeasible")

    def hold(self, i: int, p_mw: float) -> None:
        self.opf = solve_opf(with_held(self.problem, {i: p_mw}), self.minute)
        if self.opf.status != "optimal":
            raise ValueError(f"the DC-OPF with generator {self.problem.generators[i]} held at "
                             f"{p_mw * KW_PER_MW:.3f} kW is infeasible")  # fmt: skip


def run_algorithm(name: str, problem: DispatchProblem, minute: int, faults: Faults | None = None,
                  params=None, options: RunOptions | None = None) -> AlgorithmRun:  # fmt: skip
    """Run algorithm ``name`` (:data:`popdispatch.algorithms.ALGORITHMS`) on ``minute``."""
    options = options or RunOptions()
    entry = ALGORITHMS[name]
    params = params if params is not None else entry.params()
    network = Network(faults)
    m = Minute.of(problem, minute)
    yardstick = Yardstick(problem, minute)
    algorithm = entry.cls(m, network, params)
    algorithm.exchange(0)
    tol = max(options.accuracy_kw, options.accuracy_rel * m.demand * KW_PER_MW)
    rows = [_measure(m, yardstick, algorithm.applied_mw(), network)]
    trajectory = [algorithm.applied_mw()]
    crash = network.faults.crash
    calm, converged = 0, None
    for r in range(1, options.max_rounds + 1):
        inbox = network.deliver(r)
        algorithm.local_update(inbox, r)
        algorithm.exchange(r)
        if crash is not None and r == crash[1] and crash[0] in m.names:
            i = m.names.index(crash[0])
            yardstick.hold(i, algorithm.held_mw(i))
        trajectory.append(algorithm.applied_mw())
        rows.append(_measure(m, yardstick, trajectory[-1], network))
        distance, _, overflow, imbalance = rows[-1][:4]
        calm = calm + 1 if max(distance, overflow, abs(imbalance)) <= tol else 0
        if calm >= options.hold:
            converged = r - options.hold + 1
            break
    table = np.array([row[:6] for row in rows])
    c = network.counters
    agents = algorithm.agents()
    partners = [len(c.partners.get(a, ())) for a in agents]
    reveals = {a: sorted(c.reveals[a]) for a in agents if c.reveals.get(a)}
    return AlgorithmRun(
        name, "converged" if converged is not None else "not_converged", converged, tol,
        table[:, 0], table[:, 1], table[:, 2], table[:, 3], table[:, 4].astype(int),
        table[:, 5].astype(int), c.bytes, c.lost, c.duplicated, len(agents),
        c.messages / (len(agents) * max(1, len(rows) - 1)), float(np.mean(partners)),
        int(max(partners)), _by_role(reveals, m.names), algorithm.loss_handling,
        algorithm.rounds_per_iteration, algorithm.applied_mw() * KW_PER_MW,
        yardstick.opf.p_kw.copy(), np.array(trajectory) * KW_PER_MW,
    )  # fmt: skip


def _by_role(reveals: dict[str, list[str]], generators: list[str]) -> dict[str, list[str]]:
    """What the DGs, the node controllers and the coordinator reveal."""
    out: dict[str, set[str]] = {}
    for agent, what in reveals.items():
        role = "DG" if agent in generators else "coordinator" if agent == "coordinator" \
            else "controller"  # fmt: skip
        out.setdefault(role, set()).update(what)
    return {role: sorted(what) for role, what in sorted(out.items())}


def _measure(m: Minute, yardstick: Yardstick, p: np.ndarray, network: Network) -> tuple:
    """(distance kW, cost gap EUR/h, largest overflow kW, imbalance kW, messages, scalars)."""
    opf = yardstick.opf
    problem = m.problem
    online = problem.online[m.minute - 1]
    distance = float(np.max(np.abs(p * KW_PER_MW - opf.p_kw)))
    cost = float(generation_cost(problem, p, online))
    flows = m.flows(p)
    overflow = float(np.max(np.abs(flows) - problem.limit, initial=0.0)) * KW_PER_MW
    imbalance = (float(p.sum()) - m.demand) * KW_PER_MW
    return (distance, cost - opf.cost, max(overflow, 0.0), imbalance,
            network.counters.messages, network.counters.scalars)  # fmt: skip
