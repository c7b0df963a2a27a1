"""The yardstick: an exact DC optimal power flow of the same problem (paper eq. 1).

    min  sum_i a_i + b_i p_i + c_i p_i^2
    s.t. Pmin_i <= p_i <= Pmax_i,  sum_i p_i = P_d,  |flow_k| <= U_k on limited lines,

with the lossless DC flows ``flow = load_flow - D p`` (on a meshed network written with bus
angles, as sparse as the network: :func:`angle_rows`); a problem with voltage limits
adds the LinDistFlow rows ``vmin^2 <= v0_j^2 + sum_i S_ji p_i <= vmax^2`` of its monitored
buses (the LinDistFlow OPF, docs/voltage.md), scaled like the voltage mode's controllers
(divided by ``s_j``, in MW equivalents) so that their duals are the prices the controllers
broadcast. Solved with Clarabel (interior point, QP). The solver works in kW (better scaled
than MW for these small generators); results are returned in kW. An infeasible problem is
reported as infeasible, never as a solution.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import clarabel
import numpy as np
from scipy import sparse

from popdispatch.game.problem import KW_PER_MW, DispatchProblem

#: The fraction of the way to the cone's boundary the careful solve steps (Clarabel: 0.99).
CAREFUL_STEP = 0.9
#: Clarabel's statuses of a solved minute and of an infeasible one; any other is retried
#: carefully once, then raised.
SOLVED = ("Solved", "AlmostSolved")
INFEASIBLE = ("PrimalInfeasible", "AlmostPrimalInfeasible")


def clarabel_settings(max_step: float | None = None) -> clarabel.DefaultSettings:
    """Clarabel's settings for the DC-OPF: tolerances 1e-10, no presolve (it keeps the data
    updatable), quiet; ``max_step``: the fraction of the way to the cone's boundary an
    interior-point step may go (None: Clarabel's own)."""
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.presolve_enable = False
    settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    if max_step is not None:
        settings.max_step_fraction = max_step
    return settings


@dataclass(frozen=True)
class OpfResult:
    """One minute's DC-OPF.

    Attributes
    ----------
    status : ``"optimal"`` or ``"infeasible"``.
    minute : 1-based minute.
    demand_kw : total demand, kW.
    p_kw : set point per generator, kW (NaN if infeasible).
    cost : total cost ``sum C_i(p_i)`` with p in MW, EUR (per hour, Table I's coefficients).
    line_price : dual of each limited line's constraint, EUR/MW (0 if not binding).
    marginal_price : dual of the power balance, EUR/MW.
    voltage_price : per monitored bus, the dual of its lower bound minus that of its upper
        bound, EUR/MW per MW equivalent (the voltage mode's net price ``m_j``; divide by
        ``voltage_scale`` for EUR/h per p.u.^2); empty without voltage limits.
    v_pu : per monitored bus, the LinDistFlow voltage at the optimum, p.u. (empty without).
    """

    status: str
    minute: int
    demand_kw: float
    p_kw: np.ndarray
    cost: float
    line_price: np.ndarray
    marginal_price: float
    voltage_price: np.ndarray = field(default_factory=lambda: np.zeros(0))
    v_pu: np.ndarray = field(default_factory=lambda: np.zeros(0))


def generation_cost(problem: DispatchProblem, p_mw: np.ndarray, online: np.ndarray | None = None):
    """``sum_i a_i + b_i p_i + c_i p_i^2`` (EUR) over online generators; ``p_mw`` in MW (..., n)."""
    online = np.ones(problem.n_generators, bool) if online is None else online
    terms = problem.a + problem.b * p_mw + problem.c * p_mw**2
    return np.sum(np.where(online, terms, 0.0), axis=-1)


#: The ways :class:`OpfSolver` can write the limited lines' rows: ``"factors"`` (dense rows of
#: the coefficients ``D``, any problem) and ``"angles"`` (a meshed network's bus angles and its
#: sparse ``B``, :func:`angle_rows`).
FORMULATIONS = ("factors", "angles")


@dataclass(frozen=True)
class AngleRows:
    """A meshed network's DC-OPF rows in bus angles (:func:`angle_rows`), on the variables
    ``[p (kW, generators), theta (mrad, groups of buses but the slack's)]`` (milliradians scale
    the rows well: a p.u. susceptance times ``S``, the base MVA, in kW per mrad). A group is
    the buses zero-reactance lines join (:mod:`popdispatch.feeder.fusion`; one bus each
    without such lines), at one angle. ``theta`` are the angles of the generators' injections
    balanced by the demand spread over the buses in the shares ``w`` (the network's own ``pd +
    gs``): close to the true angles, so no large flows cancel (angles of the generators
    withdrawn at the slack would carry the whole demand's flow).

    ``bus_rows``: ``S B_r theta - C_g p = -w_r P_d`` (kW) per group but the slack's;
    ``line_rows``: ``S Bf_L theta``, with ``flow = load_flow + S Bf_L theta + P_d line_share``
    (kW) on the limited lines ``L`` that can reach their limits, as ``sum p = P_d`` makes ``-D
    p = S Bf_L theta + P_d PTDF_L w``; a zero-reactance line's flow is no function of the
    angles (Kirchhoff's current law in its group gives it), so its row is ``-D_k p`` (its
    factors) and its ``line_share`` 0: ``flow = load_flow - D_k p``. ``bus_share``: ``w_r``;
    ``line_share``: ``PTDF_L w`` (MW per MW of demand); ``kept``: the positions of ``L`` among
    the problem's limited lines, those whose flow can reach the limit at some minute (``max
    |load_flow| + sum_i |D_ki| max(|Pmin_i|, |Pmax_i|) >= U``: a line rated far above any flow
    it can carry, as a case's 99,999 MVA, is a row that never binds and only spoils the
    scaling)."""

    bus_rows: sparse.csr_matrix
    line_rows: sparse.csr_matrix
    bus_share: np.ndarray
    line_share: np.ndarray
    kept: np.ndarray


def angle_rows(problem: DispatchProblem) -> AngleRows:
    """The :class:`AngleRows` of a meshed problem (its ``feeder`` a
    :class:`~popdispatch.feeder.dcnet.DcNetwork` whose fleet is the problem's)."""
    net = problem.feeder
    model = net.model
    if len(net.generators) != problem.n_generators:
        raise ValueError("the problem's fleet is not its network's")
    kept = _reachable(problem)
    lines_kept = problem.lines[kept]
    load = (net.buses.pd_mw + net.buses.gs_mw).to_numpy(float)
    share = load / load.sum() if load.sum() > 0 else np.full(len(load), 1.0 / len(load))
    flows = model.flows_mw(np.c_[share, np.zeros(len(share))], lines_kept)
    line_share = flows[:, 0] - flows[:, 1]  # without the phase shifters' own flows
    ideal = np.isin(lines_kept, model.zero.lines if model.zero is not None else [])
    line_share = np.where(ideal, 0.0, line_share)
    return AngleRows(_bus_rows(problem), _line_rows(problem, kept, ideal),
                     model.group_sums(share)[model.keep], line_share, kept)  # fmt: skip


def _reachable(problem: DispatchProblem) -> np.ndarray:
    """The positions of the problem's limited lines whose flow can reach the limit at some
    minute (:class:`AngleRows` ``kept``)."""
    largest = np.maximum(np.abs(problem.pmin), np.abs(problem.pmax))  # MW
    loads = np.abs(problem.line_load_flow).max(axis=0, initial=0.0)
    reach = loads + np.abs(problem.factor) @ largest
    return np.flatnonzero(reach >= problem.limit * (1.0 - 1e-9))


def _bus_rows(problem: DispatchProblem) -> sparse.csr_matrix:
    """``[-C_g, S B_r]``: per group of buses but the slack's, its generators (kW) and its row
    of the groups' ``B`` (kW per mrad)."""
    net = problem.feeder
    model = net.model
    keep = model.keep
    Bbus = model.base_mva * sparse.csr_matrix(model.Bbus)[keep][:, keep]
    position = np.full(model.Bbus.shape[0], -1)
    position[keep] = np.arange(len(keep))
    at = position[model.group[net.buses.index.get_indexer(net.generators.bus)]]
    injected = np.flatnonzero(at >= 0)  # a generator in the slack's group is in no bus row
    Cg = sparse.csr_matrix((np.ones(len(injected)), (at[injected], injected)),
                           shape=(len(keep), problem.n_generators))  # fmt: skip
    return sparse.hstack([-Cg, Bbus]).tocsr()


def _line_rows(problem: DispatchProblem, kept: np.ndarray, ideal: np.ndarray) -> sparse.csr_matrix:
    """``[0, S Bf_L]`` on the limited lines ``kept`` (positions among the problem's), ``[-D_k,
    0]`` on those of them that are zero-reactance lines (``ideal``)."""
    model = problem.feeder.model
    n = problem.n_generators
    lines = model.base_mva * sparse.csr_matrix(model.Bf)[problem.lines[kept]][:, model.keep]
    rows = np.flatnonzero(ideal)
    factors = -problem.factor[kept[rows]]
    r, c = np.nonzero(factors)
    p_rows = sparse.csr_matrix((factors[r, c], (rows[r], c)), shape=(len(kept), n))
    return sparse.hstack([p_rows, lines]).tocsr()


class OpfSolver:
    """The DC-OPF of one problem, built once; each minute changes only the constraint bounds.

    Clarabel's data update keeps the factorisation structure, so a day of 1440 solves costs
    little more than 1440 interior-point runs on a 6-variable QP. ``formulation``
    (:data:`FORMULATIONS`): on a meshed network the default is ``"angles"``, whose rows are as
    sparse as the network (a dense row of factors per limited line makes a large meshed case's
    QP dense); elsewhere ``"factors"``. Both give the same optimum and duals.
    """

    def __init__(self, problem: DispatchProblem, formulation: str | None = None):
        self.problem = problem
        if formulation is None:
            formulation = "angles" if problem.meshed and not problem.n_voltage else "factors"
        if formulation not in FORMULATIONS:
            raise ValueError(f"formulation {formulation!r}: one of {', '.join(FORMULATIONS)}")
        if formulation == "angles" and not (problem.meshed and not problem.n_voltage):
            raise ValueError("the angle formulation needs a meshed network without voltage rows")
        self.formulation = formulation
        self._angles: AngleRows | None = None
        self._rows = np.arange(len(problem.limit))  # the limited lines with rows
        n = problem.n_generators
        # Objective scaled by 1000: b p_MW + c p_MW^2 = (b p_kW + c p_kW^2 / 1000) / 1000.
        P = sparse.diags(2.0 * problem.c / KW_PER_MW)
        q = problem.b.astype(float)
        eye = sparse.eye(n)
        balance = sparse.csr_matrix(np.ones((1, n)))
        if formulation == "angles":
            self._angles = angle_rows(problem)
            buses, lines = self._angles.bus_rows, self._angles.line_rows
            self._rows = self._angles.kept
            n_angles = buses.shape[1] - n
            P = sparse.block_diag([P, sparse.csc_matrix((n_angles, n_angles))])
            q = np.r_[q, np.zeros(n_angles)]
            pad = sparse.csr_matrix((n, n_angles))
            balance = sparse.hstack([balance, sparse.csr_matrix((1, n_angles))])
            zero_rows = sparse.vstack([balance, buses])
            rows_ = [sparse.hstack([-eye, pad]), sparse.hstack([eye, pad]), lines, -lines]
        else:
            down = sparse.csr_matrix(problem.down)
            sens = sparse.csr_matrix(problem.voltage_sens.reshape(problem.n_voltage, n))
            zero_rows = balance
            rows_ = [-eye, eye, -down, down, -sens, sens]
        A = sparse.vstack([zero_rows, *rows_]).tocsc()
        self._zeros = zero_rows.shape[0]
        rows = 2 * n + 2 * len(self._rows) + 2 * problem.n_voltage
        cones = [clarabel.ZeroConeT(self._zeros), clarabel.NonnegativeConeT(rows)]
        self._data = (sparse.csc_matrix(P), q, A, cones)
        self._solvers: dict[bool, clarabel.DefaultSolver] = {}  # built by their first solve

    def _rhs(self, minute: int) -> np.ndarray:
        problem = self.problem
        online = problem.online[minute - 1]
        pmin = np.where(online, problem.pmin, 0.0) * KW_PER_MW
        pmax = np.where(online, problem.pmax, 0.0) * KW_PER_MW
        n_lines, n_v = len(problem.limit), problem.n_voltage
        loads = problem.load_flow[minute - 1] * KW_PER_MW
        load_flow = loads[:n_lines][self._rows]
        limit = problem.limit[self._rows] * KW_PER_MW
        demand = problem.demand[minute - 1] * KW_PER_MW
        bus_rows = np.zeros(0)
        if self._angles is not None:  # the demand's share of each bus and of each line's flow
            bus_rows = -self._angles.bus_share * demand
            load_flow = load_flow + self._angles.line_share * demand
        # voltage rows: e0_lo - sens p <= 0 and e0_hi + sens p <= 0 (kW equivalents)
        v_lo, v_hi = -loads[n_lines : n_lines + n_v], -loads[n_lines + n_v :]
        return np.concatenate([[demand], bus_rows, -pmin, pmax,
                               limit - load_flow, limit + load_flow, v_lo, v_hi])  # fmt: skip

    def _solved(self, rhs: np.ndarray, careful: bool):
        """Clarabel's solution at the bounds ``rhs``. ``careful``: with interior-point steps
        of at most :data:`CAREFUL_STEP` of the way to the cone's boundary, Clarabel's default
        0.99 having cycled without converging (MaxIterations) on rare small meshed problems;
        a solver built once for each kind and updated with each minute's bounds."""
        solver = self._solvers.get(careful)
        if solver is None:
            P, q, A, cones = self._data
            settings = clarabel_settings(CAREFUL_STEP if careful else None)
            solver = self._solvers[careful] = clarabel.DefaultSolver(P, q, A, rhs, cones,
                                                                     settings)  # fmt: skip
        else:
            solver.update(b=rhs)
        return solver.solve()

    def solve(self, minute: int) -> OpfResult:
        """Solve the DC-OPF of one 1-based minute (offline generators held at 0)."""
        problem = self.problem
        n, n_limits = problem.n_generators, len(problem.limit)
        rhs = self._rhs(minute)
        solution = self._solved(rhs, careful=False)
        status = str(solution.status)
        if status not in SOLVED + INFEASIBLE:
            solution = self._solved(rhs, careful=True)
            status = str(solution.status)
        demand = float(rhs[0])
        if status in INFEASIBLE:
            nan = np.full(n, np.nan)
            n_v = problem.n_voltage
            return OpfResult(
                "infeasible", minute, demand, nan, np.nan, np.full(n_limits, np.nan), np.nan,
                np.full(n_v, np.nan), np.full(n_v, np.nan),
            )  # fmt: skip
        if status not in SOLVED:
            raise RuntimeError(f"DC-OPF at minute {minute}: Clarabel returned {status}")
        bounds = rhs[self._zeros :]
        p_kw = np.clip(np.asarray(solution.x)[:n], -bounds[:n], bounds[n : 2 * n])
        balance_dual = float(solution.z[0])
        dual = np.asarray(solution.z)[self._zeros :]  # the inequalities' duals
        n_rows = len(self._rows)
        line_dual = dual[2 * n : 2 * n + 2 * n_rows]
        line_price = np.zeros(n_limits)
        line_price[self._rows] = line_dual[:n_rows] - line_dual[n_rows:]
        v_dual = dual[2 * n + 2 * n_rows :]
        n_v = problem.n_voltage
        online = problem.online[minute - 1]
        cost = float(generation_cost(problem, p_kw / KW_PER_MW, online))
        v_pu = np.sqrt(np.maximum(problem.voltage_sq(p_kw / KW_PER_MW, minute), 0.0))
        return OpfResult("optimal", minute, demand, p_kw, cost, line_price, -balance_dual,
                         v_dual[:n_v] - v_dual[n_v:], v_pu)  # fmt: skip


def solve_opf(problem: DispatchProblem, minute: int) -> OpfResult:
    """Solve the DC-OPF of one 1-based minute (generators offline that minute are held at 0)."""
    return OpfSolver(problem).solve(minute)


def solve_opf_day(
    problem: DispatchProblem, minutes: Iterable[int] | None = None
) -> list[OpfResult]:
    """Solve the DC-OPF of every minute (any iterable of 1-based minutes, e.g. one that drives
    a progress bar; default 1..1440) with one solver built once."""
    minutes = np.arange(1, len(problem.demand) + 1) if minutes is None else minutes
    solver = OpfSolver(problem)
    return [solver.solve(int(m)) for m in minutes]
