"""The yardstick: an exact DC optimal power flow of the same problem (paper eq. 1).

    min  sum_i a_i + b_i p_i + c_i p_i^2
    s.t. Pmin_i <= p_i <= Pmax_i,  sum_i p_i = P_d,  |flow_k| <= U_k on limited lines,

with the lossless radial DC flows ``flow = load_flow - D p``; a problem with voltage limits
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


class OpfSolver:
    """The DC-OPF of one problem, built once; each minute changes only the constraint bounds.

    Clarabel's data update keeps the factorisation structure, so a day of 1440 solves costs
    little more than 1440 interior-point runs on a 6-variable QP.
    """

    def __init__(self, problem: DispatchProblem):
        self.problem = problem
        n = problem.n_generators
        # Objective scaled by 1000: b p_MW + c p_MW^2 = (b p_kW + c p_kW^2 / 1000) / 1000.
        P = sparse.csc_matrix(sparse.diags(2.0 * problem.c / KW_PER_MW))
        q = problem.b.astype(float)
        eye = sparse.eye(n)
        down = sparse.csr_matrix(problem.down)
        sens = sparse.csr_matrix(problem.voltage_sens.reshape(problem.n_voltage, n))
        A = sparse.vstack(
            [sparse.csr_matrix(np.ones((1, n))), -eye, eye, -down, down, -sens, sens]
        ).tocsc()
        rows = 2 * n + 2 * len(problem.limit) + 2 * problem.n_voltage
        cones = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(rows)]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.presolve_enable = False  # keeps the data updatable
        settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
        settings.tol_feas = 1e-10
        self._data = (P, q, A, cones, settings)
        self._solver = None  # built by the first solve, with that minute's bounds

    def _rhs(self, minute: int) -> np.ndarray:
        problem = self.problem
        online = problem.online[minute - 1]
        pmin = np.where(online, problem.pmin, 0.0) * KW_PER_MW
        pmax = np.where(online, problem.pmax, 0.0) * KW_PER_MW
        n_lines, n_v = len(problem.limit), problem.n_voltage
        loads = problem.load_flow[minute - 1] * KW_PER_MW
        load_flow = loads[:n_lines]
        limit = problem.limit * KW_PER_MW
        demand = problem.demand[minute - 1] * KW_PER_MW
        # voltage rows: e0_lo - sens p <= 0 and e0_hi + sens p <= 0 (kW equivalents)
        v_lo, v_hi = -loads[n_lines : n_lines + n_v], -loads[n_lines + n_v :]
        return np.concatenate(
            [[demand], -pmin, pmax, limit - load_flow, limit + load_flow, v_lo, v_hi]
        )

    def solve(self, minute: int) -> OpfResult:
        """Solve the DC-OPF of one 1-based minute (offline generators held at 0)."""
        problem = self.problem
        n, n_limits = problem.n_generators, len(problem.limit)
        rhs = self._rhs(minute)
        if self._solver is None:
            P, q, A, cones, settings = self._data
            self._solver = clarabel.DefaultSolver(P, q, A, rhs, cones, settings)
        else:
            self._solver.update(b=rhs)
        solution = self._solver.solve()
        status = str(solution.status)
        demand = float(rhs[0])
        if status in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
            nan = np.full(n, np.nan)
            n_v = problem.n_voltage
            return OpfResult(
                "infeasible", minute, demand, nan, np.nan, np.full(n_limits, np.nan), np.nan,
                np.full(n_v, np.nan), np.full(n_v, np.nan),
            )  # fmt: skip
        if status not in ("Solved", "AlmostSolved"):
            raise RuntimeError(f"DC-OPF at minute {minute}: Clarabel returned {status}")
        p_kw = np.clip(np.asarray(solution.x), -rhs[1 : 1 + n], rhs[1 + n : 1 + 2 * n])
        dual = np.asarray(solution.z)
        line_dual = dual[1 + 2 * n : 1 + 2 * n + 2 * n_limits]
        line_price = line_dual[:n_limits] - line_dual[n_limits:]
        v_dual = dual[1 + 2 * n + 2 * n_limits :]
        n_v = problem.n_voltage
        online = problem.online[minute - 1]
        cost = float(generation_cost(problem, p_kw / KW_PER_MW, online))
        v_pu = np.sqrt(np.maximum(problem.voltage_sq(p_kw / KW_PER_MW, minute), 0.0))
        return OpfResult("optimal", minute, demand, p_kw, cost, line_price, float(-dual[0]),
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
