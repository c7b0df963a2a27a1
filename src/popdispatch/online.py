"""Running the population game: one minute (snapshot) or the online day.

Online: each minute the demand changes and the dynamics continue from the shares they had
(warm start: ``p = x * P_d`` with the new ``P_d``). Generators may go off- and on-line at given
minutes; the mass of a generator that trips is handed to the online generators in proportion
to their shares, and the offline one is cut out of the communication graph until it returns
(at zero share; imitative dynamics cannot bring it back: extinction).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
import pandas as pd

from popdispatch.dynamics import communication_graph, get_dynamics, project_to_box
from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.integrate import INFEASIBLE, Integrator, integrate
from popdispatch.modes import game_parameters, get_mode
from popdispatch.opf import generation_cost

X0_CHOICES = ("uniform", "capacity")


@dataclass(frozen=True)
class RunSettings:
    """What to run: dynamics, mode, communication graph, initial state, constants, integrator."""

    dynamics: str = "smith"
    mode: str = "paper"
    graph: str | nx.Graph = "complete"
    x0: str | dict[str, float] = "uniform"
    fitness: FitnessParameters = field(default_factory=FitnessParameters)
    integrator: Integrator | None = None  # None: the mode's default

    @property
    def stepping(self) -> Integrator:
        """The integrator in force: the given one, else the mode's default."""
        return self.integrator or get_mode(self.mode).integrator

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
        names = list(problem.generators)
        self.graph = communication_graph(
            settings.graph if self.dynamics.uses_graph else "complete", names
        )
        self.field = self.dynamics.bounded_field if self.mode.bounded else self.dynamics.field
        if self.field is None:
            raise ValueError(
                f"{self.mode.name} mode cannot run {self.dynamics.name} dynamics: they are "
                "imitative, so a generator at zero share stays at zero (extinction) and the "
                "DC-OPF is out of reach whenever it uses one; use smith or distributed-smith"
            )
        self.z = np.zeros(self.mode.controller_states(problem))
        self.z_cap = self.mode.price_cap(problem) if self.mode.bounded else np.inf

    def warm_up(self, x: np.ndarray, minute: int) -> None:
        """Compile (or load from the disk cache) the kernels outside any timed region."""
        z = self.z.copy()
        self.run_minute(x.copy(), minute, max_iterations=1)
        self.z = z

    def run_minute(self, x: np.ndarray, minute: int, max_iterations: int | None = None):
        """Integrate one minute from shares ``x``; returns the kernel's raw outputs."""
        problem, settings = self.problem, self.settings
        integrator = settings.stepping
        online = problem.online[minute - 1]
        graph = self.graph * online[:, None] * online[None, :]
        demand = float(problem.demand[minute - 1])
        lo = np.where(online, problem.pmin, 0.0) / demand
        hi = np.where(online, problem.pmax, 0.0) / demand
        if self.mode.bounded:
            x = project_to_box(x, lo, hi)
        params = game_parameters(problem, minute, settings.fitness)
        out = integrate(
            self.field,
            self.mode.code,
            x,
            self.z,
            demand,
            graph,
            lo,
            hi,
            params,
            integrator.dt,
            integrator.method_code,
            integrator.substeps,
            (integrator.rtol, integrator.atol, integrator.price_atol),
            integrator.tol_kw / KW_PER_MW,
            integrator.window,
            max_iterations or integrator.max_iterations,
            self.z_cap,
            integrator.extrapolate,
        )
        setpoints, x, self.z, converged_at, first_congestion = out
        return setpoints, x, converged_at, first_congestion


def overflow_kw(problem: DispatchProblem, p_mw: np.ndarray, minute: int) -> np.ndarray:
    """Overflow (kW) per limited line: ``max(|flow| - U, 0)``; ``p_mw`` may be (..., n)."""
    flows = problem.load_flow[minute - 1] - p_mw @ problem.down.T
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
    flows = problem.load_flow[minute - 1] - problem.down @ final
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


def redistribute_tripped(x: np.ndarray, online: np.ndarray) -> np.ndarray:
    """Hand the shares of offline generators to online ones, in proportion to their shares."""
    kept = np.where(online, x, 0.0)
    total = kept.sum()
    if total <= 0:
        kept = online.astype(float)
        total = kept.sum()
    return kept / total


def run_day(
    problem: DispatchProblem,
    settings: RunSettings | None = None,
    minutes: np.ndarray | None = None,
    progress: Callable[[int], None] | None = None,
) -> DayResult:
    """The online day: every minute continues from the previous state until converged.

    ``minutes``: 1-based minutes to simulate in order (default the whole day 1..1440).
    ``progress``: called with each minute once it is done (e.g. to advance a progress bar).
    """
    settings = settings or RunSettings()
    minutes = np.arange(1, len(problem.demand) + 1) if minutes is None else np.asarray(minutes)
    engine = Engine(problem, settings)
    n = problem.n_generators
    setpoints = np.empty((len(minutes), n))
    iterations = np.empty(len(minutes), dtype=np.int64)
    converged = np.empty(len(minutes), dtype=bool)
    infeasible = np.zeros(len(minutes), dtype=bool)
    x = initial_shares(problem, settings.x0, int(minutes[0]))
    engine.warm_up(x, int(minutes[0]))
    start = time.perf_counter()
    for row, minute in enumerate(minutes):
        online = problem.online[minute - 1]
        if (x[~online] > 0).any():
            x = redistribute_tripped(x, online)
        trajectory, x, converged_at, _ = engine.run_minute(x, int(minute))
        setpoints[row] = trajectory[-1]
        iterations[row] = len(trajectory) - 1
        converged[row] = converged_at >= 0
        infeasible[row] = converged_at == INFEASIBLE
        if progress is not None:
            progress(int(minute))
    wall = time.perf_counter() - start
    overflow = np.stack([overflow_kw(problem, setpoints[r], m) for r, m in enumerate(minutes)])
    online = problem.online[minutes - 1]
    return DayResult(
        minutes=minutes,
        settings=settings,
        generators=problem.generators,
        demand_kw=problem.demand[minutes - 1] * KW_PER_MW,
        setpoints_kw=setpoints * KW_PER_MW,
        iterations=iterations,
        converged=converged,
        overflow_kw=overflow,
        cost=generation_cost(problem, setpoints, online),
        online=online,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=infeasible,
    )
