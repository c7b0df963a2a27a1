"""Why a minute has no DC-OPF (or LinDistFlow OPF): the limits that cannot hold together.

A minute is infeasible when no dispatch meets the demand within the generators' limits and the
limits of the lines (and, with ``--vmin``/``--vmax``, of the bus voltages). The cause is found
by relaxing one family of limits at a time, as an elastic linear programme (HiGHS through
:func:`scipy.optimize.linprog`): every line limit and voltage row gets a non-negative slack,
in kW (voltage rows in the same kW equivalents as the OPF's rows), and the total slack is
minimised over the dispatches within the generator limits that meet the demand.

1. The generators online cannot meet the demand at all (sum of ``pmax`` below it, or sum of
   ``pmin`` above it): generator capacity.
2. Else the line limits alone (voltage rows dropped) need a positive slack: line limits, naming
   the lines with slack (and where each limit comes from, see
   :func:`popdispatch.report.summaries.limits_in_force`).
3. Else the voltage rows alone need one: voltage limits, naming the buses with slack and the
   best voltage each can reach (LinDistFlow) within the generator and line limits.
4. Else both together: line and voltage limits.

The powers the text gives are kW; voltages p.u.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from popdispatch.game.problem import KW_PER_MW, DispatchProblem

#: At most this many lines or buses are named in a message.
SHOWN = 4


@dataclass(frozen=True)
class Elastic:
    """The result of :func:`elastic`: total slack (kW), the dispatch (kW) and the slack of
    each line limit (``line_kw``, the larger of its two directions) and each voltage row
    (``low_kw``, ``high_kw``: kW equivalents)."""

    total_kw: float
    p_kw: np.ndarray
    line_kw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    low_kw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    high_kw: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _rows(problem: DispatchProblem, minute: int) -> dict:
    """The minute's constraint data in kW: flows ``flow = load_flow - D p`` within ``limit``,
    voltage rows ``low - S p <= 0`` and ``high + S p <= 0``."""
    n_lines, n_v = len(problem.limit), problem.n_voltage
    loads = problem.load_flow[minute - 1] * KW_PER_MW
    online = problem.online[minute - 1]
    return {
        "pmin": np.where(online, problem.pmin, 0.0) * KW_PER_MW,
        "pmax": np.where(online, problem.pmax, 0.0) * KW_PER_MW,
        "demand": float(problem.demand[minute - 1] * KW_PER_MW),
        "down": np.asarray(problem.down, float).reshape(n_lines, problem.n_generators),
        "load_flow": loads[:n_lines],
        "limit": problem.limit * KW_PER_MW,
        "sens": np.asarray(problem.voltage_sens, float).reshape(n_v, problem.n_generators),
        "low": loads[n_lines : n_lines + n_v],
        "high": loads[n_lines + n_v : n_lines + 2 * n_v],
    }


def elastic(
    problem: DispatchProblem, minute: int, lines: str = "elastic", voltage: str = "elastic",
    objective: np.ndarray | None = None,
) -> Elastic | None:  # fmt: skip
    """The dispatch within the generator limits meeting the demand at ``minute`` that needs the
    least total slack; ``lines`` and ``voltage``: ``"elastic"`` (with slack), ``"hard"`` or
    ``"off"`` (left out). ``objective``: minimise this linear cost of the set points (kW)
    instead (with every row hard or off). ``None`` where no such dispatch exists."""
    from scipy.optimize import linprog

    d = _rows(problem, minute)
    n = problem.n_generators
    D, S = d["down"], d["sens"]
    families = {  # name: (A on p, right-hand side, elastic); flows within +-limit
        "up": (-D, d["limit"] - d["load_flow"], lines),
        "down": (D, d["limit"] + d["load_flow"], lines),
        "low": (-S, -d["low"], voltage), "high": (S, -d["high"], voltage),
    }  # fmt: skip
    used = {name: f for name, f in families.items() if f[2] != "off" and len(f[1])}
    soft = [name for name, f in used.items() if f[2] == "elastic"]
    width = n + sum(len(used[name][1]) for name in soft)
    rows, rhs, at = [], [], n
    for name, (A, b, _) in used.items():
        block = np.zeros((len(b), width))
        block[:, :n] = A
        if name in soft:
            block[:, at : at + len(b)] = -np.eye(len(b))
            at += len(b)
        rows.append(block)
        rhs.append(b)
    cost = np.concatenate([np.zeros(n) if objective is None else objective,
                           np.ones(width - n)])  # fmt: skip
    done = linprog(
        cost,
        A_ub=np.vstack(rows) if rows else None,
        b_ub=np.concatenate(rhs) if rows else None,
        A_eq=np.concatenate([np.ones(n), np.zeros(width - n)])[None, :],
        b_eq=[d["demand"]],
        bounds=list(zip(d["pmin"], d["pmax"], strict=True)) + [(0, None)] * (width - n),
        method="highs",
    )
    if done.status != 0:
        return None
    slack, at = {}, n
    for name in soft:
        slack[name] = done.x[at : at + len(used[name][1])]
        at += len(used[name][1])
    zeros = {"up": len(d["limit"]), "down": len(d["limit"]), "low": len(S), "high": len(S)}
    part = {name: slack.get(name, np.zeros(size)) for name, size in zeros.items()}
    return Elastic(float(done.x[n:].sum()), done.x[:n], np.maximum(part["up"], part["down"]),
                   part["low"], part["high"])  # fmt: skip


def diagnose(problem: DispatchProblem, minute: int, in_force: Sequence[dict] = ()) -> dict:
    """Why ``minute`` (1-based) has no OPF, as a JSON object: ``minute``, ``cause``
    (``"generator capacity"``, ``"line limits"``, ``"voltage limits"`` or ``"line and voltage
    limits"``), ``demand_kw``, ``capacity_kw`` (online), ``min_output_kw`` (the online
    generators' ``pmin`` summed), ``lines`` (the line limits that cannot all hold: the rows
    of ``in_force`` (:func:`~popdispatch.report.summaries.limits_in_force`, the problem's
    order) with ``excess_kw``, their slack), ``buses`` (``bus``, ``bound`` ``vmin`` or
    ``vmax``, ``limit_pu``, ``best_pu``: the closest LinDistFlow voltage any dispatch reaches
    there) and ``short_kw`` (the least total overflow of the named lines, kW; null without
    lines)."""
    d = _rows(problem, minute)
    out = {
        "minute": int(minute), "cause": None, "demand_kw": d["demand"],
        "capacity_kw": float(d["pmax"].sum()), "min_output_kw": float(d["pmin"].sum()),
        "lines": [], "buses": [], "short_kw": None,
    }  # fmt: skip
    tol = 1e-6 * max(d["demand"], 1.0)
    if d["pmax"].sum() < d["demand"] - tol or d["pmin"].sum() > d["demand"] + tol:
        out["cause"] = "generator capacity"
        return out
    by_lines = elastic(problem, minute, lines="elastic", voltage="off")
    by_voltage = elastic(problem, minute, lines="off", voltage="elastic")
    lines_bad = by_lines is not None and by_lines.total_kw > tol
    voltage_bad = by_voltage is not None and by_voltage.total_kw > tol
    if not lines_bad and not voltage_bad:
        both = elastic(problem, minute)
        out["cause"] = "line and voltage limits"
        if both is not None and both.total_kw > tol:
            _name_lines(out, both, in_force, tol)
            _name_buses(out, problem, minute, both, tol, lines_hard=False)
            out["short_kw"] = float(both.line_kw.sum()) or None
        return out
    if lines_bad:
        out["cause"] = "line limits"
        _name_lines(out, by_lines, in_force, tol)
        out["short_kw"] = float(by_lines.line_kw.sum())
    if voltage_bad and not lines_bad:
        out["cause"] = "voltage limits"
        _name_buses(out, problem, minute, by_voltage, tol, lines_hard=True)
    return out


def _name_lines(out: dict, found: Elastic, in_force: Sequence[dict], tol: float) -> None:
    for k in np.flatnonzero(found.line_kw > tol):
        row = dict(in_force[k]) if k < len(in_force) else {"line": int(k)}
        out["lines"].append({**row, "excess_kw": float(found.line_kw[k])})


def _name_buses(out: dict, problem: DispatchProblem, minute: int, found: Elastic, tol: float,
                lines_hard: bool) -> None:  # fmt: skip
    """The buses with slack, each with the best LinDistFlow voltage a dispatch reaches there
    (within the line limits where they hold by themselves)."""
    sens = np.asarray(problem.voltage_sens, float).reshape(problem.n_voltage, -1)
    lines = "hard" if lines_hard else "off"
    for bound, slack, sign, limit in (("vmin", found.low_kw, -1.0, problem.vmin_pu),
                                      ("vmax", found.high_kw, 1.0, problem.vmax_pu)):  # fmt: skip
        for j in np.flatnonzero(slack > tol):
            best = elastic(problem, minute, lines=lines, voltage="off",
                           objective=sign * sens[j])  # fmt: skip
            p_mw = (best.p_kw if best is not None else found.p_kw) / KW_PER_MW
            v_sq = problem.voltage_sq(p_mw, minute)[j]
            out["buses"].append({"bus": int(problem.voltage_buses[j]), "bound": bound,
                                 "limit_pu": float(limit),
                                 "best_pu": float(np.sqrt(max(v_sq, 0.0)))})  # fmt: skip


def cause_text(why: dict | None) -> str:
    """One clause saying why a minute has no OPF (:func:`diagnose`), e.g. ``line limits:
    rg60-632 at 2882.13 kW (rating of 650632) cannot hold with the demand 3466.000 kW (at
    least 83.867 kW over)``."""
    if not why or why.get("cause") is None:
        return "no dispatch meets the demand within the generator and line limits"
    demand = f"the demand {why['demand_kw']:.3f} kW"
    cause = why["cause"]
    if cause == "generator capacity":
        if why["capacity_kw"] < why["demand_kw"]:
            return f"{demand} exceeds the online generators' capacity {why['capacity_kw']:.3f} kW"
        least = why["min_output_kw"]
        return f"the online generators' minimum output {least:.3f} kW exceeds {demand}"
    parts = []
    if why["lines"]:
        every = "all " if len(why["lines"]) > 1 else ""
        parts.append(f"{_lines(why['lines'])} cannot {every}hold with {demand}")
    if why["buses"]:
        parts.append(_buses(why["buses"]))
    if not parts:
        return f"{cause}: they cannot all hold with {demand} (at the solvers' tolerance)"
    short = why.get("short_kw")
    total = " in total" if len(why["lines"]) > 1 else ""
    over = f" (at least {short:.3f} kW over{total})" if why["lines"] and short else ""
    return f"{cause}: " + "; ".join(parts) + over


def _lines(rows: list[dict]) -> str:
    """The named line limits: ratings one by one, each ``--limit`` once with its lines."""
    named: dict[str, list[str]] = {}
    for row in rows:
        ends = f"{row.get('from_bus')}-{row.get('to_bus')}"
        if row.get("source") == "--limit":
            named.setdefault(f"--limit {row['element']} kW on ", []).append(ends)
        else:
            named[f"{ends} at {row['limit_kw']:.6g} kW (rating of {row.get('element')})"] = []
    parts = [head + ", ".join(ends[:SHOWN]) + (" ..." if len(ends) > SHOWN else "")
             for head, ends in named.items()]  # fmt: skip
    more = f" and {len(parts) - SHOWN} more" if len(parts) > SHOWN else ""
    return ", ".join(parts[:SHOWN]) + more


def _buses(rows: list[dict]) -> str:
    parts = []
    for bound in ("vmin", "vmax"):
        named = sorted((b for b in rows if b["bound"] == bound), key=lambda b: b["best_pu"],
                       reverse=bound == "vmax")  # fmt: skip
        if not named:
            continue
        buses = ", ".join(f"bus {b['bus']} (at best {b['best_pu']:.4f} p.u.)"
                          for b in named[:SHOWN])  # fmt: skip
        more = f" and {len(named) - SHOWN} more" if len(named) > SHOWN else ""
        parts.append(f"{bound} {named[0]['limit_pu']:g} p.u. is out of reach at {buses}{more}")
    return "; ".join(parts) + " (LinDistFlow)"


def ratings_hint(why: dict | None) -> str:
    """`` (--no-ratings ignores the network's ratings)`` where a named line limit is one."""
    rated = why and any(row.get("source") == "rating" for row in why.get("lines", []))
    return " (--no-ratings ignores the network's ratings)" if rated else ""
