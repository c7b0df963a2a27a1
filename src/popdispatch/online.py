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

from popdispatch.dynamics import DYNAMICS, GRAPHS, communication_graph, get_dynamics
from popdispatch.errors import OptionError
from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.flows import limited_line_flows
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.integrate import INFEASIBLE, Integrator, integrate, integrate_day, workspace
from popdispatch.modes import game_parameters, get_mode
from popdispatch.opf import generation_cost
from popdispatch.warm_start import SHARES, WARM_STARTS, warm_start

SHARES_NAME = "shares"  # the paper's warm start, the only one for modes without limits

X0_CHOICES = ("uniform", "capacity")


@dataclass(frozen=True)
class RunSettings:
    """What to run: dynamics, mode, communication graph, initial state, constants, integrator,
    warm start between minutes (``None``: the mode's default; see :mod:`popdispatch.warm_start`).

    Construction validates the combination without touching any data, so a command line can
    check its options before loading a feeder: bad values or combinations raise
    :class:`~popdispatch.errors.OptionError` with a one-line message naming them and the option
    to change (see :meth:`validate`).
    """

    dynamics: str = "smith"
    mode: str = "paper"
    graph: str | nx.Graph = "complete"
    x0: str | dict[str, float] = "uniform"
    fitness: FitnessParameters = field(default_factory=FitnessParameters)
    integrator: Integrator | None = None  # None: the mode's default
    warm_start: str | None = None

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`OptionError` for an unknown name or a combination that cannot run or
        would silently be ignored:

        - unknown ``dynamics`` (``--dynamics``), ``mode`` (``--mode``), ``graph``
          (``--graph``), ``x0`` name (``--x0``) or ``warm_start`` (``--warm-start``);
        - exact mode with imitative dynamics (replicator, local replicator): a generator at
          zero share stays there (extinction), so the DC-OPF is out of reach (``--mode``);
        - a graph other than ``complete`` with dynamics that ignore it (smith, replicator:
          paper eqs. 9 and 13 compare every pair) (``--graph``);
        - the ``setpoints`` warm start in a mode without generator limits in its revision rule
          (paper mode continues the shares, eq. 10's ``x``; ``--warm-start``).
        """
        dynamics = _lookup(get_dynamics, self.dynamics, "--dynamics")
        mode = _lookup(get_mode, self.mode, "--mode")
        if mode.bounded and dynamics.bounded_field is None:
            raise OptionError(
                f"{mode.name} mode cannot run {dynamics.name} dynamics: they are imitative, so a "
                "generator at zero share stays at zero (extinction) and the DC-OPF is out of "
                "reach whenever it uses one; use smith or distributed-smith",
                "--mode",
            )
        graph = self.graph if isinstance(self.graph, str) else "custom"
        if isinstance(self.graph, str) and self.graph not in GRAPHS:
            raise OptionError(
                f"unknown communication graph {graph!r} (known: {', '.join(GRAPHS)})", "--graph"
            )
        if graph != "complete" and not dynamics.uses_graph:
            users = " or ".join(d.name for d in DYNAMICS.values() if d.uses_graph)
            raise OptionError(
                f"graph {graph!r} has no effect on {dynamics.name} dynamics, which compare every "
                f"pair of generators; use it with {users}, or leave the graph complete",
                "--graph",
            )
        if isinstance(self.x0, str) and self.x0 not in X0_CHOICES:
            raise OptionError(
                f"unknown initial state {self.x0!r} (known: {', '.join(X0_CHOICES)}, or "
                "shares per generator)",
                "--x0",
            )
        self._validate_warm_start(mode)

    def _validate_warm_start(self, mode) -> None:
        if self.warm_start is None:
            return
        if self.warm_start not in WARM_STARTS:
            raise OptionError(
                f"unknown warm start {self.warm_start!r} (known: {', '.join(WARM_STARTS)})",
                "--warm-start",
            )
        if self.warm_start != SHARES_NAME and not mode.bounded:
            raise OptionError(
                f"warm start {self.warm_start!r} needs a mode with generator limits in its "
                f"revision rule (exact); {mode.name} mode continues the shares",
                "--warm-start",
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

    Status semantics: ``converged`` means the dynamics came to rest (the stopping rule of
    :mod:`popdispatch.integrate`) and, in a mode that claims the DC-OPF (exact), that the end
    state passes the DC-OPF's KKT check (:func:`kkt_violations`). A run of such a mode that
    came to rest at a state failing the check is ``stalled``: ``converged_at`` is then None,
    ``rest_at`` the iteration it came to rest and ``stall_reason`` says which condition failed.
    Paper mode claims only a rest point of the paper's dynamics (its rules do not land on the
    DC-OPF, docs/paper-mode.md), so its ``converged`` is never checked against the KKT system.
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
    stall_reason: str | None = None
    rest_at: int | None = None

    @property
    def setpoints_kw(self) -> np.ndarray:
        return self.trajectory_kw[-1]

    @property
    def status(self) -> str:
        """``"converged"``, ``"stalled"`` (at rest, not the DC-OPF: see ``stall_reason``),
        ``"not_converged"`` or ``"infeasible"`` (prices ran away)."""
        if self.infeasible:
            return "infeasible"
        if self.stall_reason is not None:
            return "stalled"
        return "converged" if self.converged_at is not None else "not_converged"

    @property
    def iterations(self) -> int:
        return len(self.trajectory_kw) - 1


def _lookup(get: Callable, name: str, option: str):
    """``get(name)``, its ``ValueError`` (unknown name) re-raised as :class:`OptionError`."""
    try:
        return get(name)
    except ValueError as error:
        raise OptionError(str(error), option) from None


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

    @property
    def kkt_tolerances(self) -> KktTolerances:
        """Tolerances of the KKT check, from the integrator in force and the revision gain."""
        return KktTolerances.of(self.settings.stepping, self.settings.fitness.gain)

    def stall_reasons(
        self, minutes: np.ndarray, p_mw: np.ndarray, z: np.ndarray, rested: np.ndarray
    ) -> list[str | None]:
        """Per minute: why a run that came to rest (``rested``) is not at the DC-OPF, in a
        mode that claims it (else None everywhere)."""
        reasons: list[str | None] = [None] * len(minutes)
        if not self.mode.claims_dc_opf or not np.any(rested):
            return reasons
        rows = np.flatnonzero(rested)
        checked = kkt_violations(self.problem, minutes[rows], p_mw[rows], z[rows],
                                 self.kkt_tolerances, self.settings.fitness.C)  # fmt: skip
        for r, reason in zip(rows, checked, strict=True):
            reasons[r] = reason
        return reasons

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
        self.run_day_chunk(x.copy(), np.array([minute]), _DayArrays.empty(1, len(x), len(z)))
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
    states: np.ndarray  # controller states at each minute's end (exact mode's prices)
    last_demand: float = 0.0

    @classmethod
    def empty(cls, minutes: int, n: int, n_states: int) -> _DayArrays:
        return cls(
            np.zeros((minutes, n)), np.zeros(minutes, np.int64), np.zeros(minutes, np.int64),
            np.zeros((minutes, n_states)),
        )  # fmt: skip

    def chunk_views(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.setpoints, self.iterations, self.converged_at, self.states


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


@dataclass(frozen=True)
class KktTolerances:
    """Tolerances of the DC-OPF KKT check, derived from the integrator that ran (see
    :func:`kkt_violations`). ``power_mw``: on bounds, overflow and slack, MW; ``flow_gap``:
    on marginal-cost gap times movable power, EUR/MW * MW (= EUR/h); ``price``: on the net
    price of one limited line, EUR/MW."""

    power_mw: float
    flow_gap: float
    price: float

    @classmethod
    def of(cls, integrator: Integrator, gain: float) -> KktTolerances:
        """``power_mw = tol_kw``; ``flow_gap = tol_kw / (gain * window * dt)``; ``price =
        2 price_atol`` (see :func:`kkt_violations`)."""
        tol_mw = integrator.tol_kw / KW_PER_MW
        flow_gap = tol_mw / (max(gain, 1e-300) * integrator.window * integrator.dt)
        return cls(tol_mw, flow_gap, 2.0 * integrator.price_atol)


def kkt_violations(
    problem: DispatchProblem,
    minutes: np.ndarray,
    p_mw: np.ndarray,
    z: np.ndarray,
    tol: KktTolerances,
    C: float = 0.0,
) -> list[str | None]:
    """Per minute, why set points ``p_mw`` (minutes x generators, MW) and controller prices
    ``z`` (minutes x 2 limited lines, EUR/MW: upward then downward) are *not* a KKT point of the
    DC-OPF (paper eq. 1), or ``None`` where they are, within ``tol``.

    The candidate duals are the prices the controllers broadcast, ``mu = max(0, z + C e)``
    per line-direction with excess ``e`` (``flow - U`` upward, ``-flow - U`` downward; ``C``
    the proportional part, EUR/MW per MW: at a state within ``tol_kw`` of the limit it shifts
    a price by up to ``C tol_kw``, which the dynamics do see). With ``nu = mu_up - mu_down``
    and ``D_ki = 1`` for generator ``i`` below line ``k``, the locational marginal cost is
    ``lmc_i = b_i + 2 c_i p_i - (D^T nu)_i`` (EUR/MW; the exact mode's fitness is
    ``gain * (B - lmc_i)`` up to a constant, docs/exact-mode.md). KKT of eq. 1 (flows
    ``load_flow - D p``):

    1. primal feasibility: ``Pmin <= p <= Pmax`` and ``|flow_k| <= U_k``, within ``power_mw``;
    2. dual feasibility and complementarity: ``z >= 0`` (the controllers project), and a
       positive price only on a line-direction at its limit (slack at most ``power_mw``);
    3. stationarity: one value ``lambda`` with ``lmc_i = lambda`` for generators strictly
       inside their limits, ``lmc_i <= lambda`` at Pmax and ``>= lambda`` at Pmin. Equivalently
       no *giver* ``j`` (above Pmin by more than ``power_mw``) has a higher ``lmc`` than a
       *taker* ``i`` (below Pmax by more than ``power_mw``).

    Tolerance of 3: on the complete graph the capacity-constrained Smith dynamics move power
    from giver ``j`` to the cheapest taker ``i`` at ``gain * (lmc_j - lmc_i) * (p_j - Pmin_j)``
    MW/s (receiver weight 1, sender weight its movable power), and ``i`` only receives. The
    stopping rule accepts a state whose window means move at most ``tol_kw`` per window of
    ``window * dt`` seconds; so every giver-taker pair of a state it may accept has
    ``(lmc_j - lmc_i) (p_j - Pmin_j) <= tol_kw / (gain * window * dt)`` = ``flow_gap``. A gap
    beyond that is a pair the complete graph would still trade: the state is a rest point of
    the run's dynamics (e.g. distributed Smith on a sparse graph) but not the DC-OPF. Prices
    are resolved only to the Heun error control's ``price_atol`` (EUR/MW), so the net price
    of a line (two such states) is known to ``price = 2 price_atol``; a pair separated by
    ``s`` limited lines may differ by ``s * price`` more (measured: a converged random feeder
    left 1.3e-5 EUR/MW across a binding line while its set points were within 4e-6 kW of the
    DC-OPF; the ring rest point of minute 566 leaves 1.0 EUR/MW). The powers' tolerance is
    the convergence criterion's residual, ``tol_kw``.
    """
    rows = np.asarray(minutes, dtype=np.int64) - 1
    p_mw, z = np.atleast_2d(p_mw), np.atleast_2d(z)
    n_lines = len(problem.limit)
    down = problem.down
    flow = problem.load_flow[rows] - p_mw @ down.T
    excess = np.concatenate([flow - problem.limit, -flow - problem.limit], axis=1)
    mu = np.maximum(0.0, z + C * excess)
    nu = mu[:, :n_lines] - mu[:, n_lines:]
    lmc = problem.b + 2.0 * problem.c * p_mw - nu @ down
    online = problem.online[rows]
    lo = np.where(online, problem.pmin, 0.0)
    hi = np.where(online, problem.pmax, 0.0)
    reasons: list[str | None] = []
    for r in range(len(rows)):
        reasons.append(
            _bounds_violation(problem, p_mw[r], lo[r], hi[r], tol)
            or _price_violation(problem, flow[r], mu[r], tol)
            or _stationarity_violation(problem, p_mw[r], lmc[r], (lo[r], hi[r]), online[r], tol)
        )
    return reasons


def _bounds_violation(problem, p, lo, hi, tol: KktTolerances) -> str | None:
    outside = (p < lo - tol.power_mw) | (p > hi + tol.power_mw)
    if not outside.any():
        return None
    i = int(np.argmax(outside))
    return (
        f"{problem.generators[i]} at {p[i] * KW_PER_MW:.6g} kW is outside its limits "
        f"[{lo[i] * KW_PER_MW:g}, {hi[i] * KW_PER_MW:g}] kW"
    )


def _line_name(problem: DispatchProblem, k: int) -> str:
    row = problem.feeder.lines.iloc[int(problem.lines[k])]
    return f"line {int(row.from_bus)}-{int(row.to_bus)}"


def _price_violation(problem, flow, z, tol: KktTolerances) -> str | None:
    n_lines = len(problem.limit)
    for k in range(n_lines):
        for sign, price, direction in ((1.0, z[k], "+"), (-1.0, z[n_lines + k], "-")):
            excess = sign * flow[k] - problem.limit[k]
            if excess > tol.power_mw:
                return f"{_line_name(problem, k)} is {excess * KW_PER_MW:.3g} kW over its limit"
            if price > 0.0 and excess < -tol.power_mw:
                return (
                    f"{_line_name(problem, k)} has price {price:.4g} EUR/MWh ({direction}) but "
                    f"is {-excess * KW_PER_MW:.3g} kW below its limit"
                )
    return None


def _where(p, lo, hi, i, tol: KktTolerances) -> str:
    if p[i] >= hi[i] - tol.power_mw:
        return "at Pmax"
    return "at Pmin" if p[i] <= lo[i] + tol.power_mw else "interior"


def _stationarity_violation(problem, p, lmc, limits, online, tol: KktTolerances) -> str | None:
    lo, hi = limits
    givers = online & (p > lo + tol.power_mw)
    takers = online & (p < hi - tol.power_mw)
    if not givers.any() or not takers.any():
        return None
    i = int(np.flatnonzero(takers)[np.argmin(lmc[takers])])
    separating = np.abs(problem.down - problem.down[:, [i]]).sum(axis=0)
    movable = np.maximum(p - lo, tol.power_mw)
    allowed = separating * tol.price + tol.flow_gap / movable
    excess = np.where(givers, lmc - lmc[i] - allowed, -np.inf)
    j = int(np.argmax(excess))
    if excess[j] <= 0.0:
        return None
    names = problem.generators
    return (
        f"rest point is not a KKT point of the DC-OPF: {names[j]} {_where(p, lo, hi, j, tol)} "
        f"has marginal cost {lmc[j]:.6f} EUR/MWh (with line prices) above the "
        f"{lmc[i]:.6f} of {names[i]} {_where(p, lo, hi, i, tol)}, which could take more"
    )


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
    rested = converged_at >= 0
    reason = engine.stall_reasons(np.array([minute]), final[None], engine.z[None],
                                  np.array([rested]))[0]  # fmt: skip
    return SnapshotResult(
        minute=minute,
        demand_kw=float(problem.demand[minute - 1] * KW_PER_MW),
        settings=settings,
        generators=problem.generators,
        trajectory_kw=setpoints * KW_PER_MW,
        converged_at=int(converged_at) if rested and reason is None else None,
        first_congestion=None if first_congestion < 0 else int(first_congestion),
        overflow_kw=overflow_kw(problem, final, minute),
        flows_kw=flows * KW_PER_MW,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=converged_at == INFEASIBLE,
        stall_reason=reason,
        rest_at=int(converged_at) if rested else None,
    )


@dataclass(frozen=True)
class DayResult:
    """An online day. Arrays have one row per simulated minute; powers in kW.

    ``setpoints_kw`` (minutes, generators); ``iterations`` and ``converged`` per minute;
    ``overflow_kw`` (minutes, limited lines); ``cost`` per minute (EUR/h, Table I's units).
    ``wall_seconds`` is the engine's own time (no imports, data loading or DC-OPF).

    Per minute, as for a snapshot (:class:`SnapshotResult`): ``converged`` means at rest and,
    in a mode that claims the DC-OPF, passing its KKT check; ``stalled`` means at rest but
    failing it (``stall_reasons`` maps such 1-based minutes to the reason). A stalled minute
    is never counted as converged.
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
    stalled: np.ndarray | None = None
    stall_reasons: dict[int, str] = field(default_factory=dict)

    @property
    def status(self) -> str:
        """``"infeasible"`` if any minute was, else ``"converged"`` if every minute converged,
        else ``"stalled"`` if some minute came to rest away from the DC-OPF, else
        ``"not_converged"``."""
        if self.infeasible is not None and self.infeasible.any():
            return "infeasible"
        if self.converged.all():
            return "converged"
        if self.stalled is not None and self.stalled.any():
            return "stalled"
        return "not_converged"


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
    out = _DayArrays.empty(len(minutes), problem.n_generators, len(engine.z))
    chunk = PROGRESS_CHUNK if progress is not None else len(minutes)
    start = time.perf_counter()
    for first in range(0, len(minutes), chunk):
        part = slice(first, first + chunk)
        view = _DayArrays(
            out.setpoints[part], out.iterations[part], out.converged_at[part], out.states[part],
            out.last_demand,
        )  # fmt: skip
        engine.run_day_chunk(x, minutes[part], view)
        out.last_demand = view.last_demand
        if progress is not None:
            for minute in minutes[part]:
                progress(int(minute))
    wall = time.perf_counter() - start
    setpoints = out.setpoints
    overflow = np.stack([overflow_kw(problem, setpoints[r], m) for r, m in enumerate(minutes)])
    online = problem.online[minutes - 1]
    rested = out.converged_at >= 0
    reasons = engine.stall_reasons(minutes, setpoints, out.states, rested)
    stalled = np.array([r is not None for r in reasons], dtype=bool)
    return DayResult(
        minutes=minutes,
        settings=settings,
        generators=problem.generators,
        demand_kw=problem.demand[minutes - 1] * KW_PER_MW,
        setpoints_kw=setpoints * KW_PER_MW,
        iterations=out.iterations,
        converged=rested & ~stalled,
        overflow_kw=overflow,
        cost=generation_cost(problem, setpoints, online),
        online=online,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=out.converged_at == INFEASIBLE,
        stalled=stalled,
        stall_reasons={int(m): r for m, r in zip(minutes, reasons, strict=True) if r},
    )
