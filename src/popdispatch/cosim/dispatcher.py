"""The online dispatcher of a co-simulation: the DG agents and node controllers of the engine,
driven by what a plant measures.

Each step (a minute of the plant) gives the loads' demand (kW per load); the dispatcher builds
that step's dispatch problem from it (total demand, the loads-only DC flow of every limited
line) and runs the engine's dynamics, continuing from the last step's shares, controller
prices and integrator step, with the mode's warm start placing the demand step (as the online
day does). A measured AC flow of a limited line then enters the node controller's congestion
price as the controller would use a meter: between two measurements the controller's flow is

    flow(p) = measured + D (p_applied - p)        (MW; D: the generators below the line)

the measured flow plus the DC change of the generation below since the measurement. This is
the DC model with the loads-only flow shifted by ``offset = measured - (load_flow - D
p_applied)``, the part of the AC flow the DC model misses (losses below the line, reactive
currents do not enter: the meter reads active power). The step's dynamics rerun with that
offset until a measurement changes it by less than :data:`OFFSET_TOL_KW`: the dispatch then
keeps the *measured AC* flow of every limited line within its limit. The first run of a step
uses the previous step's offset.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from popdispatch.constants import KW_PER_MW
from popdispatch.game.problem import DispatchProblem, build_problem_from_loads
from popdispatch.integrate import Status
from popdispatch.online import Engine, RunSettings, initial_shares, verdicts
from popdispatch.online.day import DayArrays

#: A step's reruns stop when a measurement moves every limited line's offset by less (kW).
OFFSET_TOL_KW = 1e-3
#: At most this many runs of the dynamics per step (measurement rounds).
MAX_ROUNDS = 20


@dataclass(frozen=True)
class StepResult:
    """One run of a step: set points (kW, generator order), the engine's status word (as a
    day minute's: ``converged`` when certified within the settings' accuracy of the DC-OPF of
    the offset-corrected problem), iterations of the dynamics and the offsets in force (kW per
    limited line)."""

    setpoints_kw: np.ndarray
    status: str
    iterations: int
    offset_kw: np.ndarray


class OnlineDispatcher:
    """The dispatcher's state from step to step (module docstring).

    ``problem``: any dispatch problem of the feeder (its reduced feeder, fleet and limits are
    used; its own demand is not); ``settings``: the run's (exact mode certifies every run).
    """

    def __init__(self, problem: DispatchProblem, settings: RunSettings):
        self.feeder = problem.feeder
        self.settings = settings
        self.generators = problem.generators
        self.limit_kw = problem.limit * KW_PER_MW
        self.offset = np.zeros(len(problem.limit))  # MW
        self.problem: DispatchProblem | None = None
        self.x: np.ndarray | None = None
        self.z: np.ndarray | None = None
        self.h_try = 0.0
        self.last_demand = 0.0
        self.applied: np.ndarray | None = None  # MW, the last set points sent
        self.rounds = 0

    @property
    def n_lines(self) -> int:
        return len(self.limit_kw)

    def start_step(self, load_kw: np.ndarray) -> StepResult:
        """A new step with per-load demand ``load_kw`` (kW, order of the feeder's loads): its
        first run, with the last step's offsets."""
        load_kw = np.asarray(load_kw, dtype=float)[None]
        self.problem = build_problem_from_loads(self.feeder, load_kw, "co-simulation",
                                                check=False)  # fmt: skip
        self.rounds = 0
        return self._run()

    def measured(self, flow_kw: np.ndarray) -> StepResult | None:
        """The limited lines' measured flows (kW, positive away from the source, order of
        :attr:`problem.lines`) at the set points last sent: a rerun with the new offsets, or
        ``None`` when they moved by less than :data:`OFFSET_TOL_KW` (or the step ran
        :data:`MAX_ROUNDS` times)."""
        if self.problem is None or self.applied is None:
            return None
        flow = np.asarray(flow_kw, dtype=float) / KW_PER_MW
        dc = self.problem.line_load_flow[0] - self.problem.down @ self.applied
        offset = flow - dc
        moved = np.abs(offset - self.offset) * KW_PER_MW
        if not np.any(moved >= OFFSET_TOL_KW) or self.rounds >= MAX_ROUNDS:
            return None
        self.offset = offset
        return self._run()

    def corrected_problem(self) -> DispatchProblem:
        """The step's problem with the offsets in force (the loads-only flows shifted)."""
        assert self.problem is not None
        load_flow = self.problem.load_flow.copy()
        load_flow[0, : self.n_lines] += self.offset
        return replace(self.problem, load_flow=load_flow)

    def _run(self) -> StepResult:
        problem = self.corrected_problem()
        engine = Engine(problem, self.settings)
        if self.x is None:
            self.x = initial_shares(problem, self.settings.x0, 1)
            engine.warm_up(self.x, 1)
            self.z, self.h_try = engine.z, engine.h_try
        engine.z, engine.h_try = self.z, self.h_try
        out = DayArrays.empty(1, problem.n_generators, len(self.z))
        out.last_demand = self.last_demand
        engine.run_day_chunk(self.x, np.array([1]), out)
        self.z, self.h_try = engine.z, engine.h_try
        self.last_demand = float(problem.demand[0])
        self.applied = out.setpoints[0].copy()
        self.rounds += 1
        status = Status(int(out.status[0]))
        verdict = verdicts(engine, np.array([1]), out.setpoints, self.z[None],
                           np.array([status == Status.CONVERGED]),
                           np.array([status == Status.INFEASIBLE]))  # fmt: skip
        return StepResult(self.applied * KW_PER_MW, verdict.status(0, status),
                          int(out.iterations[0]), self.offset * KW_PER_MW)  # fmt: skip
