"""The DC-OPF's KKT conditions, checked at the end state of a mode that claims the DC-OPF
(with voltage limits: the LinDistFlow OPF's, its voltage rows included; docs/voltage.md)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.integrate import Integrator


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
    def of(
        cls, integrator: Integrator, gain: float, demand_mw: float = 0.0, price_scale: float = 1.0
    ) -> KktTolerances:
        """``power_mw`` = the minute's stopping tolerance ``max(tol_rel * demand_mw, tol_kw)``;
        ``flow_gap = power_mw / (gain * window * dt)``; ``price = 2 price_atol * price_scale``
        (EUR/MW; see :func:`kkt_violations`). ``gain``: the revision gain in force, per EUR/MW."""
        tol_mw = integrator.tol_mw(demand_mw)
        flow_gap = tol_mw / (max(gain, 1e-300) * integrator.window * integrator.dt)
        return cls(tol_mw, flow_gap, 2.0 * integrator.price_atol * price_scale)


def kkt_violations(
    problem: DispatchProblem,
    minutes: np.ndarray,
    p_mw: np.ndarray,
    z: np.ndarray,
    tol: KktTolerances | Sequence[KktTolerances],
    C: float | np.ndarray = 0.0,
) -> list[str | None]:
    """Per minute, why set points ``p_mw`` (minutes x generators, MW) and controller prices
    ``z`` (minutes x 2 limited lines, EUR/MW: upward then downward) are *not* a KKT point of the
    DC-OPF (paper eq. 1), or ``None`` where they are, within ``tol``.

    The candidate duals are the prices the controllers broadcast, ``mu = max(0, z + C e)``
    per line-direction with excess ``e`` (``flow - U`` upward, ``-flow - U`` downward; ``C``
    the proportional part, EUR/MW per MW, one value or one per minute and limited line: at a
    state within ``tol_kw`` of the limit it shifts
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

    With voltage limits (``problem.n_voltage`` rows, docs/voltage.md) ``z`` continues with the
    monitored buses' low then high prices; their excesses ``e`` are in MW equivalents
    (:func:`voltage_prices`), checked like a line's (beyond its bound, or priced while slack,
    against ``power_mw``), and ``lmc_i`` also subtracts ``sum_j (mu_lo_j - mu_hi_j) sens_ji``;
    in 3 each priced bus separating a pair adds ``|sens_ji - sens_jk| price`` to the allowance.
    A ``z`` without the voltage prices (a run of another mode) is checked with zero prices.
    """
    rows = np.asarray(minutes, dtype=np.int64) - 1
    p_mw, z = np.atleast_2d(p_mw), np.atleast_2d(z)
    n_lines = len(problem.limit)
    down = problem.down
    flow, mu = line_prices(problem, rows, p_mw, z, C)
    nu = mu[:, :n_lines] - mu[:, n_lines:]
    v_excess, v_mu = voltage_prices(problem, rows, p_mw, z, C)
    n_v = problem.n_voltage
    lmc = problem.b + 2.0 * problem.c * p_mw - nu @ down
    if n_v:
        lmc = lmc - (v_mu[:, :n_v] - v_mu[:, n_v:]) @ problem.voltage_sens
    online = problem.online[rows]
    lo = np.where(online, problem.pmin, 0.0)
    hi = np.where(online, problem.pmax, 0.0)
    tols = [tol] * len(rows) if isinstance(tol, KktTolerances) else list(tol)
    reasons: list[str | None] = []
    for r, t in enumerate(tols):
        reasons.append(
            _bounds_violation(problem, p_mw[r], lo[r], hi[r], t)
            or _price_violation(problem, flow[r], mu[r], t)
            or _voltage_violation(problem, v_excess[r], v_mu[r], t)
            or _stationarity_violation(
                problem, p_mw[r], lmc[r], (lo[r], hi[r]), online[r], t, v_mu[r]
            )
        )
    return reasons


def line_prices(
    problem: DispatchProblem, rows: np.ndarray, p_mw: np.ndarray, z: np.ndarray, C
) -> tuple[np.ndarray, np.ndarray]:
    """``(flow, mu)`` of the limited lines at 0-based ``rows`` (minutes - 1): the flows (MW,
    minutes x lines) of set points ``p_mw`` (MW) and the broadcast prices ``mu = max(0, z +
    C e)`` (EUR/MW, minutes x 2 lines: upward then downward; ``e`` the excess over the limit,
    MW; ``C`` one value or one per minute and limited line, EUR/MW per MW)."""
    flow = problem.line_load_flow[rows] - p_mw @ problem.down.T
    excess = np.concatenate([flow - problem.limit, -flow - problem.limit], axis=1)
    C = np.asarray(C, dtype=float)
    if C.ndim == 2:  # per minute and limited line, the same for both directions
        C = np.concatenate([C, C], axis=1)
    return flow, np.maximum(0.0, z[:, : 2 * len(problem.limit)] + C * excess)


def net_prices(
    problem: DispatchProblem, minutes: np.ndarray, p_mw: np.ndarray, z: np.ndarray, C
) -> tuple[np.ndarray, np.ndarray]:
    """The prices the controllers broadcast at set points ``p_mw`` (minutes x generators, MW)
    and controller states ``z`` (a mode with price controllers: exact, voltage) at the 1-based
    ``minutes``: ``(line, voltage)``, EUR/MWh (= EUR/MW, Table I's cost per hour).

    ``line`` (minutes x limited lines): ``nu_k = mu_up,k - mu_down,k`` (positive: the flow
    towards the leaves binds); ``voltage`` (minutes x monitored buses): ``m_j = mu_lo,j -
    mu_hi,j`` per MW equivalent (positive: ``vmin`` binds; modes/voltage.py). At a KKT point
    they are the DC-OPF's duals, :attr:`popdispatch.opf.OpfResult.line_price` and
    ``voltage_price``, with the same signs."""
    rows = np.asarray(minutes, dtype=np.int64) - 1
    p_mw, z = np.atleast_2d(p_mw), np.atleast_2d(z)
    n_lines, n_v = len(problem.limit), problem.n_voltage
    _, mu = line_prices(problem, rows, p_mw, z, C)
    _, v_mu = voltage_prices(problem, rows, p_mw, z, C)
    return mu[:, :n_lines] - mu[:, n_lines:], v_mu[:, :n_v] - v_mu[:, n_v:]


def voltage_prices(
    problem: DispatchProblem, rows: np.ndarray, p_mw: np.ndarray, z: np.ndarray, C
) -> tuple[np.ndarray, np.ndarray]:
    """``(excess, mu)`` of the voltage rows (modes/voltage.py): per minute, each monitored
    bus's excess over its lower then its upper bound (MW equivalents, ``(vmin^2 - v^2) / s_j``
    and ``(v^2 - vmax^2) / s_j``) and the broadcast prices ``mu = max(0, z + C e)`` (EUR/MW per
    MW equivalent; ``z``: the full controller states, lines first). ``C``: a scalar here (the
    voltage rows take the game's one value)."""
    n_v, n_lines = problem.n_voltage, len(problem.limit)
    if not n_v:
        empty = np.zeros((len(rows), 0))
        return empty, empty
    rise = p_mw @ problem.voltage_sens.T
    load = problem.load_flow[rows]
    excess = np.concatenate(
        [load[:, n_lines : n_lines + n_v] - rise, load[:, n_lines + n_v :] + rise], axis=1
    )
    C_v = float(np.max(C)) if np.size(C) else 0.0
    states = z[:, 2 * n_lines :]
    if states.shape[1] != 2 * n_v:  # a run without the voltage prices
        states = np.zeros_like(excess)
    return excess, np.maximum(0.0, states + C_v * excess)


def _voltage_violation(problem, excess, mu, tol: KktTolerances) -> str | None:
    """A voltage row beyond its bound, or priced while slack (MW equivalents against
    ``power_mw``); the message in p.u."""
    n_v = problem.n_voltage
    for r in range(2 * n_v):
        j = r % n_v
        bound = "vmin" if r < n_v else "vmax"
        if excess[r] <= tol.power_mw and not (mu[r] > 0.0 and excess[r] < -tol.power_mw):
            continue
        v_pu = np.sqrt(max(_v_sq(problem, excess, j), 0.0))
        bus = int(problem.voltage_buses[j])
        if excess[r] > tol.power_mw:
            return f"bus {bus} is at {v_pu:.6f} p.u., beyond {bound} (LinDistFlow)"
        return (
            f"bus {bus} has a {bound} price {mu[r]:.4g} EUR/MWh but is at {v_pu:.6f} p.u., "
            "inside its limits"
        )
    return None


def _v_sq(problem, excess, j: int) -> float:
    """The squared voltage (p.u.^2) of voltage row ``j`` from its low-bound excess."""
    return problem.vmin_pu**2 - excess[j] * problem.voltage_scale[j]


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


def _stationarity_violation(
    problem, p, lmc, limits, online, tol: KktTolerances, v_mu=None
) -> str | None:
    lo, hi = limits
    givers = online & (p > lo + tol.power_mw)
    takers = online & (p < hi - tol.power_mw)
    if not givers.any() or not takers.any():
        return None
    i = int(np.flatnonzero(takers)[np.argmin(lmc[takers])])
    separating = np.abs(problem.down - problem.down[:, [i]]).sum(axis=0)
    if problem.n_voltage and v_mu is not None:  # each priced bus: known to 2 price_atol too
        n_v = problem.n_voltage
        priced = (v_mu[:n_v] > 0.0) | (v_mu[n_v:] > 0.0)
        sens = problem.voltage_sens[priced]
        separating = separating + np.abs(sens - sens[:, [i]]).sum(axis=0)
    movable = np.maximum(p - lo, tol.power_mw)
    allowed = separating * tol.price + tol.flow_gap / movable
    excess = np.where(givers, lmc - lmc[i] - allowed, -np.inf)
    j = int(np.argmax(excess))
    if excess[j] <= 0.0:
        return None
    names = problem.generators
    return (
        f"rest point is not a KKT point of the DC-OPF: {names[j]} {_where(p, lo, hi, j, tol)} "
        f"has marginal cost {lmc[j]:.6f} EUR/MWh (with line and voltage prices) above the "
        f"{lmc[i]:.6f} of {names[i]} {_where(p, lo, hi, i, tol)}, which could take more"
    )
