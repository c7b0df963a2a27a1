"""The ``voltage`` JSON object of a run with voltage limits (docs/voltage.md).

Voltages of the monitored buses by LinDistFlow (the model the voltage prices work on), the
buses whose limit binds in the LinDistFlow OPF with their prices, and, with the AC check, the
linearization error: the LinDistFlow minimum voltage minus the AC one.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from popdispatch.constants import KW_PER_MW
from popdispatch.game.problem import DispatchProblem

#: A row binds in the LinDistFlow OPF where its dual exceeds this, EUR/MW per MW equivalent.
BINDING_PRICE = 1e-6


def lindistflow_v_pu(problem: DispatchProblem, p_kw: np.ndarray, minutes: Sequence[int]):
    """(steps, monitored buses): LinDistFlow voltages, p.u., of set points ``p_kw`` (steps,
    generators; kW) at the 1-based ``minutes``."""
    p_mw = np.atleast_2d(np.asarray(p_kw, dtype=float)) / KW_PER_MW
    sq = [problem.voltage_sq(p, int(m)) for p, m in zip(p_mw, minutes, strict=True)]
    return np.sqrt(np.maximum(np.array(sq), 0.0))


def voltage_columns(problem: DispatchProblem, minutes: Sequence[int], p_kw: np.ndarray):
    """Per minute (index ``minute``): the lowest and highest LinDistFlow voltage of the
    monitored buses, ``lindistflow_v_min_pu`` and ``lindistflow_v_max_pu`` (p.u.)."""
    v = lindistflow_v_pu(problem, p_kw, minutes)
    index = pd.Index(np.asarray(minutes), name="minute")
    return pd.DataFrame(
        {"lindistflow_v_min_pu": v.min(axis=1), "lindistflow_v_max_pu": v.max(axis=1)}, index
    )


def binding_rows(problem: DispatchProblem, opf, engine: np.ndarray | None = None) -> list[dict]:
    """The monitored buses whose bound binds in one minute's LinDistFlow OPF: ``bus``,
    ``bound`` (``vmin``/``vmax``), ``v_pu`` (the OPF's), ``opf_price_eur_per_mwh`` (the OPF's
    dual of the bus's scaled row: the net price ``mu_lo - mu_hi`` a controller at rest would
    broadcast, EUR/MWh per MW equivalent), ``engine_price_eur_per_mwh`` (the price the run's
    own controller broadcast at that minute's end, from ``engine``, per monitored bus; null
    without) and ``dual_eur_per_h_pu2`` (the OPF's dual of the unscaled row ``v^2 >=
    vmin^2``, EUR/h per p.u.^2). ``price_eur_per_mwh``: deprecated twin of
    ``opf_price_eur_per_mwh``, kept one release."""
    if opf.status != "optimal":
        return []
    rows = []
    for j in np.flatnonzero(np.abs(opf.voltage_price) > BINDING_PRICE):
        price = float(opf.voltage_price[j])
        rows.append({
            "bus": int(problem.voltage_buses[j]),
            "bound": "vmin" if price > 0 else "vmax",
            "v_pu": float(opf.v_pu[j]),
            "opf_price_eur_per_mwh": price,
            "engine_price_eur_per_mwh": None if engine is None else float(engine[j]),
            "price_eur_per_mwh": price,  # deprecated: opf_price_eur_per_mwh
            "dual_eur_per_h_pu2": abs(price) / float(problem.voltage_scale[j]),
        })  # fmt: skip
    return rows


def voltage_summary(
    problem: DispatchProblem,
    minutes: Sequence[int],
    p_kw: np.ndarray,
    opf: Sequence,
    engine_prices: np.ndarray | None = None,
) -> dict:
    """The ``voltage`` object: limits, monitored buses, the run's LinDistFlow extremes (with
    their bus and minute), the LinDistFlow OPF's lowest voltage, the minutes where a voltage
    row binds in the OPF and the binding buses of the minute with the highest voltage price
    (``binding_minute``; a snapshot: its minute if any binds), with the run's own prices there
    from ``engine_prices`` (EUR/MWh, steps x monitored buses, :func:`binding_rows`)."""
    v = lindistflow_v_pu(problem, p_kw, minutes)
    low = np.unravel_index(np.argmin(v), v.shape)
    high = np.unravel_index(np.argmax(v), v.shape)
    feasible = [o for o in opf if o.status == "optimal"]
    opf_low = min((float(np.min(o.v_pu)) for o in feasible), default=None)
    priced = [float(np.max(np.abs(o.voltage_price), initial=0.0)) for o in feasible]
    worst = feasible[int(np.argmax(priced))] if feasible else None
    engine = None
    if worst is not None and engine_prices is not None:
        engine = np.atleast_2d(engine_prices)[list(minutes).index(worst.minute)]
    return {
        "vmin_pu": problem.vmin_pu if problem.vmin_pu > 0.0 else None,  # None: no bound
        "vmax_pu": problem.vmax_pu if problem.vmax_pu < 2.0 else None,
        "monitored_buses": int(problem.n_voltage),
        "v_min_pu": float(v[low]),
        "v_min_bus": int(problem.voltage_buses[low[1]]),
        "v_min_minute": int(minutes[low[0]]),
        "v_max_pu": float(v[high]),
        "v_max_bus": int(problem.voltage_buses[high[1]]),
        "opf_v_min_pu": opf_low,
        "binding": [] if worst is None else binding_rows(problem, worst, engine),
        "binding_minute": None
        if worst is None or not max(priced) > BINDING_PRICE
        else int(worst.minute),
        "binding_minutes": int(sum(p > BINDING_PRICE for p in priced)),
        "model": "LinDistFlow (key nodes; DGs at unity power factor, loads with their Q)",
    }


def linearization_error(summary: dict, ac_v_min_pu: float) -> dict:
    """The AC check's view of the voltage object: ``ac_v_min_pu`` and
    ``linearization_error_pu`` = LinDistFlow minimum minus AC minimum (p.u.; positive: the AC
    voltage is lower, by the losses LinDistFlow drops)."""
    return {
        "ac_v_min_pu": float(ac_v_min_pu),
        "linearization_error_pu": float(summary["v_min_pu"] - ac_v_min_pu),
    }
