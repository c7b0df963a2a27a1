"""Running the population game: one minute (snapshot) or the online day.

Online: each minute the demand changes and the dynamics continue from where they were (warm
start, :mod:`popdispatch.warm_start`: the paper continues the shares, ``p = x * P_d`` with the
new ``P_d``; exact mode by default continues the set points). Generators may go off- and
on-line at given minutes; the mass of a generator that trips is handed to the online generators
in proportion to their shares, and the offline one takes no part in any revision until it
returns (at zero share; imitative dynamics cannot bring it back: extinction).

- :mod:`~popdispatch.online.settings`: :class:`RunSettings`, :func:`initial_shares`;
- :mod:`~popdispatch.online.engine`: :class:`Engine`, the compiled pieces of a configuration;
- :mod:`~popdispatch.online.day`: the day loop, one compiled loop over minutes, called in
  chunks so that progress can be reported; a day keeps only per-minute arrays;
- :mod:`~popdispatch.online.kkt`: the DC-OPF's KKT check of an end state;
- here: :func:`run_snapshot`, :func:`run_day` and their results.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.integrate import Status
from popdispatch.online.day import DayArrays
from popdispatch.online.engine import Engine, MinuteRun, limited_flows_mw, overflow_kw
from popdispatch.online.kkt import KktTolerances, kkt_violations, net_prices
from popdispatch.online.settings import SHARES_NAME, X0_CHOICES, RunSettings, initial_shares
from popdispatch.opf import generation_cost


@dataclass(frozen=True)
class SnapshotResult:
    """One minute of dynamics. Powers in kW.

    ``trajectory_kw``: set points per iteration (rows 0..last, columns generators);
    ``converged_at`` / ``first_congestion``: iterations (None if never);
    ``overflow_kw``: final overflow per limited line (max(|flow| - U, 0)).
    ``evaluations``: of the game and field, in the run (the integrator's cost).
    ``line_price_eur_per_mwh`` (per limited line) and ``voltage_price_eur_per_mwh`` (per
    monitored bus): the prices the engine's controllers broadcast at the end state, EUR/MWh
    (:func:`~popdispatch.online.kkt.net_prices`: a line's ``mu_up - mu_down``, a bus's
    ``mu_lo - mu_hi`` per MW equivalent); at a converged minute they are the DC-OPF's
    (LinDistFlow OPF's) duals. ``None`` in a mode without price controllers (paper mode).

    Status semantics: in a mode that claims the DC-OPF (exact, voltage), ``converged`` means
    the end state is *proved* within the accuracy of the DC-OPF: ``distance_bound_kw``, the
    largest distance of any set point from the DC-OPF's that the distance certificate allows
    (:mod:`popdispatch.online.certificate`), is at most ``accuracy_kw`` (the settings'
    ``max(accuracy_kw, accuracy_rel * demand)``). A run that came to rest (the stopping rule of
    :mod:`popdispatch.integrate`) without that proof is ``stalled``: ``converged_at`` is then
    None, ``rest_at`` the iteration it came to rest and ``stall_reason`` says why (a KKT
    condition that fails, :func:`kkt_violations`, else the bound). Logit dynamics rest at their
    own equilibrium, not the DC-OPF's: in exact mode they are never ``converged``, a rest is
    ``stalled`` with the bound (docs/dynamics.md). Paper mode claims only a rest point of the
    paper's dynamics (its rules do not land on the DC-OPF, docs/paper-mode.md): its
    ``converged`` is that rest, and it has no bound (``None``).
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
    line_price_eur_per_mwh: np.ndarray | None = None
    voltage_price_eur_per_mwh: np.ndarray | None = None
    distance_bound_kw: float | None = None
    accuracy_kw: float | None = None
    evaluations: int | None = None

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


def run_snapshot(
    problem: DispatchProblem, minute: int, settings: RunSettings | None = None
) -> SnapshotResult:
    """Run the dynamics for one minute from ``settings.x0`` until converged or the horizon.

    In a mode that claims the DC-OPF, a run that comes to rest without the distance
    certificate's proof continues (to the horizon) as long as each rest's proved bound is at
    least 1 % below the one before (:data:`RUN_ON_FACTOR`): the stopping rule's window can end
    a run whose last watts still move."""
    settings = settings or RunSettings()
    engine = Engine(problem, settings)
    x = initial_shares(problem, settings.x0, minute)
    engine.warm_up(x, minute)
    evaluated = engine.evaluations
    run, wall = _run_until_proved(engine, x, minute)
    setpoints, converged_at = run.trajectory, run.converged_at
    first_congestion = run.first_congestion
    final = setpoints[-1]
    flows = limited_flows_mw(problem, final, minute)
    rested = run.status == Status.CONVERGED
    infeasible = np.array([run.status == Status.INFEASIBLE])
    verdict = verdicts(engine, np.array([minute]), final[None], run.z_end[None],
                        np.array([rested]), infeasible)  # fmt: skip
    certified, reason = bool(verdict.certified[0]), verdict.reasons[0]
    line_price, voltage_price = _prices(engine, np.array([minute]), final[None], run.z_end[None])
    return SnapshotResult(
        minute=minute,
        demand_kw=float(problem.demand[minute - 1] * KW_PER_MW),
        settings=settings,
        generators=problem.generators,
        trajectory_kw=setpoints * KW_PER_MW,
        converged_at=(int(converged_at) if rested else run.iterations) if certified else None,
        first_congestion=None if first_congestion < 0 else int(first_congestion),
        overflow_kw=overflow_kw(problem, final, minute),
        flows_kw=flows * KW_PER_MW,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=run.status == Status.INFEASIBLE,
        stall_reason=reason,
        rest_at=int(converged_at) if rested else None,
        line_price_eur_per_mwh=None if line_price is None else line_price[0],
        voltage_price_eur_per_mwh=None if voltage_price is None else voltage_price[0],
        distance_bound_kw=None if verdict.bound_kw is None else float(verdict.bound_kw[0]),
        accuracy_kw=None if verdict.bound_kw is None else float(verdict.accuracy_kw[0]),
        evaluations=engine.evaluations - evaluated,
    )


#: A snapshot at rest without the proof runs on while each rest's proved bound is at least 1 % below
#: the last one's (the bound still falling, not at a floor).
RUN_ON_FACTOR = 0.99
#: Iterations between two certificates of a snapshot that is not at rest (at least; a quarter
#: of the iterations so far once that is more, so that a long run on a large feeder asks a
#: few dozen times, not hundreds): a proof ends the run there, at rest or not (a state can sit
#: within the accuracy while its last microwatts still move, and never satisfy the rest rule).
PROOF_EVERY = 20


def _run_until_proved(engine: Engine, x: np.ndarray, minute: int) -> tuple[MinuteRun, float]:
    """:meth:`Engine.run_minute` in pieces of :data:`PROOF_EVERY` iterations (or a quarter
    of those done, if more), each piece's end state certified: a state proved within the
    accuracy ends the run; a rest that the certificate does not prove runs on while the
    proved bound keeps falling (:data:`RUN_ON_FACTOR`) and the horizon allows (see
    :func:`run_snapshot`); iterations count from the start. Also the seconds spent in the
    engine (the certificates' checks not counted: they are the audit, not the dispatch)."""
    if not engine.mode.claims_dc_opf:
        began = time.perf_counter()
        run = engine.run_minute(x, minute)
        return run, time.perf_counter() - began
    horizon = engine.settings.stepping.max_iterations
    accuracy = float(engine.settings.accuracy_mw(engine.problem.demand[minute - 1]))
    pieces, done, last_bound, seconds = [], 0, np.inf, 0.0
    first, run = -1, None
    while done < horizon:
        began = time.perf_counter()
        more = engine.run_minute(x if run is None else run.x, minute,
                                 max_iterations=min(max(PROOF_EVERY, done // 4),
                                                    horizon - done))  # fmt: skip
        seconds += time.perf_counter() - began
        pieces.append(more.trajectory if run is None else more.trajectory[1:])
        if first < 0 <= more.first_congestion:
            first = done + more.first_congestion
        converged_at = done + more.converged_at if more.converged_at >= 0 else -1
        done += more.iterations
        run = more._replace(converged_at=converged_at)
        if run.status == Status.INFEASIBLE:
            break
        bound = _bound_mw(engine, minute, run.x * engine.problem.demand[minute - 1], engine.z)
        if bound <= accuracy:
            break
        if run.status == Status.CONVERGED:  # at rest and not proved
            if not bound < RUN_ON_FACTOR * last_bound:
                break
            last_bound = bound
    return run._replace(trajectory=np.concatenate(pieces), iterations=done,
                        first_congestion=first), seconds  # fmt: skip


@dataclass(frozen=True)
class Verdict:
    """Per minute: proved within the accuracy (``certified``), why a minute at rest is not
    (``reasons``), the bound and the accuracy (kW; ``None`` in paper mode)."""

    certified: np.ndarray
    reasons: list[str | None]
    bound_kw: np.ndarray | None
    accuracy_kw: np.ndarray | None

    def status(self, index: int, engine_status: Status) -> str:
        """The status word of the ``index``-th minute, the engine having ended it with
        ``engine_status``: ``"infeasible"``, ``"converged"`` (proved), ``"stalled"`` (at rest
        with a reason) or ``"not_converged"``."""
        if engine_status == Status.INFEASIBLE:
            return "infeasible"
        if self.certified[index]:
            return "converged"
        return "stalled" if self.reasons[index] else "not_converged"


def verdicts(
    engine: Engine,
    minutes: np.ndarray,
    p_mw: np.ndarray,
    z: np.ndarray,
    rested: np.ndarray,
    infeasible: np.ndarray,
) -> Verdict:
    """Each minute's verdict: in a mode that claims the DC-OPF, certified when the distance
    certificate proves the accuracy (and the run was not infeasible); a minute at rest that
    is not certified gets the reason (a failing KKT condition, else the bound). Dynamics whose
    rest points are not the game's equilibria (logit) are never certified; their minutes at
    rest are stalled with the bound. Paper mode: certified means at rest. A minute whose end
    state is not finite (a step too long for the field overflowed it) is never certified and
    is stalled with that reason, in every mode."""
    overflowed = ~(np.isfinite(p_mw).all(axis=1) & np.isfinite(z).all(axis=1)) & ~infeasible
    certificates = engine.certificates(minutes, p_mw, z)
    if certificates is None:
        verdict = Verdict(rested & ~infeasible, [None] * len(minutes), None, None)
        return _overflowed(verdict, engine, overflowed)
    bound = np.array([c.distance_mw for c in certificates]) * KW_PER_MW
    demand = engine.problem.demand[np.asarray(minutes) - 1]
    accuracy = np.atleast_1d(engine.settings.accuracy_mw(demand)) * KW_PER_MW
    certified = (bound <= accuracy) & ~infeasible
    own_rest = not engine.dynamics.rests_at_optimum  # logit: never the DC-OPF's, by design
    if own_rest:
        certified[:] = False
    pending = rested & ~certified & ~infeasible
    reasons = engine.stall_reasons(minutes, p_mw, z, pending)
    for r in np.flatnonzero(pending):
        if own_rest:
            distance = (
                f"the distance to it is bounded by {bound[r]:.3g} kW"
                if np.isfinite(bound[r])
                else "the certificate bounds no distance to it"
            )
            reasons[r] = (
                f"{engine.dynamics.name} dynamics rest at their own equilibrium, not in general "
                f"the DC-OPF (docs/dynamics.md): {distance}"
                + (f"; {reasons[r]}" if reasons[r] else "")
            )  # fmt: skip
        elif reasons[r] is None:
            why = certificates[r].reason
            reasons[r] = (
                f"the distance to the DC-OPF is bounded only by {bound[r]:.3g} kW, above the "
                f"accuracy {accuracy[r]:.3g} kW" + (f" ({why})" if why else "")
            )
    return _overflowed(Verdict(certified, reasons, bound, accuracy), engine, overflowed)


def _overflowed(verdict: Verdict, engine: Engine, overflowed: np.ndarray) -> Verdict:
    """``verdict`` with the minutes ``overflowed`` (end state not finite) not certified and
    their reason the steps'."""
    stepping = engine.settings.stepping
    step = stepping.dt / stepping.substeps if stepping.method == "euler" else stepping.dt
    reason = (
        f"the state overflowed (set points or prices not finite): {stepping.method} steps of "
        f"{step:.3g} s are too long for this field; shorten them (the Integrator's dt, "
        f"substeps)" + ("" if stepping.method == "heun" else " or use method='heun'")
    )
    for r in np.flatnonzero(overflowed):
        verdict.certified[r] = False
        verdict.reasons[r] = reason
    return verdict


def _prices(
    engine: Engine, minutes: np.ndarray, p_mw: np.ndarray, z: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The engine's broadcast ``(line, voltage)`` prices (EUR/MWh, minutes x lines / buses)
    at set points ``p_mw`` (MW) and controller states ``z``; ``(None, None)`` in a mode
    without price controllers (paper mode)."""
    if z.shape[1] == 0:
        return None, None
    return net_prices(engine.problem, minutes, p_mw, z, engine.price_weight(minutes))


@dataclass(frozen=True)
class DayResult:
    """An online day. Arrays have one row per simulated minute; powers in kW.

    ``setpoints_kw`` (minutes, generators); ``iterations`` and ``converged`` per minute;
    ``overflow_kw`` (minutes, limited lines); ``cost`` per minute (EUR/h, Table I's units).
    ``wall_seconds`` is the engine's own time (no imports, data loading or DC-OPF).

    Per minute, as for a snapshot (:class:`SnapshotResult`): ``converged`` means at rest and,
    in a mode that claims the DC-OPF, proved within ``accuracy_kw`` of it by the distance
    certificate (``distance_bound_kw``); ``stalled`` means at rest without that proof
    (``stall_reasons`` maps such 1-based minutes to the reason). A stalled minute is never
    counted as converged.

    ``line_price_eur_per_mwh`` (minutes, limited lines) and ``voltage_price_eur_per_mwh``
    (minutes, monitored buses): the engine's broadcast prices at each minute's end, EUR/MWh,
    as for a snapshot (``None`` in paper mode). ``distance_bound_kw`` and ``accuracy_kw``
    (minutes): each minute's proved distance to the DC-OPF and the accuracy it had to prove
    (``None`` in paper mode).
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
    line_price_eur_per_mwh: np.ndarray | None = None
    voltage_price_eur_per_mwh: np.ndarray | None = None
    distance_bound_kw: np.ndarray | None = None
    accuracy_kw: np.ndarray | None = None

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


def _run_day_loop(engine: Engine, x: np.ndarray, minutes: np.ndarray, out: DayArrays,
                  chunk: int, progress: Callable[[int], None] | None) -> float:  # fmt: skip
    """The compiled day loop over ``minutes`` in chunks of ``chunk``, into ``out``; the
    engine's seconds. In a mode that claims the DC-OPF, a minute that comes to rest without
    the certificate's proof runs on from its end state as a snapshot does
    (:func:`_run_until_proved`) and, where that lowers its proved bound, the minutes after it
    run again from there (the state they continue from has changed), from then on in chunks of
    at most :data:`PROGRESS_CHUNK` minutes (so that a later run-on wastes at most that)."""
    seconds, position = 0.0, 0
    while position < len(minutes):
        part = slice(position, min(position + chunk, len(minutes)))
        view = out.chunk(part)
        began = time.perf_counter()
        engine.run_day_chunk(x, minutes[part], view)
        seconds += time.perf_counter() - began
        out.last_demand = view.last_demand
        end = part.stop
        for row, bound in _unproved_rows(engine, minutes, out, part):
            lowered, ran = _run_on_minute(engine, x, minutes, out, row, bound)
            seconds += ran
            if lowered:
                end, chunk = row + 1, min(chunk, PROGRESS_CHUNK)
                break
        if progress is not None:
            for minute in minutes[position:end]:
                progress(int(minute))
        position = end
    return seconds


def _bound_mw(engine: Engine, minute: int, p_mw: np.ndarray, z: np.ndarray) -> float:
    """The distance certificate's bound (MW) of one minute's end state: set points ``p_mw``
    (MW) and controller states ``z``."""
    return engine.certificates(np.array([minute]), p_mw[None], z[None])[0].distance_mw


def _unproved_rows(engine: Engine, minutes: np.ndarray, out: DayArrays, part: slice) -> list:
    """``(row, proved bound in MW)`` of the rows of ``part`` at rest whose end state the
    certificate does not prove within the accuracy (none in a mode that does not claim the
    DC-OPF)."""
    rows = np.arange(part.start, part.stop)
    rows = rows[out.status[rows] == Status.CONVERGED]
    if not engine.mode.claims_dc_opf or not len(rows):
        return []
    proofs = engine.certificates(minutes[rows], out.setpoints[rows], out.states[rows])
    accuracy = engine.settings.accuracy_mw(engine.problem.demand[minutes[rows] - 1])
    bounds = np.array([proof.distance_mw for proof in proofs])
    short = ~(bounds <= np.atleast_1d(accuracy))
    return [(int(r), float(b)) for r, b in zip(rows[short], bounds[short], strict=True)]


def _run_on_minute(engine: Engine, x: np.ndarray, minutes: np.ndarray, out: DayArrays,
                   row: int, before: float) -> tuple[bool, float]:  # fmt: skip
    """Continue the minute of ``row``, whose end state proves ``before`` (MW), from that state
    (:func:`_run_until_proved`): ``(lowered, engine seconds)``. Where that lowers its proved
    bound by :data:`RUN_ON_FACTOR` (``lowered``), its row, ``x`` and the engine's state become
    the new end state; else everything is left as it was."""
    minute = int(minutes[row])
    demand = engine.problem.demand[minute - 1]
    kept = engine.z.copy(), engine.h_try
    engine.z[:] = out.states[row]
    run, seconds = _run_until_proved(engine, out.setpoints[row] / demand, minute)
    p = run.x * demand
    if not _bound_mw(engine, minute, p, engine.z) < RUN_ON_FACTOR * before:
        engine.z, engine.h_try = kept
        return False, seconds
    rested = run.converged_at >= 0
    out.converged_at[row] = out.iterations[row] + run.converged_at if rested else -1
    out.iterations[row] += run.iterations
    out.setpoints[row], out.states[row] = p, engine.z
    out.status[row] = int(run.status)
    x[:] = run.x
    out.last_demand = demand
    return True, seconds


def run_day(
    problem: DispatchProblem,
    settings: RunSettings | None = None,
    minutes: np.ndarray | None = None,
    progress: Callable[[int], None] | None = None,
) -> DayResult:
    """The online day: every minute continues from the previous state until converged.

    ``minutes``: 1-based steps of the problem's series to simulate in order (default all of
    them, ``1..len(problem.demand)``: 1440 for a day of minutes, 96 for a day of 15-minute
    SimBench steps); each step warm-starts from the state the previous simulated one ended in.
    ``progress``: called with each minute once it is done (e.g. to advance a progress bar);
    the compiled loop then runs in chunks of :data:`PROGRESS_CHUNK` minutes.
    """
    settings = settings or RunSettings()
    minutes = np.arange(1, len(problem.demand) + 1) if minutes is None else np.asarray(minutes)
    minutes = minutes.astype(np.int64)
    engine = Engine(problem, settings)
    x = initial_shares(problem, settings.x0, int(minutes[0]))
    engine.warm_up(x, int(minutes[0]))
    out = DayArrays.empty(len(minutes), problem.n_generators, len(engine.z))
    chunk = PROGRESS_CHUNK if progress is not None else len(minutes)
    wall = _run_day_loop(engine, x, minutes, out, chunk, progress)
    setpoints = out.setpoints
    overflow = np.stack([overflow_kw(problem, setpoints[r], m) for r, m in enumerate(minutes)])
    online = problem.online[minutes - 1]
    rested = out.status == Status.CONVERGED
    infeasible = out.status == Status.INFEASIBLE
    verdict = verdicts(engine, minutes, setpoints, out.states, rested, infeasible)
    reasons = verdict.reasons
    stalled = np.array([r is not None for r in reasons], dtype=bool)
    line_price, voltage_price = _prices(engine, minutes, setpoints, out.states)
    return DayResult(
        minutes=minutes,
        settings=settings,
        generators=problem.generators,
        demand_kw=problem.demand[minutes - 1] * KW_PER_MW,
        setpoints_kw=setpoints * KW_PER_MW,
        iterations=out.iterations,
        converged=verdict.certified,
        overflow_kw=overflow,
        cost=generation_cost(problem, setpoints, online),
        online=online,
        wall_seconds=wall,
        profile_source=problem.profile_source,
        infeasible=infeasible,
        stalled=stalled,
        stall_reasons={int(m): r for m, r in zip(minutes, reasons, strict=True) if r},
        line_price_eur_per_mwh=line_price,
        voltage_price_eur_per_mwh=voltage_price,
        distance_bound_kw=verdict.bound_kw,
        accuracy_kw=verdict.accuracy_kw,
    )


__all__ = [
    "PROGRESS_CHUNK",
    "SHARES_NAME",
    "X0_CHOICES",
    "DayResult",
    "Engine",
    "KktTolerances",
    "MinuteRun",
    "RunSettings",
    "SnapshotResult",
    "Verdict",
    "initial_shares",
    "kkt_violations",
    "limited_flows_mw",
    "overflow_kw",
    "run_day",
    "run_snapshot",
    "verdicts",
]
