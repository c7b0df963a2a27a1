"""Plain-numpy reference of the distance certificate (:mod:`popdispatch.online.certificate`
compiles the same steps): how far an end state can be from the DC-OPF, proved from the state
itself (docs/exact-mode.md, "The distance certificate"). Written for clarity: dense rows, one
minute at a time.

The DC-OPF (paper eq. 1, with the LinDistFlow voltage rows when given) is

    min  sum_i C_i(p_i),  C_i(p) = a_i + b_i p + c_i p^2
    s.t. lo_i <= p_i <= hi_i,   sum_i p_i = P_d,   e_r(p) = e0_r + sum_i A_ri p_i <= 0,

with one row ``r`` per limited line and direction (``flow - U``, ``-flow - U``) and per
monitored bus and bound. For any prices ``mu >= 0`` (the controllers') and any balance price
``lambda``, the Lagrangian bounds the optimum ``p*`` from below, and a feasible end state ``p``
bounds it from above. Writing ``pi_i = lambda - (A^T mu)_i`` (generator ``i``'s locational
price), ``h_i(y) = C_i(y) - pi_i y`` and ``q_i`` its minimiser over ``[lo_i, hi_i]`` (the
generator's best response to its price):

    sum_i [h_i(p*_i) - h_i(q_i)] + sum_r mu_r (-e_r(p*)) = C(p*) - g(lambda, mu)
                                                         <= C(p) - g(lambda, mu) = G,

    G = sum_i [h_i(p_i) - h_i(q_i)] + sum_r mu_r (-e_r(p)) + lambda (P_d - sum_i p_i),

every term on the left being non-negative (``p*`` is feasible, ``q_i`` minimises ``h_i``).
So each generator's optimum lies where ``h_i(y) - h_i(q_i) <= G``: with ``g_i = h_i'(q_i)``
(zero inside the limits, the reduced cost at a limit), ``h_i(y) - h_i(q_i) = g_i (y - q_i)
+ c_i (y - q_i)^2``, an interval around ``q_i`` of half-width ``2 G / (|g_i| + sqrt(g_i^2 +
4 c_i G))`` (on the side the limits allow). A linear generator at its margin (``c_i = 0``,
``g_i = 0``) gets its whole range. Each priced row is within ``G / mu_r`` of its bound at the
optimum. Interval propagation over the balance and the rows (each sum of generators must reach
its bounds with the others inside theirs) then narrows the generators the first step leaves
wide: the margin generator is what the balance leaves of the others. The bound on
``|p_i - p*_i|`` is the farthest end of ``p*_i``'s interval from ``p_i``.

``G`` is summed from non-negative terms computed without cancellation; ``lambda`` minimises it
(the root of ``sum_i q_i(lambda) = sum_i p_i``, the envelope theorem). An end state outside a
row's bound is not feasible and proves nothing: its certificate is infinite. Everything in MW
and EUR/h (prices EUR/MWh).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Passes of interval propagation over the balance and the rows.
PROPAGATION_PASSES = 8


@dataclass(frozen=True)
class Rows:
    """The inequality rows of a minute's DC-OPF, ``e(p) = e0 + A p <= 0`` (MW or MW
    equivalents): ``A`` (rows x generators, dimensionless) and ``e0`` (rows, MW)."""

    A: np.ndarray
    e0: np.ndarray


@dataclass(frozen=True)
class Certificate:
    """What the end state proves. ``bound_mw``: per generator, the largest possible
    ``|p_i - p*_i|`` (MW; ``inf`` when nothing is proved); ``gap``: the duality gap ``G``
    (EUR/h); ``balance_price``: the ``lambda`` that minimises it (EUR/MWh); ``low_mw``,
    ``high_mw``: the interval proved to hold each ``p*_i`` (MW); ``reason``: why nothing is
    proved (an infeasible end state), else ``None``."""

    bound_mw: np.ndarray
    gap: float
    balance_price: float
    low_mw: np.ndarray
    high_mw: np.ndarray
    reason: str | None = None

    @property
    def distance_mw(self) -> float:
        """The largest bound over the generators, MW."""
        return float(self.bound_mw.max()) if len(self.bound_mw) else 0.0


def certify(
    b: np.ndarray,
    c: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    p: np.ndarray,
    demand: float,
    rows: Rows,
    mu: np.ndarray,
    feasibility_mw: float = 0.0,
    target_mw: float = 0.0,
) -> Certificate:
    """The distance certificate of set points ``p`` (MW) against the DC-OPF with costs ``b``
    (EUR/MWh), ``c`` (EUR/MW^2h), limits ``lo``/``hi`` (MW, the minute's: 0 and 0 offline),
    demand ``demand`` (MW), rows ``rows`` and row prices ``mu >= 0`` (EUR/MWh per MW).

    ``feasibility_mw``: how far beyond a row's bound the end state may be and still count as
    on it (round-off of the flows, MW); beyond that the certificate is infinite.
    ``target_mw``: the bound that suffices; propagation is skipped when the generators' own
    intervals already prove it.
    """
    p = np.clip(np.asarray(p, dtype=float), lo, hi)
    mu = np.maximum(np.asarray(mu, dtype=float), 0.0)
    excess = rows.e0 + rows.A @ p if len(mu) else np.zeros(0)
    n = len(p)
    if len(excess) and excess.max() > feasibility_mw:
        r = int(np.argmax(excess))
        return _nothing(n, f"row {r} is {excess[r]:.3g} MW beyond its bound")
    signal = -(rows.A.T @ mu) if len(mu) else np.zeros(n)
    imbalance = demand - float(p.sum())
    lam = balance_price(b, c, lo, hi, float(p.sum()), signal)
    q, slope = best_response(b, c, lo, hi, lam + signal)
    terms = slope * (p - q) + c * (p - q) ** 2
    gap = float(np.maximum(terms, 0.0).sum() + np.maximum(-mu * excess, 0.0).sum())
    gap += abs(lam * imbalance)
    low, high = own_intervals(c, lo, hi, q, slope, gap)
    if np.maximum(np.abs(p - low), np.abs(high - p)).max(initial=0.0) > target_mw:
        low, high = propagate(low, high, demand, abs(imbalance), rows, mu, gap)
    if (low > high).any():
        i = int(np.argmax(low - high))
        return _nothing(n, f"generator {i}: no set point is consistent with the prices")
    bound = np.maximum(np.abs(p - low), np.abs(high - p))
    return Certificate(bound, gap, lam, low, high)


def _nothing(n: int, reason: str) -> Certificate:
    inf = np.full(n, np.inf)
    return Certificate(inf, np.inf, np.nan, -inf, inf, reason)


def best_response(b, c, lo, hi, price) -> tuple[np.ndarray, np.ndarray]:
    """``(q, g)``: each generator's minimiser ``q_i`` of ``C_i(y) - price_i y`` over ``[lo_i,
    hi_i]`` (MW) and the derivative ``g_i = b_i + 2 c_i q_i - price_i`` there (EUR/MWh: 0
    inside, the reduced cost at a limit). A linear generator priced exactly at its cost takes
    ``lo`` (any point is a minimiser; its ``g`` is 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = np.where(c > 0.0, (price - b) / (2.0 * c), np.where(price > b, hi, lo))
    q = np.clip(inside, lo, hi)
    return q, b + 2.0 * c * q - price


def balance_price(b, c, lo, hi, total: float, signal: np.ndarray) -> float:
    """The balance price ``lambda`` (EUR/MWh) at which the best responses to ``lambda +
    signal`` sum to ``total`` (MW): the minimiser of ``G``. ``sum_i q_i(lambda)`` is piecewise
    linear and non-decreasing in ``lambda`` (a step at a linear generator's cost), so the root
    is found exactly between two of its breakpoints (where a generator reaches a limit)."""
    start = b + 2.0 * c * lo - signal  # lambda at which each generator leaves lo
    stop = b + 2.0 * c * hi - signal  # ... reaches hi
    points = np.unique(np.concatenate([start, stop]))
    sums = np.array([best_response(b, c, lo, hi, lam + signal)[0].sum() for lam in points])
    above = np.flatnonzero(sums >= total)
    if not len(above):
        return float(points[-1])
    k = int(above[0])
    if k == 0 or sums[k] == total:
        return float(points[k])
    # between points[k-1] and points[k] the sum is linear (no generator changes regime), with
    # steps at the breakpoints themselves (linear generators): the line through two inner
    # points, the root on it, else at a step
    left, right = points[k - 1], points[k]
    one, two = left + (right - left) / 3.0, left + 2.0 * (right - left) / 3.0
    sum_one = best_response(b, c, lo, hi, one + signal)[0].sum()
    sum_two = best_response(b, c, lo, hi, two + signal)[0].sum()
    slope = (sum_two - sum_one) / (two - one)
    start_sum = sum_one - slope * (one - left)  # just right of the step at ``left``
    if total <= start_sum or not slope > 0.0:
        return float(left if total <= start_sum else right)
    return float(min(left + (total - start_sum) / slope, right))


def own_intervals(c, lo, hi, q, slope, gap) -> tuple[np.ndarray, np.ndarray]:
    """Where ``g_i (y - q_i) + c_i (y - q_i)^2 <= gap`` within ``[lo_i, hi_i]`` (MW): the
    half-width ``2 gap / (|g_i| + sqrt(g_i^2 + 4 c_i gap))`` on each side of ``q_i`` the limits
    leave open (both inside, where ``g_i`` is 0; above ``lo``, below ``hi``)."""
    inside = (q > lo) & (q < hi)
    g = np.where(inside, 0.0, np.abs(slope))
    with np.errstate(divide="ignore", invalid="ignore"):
        width = 2.0 * gap / (g + np.sqrt(g**2 + 4.0 * c * gap))
    flat = (c == 0.0) & (g == 0.0)  # a linear generator at its margin: any set point
    width = np.where(flat, np.inf, np.where(gap == 0.0, 0.0, width))
    low = np.where(q > lo, np.maximum(q - width, lo), q)
    high = np.where(q < hi, np.minimum(q + width, hi), q)
    return low, high


def propagate(low, high, demand, balance_slack, rows: Rows, mu, gap) -> tuple[np.ndarray, ...]:
    """Narrow the intervals ``[low, high]`` (MW) by the balance ``sum y = demand`` (within
    ``balance_slack``) and each row's window ``-e0 - gap / mu <= A y <= -e0`` (the lower side
    only for a priced row), a few passes of interval propagation."""
    n_rows = len(rows.e0)
    A = np.vstack([np.ones(len(low)), rows.A]) if n_rows else np.ones((1, len(low)))
    with np.errstate(divide="ignore"):
        floor = np.where(mu > 0.0, -rows.e0 - gap / np.where(mu > 0.0, mu, 1.0), -np.inf)
    left = np.concatenate([[demand - balance_slack], floor])
    right = np.concatenate([[demand + balance_slack], -rows.e0])
    for _ in range(PROPAGATION_PASSES):
        new_low, new_high = _propagation_pass(A, left, right, low, high)
        if np.array_equal(new_low, low) and np.array_equal(new_high, high):
            break
        low, high = new_low, new_high
    return low, high


def _propagation_pass(A, left, right, low, high) -> tuple[np.ndarray, np.ndarray]:
    """One pass: for each row ``left <= A y <= right`` and each member ``i``, the values
    ``A_ri y_i`` can take with every other member anywhere in its interval."""
    for r in range(A.shape[0]):
        a = A[r]
        members = np.flatnonzero(a)
        if not len(members):
            continue
        coef = a[members]
        least = np.where(coef > 0, coef * low[members], coef * high[members])
        most = np.where(coef > 0, coef * high[members], coef * low[members])
        if np.isinf(least).any() or np.isinf(most).any():
            continue
        sum_least, sum_most = least.sum(), most.sum()
        slack = 4.0 * np.finfo(float).eps * (np.abs(least).sum() + np.abs(most).sum() + 1e-300)
        term_low = left[r] - (sum_most - most) - slack  # A_ri y_i >= this
        term_high = right[r] - (sum_least - least) + slack  # A_ri y_i <= this
        with np.errstate(invalid="ignore"):
            y_low = np.where(coef > 0, term_low / coef, term_high / coef)
            y_high = np.where(coef > 0, term_high / coef, term_low / coef)
        low = low.copy()
        high = high.copy()
        low[members] = np.maximum(low[members], np.nan_to_num(y_low, nan=-np.inf))
        high[members] = np.minimum(high[members], np.nan_to_num(y_high, nan=np.inf))
    return low, high


@dataclass(frozen=True)
class KktPoint:
    """An exact KKT point of the DC-OPF near an end state: set points ``p`` (MW), the balance
    price ``balance_price`` (EUR/MWh) and the row prices ``mu`` (EUR/MWh per MW)."""

    p: np.ndarray
    balance_price: float
    mu: np.ndarray


def polish(b, c, lo, hi, p, demand: float, rows: Rows, mu, margin_mw: float) -> KktPoint | None:
    """The KKT point of the DC-OPF on the end state's active set, or ``None`` if there is
    none there: generators within ``margin_mw`` of a limit held on it, the priced (or
    overflowing) rows held on their bounds, and the rest solved from stationarity
    (``b_i + 2 c_i y_i - lambda + sum_r mu_r A_ri = 0``), the balance and the held rows (a
    linear system; least squares, nearest the end state, when the active set leaves it
    singular). The point counts only if it is a KKT point within round-off: inside the limits,
    every other row within its bound, ``mu >= 0`` and each held generator's reduced cost of the
    right sign."""
    at_lo = p <= lo + margin_mw
    at_hi = ~at_lo & (p >= hi - margin_mw)
    fixed = at_lo | at_hi
    free = np.flatnonzero(~fixed)
    value = np.where(at_lo, lo, np.where(at_hi, hi, p))
    excess = rows.e0 + rows.A @ p if len(rows.e0) else np.zeros(0)
    held = np.flatnonzero((mu > 0.0) | (excess > 0.0))
    A_free = rows.A[np.ix_(held, free)]
    m, k = len(free), len(held)
    K = np.zeros((m + 1 + k, m + 1 + k))
    K[:m, :m] = np.diag(2.0 * c[free])
    K[:m, m] = -1.0
    K[:m, m + 1 :] = A_free.T
    K[m, :m] = 1.0
    K[m + 1 :, :m] = A_free
    rhs = np.concatenate(
        [
            -b[free] - 2.0 * c[free] * p[free],
            [demand - value.sum()],
            -(rows.e0[held] + rows.A[held] @ value),
        ]
    )  # the deviation d = y - p of the free generators, then lambda, mu
    solution, *_ = np.linalg.lstsq(K, rhs, rcond=None)
    y = value.copy()
    y[free] = p[free] + solution[:m]
    lam = float(solution[m]) if m or k else 0.0
    prices = np.zeros(len(rows.e0))
    prices[held] = solution[m + 1 :]
    scale = max(float(np.abs(hi).max(initial=0.0)), demand, 1e-300)
    round_off = 1e-9 * scale
    price_scale = max(float(np.abs(b).max(initial=0.0)), abs(lam), 1.0)
    residual = K @ solution - rhs
    if np.abs(residual).max(initial=0.0) > 1e-9 * max(price_scale, scale):
        return None
    if (y < lo - round_off).any() or (y > hi + round_off).any():
        return None
    if (prices < -1e-9 * price_scale).any():
        return None
    after = rows.e0 + rows.A @ y if len(rows.e0) else np.zeros(0)
    if len(after) and after.max() > round_off:
        return None
    prices = np.maximum(prices, 0.0)
    reduced = b + 2.0 * c * y - lam + (rows.A.T @ prices if len(prices) else 0.0)
    tolerance = 1e-9 * price_scale
    if (reduced[at_lo & (hi > lo)] < -tolerance).any():
        return None
    if (reduced[at_hi & (hi > lo)] > tolerance).any():
        return None
    return KktPoint(np.clip(y, lo, hi), lam, prices)


def certify_end_state(
    b, c, lo, hi, p, demand: float, rows: Rows, mu, target_mw: float
) -> Certificate:
    """The certificate of set points ``p`` (MW) with the controllers' prices ``mu``.

    First the exact KKT point ``p_hat`` on the end state's active set (:func:`polish`: with
    the generators at their limits to round-off, then to within ``target_mw``), certified
    with its own prices: the optimum lies in the intervals that proves. Where that does not
    bring every generator within ``target_mw`` (MW) of ``p``, the gap bound of ``p`` itself
    with the controllers' prices (:func:`certify`) narrows them: each is a proof, so the
    optimum lies in the intersection. The bound is its farthest end from ``p``."""
    round_off = 1e-12 * max(demand, 1e-300)
    low, high = np.asarray(lo, dtype=float).copy(), np.asarray(hi, dtype=float).copy()
    best = None
    for margin in (round_off, target_mw):
        point = polish(b, c, lo, hi, p, demand, rows, mu, margin)
        if point is None:
            continue
        exact = certify(b, c, lo, hi, point.p, demand, rows, point.mu, round_off, target_mw / 2)
        if exact.reason is None:
            low, high = np.maximum(low, exact.low_mw), np.minimum(high, exact.high_mw)
            best = exact if best is None or exact.gap < best.gap else best
            if _bound(p, low, high).max(initial=0.0) <= target_mw:
                break
    if best is None or _bound(p, low, high).max(initial=0.0) > target_mw:
        direct = certify(b, c, lo, hi, p, demand, rows, mu, round_off, target_mw)
        if direct.reason is None:
            low, high = np.maximum(low, direct.low_mw), np.minimum(high, direct.high_mw)
            best = direct if best is None else best
    if best is None:
        return _nothing(len(p), "no set point near the end state is a KKT point, and the end "
                        "state is beyond a limit")  # fmt: skip
    if (low > high).any():  # two proofs that disagree: round-off beyond what was allowed
        return _nothing(len(p), "the proofs of the end state disagree")
    return Certificate(_bound(p, low, high), best.gap, best.balance_price, low, high)


def _bound(p, low, high) -> np.ndarray:
    """The farthest end of each interval from ``p``."""
    return np.maximum(np.abs(p - low), np.abs(high - p))


def problem_rows(problem, minute: int) -> Rows:
    """The rows of ``problem``'s DC-OPF at the 1-based ``minute``: each limited line's
    ``flow - U`` then ``-flow - U`` (``flow = load_flow - D p``), then the voltage rows'
    low-bound then high-bound excesses (MW equivalents, modes/voltage.py)."""
    row = minute - 1
    down = problem.down
    n_lines = len(problem.limit)
    line_flow = problem.line_load_flow[row]
    A = [-down, down]
    e0 = [line_flow - problem.limit, -line_flow - problem.limit]
    if problem.n_voltage:
        n_v = problem.n_voltage
        load = problem.load_flow[row]
        A += [-problem.voltage_sens, problem.voltage_sens]
        e0 += [load[n_lines : n_lines + n_v], load[n_lines + n_v :]]
    return Rows(np.vstack(A), np.concatenate(e0))


def certify_minutes(
    problem, minutes: np.ndarray, p_mw: np.ndarray, mu: np.ndarray, accuracy_mw: np.ndarray
) -> list[Certificate]:
    """The certificate of each minute's end state: set points ``p_mw`` (minutes x generators,
    MW) and broadcast row prices ``mu`` (minutes x rows of :func:`problem_rows`, EUR/MWh per
    MW), against the accuracy ``accuracy_mw`` of each minute (MW)."""
    certificates = []
    for r, minute in enumerate(np.asarray(minutes, dtype=np.int64)):
        online = problem.online[minute - 1]
        lo = np.where(online, problem.pmin, 0.0)
        hi = np.where(online, problem.pmax, 0.0)
        rows = problem_rows(problem, int(minute))
        certificates.append(certify_end_state(
            problem.b, problem.c, lo, hi, p_mw[r], float(problem.demand[minute - 1]), rows,
            mu[r], float(accuracy_mw[r]),
        ))  # fmt: skip
    return certificates
