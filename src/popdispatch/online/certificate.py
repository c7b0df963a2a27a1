"""The distance certificate: how far an end state can be from the DC-OPF, proved from the
state itself (docs/exact-mode.md, "The distance certificate").

The DC-OPF (paper eq. 1, with the LinDistFlow voltage rows when given) is

    min  sum_i C_i(p_i),  C_i(p) = a_i + b_i p + c_i p^2
    s.t. lo_i <= p_i <= hi_i,   sum_i p_i = P_d,   e_r(p) = e0_r + sum_i A_ri p_i <= 0,

with one row ``r`` per limited line and direction (``flow - U``, ``-flow - U``) and per
monitored bus and bound. For any prices ``mu >= 0`` and balance price ``lambda`` the
Lagrangian bounds the optimum ``p*`` from below and a feasible end state ``y`` bounds it from
above. With ``pi_i = lambda - (A^T mu)_i`` (generator ``i``'s locational price), ``h_i(x) =
C_i(x) - pi_i x`` and ``q_i`` its minimiser over ``[lo_i, hi_i]`` (the best response):

    sum_i [h_i(p*_i) - h_i(q_i)] + sum_r mu_r (-e_r(p*))  <=  G
    G = sum_i [h_i(y_i) - h_i(q_i)] + sum_r mu_r (-e_r(y)) + |lambda (P_d - sum_i y_i)|,

every term on the left non-negative. So ``p*_i`` lies where ``g_i (x - q_i) + c_i (x - q_i)^2
<= G`` (``g_i = h_i'(q_i)``: 0 inside the limits, the reduced cost at one), an interval of
half-width ``2 G / (|g_i| + sqrt(g_i^2 + 4 c_i G))`` around ``q_i`` (the whole range for a
linear generator at its margin); each priced row is within ``G / mu_r`` of its bound at the
optimum, and interval propagation over the balance and the rows narrows the generators the
first step leaves wide. ``lambda`` minimises ``G`` (``sum_i q_i(lambda) = sum_i y_i``).

An end state is seldom exactly feasible (a line a few nanowatts over) and a slack priced row
or a flat generator makes ``G`` large against the accuracy. So the certificate first
*polishes*: it solves the KKT system on the end state's active set (generators at their
limits held there, priced rows held on their bounds; least squares nearest the end state
where the active set leaves it singular) and keeps the solution ``y`` only if it is a KKT point
within round-off (inside the limits, the other rows within their bounds, ``mu >= 0``, reduced
costs of the right sign); certified with its own prices its ``G`` is round-off and its
intervals tight. The end state's own gap bound narrows them further where it holds. Every
interval is a proof that ``p*`` lies in it; the bound on ``|p_i - p*_i|`` is the farthest end
of their intersection from ``p_i``. Powers MW, costs EUR/h, prices EUR/MWh.

The minutes of a day are certified together: the active sets repeat from minute to minute, so
each distinct one's KKT matrix is solved once for all its minutes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Passes of interval propagation over the balance and the rows.
PROPAGATION_PASSES = 8
#: Relative round-off allowed in an exact KKT point's checks (of the largest power or price).
KKT_ROUND_OFF = 1e-9
#: Relative round-off of the powers (of the demand) within which a row counts as on its bound.
FEASIBLE_ROUND_OFF = 1e-12
#: A row's coefficient at most this fraction of its largest narrows nothing (round-off).
FAINT_COEFFICIENT = 1e-9
#: A generator is solved for (:func:`_narrow_by_solve`) when its interval after propagation is
#: wider than this fraction of the widest.
SOLVE_WIDTH = 1e-3
#: Bisection steps on the balance price (the bracket reaches round-off well before).
BISECTIONS = 80


@dataclass(frozen=True)
class Certificate:
    """What an end state proves. ``bound_mw``: per generator, the largest possible ``|p_i -
    p*_i|`` (MW; ``inf`` when nothing is proved); ``gap``: the duality gap of the proof that
    counted, EUR/h; ``reason``: why nothing is proved, else ``None``."""

    bound_mw: np.ndarray
    gap: float
    reason: str | None = None

    @property
    def distance_mw(self) -> float:
        """The largest bound over the generators, MW."""
        return float(self.bound_mw.max()) if len(self.bound_mw) else 0.0


@dataclass(frozen=True)
class Batch:
    """Minutes to certify: costs ``b`` (EUR/MWh), ``c`` (EUR/MW^2h) per generator; per minute
    the limits ``lo``/``hi`` (MW, 0 offline), ``demand`` (MW), row offsets ``e0`` (MW); the
    rows' matrix ``A`` (rows x generators, dimensionless)."""

    b: np.ndarray
    c: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    demand: np.ndarray
    A: np.ndarray
    e0: np.ndarray

    @classmethod
    def of(cls, problem, minutes: np.ndarray) -> Batch:
        """The rows of ``problem``'s DC-OPF at the 1-based ``minutes``: each limited line's
        ``flow - U`` then ``-flow - U`` (``flow = load_flow - D p``), then each monitored
        bus's low-bound then high-bound excess (MW equivalents, modes/voltage.py)."""
        rows = np.asarray(minutes, dtype=np.int64) - 1
        online = problem.online[rows]
        flow = problem.line_load_flow[rows]
        blocks, e0 = [-problem.down, problem.down], [flow - problem.limit, -flow - problem.limit]
        if problem.n_voltage:
            n_lines, n_v = len(problem.limit), problem.n_voltage
            load = problem.load_flow[rows]
            blocks += [-problem.voltage_sens, problem.voltage_sens]
            e0 += [load[:, n_lines : n_lines + n_v], load[:, n_lines + n_v :]]
        return cls(
            problem.b, problem.c, np.where(online, problem.pmin, 0.0),
            np.where(online, problem.pmax, 0.0), problem.demand[rows],
            np.vstack(blocks).reshape(-1, problem.n_generators), np.concatenate(e0, axis=1),
        )  # fmt: skip


def certify_minutes(
    problem, minutes: np.ndarray, p_mw: np.ndarray, mu: np.ndarray, accuracy_mw: np.ndarray
) -> list[Certificate]:
    """The certificate of each minute's end state: set points ``p_mw`` (minutes x generators,
    MW) and broadcast row prices ``mu`` (minutes x rows of :meth:`Batch.of`, EUR/MWh per
    MW), against each minute's accuracy ``accuracy_mw`` (MW)."""
    batch = Batch.of(problem, minutes)
    bound, gap, reasons = certify(batch, np.atleast_2d(p_mw), np.atleast_2d(mu),
                                  np.broadcast_to(accuracy_mw, (len(batch.demand),)))  # fmt: skip
    return [Certificate(bound[m], float(gap[m]), reasons[m]) for m in range(len(gap))]


def certify(batch: Batch, p, mu, target) -> tuple[np.ndarray, np.ndarray, list[str | None]]:
    """``(bound, gap, reasons)`` of set points ``p`` (minutes x generators, MW) with prices
    ``mu`` (minutes x rows): per generator the bound on ``|p - p*|`` (MW), per minute the gap
    of the proof that counted (EUR/h) and why nothing is proved (else ``None``). ``target``:
    per minute the accuracy that suffices (MW)."""
    p = np.clip(p, batch.lo, batch.hi)
    low, high = batch.lo.copy(), batch.hi.copy()
    gap = np.full(len(p), np.inf)
    round_off = FEASIBLE_ROUND_OFF * np.maximum(batch.demand, 1e-300)
    for margin in (round_off, target):
        done = _farthest(p, low, high) <= target
        y, prices, ok = polish(batch, p, mu, margin, ~done)
        if ok.any():
            exact = prove(batch, y, prices, round_off, 0.5 * target, ok)
            low, high, gap = _narrow(low, high, gap, exact, ok)
    todo = _farthest(p, low, high) > target
    if todo.any():
        low, high, gap = _narrow(low, high, gap, prove(batch, p, mu, round_off, target, todo),
                                 todo)  # fmt: skip
    bound = np.maximum(np.abs(p - low), np.abs(high - p))
    reasons: list[str | None] = [None] * len(p)
    for m in np.flatnonzero(~np.isfinite(gap)):
        reasons[m] = "the end state is beyond a limit and no set point near it is a KKT point"
        bound[m] = np.inf
    for m in np.flatnonzero(np.isfinite(gap) & (low > high).any(axis=1)):
        reasons[m] = "the proofs of the end state disagree (round-off beyond what was allowed)"
        bound[m] = np.inf
    return bound, gap, reasons


def _narrow(low, high, gap, proof, where):
    """Intersect the intervals of the minutes ``where`` with a proof's ``(gap, low, high)``
    (an infinite gap proves nothing); keep the smaller gap."""
    proof_gap, proof_low, proof_high = proof
    use = where & np.isfinite(proof_gap)
    low = np.where(use[:, None], np.maximum(low, proof_low), low)
    high = np.where(use[:, None], np.minimum(high, proof_high), high)
    return low, high, np.where(use, np.minimum(gap, proof_gap), gap)


def _farthest(p, low, high) -> np.ndarray:
    """Per minute, the largest distance from a set point to an end of its interval (MW)."""
    return np.maximum(np.abs(p - low), np.abs(high - p)).max(axis=1, initial=0.0)


def prove(batch: Batch, y, mu, feasibility, target, where) -> tuple[np.ndarray, ...]:
    """The gap bound (module docstring) of set points ``y`` with prices ``mu`` at the minutes
    ``where``: ``(gap, low, high)``, the intervals proved to hold ``p*`` (MW; ``G`` infinite
    where ``y`` is beyond a row's bound by more than ``feasibility``, MW). Propagation runs
    only at the minutes whose intervals leave a generator farther than ``target`` (MW)."""
    b, c, lo, hi = batch.b, batch.c, batch.lo, batch.hi
    excess = batch.e0 + y @ batch.A.T
    feasible = where & (excess <= np.broadcast_to(feasibility, (len(y),))[:, None]).all(axis=1)
    signal = -(np.maximum(mu, 0.0) @ batch.A)
    total = y.sum(axis=1)
    lam = balance_prices(b, c, lo, hi, total, signal)
    q, g = best_response(b, c, lo, hi, lam[:, None] + signal)
    d = y - q
    gap = (
        np.maximum(g * d + c * d * d, 0.0).sum(axis=1)
        + np.maximum(-mu * excess, 0.0).sum(axis=1)
        + np.abs(lam * (batch.demand - total))
    )
    low, high = own_intervals(c, lo, hi, q, g, gap[:, None])
    wide = feasible & (_farthest(y, low, high) > target)
    for m in np.flatnonzero(wide):
        low[m], high[m] = propagate(low[m], high[m], batch.demand[m],
                                    abs(batch.demand[m] - total[m]), batch.A, batch.e0[m], mu[m],
                                    gap[m])  # fmt: skip
    return np.where(feasible, gap, np.inf), low, high


def best_response(b, c, lo, hi, price) -> tuple[np.ndarray, np.ndarray]:
    """``(q, g)``: each generator's minimiser ``q`` of ``C(x) - price x`` over ``[lo, hi]``
    (MW; a linear generator priced exactly at its cost takes ``lo``) and the derivative ``g =
    b + 2 c q - price`` there (EUR/MWh)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = np.where(c > 0.0, (price - b) / (2.0 * c), np.where(price > b, hi, lo))
    q = np.clip(inside, lo, hi)
    return q, b + 2.0 * c * q - price


def balance_prices(b, c, lo, hi, total, signal) -> np.ndarray:
    """Per minute the ``lambda`` (EUR/MWh) at which the best responses to ``lambda + signal``
    sum to ``total`` (MW), by bisection to round-off: the sum is non-decreasing in ``lambda``
    (with a step at a linear generator's cost, where the root may sit); the end of the last
    bracket whose sum is nearer ``total``."""
    low = (b + 2.0 * c * lo - signal).min(axis=1, initial=np.inf)
    high = (b + 2.0 * c * hi - signal).max(axis=1, initial=-np.inf)
    for _ in range(BISECTIONS):
        middle = 0.5 * (low + high)
        below = best_response(b, c, lo, hi, middle[:, None] + signal)[0].sum(axis=1) < total
        low, high = np.where(below, middle, low), np.where(below, high, middle)
    miss_low = np.abs(best_response(b, c, lo, hi, low[:, None] + signal)[0].sum(axis=1) - total)
    miss_high = np.abs(best_response(b, c, lo, hi, high[:, None] + signal)[0].sum(axis=1) - total)
    return np.where(miss_low < miss_high, low, high)


def own_intervals(c, lo, hi, q, g, gap) -> tuple[np.ndarray, np.ndarray]:
    """Where ``g (x - q) + c (x - q)^2 <= gap`` within ``[lo, hi]`` (MW), on each side of ``q``
    the limits leave open (both inside, where ``g`` is 0)."""
    inside = (q > lo) & (q < hi)
    slope = np.where(inside, 0.0, np.abs(g))
    with np.errstate(divide="ignore", invalid="ignore"):
        width = 2.0 * gap / (slope + np.sqrt(slope**2 + 4.0 * c * gap))
    flat = (c == 0.0) & (slope == 0.0)  # a linear generator at its margin: any set point
    width = np.where(flat, np.inf, np.where(gap == 0.0, 0.0, width))
    width = width + 8.0 * np.finfo(float).eps * np.maximum(np.abs(q), np.abs(hi))  # round-off
    low = np.where(q > lo, np.maximum(q - width, lo), q)
    high = np.where(q < hi, np.minimum(q + width, hi), q)
    return low, high


def propagate(low, high, demand, balance_slack, A, e0, mu, gap) -> tuple[np.ndarray, np.ndarray]:
    """One minute's intervals ``[low, high]`` (MW) narrowed by the balance ``sum y = demand``
    (within ``balance_slack``) and each row's window ``-e0 - gap / mu <= A y <= -e0`` (the
    lower side only for a priced row), a few passes of interval propagation."""
    matrix = np.vstack([np.ones(len(low)), A])
    with np.errstate(divide="ignore"):
        floor = np.where(mu > 0.0, -e0 - gap / np.where(mu > 0.0, mu, 1.0), -np.inf)
    left = np.concatenate([[demand - balance_slack], floor])
    right = np.concatenate([[demand + balance_slack], -e0])
    members = [np.flatnonzero(row) for row in matrix]
    for _ in range(PROPAGATION_PASSES):
        before = (low.copy(), high.copy())
        for r, idx in enumerate(members):
            if len(idx):
                _narrow_row(matrix[r, idx], idx, left[r], right[r], low, high)
        if np.array_equal(before[0], low) and np.array_equal(before[1], high):
            break
    priced = np.r_[0, 1 + np.flatnonzero(mu > 0.0)]  # the balance and the priced rows
    _narrow_by_solve(matrix[priced], left[priced], right[priced], low, high)
    return low, high


def _narrow_by_solve(matrix, left, right, low, high) -> None:
    """The generators whose intervals are still wide, narrowed in place by solving the rows
    ``left <= matrix y <= right`` for them when those rows determine them (full column rank):
    the case propagation cannot settle, several linear generators at the margin of a linear
    program sharing the balance and the priced rows, each row with more than one of them.
    With ``M`` the wide generators' columns and ``L`` a left inverse of it (the pseudo-inverse
    of its rows weighted by their windows' inverse widths, so that a loose row counts little),
    ``y_W = L (M y_W) - E y_W`` (``E = L M - I``, round-off), and ``M y_W`` lies in the rows'
    windows less the other generators' intervals: interval arithmetic bounds ``y_W``."""
    width = high - low
    wide = np.flatnonzero(width > SOLVE_WIDTH * max(width.max(initial=0.0), 0.0))
    if not len(wide) or len(wide) > len(matrix) or not np.isfinite(width[wide]).all():
        return
    narrow = np.setdiff1d(np.arange(len(low)), wide)
    M, rest = matrix[:, wide], matrix[:, narrow]
    least = np.maximum(rest, 0.0) @ low[narrow] + np.minimum(rest, 0.0) @ high[narrow]
    most = np.maximum(rest, 0.0) @ high[narrow] + np.minimum(rest, 0.0) @ low[narrow]
    a, b = left - most, right - least  # the window of M y_W
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return
    if np.linalg.matrix_rank(M) < len(wide):
        return
    half = 0.5 * (b - a)
    weight = 1.0 / np.maximum(half, 1e-12 * max(1.0, np.abs(a).max(), np.abs(b).max()))
    inverse = np.linalg.pinv(weight[:, None] * M) * weight  # a left inverse of M
    size = np.maximum(np.abs(low[wide]), np.abs(high[wide]))
    error = np.abs(inverse @ M - np.eye(len(wide))) @ size
    scale = np.abs(inverse) @ np.maximum(np.abs(a), np.abs(b))
    radius = np.abs(inverse) @ half + error + 16.0 * np.finfo(float).eps * scale
    center = inverse @ (0.5 * (a + b))
    low[wide] = np.maximum(low[wide], center - radius)
    high[wide] = np.minimum(high[wide], center + radius)


def _narrow_row(coef, idx, left, right, low, high) -> None:
    """One row ``left <= sum coef y[idx] <= right``: each member's interval narrowed, in place,
    to what the row allows with every other member anywhere in its own (a few units of
    round-off of slack)."""
    least = np.where(coef > 0, coef * low[idx], coef * high[idx])
    most = np.where(coef > 0, coef * high[idx], coef * low[idx])
    slack = 4.0 * np.finfo(float).eps * (np.abs(least).sum() + np.abs(most).sum())
    floor = left - (most.sum() - most) - slack  # coef y >= floor
    ceiling = right - (least.sum() - least) + slack  # coef y <= ceiling
    with np.errstate(invalid="ignore", over="ignore"):
        new_low = np.where(coef > 0, floor / coef, ceiling / coef)
        new_high = np.where(coef > 0, ceiling / coef, floor / coef)
    # a coefficient at round-off of the row's largest (a distribution factor's 1e-17) would
    # turn the row's round-off into a bound of any size: such a member is not narrowed
    faint = np.abs(coef) <= FAINT_COEFFICIENT * np.abs(coef).max()
    new_low, new_high = np.where(faint, -np.inf, new_low), np.where(faint, np.inf, new_high)
    low[idx] = np.maximum(low[idx], np.nan_to_num(new_low, nan=-np.inf))
    high[idx] = np.minimum(high[idx], np.nan_to_num(new_high, nan=np.inf))


def polish(batch: Batch, p, mu, margin, where) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The KKT point of the DC-OPF on each minute's active set: ``(y, prices, ok)`` (MW,
    EUR/MWh per MW, per minute whether it is a KKT point within round-off). Generators within
    ``margin`` (MW, per minute) of a limit are held on it, priced or overflowing rows on their
    bounds; the free generators' deviations from ``p``, ``lambda`` and the held rows' prices
    solve stationarity (``b_i + 2 c_i y_i - lambda + sum_r mu_r A_ri = 0``), the balance and
    the held rows. Minutes with the same active set share one KKT matrix (one least-squares
    solve for all of them)."""
    margin = np.broadcast_to(margin, (len(p),))[:, None]
    at_lo = p <= batch.lo + margin
    at_hi = ~at_lo & (p >= batch.hi - margin)
    held_value = np.where(at_lo, batch.lo, np.where(at_hi, batch.hi, p))
    excess = batch.e0 + p @ batch.A.T
    rows_held = (mu > 0.0) | (excess > 0.0)
    y = held_value.copy()
    prices = np.zeros_like(mu)
    ok = np.zeros(len(p), dtype=bool)
    state = np.concatenate([at_lo * 1 + at_hi * 2, rows_held * 1], axis=1).astype(np.int8)
    patterns, group = np.unique(state[where], axis=0, return_inverse=True)
    minutes = np.flatnonzero(where)
    for k in range(len(patterns)):
        chosen = minutes[group.ravel() == k]
        fixed = at_lo[chosen[0]] | at_hi[chosen[0]]
        held = np.flatnonzero(rows_held[chosen[0]])
        y[chosen], prices[chosen], lam = _solve_active_set(batch, p, held_value, fixed, held,
                                                           chosen)  # fmt: skip
        ok[chosen] = _is_kkt_point(batch, y, prices, lam, at_lo, at_hi, chosen)
    return y, prices, ok


def _solve_active_set(batch: Batch, p, held_value, fixed, held, chosen):
    """The least-squares solution (nearest ``p``) of one active set's KKT system for the
    minutes ``chosen``: ``(y, prices, lambda)``. Held rows with the same coefficients (series
    lines with the same generators below, at different limits) are one row, the tightest of
    them each minute (the largest ``e0``), which carries their price."""
    free = np.flatnonzero(~fixed)
    held_all = held
    held, tightest = _distinct_rows(batch, held, chosen)
    m, k = len(free), len(held)
    A_free = batch.A[np.ix_(held, free)]
    K = np.zeros((m + 1 + k, m + 1 + k))
    K[:m, :m] = np.diag(2.0 * batch.c[free])
    K[:m, m] = -1.0
    K[:m, m + 1 :] = A_free.T
    K[m, :m] = 1.0
    K[m + 1 :, :m] = A_free
    base = held_value[chosen]
    rhs = np.concatenate(
        [
            -batch.b[free] - 2.0 * batch.c[free] * p[np.ix_(chosen, free)],
            (batch.demand[chosen] - base.sum(axis=1))[:, None],
            -(tightest + base @ batch.A[held].T),
        ],
        axis=1,
    )  # the free generators' deviations from p, lambda, the held rows' prices
    solution = np.zeros((len(chosen), 0))
    if K.size:  # least squares, then one step of iterative refinement on its residual
        solution = np.linalg.lstsq(K, rhs.T, rcond=None)[0].T
        solution += np.linalg.lstsq(K, (rhs - solution @ K.T).T, rcond=None)[0].T
    y = base.copy()
    y[:, free] = p[np.ix_(chosen, free)] + solution[:, :m]
    if m:  # the solve's round-off off the balance, to the free generator with the most room
        room = np.minimum(y[:, free] - batch.lo[np.ix_(chosen, free)],
                          batch.hi[np.ix_(chosen, free)] - y[:, free])  # fmt: skip
        widest = free[np.argmax(room, axis=1)]
        y[np.arange(len(chosen)), widest] += batch.demand[chosen] - y.sum(axis=1)
    prices = np.zeros((len(chosen), batch.e0.shape[1]))
    for h, group in enumerate(_groups(batch, held_all)):
        which = group[np.argmax(batch.e0[np.ix_(chosen, group)], axis=1)]
        prices[np.arange(len(chosen)), which] = solution[:, m + 1 + h]
    lam = solution[:, m] if m + k else np.zeros(len(chosen))
    residual = np.abs(solution @ K.T - rhs).max(axis=1, initial=0.0)
    scale = np.maximum(np.abs(rhs).max(axis=1, initial=0.0), 1.0)
    lam = np.where(residual <= 1e-9 * scale, lam, np.nan)  # an inconsistent active set
    return y, prices, lam


def _distinct_rows(batch: Batch, held, chosen) -> tuple[np.ndarray, np.ndarray]:
    """``held`` without repeated rows (one per set of equal coefficients) and each kept row's
    tightest offset per minute ``chosen`` (minutes x kept rows, MW)."""
    groups = _groups(batch, held)
    kept = np.array([group[0] for group in groups], dtype=np.int64)
    tightest = np.stack([batch.e0[np.ix_(chosen, group)].max(axis=1) for group in groups],
                        axis=1) if groups else np.zeros((len(chosen), 0))  # fmt: skip
    return kept, tightest


def _groups(batch: Batch, held) -> list[np.ndarray]:
    """The held rows grouped by equal coefficients, in the order of their first members."""
    _, first, inverse = np.unique(batch.A[held], axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    return [np.asarray(held)[inverse.ravel() == g] for g in order]


def _is_kkt_point(batch: Batch, y, prices, lam, at_lo, at_hi, chosen) -> np.ndarray:
    """Per minute ``chosen``, is ``y`` with ``lam`` and ``prices`` a KKT point within
    :data:`KKT_ROUND_OFF` (of the largest power and price)? Clips ``y`` into its limits and the
    prices to ``>= 0`` where it is."""
    lo, hi = batch.lo[chosen], batch.hi[chosen]
    yy, pp = y[chosen], prices[chosen]
    power_tol = KKT_ROUND_OFF * np.maximum(batch.demand[chosen], np.abs(hi).max(axis=1))
    price_tol = KKT_ROUND_OFF * np.maximum(np.abs(lam), np.abs(batch.b).max(initial=1.0))
    inside = ((yy >= lo - power_tol[:, None]) & (yy <= hi + power_tol[:, None])).all(axis=1)
    nonnegative = (pp >= -price_tol[:, None]).all(axis=1)
    after = batch.e0[chosen] + yy @ batch.A.T
    within = (after <= power_tol[:, None]).all(axis=1)
    reduced = batch.b + 2.0 * batch.c * yy - lam[:, None] + np.maximum(pp, 0.0) @ batch.A
    width = hi > lo
    signs = ~((at_lo[chosen] & width & (reduced < -price_tol[:, None]))
              | (at_hi[chosen] & width & (reduced > price_tol[:, None]))).any(axis=1)  # fmt: skip
    ok = inside & nonnegative & within & signs & np.isfinite(lam)
    y[chosen] = np.where(ok[:, None], np.clip(yy, lo, hi), yy)
    prices[chosen] = np.where(ok[:, None], np.maximum(pp, 0.0), pp)
    return ok
