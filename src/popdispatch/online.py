"""Running the population game: one minute (snapshot) or the online day.

Online: each minute the demand changes and the dynamics continue from where they were (warm
start, :mod:`popdispatch.warm_start`: the paper continues the shares, ``p = x * P_d`` with the
new ``P_d``; exact mode by default continues the set points). Generators may go off- and
on-line at given minutes; the mass of a generator that trips is handed to the online generators
in proportion to their shares, and the offline one takes no part in any revision until it
returns (at zero share; imitative dynamics cannot bring it back: extinction).

The day runs as one compiled loop (:func:`popdispatch.integrate.integrate_day`), called in
chunks of minutes so that progress can be reported; a day keeps only per-minute arrays.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import networkx as nx
import numpy as np
import pandas as pd
from scipy import sparse

from popdispatch.dynamics import communication_graph, get_dynamics
from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.flows import limited_line_flows
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.integrate import INFEASIBLE, Integrator, integrate, integrate_day, workspace
from popdispatch.modes import game_parameters, get_mode
from popdispatch.opf import generation_cost
from popdispatch.warm_start import SHARES, WARM_STARTS, warm_start

X0_CHOICES = ("uniform", "capacity")


@dataclass(frozen=True)
class RunSettings:
    """What to run: dynamics, mode, communication graph, initial state, constants, integrator,
    warm start between minutes (``None``: the mode's default; see :mod:`popdispatch.warm_start`).
    """

    dynamics: str = "smith"
    mode: str = "paper"
    graph: str | nx.Graph = "complete"
    x0: str | dict[str, float] = "uniform"
    fitness: FitnessParameters = field(default_factory=FitnessParameters)
    integrator: Integrator | None = None  # None: the mode's default
    warm_start: str | None = None

    def __post_init__(self) -> None:
        if self.warm_start is not None and self.warm_start not in WARM_STARTS:
            raise ValueError(
                f"unknown warm start {self.warm_start!r} (known: {', '.join(WARM_STARTS)})"
            )

    @property
    def stepping(self) -> Integrator:
        """The integrator in force: the given one, else the mode's default."""
        return self.integrator or get_mode(self.mode).integrator

    @property
    def warm_start_policy(self) -> str:
        """The warm start in force: the given one, else the mode's default."""
        return self.warm_start or get_mode(self.mode).warm_start

    def x0_label(self) -> str:
        if isinstance(self.x0, str):
            return self.x0
        return ",".join(f"{k}={v:g}" for k, v in self.x0.items())


@dataclass(frozen=True)
class SnapshotResult:
    """One minute of dynamics. Powers in kW.

    ``trajectory_kw``: set points per iteration (rows 0..last, columns generators);
    ``converged_at`` / ``first_congestion``: iterations (None if never);
    ``overflow_kw``: final overflow per limited line (max(|flow| - U, 0)).
    """

    minute: int
    demand_kw: float
    settings: RunSettings
    generators: pd.Index
    trajectory_kw: np.ndarray
    converged_at: int | None
    first_congestion: int | None
    overflow_kw: np.ndarray
    flows_kw: np.ndarray
    wall_seconds: float
    profile_source: str
    infeasible: bool = False

    @property
    def setpoints_kw(self) -> np.ndarray:
        return self.trajectory_kw[-1]

    @property
    def status(self) -> str:
        """``"converged"``, ``"not_converged"`` or ``"infeasible"`` (prices ran away)."""
        if self.infeasible:
            return "infeasible"
        return "converged" if self.converged_at is not None else "not_converged"

    @property
    def iterations(self) -> int:
        return len(self.trajectory_kw) - 1


def initial_shares(problem: DispatchProblem, x0: str | dict[str, float], minute: int) -> np.ndarray:
    """Initial shares over the generators online at ``minute``.

    ``"uniform"``: equal shares; ``"capacity"``: proportional to Pmax; a mapping
    ``{generator: share}``: given shares (missing ones 0), normalised to sum 1.
    """
    online = problem.online[minute - 1]
    if isinstance(x0, dict):
        unknown = set(x0) - set(problem.generators)
        if unknown:
            raise ValueError(f"initial share given for unknown generator {sorted(unknown)[0]!r}")
        x = np.array([float(x0.get(g, 0.0)) for g in problem.generators])
        if (x < 0).any() or not np.isfinite(x).all():
            raise ValueError("initial shares must be finite and non-negative")
    elif x0 == "uniform":
        x = np.ones(problem.n_generators)
    elif x0 == "capacity":
        x = problem.pmax.copy()
    else:
        raise ValueError(f"unknown initial state {x0!r} (known: {', '.join(X0_CHOICES)})")
    x = np.where(online, x, 0.0)
    if x.sum() <= 0:
        raise ValueError("initial shares are all zero on the online generators")
    return x / x.sum()


class Engine:
    """The compiled pieces of one run configuration, reused minute after minute."""

    def __init__(self, problem: DispatchProblem, settings: RunSettings):
        self.problem = problem
        self.settings = settings
        self.dynamics = get_dynamics(settings.dynamics)
        self.mode = get_mode(settings.mode)
        self.field = self.dynamics.bounded_field if self.mode.bounded else self.dynamics.field
        if self.field is None:
            raise ValueError(
                f"{self.mode.name} mode cannot run {self.dynamics.name} dynamics: they are "
                "imitative, so a generator at zero share stays at zero (extinction) and the "
                "DC-OPF is out of reach whenever it uses one; use smith or distributed-smith"
            )
        self.rules = (self.field, self.mode.code, *self._graph())
        self.z = np.zeros(self.mode.controller_states(problem))
        self.z_cap = self.mode.price_cap(problem) if self.mode.bounded else np.inf
        integrator = settings.stepping
        self.kernel_settings = self._kernel_settings(integrator)
        self.ws = workspace(
            problem.n_generators, len(problem.limit), len(self.z), integrator.window
        )
        self.h_try = integrator.dt

    def _kernel_settings(self, integrator: Integrator) -> tuple:
        return integrator.settings(integrator.tol_kw / KW_PER_MW, self.z_cap)

    def _graph(self) -> tuple[bool, np.ndarray, np.ndarray]:
        """``(complete?, indptr, indices)`` of the communication graph (CSR)."""
        names = list(self.problem.generators)
        if not self.dynamics.uses_graph or self.settings.graph == "complete":
            communication_graph("complete", names)  # validates the names
            empty = np.zeros(0, dtype=np.int64)
            return True, empty, empty
        adjacency = sparse.csr_matrix(communication_graph(self.settings.graph, names))
        return False, adjacency.indptr.astype(np.int64), adjacency.indices.astype(np.int64)

    def _minute_problem(self, minute: int) -> tuple:
        problem = self.problem
        online = problem.online[minute - 1]
        demand = float(problem.demand[minute - 1])
        lo = np.where(online, problem.pmin, 0.0) / demand
        hi = np.where(online, problem.pmax, 0.0) / demand
        params = game_parameters(problem, minute, self.settings.fitness)
        return params, lo, hi, online

    def warm_up(self, x: np.ndarray, minute: int) -> None:
        """Compile (or load from the disk cache) the kernels outside any timed region."""
        z, h_try = self.z.copy(), self.h_try
        self.run_minute(x.copy(), minute, max_iterations=1)
        self.run_day_chunk(x.copy(), np.array([minute]), _DayArrays.empty(1, len(x)))
        self.z, self.h_try = z, h_try

    def run_minute(
        self, x: np.ndarray, minute: int, max_iterations: int | None = None, record: bool = True
    ) -> tuple[np.ndarray, np.ndarray, int, int]:
        """Integrate one minute from shares ``x`` at the given minute's demand (no warm-start
        step: ``x`` is projected onto the limits in bounded modes).

        Returns ``(setpoints per iteration (MW), final shares, converged_at,
        first_congestion)``; without ``record`` no per-iteration history is kept and the
        first element is the number of iterations run instead.
        """
        x = np.array(x, dtype=float)
        demand = float(self.problem.demand[minute - 1])
        online = self.problem.online[minute - 1]
        weight = np.empty_like(x)
        warm_start(SHARES, self.mode.bounded, x, 0.0, demand, self.problem.pmin,
                   self.problem.pmax, online, weight)  # fmt: skip
        integrator = self.settings.stepping
        if max_iterations is not None:
            integrator = replace(integrator, max_iterations=int(max_iterations))
        settings = self._kernel_settings(integrator)
        history = np.empty((integrator.max_iterations + 1 if record else 0, len(x)))
        steps, converged_at, first_congestion, self.h_try = integrate(
            x, self.z, demand, self.rules, self._minute_problem(minute), self.ws, settings,
            self.h_try, history,
        )  # fmt: skip
        if not record:
            return steps, x, converged_at, first_congestion
        return history[: steps + 1], x, converged_at, first_congestion

    def run_day_chunk(self, x: np.ndarray, minutes: np.ndarray, out: _DayArrays) -> None:
        """Run consecutive ``minutes`` (1-based) from shares ``x`` (updated in place)."""
        problem = self.problem
        rows = minutes - 1
        params = game_parameters(problem, int(minutes[0]), self.settings.fitness)
        policy = WARM_STARTS[self.settings.warm_start_policy]
        day = (
            params, problem.demand[rows], problem.load_flow[rows], problem.online[rows],
            problem.pmin, problem.pmax, self.mode.bounded, policy, out.last_demand,
        )  # fmt: skip
        self.h_try, out.last_demand = integrate_day(
            x, self.z, self.rules, day, self.ws, self.kernel_settings, self.h_try,
            0, len(minutes), out.chunk_views(),
        )  # fmt: skip


@dataclass
class _DayArrays:
    """Per-minute outputs of a chunk of the compiled day loop."""

    setpoints: np.ndarray
    iterations: np.ndarray
    converged_at: np.ndarray
    last_demand: float = 0.0

    @classmethod
    def empty(cls, minutes: int, n: int) -> _DayArrays:
        return cls(
            np.zeros((minutes, n)), np.zeros(minutes, np.int64), np.zeros(minutes, np.int64)
        )

    def chunk_views(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.setpoints, self.iterations, self.converged_at


def limited_flows_mw(problem: DispatchProblem, p_mw: np.ndarray, minute: int) -> np.ndarray:
    """Flows (MW) on the limited lines for set points ``p_mw`` (MW) at a 1-based minute."""
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


def run_snapshot(
    problem: DispatchProblem, minute: int, settings: RunSettings | None = None
) -> SnapshotResult:
    """Run the dynamics for one minute from ``settings.x0`` until converged or the horizon."""
    settings = settings or RunSettings()
    engine = Engine(problem, settings)
    x = initial_shares(problem, settings.x0, minute)
    engine.warm_up(x, minute)
    start = time.perf_counter()
    setpoints, x, converged_at, first_congestion = engine.run_minute(x, minute)
    wall = time.perf_counter() - start
    final = setpoints[-1]
    flows = limited_flows_mw(problem, final, minute)
    return SnapshotResult(
        minute=minute,
        demand_kw=float(problem.demand[minute - 1] * KW_PER_MW),
        settings=settings,
        generators=problem.generators,
        trajectory_kw=setpoints * KW_PER_MW,
        converged_at=None if converged_at < 0 else int(converged_at),
        first_congestion=None if first_congestion < 0 else int(first_congestion),
        overflow_kw=overflow_kw(problem, final, minute),
        flows_kw=flows * KW_PER_MW,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=converged_at == INFEASIBLE,
    )


@dataclass(frozen=True)
class DayResult:
    """An online day. Arrays have one row per simulated minute; powers in kW.

    ``setpoints_kw`` (minutes, generators); ``iterations`` and ``converged`` per minute;
    ``overflow_kw`` (minutes, limited lines); ``cost`` per minute (EUR/h, Table I's units).
    ``wall_seconds`` is the engine's own time (no imports, data loading or DC-OPF).
    """

    minutes: np.ndarray
    settings: RunSettings
    generators: pd.Index
    demand_kw: np.ndarray
    setpoints_kw: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    overflow_kw: np.ndarray
    cost: np.ndarray
    online: np.ndarray
    wall_seconds: float
    profile_source: str
    infeasible: np.ndarray | None = None

    @property
    def status(self) -> str:
        """``"infeasible"`` if any minute was, ``"converged"`` if every minute converged."""
        if self.infeasible is not None and self.infeasible.any():
            return "infeasible"
        return "converged" if self.converged.all() else "not_converged"


#: Minutes per call of the compiled day loop when progress is reported.
PROGRESS_CHUNK = 60


def run_day(
    problem: DispatchProblem,
    settings: RunSettings | None = None,
    minutes: np.ndarray | None = None,
    progress: Callable[[int], None] | None = None,
) -> DayResult:
    """The online day: every minute continues from the previous state until converged.

    ``minutes``: 1-based minutes to simulate in order (default the whole day 1..1440); each
    minute warm-starts from the state the previous simulated minute ended in.
    ``progress``: called with each minute once it is done (e.g. to advance a progress bar);
    the compiled loop then runs in chunks of :data:`PROGRESS_CHUNK` minutes.
    """
    settings = settings or RunSettings()
    minutes = np.arange(1, len(problem.demand) + 1) if minutes is None else np.asarray(minutes)
    minutes = minutes.astype(np.int64)
    engine = Engine(problem, settings)
    x = initial_shares(problem, settings.x0, int(minutes[0]))
    engine.warm_up(x, int(minutes[0]))
    out = _DayArrays.empty(len(minutes), problem.n_generators)
    chunk = PROGRESS_CHUNK if progress is not None else len(minutes)
    start = time.perf_counter()
    for first in range(0, len(minutes), chunk):
        part = slice(first, first + chunk)
        view = _DayArrays(
            out.setpoints[part], out.iterations[part], out.converged_at[part], out.last_demand
        )
        engine.run_day_chunk(x, minutes[part], view)
        out.last_demand = view.last_demand
        if progress is not None:
            for minute in minutes[part]:
                progress(int(minute))
    wall = time.perf_counter() - start
    setpoints = out.setpoints
    overflow = np.stack([overflow_kw(problem, setpoints[r], m) for r, m in enumerate(minutes)])
    online = problem.online[minutes - 1]
    return DayResult(
        minutes=minutes,
        settings=settings,
        generators=problem.generators,
        demand_kw=problem.demand[minutes - 1] * KW_PER_MW,
        setpoints_kw=setpoints * KW_PER_MW,
        iterations=out.iterations,
        converged=out.converged_at >= 0,
        overflow_kw=overflow,
        cost=generation_cost(problem, setpoints, online),
        online=online,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=out.converged_at == INFEASIBLE,
    )
