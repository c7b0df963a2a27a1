"""An exact DC-OPF for small problems, by enumerating active sets: the tests' independent
yardstick for the distance certificate and for exact mode's end states (no solver
tolerance: every candidate is a KKT point to round-off, and a convex QP's KKT points are its
optima). The optimum found is solved once more in exact rational arithmetic (its active set's
KKT system, the problem's floats taken as exact), so the set points it returns are the
optimum of the problem as given, rounded once to float: a least-squares solve of a system
mixing prices (tens of EUR/MWh) and curvatures over decades with powers (MW) loses digits,
2.7e-9 kW of them on a flat pair beside a curvature of 2000 EUR/MW^2h.

For every choice of each generator's state (free, at Pmin, at Pmax) and each limited line's
(slack, at +U, at -U) the equality-constrained problem's KKT system is solved; a candidate
counts if it is feasible, its multipliers have the right signs and the system is consistent.
Powers MW, prices EUR/MWh.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np

TOL = 1e-10


def roundoff_kw(problem, minute: int = 1) -> float:
    """How far two representations of the same set points may differ by rounding alone, kW:
    the optimum rounded once to float and a run's set points (shares times the demand), a few
    units of the last place of the demand."""
    return 16.0 * float(np.finfo(float).eps) * float(problem.demand[minute - 1]) * 1e3


def exact_dc_opf(problem, minute: int = 1) -> np.ndarray | None:
    """The optimal set points (MW) of ``problem``'s DC-OPF at ``minute``, or ``None`` when the
    optimum is not unique (or the problem is infeasible). Up to about 6 generators and 3
    limited lines (3^(n + lines) systems; repeated set points are one)."""
    row = minute - 1
    online = problem.online[row]
    lo = np.where(online, problem.pmin, 0.0)
    hi = np.where(online, problem.pmax, 0.0)
    demand = float(problem.demand[row])
    D = problem.down
    load_flow = problem.line_load_flow[row]
    limit = problem.limit
    b, c = problem.b, problem.c
    n, n_lines = len(b), len(limit)
    found: list[np.ndarray] = []
    active_set = None
    for gens in itertools.product(range(3), repeat=n):
        gens = np.where(hi <= lo, 1, np.array(gens))  # a generator with no range is held
        for lines in itertools.product(range(3), repeat=n_lines):
            point = _candidate(b, c, lo, hi, demand, D, load_flow, limit, gens, np.array(lines))
            if point is not None and not any(np.allclose(point, f, atol=1e-9) for f in found):
                found.append(point)
                active_set = (gens, np.array(lines))
    if len(found) != 1:
        return None
    exact = _candidate(b, c, lo, hi, demand, D, load_flow, limit, *active_set, exact=True)
    return found[0] if exact is None else exact


def _candidate(b, c, lo, hi, demand, D, load_flow, limit, gens, lines, exact=False):
    """The KKT point of one active set, or ``None``; ``exact``: its system solved in rational
    arithmetic (:func:`_solve_rational`)."""
    free = np.flatnonzero(gens == 0)
    fixed_value = np.where(gens == 1, lo, np.where(gens == 2, hi, 0.0))
    active = np.flatnonzero(lines != 0)
    sign = np.where(lines[active] == 1, 1.0, -1.0)  # +U: flow = U; -U: flow = -U
    m, k = len(free), len(active)
    # unknowns: p_free, lambda, nu_active (nu >= 0 on the active side)
    # stationarity: b + 2 c p - lambda - sum_k s_k nu_k D_ki = 0  (flow = load_flow - D p)
    K = np.zeros((m + 1 + k, m + 1 + k))
    rhs = np.zeros(m + 1 + k)
    for j, i in enumerate(free):
        K[j, j] = 2.0 * c[i]
        K[j, m] = -1.0
        for h, line in enumerate(active):
            K[j, m + 1 + h] = -sign[h] * D[line, i]
        rhs[j] = -b[i]
    K[m, :m] = 1.0
    rhs[m] = demand - fixed_value.sum()
    for h, line in enumerate(active):
        # load_flow - D p = s U  ->  D_free p_free = load_flow - s U - D_fixed p_fixed
        K[m + 1 + h, :m] = D[line, free]
        rhs[m + 1 + h] = load_flow[line] - sign[h] * limit[line] - D[line] @ fixed_value
    if exact and K.size:
        solution = _solve_rational(K, rhs)
        if solution is None:
            return None
    else:
        solution, *_ = np.linalg.lstsq(K, rhs, rcond=None) if K.size else (np.zeros(0),)
    scale = max(1.0, np.abs(rhs).max(initial=0.0), np.abs(b).max(initial=0.0))
    if K.size and np.abs(K @ solution - rhs).max() > TOL * scale:
        return None
    if K.size and np.linalg.matrix_rank(K) < K.shape[0]:
        return None  # not determined: leave unique optima to determined active sets
    p = fixed_value.copy()
    p[free] = solution[:m]
    lam = solution[m] if m + k else 0.0
    nu = solution[m + 1 :]
    power_tol = TOL * max(1.0, np.abs(hi).max(initial=0.0), demand)
    if (p < lo - power_tol).any() or (p > hi + power_tol).any():
        return None
    if (nu < -TOL * scale).any():
        return None
    flow = load_flow - D @ p
    if (np.abs(flow) > limit + power_tol).any():
        return None
    net = np.zeros(len(limit))
    net[active] = sign * nu
    reduced = b + 2.0 * c * p - lam - D.T @ net
    width = hi > lo
    if ((gens == 1) & width & (reduced < -TOL * scale)).any():
        return None
    if ((gens == 2) & width & (reduced > TOL * scale)).any():
        return None
    return np.clip(p, lo, hi)


def _solve_rational(K: np.ndarray, rhs: np.ndarray) -> np.ndarray | None:
    """``K x = rhs`` by Gaussian elimination in fractions (each float taken as the exact
    number it stores), the solution rounded once to float; ``None`` if ``K`` is singular."""
    size = len(rhs)
    rows = [[Fraction(float(v)) for v in K[i]] + [Fraction(float(rhs[i]))] for i in range(size)]
    for col in range(size):
        pivot = next((r for r in range(col, size) if rows[r][col] != 0), None)
        if pivot is None:
            return None
        rows[col], rows[pivot] = rows[pivot], rows[col]
        for r in range(size):
            if r != col and rows[r][col] != 0:
                factor = rows[r][col] / rows[col][col]
                rows[r] = [a - factor * p for a, p in zip(rows[r], rows[col], strict=True)]
    return np.array([float(rows[i][size] / rows[i][i]) for i in range(size)])


def dual_value(problem, minute: int, marginal_price: float, line_price: np.ndarray) -> float:
    """The DC-OPF's Lagrangian dual function at prices ``marginal_price`` (EUR/MWh) and
    ``line_price`` (EUR/MWh per line, positive where the flow presses on ``+U``), EUR/h: the
    least cost of ``sum(b p + c p^2) - lambda (sum p - D) + mu (F - A p) - |mu| U`` over the
    generator ranges, each generator alone (the line flows are ``F - A p``, ``A`` the rows of
    ``problem.down``). A lower bound on the optimal cost at any prices (weak duality), equal
    to it at optimal ones. No voltage rows."""
    row = minute - 1
    online = problem.online[row]
    lo = np.where(online, problem.pmin, 0.0)
    hi = np.where(online, problem.pmax, 0.0)
    mu = np.asarray(line_price, dtype=float)
    slope = problem.b - marginal_price - problem.down.T @ mu  # EUR/MWh
    c = problem.c
    curved = c > 0
    free = -slope / (2.0 * np.where(curved, c, 1.0))
    p = np.where(curved, np.clip(free, lo, hi), np.where(slope >= 0.0, lo, hi))
    load_flow = problem.load_flow[row][: len(problem.limit)]
    constant = marginal_price * problem.demand[row] + mu @ load_flow - np.abs(mu) @ problem.limit
    return float(slope @ p + c @ p**2 + constant)
