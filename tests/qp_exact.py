"""An exact DC-OPF for small problems, by enumerating active sets: the tests' independent
yardstick for the distance certificate and for exact mode's end states (no solver
tolerance: every candidate is a KKT point to round-off, and a convex QP's KKT points are its
optima).

For every choice of each generator's state (free, at Pmin, at Pmax) and each limited line's
(slack, at +U, at -U) the equality-constrained problem's KKT system is solved; a candidate
counts if it is feasible, its multipliers have the right signs and the system is consistent.
Powers MW, prices EUR/MWh.
"""

from __future__ import annotations

import itertools

import numpy as np

TOL = 1e-10


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
    for gens in itertools.product(range(3), repeat=n):
        gens = np.where(hi <= lo, 1, np.array(gens))  # a generator with no range is held
        for lines in itertools.product(range(3), repeat=n_lines):
            point = _candidate(b, c, lo, hi, demand, D, load_flow, limit, gens, np.array(lines))
            if point is not None and not any(np.allclose(point, f, atol=1e-9) for f in found):
                found.append(point)
    if len(found) != 1:
        return None
    return found[0]


def _candidate(b, c, lo, hi, demand, D, load_flow, limit, gens, lines):
    """The KKT point of one active set, or ``None``."""
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
