"""LinDistFlow voltage sensitivities of a radial feeder (the building block of voltage mode).

LinDistFlow (Baran and Wu's DistFlow with the losses dropped) writes, along each line ``k``
from its upstream bus to its downstream bus, in p.u.::

    v_down^2 = v_up^2 - 2 (r_k P_k + x_k Q_k)

with ``P_k``, ``Q_k`` the power flowing down the line. An injection at bus ``i`` lowers the
flow of every line on the path source -> ``i`` by the same amount, so the squared voltage of a
bus ``j`` moves with the active power ``p_i`` injected at ``i`` by twice the resistance of the
path the two buses share from the source::

    d(v_j^2) / d(p_i) = 2 R_ij,   R_ij = sum of r_k over the lines on both paths

(and with reactive power by ``2 X_ij``). In people's units, with ``p`` in kW and ``R`` in ohm,
``R_ij`` in p.u. is ``R_ij / Z_base`` with ``Z_base = vn_kv^2 * 1000`` ohm (1 kVA base), so
``d(v_j^2)/d(p_i)`` is in p.u.^2 per kW. The linearisation is exact at zero flow and 1 p.u.;
at a loaded state the AC sensitivity differs by the order of the voltage drop (tests/ac
measure it against finite differences of the AC power flow).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from popdispatch.ac.network import load_q_per_kw, nominal_kv
from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FeederError, InfeasibleError
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.tree import downstream
from popdispatch.game.problem import DispatchProblem
from popdispatch.online.settings import check_voltage_limits


def shared_path_ohm(
    feeder: Feeder,
    buses_i: Sequence[int],
    buses_j: Sequence[int],
    column: str = "r_ohm",
    vn_kv: float | None = None,
) -> np.ndarray:
    """``(len(buses_i), len(buses_j))``: the sum of ``column`` (``r_ohm`` or ``x_ohm``, ohm on
    the voltage base ``vn_kv``, default the source's) over the lines on both the path source ->
    ``i`` and the path source -> ``j``."""
    tree = feeder.bus_tree()
    down_i = downstream(tree, _positions(feeder, buses_i))  # (lines, i): line above bus i?
    down_j = downstream(tree, _positions(feeder, buses_j))
    values = feeder.lines_on_base(vn_kv)[column].to_numpy(float)
    return (down_i.T * values) @ down_j.astype(float)


def voltage_sensitivity(
    feeder: Feeder,
    injection_buses: Sequence[int],
    observed_buses: Sequence[int] | None = None,
    *,
    vn_kv: float | None = None,
    reactive: bool = False,
) -> pd.DataFrame:
    """LinDistFlow ``d(v_j^2) / d(p_i)``, p.u.^2 per kW (``reactive``: per kvar of ``q_i``).

    Rows: the observed buses ``j`` (default every bus); columns: the injection buses ``i``.
    ``vn_kv``: nominal voltage, kV (default from the network, see
    :func:`popdispatch.ac.network.nominal_kv`).
    """
    observed = list(feeder.buses.index if observed_buses is None else observed_buses)
    kv = nominal_kv(feeder, vn_kv)
    z_base_ohm = kv**2 * 1e3
    column = "x_ohm" if reactive else "r_ohm"
    shared = shared_path_ohm(feeder, observed, injection_buses, column, kv)
    return pd.DataFrame(
        2.0 * shared / z_base_ohm,
        index=pd.Index(observed, name="bus"),
        columns=pd.Index(list(injection_buses), name="injection_bus"),
    )


def _positions(feeder: Feeder, buses: Sequence[int]) -> np.ndarray:
    """Rows of ``feeder.buses`` of the given bus ids; :class:`FeederError` naming an unknown one."""
    positions = feeder.buses.index.get_indexer(list(buses))
    if (positions < 0).any():
        bad = list(buses)[int(np.flatnonzero(positions < 0)[0])]
        raise FeederError(f"unknown bus {bad} of feeder {feeder.name!r} in a sensitivity query")
    return positions


def base_voltage_sq(
    feeder: Feeder,
    observed_buses: Sequence[int],
    load_kw: np.ndarray,
    *,
    source_pu: float = 1.0,
    load_pf: float | None = None,
    vn_kv: float | None = None,
) -> np.ndarray:
    """LinDistFlow squared voltages (p.u.^2) of ``observed_buses`` with the loads alone,
    ``(steps, observed)``: ``v0^2 = source_pu^2 - sum_l (2 R_jl p_l + 2 X_jl q_l) / Z_base``
    over the loads ``l`` (``load_kw``: (steps, loads) in feeder order, kW; ``q_l = p_l
    q_per_kw_l``, the AC check's rule :func:`popdispatch.ac.network.load_q_per_kw`)."""
    load_buses = feeder.loads["bus"].to_numpy()
    ratio, _ = load_q_per_kw(feeder, load_pf)
    sens_p = voltage_sensitivity(feeder, load_buses, observed_buses, vn_kv=vn_kv).to_numpy()
    sens_q = voltage_sensitivity(
        feeder, load_buses, observed_buses, vn_kv=vn_kv, reactive=True
    ).to_numpy()
    load_kw = np.atleast_2d(np.asarray(load_kw, dtype=float))
    return source_pu**2 - load_kw @ sens_p.T - (load_kw * ratio) @ sens_q.T


def with_voltage_limits(
    problem: DispatchProblem,
    load_kw: np.ndarray,
    vmin_pu: float | None,
    vmax_pu: float | None,
    *,
    source_pu: float = 1.0,
    load_pf: float | None = None,
    vn_kv: float | None = None,
) -> DispatchProblem:
    """``problem`` with voltage rows at every key node but the source (docs/voltage.md).

    Monitored buses: the key nodes of the reduced feeder (the source excluded). Between two
    key nodes no power is drawn or injected, so LinDistFlow's ``v^2`` is linear along the
    chain and its extremes lie at key nodes: keeping the key nodes within limits keeps every
    bus within them. A key node whose voltage no dispatch can move (``d(v^2)/dp`` the same
    for every generator, since ``sum p`` is the demand) is dropped if its loads-only voltage
    is within the limits at every step, else :class:`InfeasibleError` names it.

    ``load_kw``: (steps, loads) in the order of ``problem.feeder.original.loads``, kW, the
    loads the problem was built from. DGs at unity power factor, loads with their reactive
    power (:func:`base_voltage_sq`). ``vmin_pu``/``vmax_pu``: :func:`check_voltage_limits`.
    """
    low, high = check_voltage_limits(vmin_pu, vmax_pu)
    reduced = problem.feeder
    feeder = reduced.original
    buses = reduced.nodes["bus"].to_numpy()
    buses = buses[buses != feeder.source_bus]
    gen_buses = feeder.generators.loc[problem.generators, "bus"].to_numpy()
    sens = voltage_sensitivity(feeder, gen_buses, buses, vn_kv=vn_kv).to_numpy() * KW_PER_MW
    spread = sens.max(axis=1) - sens.min(axis=1)
    base = base_voltage_sq(feeder, buses, load_kw, source_pu=source_pu, load_pf=load_pf,
                           vn_kv=vn_kv)  # fmt: skip
    fixed = spread <= 1e-12 * max(float(spread.max(initial=0.0)), 1e-300)
    _check_fixed(buses[fixed], base[:, fixed], low, high)
    keep = ~fixed
    scale = spread[keep]
    base_kept = base[:, keep]
    columns = [
        problem.line_load_flow,
        (low**2 - base_kept) / scale,
        (base_kept - high**2) / scale,
    ]
    return replace(
        problem,
        load_flow=np.ascontiguousarray(np.concatenate(columns, axis=1)),
        voltage_buses=buses[keep].astype(np.int64),
        voltage_sens=np.ascontiguousarray(sens[keep] / scale[:, None]),
        voltage_scale=scale,
        voltage_base=base_kept,
        vmin_pu=low,
        vmax_pu=high,
    )


def _check_fixed(buses: np.ndarray, base: np.ndarray, low: float, high: float) -> None:
    """:class:`InfeasibleError` for a bus no dispatch can move outside the limits at a step."""
    bad = (base < low**2) | (base > high**2)
    if bad.any():
        step, col = (int(a[0]) for a in np.nonzero(bad))
        raise InfeasibleError(
            f"bus {int(buses[col])} is at {math.sqrt(max(base[step, col], 0.0)):.4f} p.u. at "
            f"step {step + 1} with the loads alone and no generator can move its voltage "
            f"(limits {low:g}-{high:g} p.u.)"
        )
