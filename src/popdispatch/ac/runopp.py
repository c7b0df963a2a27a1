"""The anchor of the voltage-aware dispatch: pandapower's AC OPF (``runopp``) of the full feeder.

The same network as the AC check (:mod:`popdispatch.ac.network`: every bus and line, series
``r + j x`` in ohm on one nominal voltage, loads at constant power with the AC check's
reactive-power rule, an ideal source at ``source_pu``), with the fleet's costs and limits: the
generator at the source bus prices the external grid (which also supplies the losses), every
other generator is a controllable static generator held at unity power factor (``q = 0``);
every bus between ``vmin`` and ``vmax``; lines with a ``limit_kw`` rated at the current of that
power at nominal voltage and unity power factor (as the AC check rates them). pandapower's
interior-point OPF (PYPOWER's PIPS) is slow and can fail to converge: a failure is
:class:`ACOpfError`, for callers to report and skip. The net is built by the one pandapower
builder, :func:`popdispatch.ac.pandapower_net.pandapower_network`, as the export's is.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from popdispatch.ac.network import load_q_per_kw, nominal_kv
from popdispatch.ac.pandapower_net import pandapower_network, with_q
from popdispatch.constants import KW_PER_MW
from popdispatch.feeder.model import Feeder


class ACOpfError(RuntimeError):
    """pandapower's AC OPF did not converge (or is not installed)."""


@dataclass(frozen=True)
class ACOpfResult:
    """pandapower's AC OPF of one step.

    Attributes
    ----------
    p_kw : per generator (fleet order), active power, kW (the source generator: what the
        external grid supplies, losses included).
    cost : total cost, EUR/h (``sum a + b p + c p^2``, p in MW).
    v_pu : per bus (feeder order), voltage magnitude, p.u.
    losses_kw : line losses, kW.
    """

    p_kw: pd.Series
    cost: float
    v_pu: pd.Series
    losses_kw: float


def ac_opf(
    feeder: Feeder,
    load_kw: np.ndarray,
    vmin_pu: float,
    vmax_pu: float,
    *,
    source_pu: float = 1.0,
    load_pf: float | None = None,
    vn_kv: float | None = None,
) -> ACOpfResult:
    """pandapower's AC OPF of ``feeder`` with per-load ``load_kw`` (kW, feeder load order) and
    every bus within ``[vmin_pu, vmax_pu]`` (see the module docstring)."""
    try:
        import pandapower as pp
    except ImportError as exc:  # pragma: no cover - depends on the environment
        message = f"the AC OPF anchor needs pandapower: pip install pandapower ({exc})"
        raise ACOpfError(message) from None
    net, gens = _network(feeder, np.asarray(load_kw, float), vmin_pu, vmax_pu,
                         source_pu, load_pf, vn_kv)  # fmt: skip
    try:
        pp.runopp(net, calculate_voltage_angles=False, init="flat", verbose=False)
    except Exception as exc:  # pandapower raises OPFNotConverged and others
        raise ACOpfError(f"pandapower runopp did not converge: {exc}") from exc
    names, buses = feeder.generators.index, feeder.buses.index
    p_kw = pd.Series([_result_p(net, kind, index) * KW_PER_MW for kind, index in gens], names)
    v_pu = pd.Series(net.res_bus.vm_pu.loc[buses].to_numpy(), index=buses)
    g = feeder.generators
    p_mw = p_kw.to_numpy() / KW_PER_MW
    cost = float(np.sum(g.a + g.b * p_mw + g.c * p_mw**2))
    return ACOpfResult(p_kw, cost, v_pu, float(net.res_line.pl_mw.sum() * KW_PER_MW))


def _result_p(net: Any, kind: str, index: int) -> float:
    table = net.res_ext_grid if kind == "ext_grid" else net.res_sgen
    return float(table.p_mw.at[index])


def _network(feeder, load_kw, vmin_pu, vmax_pu, source_pu, load_pf, vn_kv):
    """The pandapower net and, per generator, its element ``(kind, index)``
    (:func:`popdispatch.ac.pandapower_net.pandapower_network`, ``sgen`` form)."""
    ratio, _ = load_q_per_kw(feeder, load_pf)
    kv = nominal_kv(feeder, vn_kv)
    return pandapower_network(
        feeder.buses.index, feeder.lines_on_base(kv), with_q(feeder.loads, load_kw, ratio),
        feeder.generators, int(feeder.source_bus), kv,
        dispatchable="sgen", voltage_limits_pu=(vmin_pu, vmax_pu), source_pu=source_pu,
        name=feeder.name,
    )  # fmt: skip
