"""The compiled pieces of one run configuration (:class:`Engine`) and the flows of its state."""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

import numpy as np
from scipy import sparse

from popdispatch.dynamics import communication_graph, get_dynamics
from popdispatch.game.flows import limited_line_flows
from popdispatch.game.parameters import GameParameters
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.integrate import Status, Term, workspace
from popdispatch.modes import get_mode, mode_tag
from popdispatch.modes.exact import price_weights
from popdispatch.online.certificate import Certificate, certify_minutes
from popdispatch.online.day import DayArrays, DayInputs, DayScratch, integrate_day
from popdispatch.online.kkt import KktTolerances, kkt_violations, line_prices, voltage_prices
from popdispatch.online.settings import RunSettings
from popdispatch.warm_start import WARM_STARTS, WarmStart


class MinuteRun(NamedTuple):
    """One run of :meth:`Engine.run_minute`: set points per iteration (MW; no rows without
    ``record``), final shares, :class:`~popdispatch.integrate.Status`, iteration of
    convergence and of the first congestion (-1 if none), iterations run, and the controller
    states at the minute's end (EUR/MW). After an infeasible minute the shares and the
    engine's states are those it started from (:mod:`popdispatch.online.day`); its end is the
    trajectory's last row and ``z_end``."""

    trajectory: np.ndarray
    x: np.ndarray
    status: Status
    converged_at: int
    first_congestion: int
    iterations: int
    z_end: np.ndarray


class Engine:
    """The compiled pieces of one run configuration, reused minute after minute: the term
    (field, mode, graph), the game's parameters, the stepper's and the stopping rule's
    settings, the workspace, and the state carried between minutes (``z``, ``h_try``)."""

    def __init__(self, problem: DispatchProblem, settings: RunSettings):
        self.problem = problem
        self.settings = settings
        self.dynamics = get_dynamics(settings.dynamics)
        self.mode = get_mode(settings.mode)
        field = settings.field_tag(problem)
        if field is None:
            raise ValueError(f"{self.mode.name} mode cannot run {self.dynamics.name} dynamics: "
                             f"{self.dynamics.refusal}")  # fmt: skip
        pinned_speed = settings.engine_pinned_speed(problem)
        tag = mode_tag(self.mode.code, settings.exact.price_law, problem.meshed, pinned_speed > 0)
        rates = settings.engine_revision_rates(problem)
        complete, indptr, indices = self._graph()
        held = settings.engine_held_relays(problem)
        idle = settings.engine_idle_rates(problem)
        self.term = Term.of(field, tag, complete, indptr, indices, rates, held, idle)
        self.constants = settings.game_constants(problem)  # EUR/MW
        self.price_scale = settings.price_scale(problem)
        self.params = GameParameters.of(problem, self.constants, rates, pinned_speed, idle,
                                        settings.engine_hastens_stuck_lines(problem))
        self.z = np.zeros(self.mode.controller_states(problem))
        self.day_scratch = DayScratch.empty(problem.n_generators, len(problem.limit),
                                            len(self.z))  # fmt: skip
        self.z_cap = self.mode.price_cap(problem) if self.mode.bounded else np.inf
        integrator = settings.stepping
        self.ws = workspace(
            problem.n_generators, len(problem.limit), len(self.z), integrator.window, len(idle) > 0
        )
        self.h_try = integrator.dt

    @property
    def policy(self) -> WarmStart:
        """The warm start between minutes (the settings' policy, or the mode's default)."""
        return WARM_STARTS[self.settings.warm_start_policy]

    @property
    def evaluations(self) -> int:
        """Evaluations of the game and field so far."""
        return int(self.ws.counters.evaluations[0])

    def kkt_tolerances(self, demand_mw: float) -> KktTolerances:
        """Tolerances of the KKT check of a minute with demand ``demand_mw`` (MW), from the
        integrator in force, the revision gain and the price scale."""
        return KktTolerances.of(self.settings.stepping, self.constants.gain, demand_mw,
                                self.price_scale)  # fmt: skip

    def stall_reasons(
        self, minutes: np.ndarray, p_mw: np.ndarray, z: np.ndarray, rested: np.ndarray
    ) -> list[str | None]:
        """Per minute: why a run that came to rest (``rested``) is not at the DC-OPF, in a
        mode that claims it (else None everywhere)."""
        reasons: list[str | None] = [None] * len(minutes)
        if not self.mode.claims_dc_opf or not np.any(rested):
            return reasons
        rows = np.flatnonzero(rested)
        demand = self.problem.demand[np.asarray(minutes)[rows] - 1]
        tolerances = [self.kkt_tolerances(float(d)) for d in demand]
        checked = kkt_violations(self.problem, minutes[rows], p_mw[rows], z[rows], tolerances,
                                 self.price_weight(minutes[rows]))  # fmt: skip
        for r, reason in zip(rows, checked, strict=True):
            reasons[r] = reason
        return reasons

    def certificates(
        self, minutes: np.ndarray, p_mw: np.ndarray, z: np.ndarray
    ) -> list[Certificate] | None:
        """Per minute, the distance certificate of the end state (set points ``p_mw``, MW, and
        controller states ``z``) against the settings' accuracy, with the prices the
        controllers broadcast; ``None`` in a mode that does not claim the DC-OPF."""
        if not self.mode.claims_dc_opf:
            return None
        minutes = np.asarray(minutes, dtype=np.int64)
        rows = minutes - 1
        weight = self.price_weight(minutes)
        _, line_mu = line_prices(self.problem, rows, p_mw, z, weight)
        _, voltage_mu = voltage_prices(self.problem, rows, p_mw, z, weight)
        mu = np.concatenate([line_mu, voltage_mu], axis=1)
        accuracy = self.settings.accuracy_mw(self.problem.demand[rows])
        return certify_minutes(self.problem, minutes, p_mw, mu, np.atleast_1d(accuracy))

    def price_weight(self, minutes: np.ndarray) -> float | np.ndarray:
        """The augmented-Lagrangian weight the controllers broadcast with at the 1-based
        ``minutes`` (EUR/MW per MW: one value, or one per minute and line under the scaled
        price law; :func:`popdispatch.modes.exact.price_weights`)."""
        rows = np.asarray(minutes, dtype=np.int64) - 1
        return price_weights(self.problem, self.settings.exact.price_law, self.constants.C, rows)

    def _graph(self) -> tuple[bool, np.ndarray, np.ndarray]:
        """``(complete?, indptr, indices)`` of the communication graph (CSR)."""
        names = list(self.problem.generators)
        if self.settings.complete_graph:
            communication_graph("complete", names)  # validates the names
            empty = np.zeros(0, dtype=np.int64)
            return True, empty, empty
        adjacency = sparse.csr_matrix(communication_graph(self.settings.graph, names))
        return False, adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64)

    def warm_up(self, x: np.ndarray, minute: int) -> None:
        """Compile (or load from the disk cache) the kernels outside any timed region."""
        z, h_try = self.z.copy(), self.h_try
        self.run_minute(x.copy(), minute, max_iterations=1)
        self.z, self.h_try = z, h_try

    def run_minute(
        self, x: np.ndarray, minute: int, max_iterations: int | None = None, record: bool = True
    ) -> MinuteRun:
        """Integrate one minute from shares ``x`` at the given minute's inputs (no warm-start
        step: ``x`` is projected onto the limits in bounded modes); without ``record`` no
        per-iteration history is kept. Runs as a day of one minute (the engine's one compiled
        entry point, :func:`~popdispatch.online.day.integrate_day`)."""
        x = np.array(x, dtype=float)
        integrator = self.settings.stepping
        if max_iterations is not None:
            integrator = replace(integrator, max_iterations=int(max_iterations))
        rows = integrator.max_iterations + 1 if record else 0
        out = DayArrays.empty(1, len(x), len(self.z), rows)
        # the day's own policy: with no minute before (previous demand 0) every policy starts
        # from the shares, so a minute runs the same compiled day loop as the day (one
        # compilation for both on the first run)
        self._integrate(x, np.array([minute]), out, integrator, self.policy)
        steps = int(out.iterations[0])
        trajectory = out.history[: steps + 1] if record else out.history
        return MinuteRun(trajectory, x, Status(int(out.status[0])), int(out.converged_at[0]),
                         int(out.first_congestion[0]), steps, out.states[0].copy())  # fmt: skip

    def run_day_chunk(self, x: np.ndarray, minutes: np.ndarray, out: DayArrays) -> None:
        """Run consecutive ``minutes`` (1-based) from shares ``x`` (updated in place)."""
        self._integrate(x, minutes, out, self.settings.stepping, self.policy)

    def _integrate(
        self, x: np.ndarray, minutes: np.ndarray, out: DayArrays, integrator, policy: WarmStart
    ) -> None:
        """The compiled day loop over ``minutes`` with ``integrator`` and warm start ``policy``
        (passed as a plain integer: numba types an IntEnum member slowly at every call)."""
        problem = self.problem
        rows = np.asarray(minutes) - 1
        day = DayInputs(
            problem.demand[rows], problem.load_flow[rows], problem.online[rows],
            int(policy), bool(self.mode.bounded), out.last_demand,
        )  # fmt: skip
        self.h_try, out.last_demand = integrate_day(
            x, self.z, self.term, self.params, day, self.ws, integrator.stepper(self.price_scale),
            integrator.stop_rule(self.z_cap), self.h_try, out.outputs(), self.day_scratch,
        )  # fmt: skip


def limited_flows_mw(problem: DispatchProblem, p_mw: np.ndarray, minute: int) -> np.ndarray:
    """Flows (MW) on the limited lines for set points ``p_mw`` (MW) at a 1-based minute."""
    if problem.meshed:
        return problem.flows(np.asarray(p_mw, dtype=float), minute)
    flow = np.empty(len(problem.limit))
    limited_line_flows(
        problem.load_flow[minute - 1], np.ascontiguousarray(p_mw, dtype=float),
        problem.generator_line, problem.line_up, problem.line_preorder, flow,
    )  # fmt: skip
    return flow


def overflow_kw(problem: DispatchProblem, p_mw: np.ndarray, minute: int) -> np.ndarray:
    """Overflow (kW) per limited line: ``max(|flow| - U, 0)`` for set points ``p_mw`` (MW)."""
    flows = limited_flows_mw(problem, p_mw, minute)
    return np.maximum(np.abs(flows) - problem.limit, 0.0) * KW_PER_MW
