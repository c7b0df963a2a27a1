"""The anchor of the voltage-aware dispatch: pandapower's AC OPF (``runopp``) of the full feeder.

The same network as the AC check (:mod:`popdispatch.ac.network`: every bus and line, series
``r + j x`` in ohm on one nominal voltage, loads at constant power with the AC check's
reactive-power rule, an ideal source at ``source_pu``), with the fleet's costs and limits: the
generator at the source bus prices the external grid (which also supplies the losses), every
other generator is a controllable static generator held at unity power factor (``q = 0``);
every bus between ``vmin`` and ``vmax``; lines with a ``limit_kw`` rated at the current of that
power at nominal voltage and unity power factor (as the AC check rates them). pandapower's
interior-point OPF (PYPOWER's PIPS) is slow and can fail to converge: a failure is
:class:`ACOpfError`, for callers to report and skip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from popdispatch.ac.network import load_q_per_kw, nominal_kv, rated_current_a
from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FeederError
from popdispatch.feeder.model import Feeder

#: Current rating (kA) of a line without a limit: far above anything a feeder carries, yet
#: finite enough for PIPS (measured on case33bw: 1e6 kA made runopp fail to converge, 1, 10
#: and 100 kA give the same optimum).
UNLIMITED_KA = 100.0


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
    """The pandapower net and, per generator, its element ``(kind, index)``."""
    import pandapower as pp

    kv = nominal_kv(feeder, vn_kv)
    net = pp.create_empty_network(sn_mva=1.0)
    for bus in feeder.buses.index:
        # the source is an ideal voltage source (as in the AC check), not a free OPF variable
        low, high = (source_pu, source_pu) if bus == feeder.source_bus else (vmin_pu, vmax_pu)
        pp.create_bus(net, vn_kv=kv, index=int(bus), min_vm_pu=low, max_vm_pu=high)
    for name, ln in feeder.lines.iterrows():
        limited = math.isfinite(ln.limit_kw)
        pp.create_line_from_parameters(
            net, int(ln.from_bus), int(ln.to_bus), length_km=1.0, r_ohm_per_km=ln.r_ohm,
            x_ohm_per_km=ln.x_ohm, c_nf_per_km=0.0,
            max_i_ka=float(rated_current_a(ln.limit_kw, kv)) / 1e3 if limited else UNLIMITED_KA,
            max_loading_percent=100.0, name=str(name),
        )  # fmt: skip
    ratio, _ = load_q_per_kw(feeder, load_pf)
    for (name, load), kw, q in zip(feeder.loads.iterrows(), load_kw, ratio, strict=True):
        pp.create_load(net, int(load.bus), p_mw=kw / KW_PER_MW, q_mvar=kw * q / KW_PER_MW,
                       name=str(name), controllable=False)  # fmt: skip
    return net, _generators(net, feeder, source_pu)


def _generators(net, feeder: Feeder, source_pu: float) -> list[tuple[str, int]]:
    import pandapower as pp

    at_source = feeder.generators.bus == feeder.source_bus
    if at_source.sum() != 1:
        raise FeederError(
            f"the AC OPF anchor needs exactly one generator at the source bus {feeder.source_bus} "
            f"of feeder {feeder.name!r} (it prices the external grid); found {int(at_source.sum())}"
        )
    elements = []
    for name, g in feeder.generators.iterrows():
        limits = {"min_p_mw": g.pmin_kw / KW_PER_MW, "max_p_mw": g.pmax_kw / KW_PER_MW}
        if at_source[name]:
            index = pp.create_ext_grid(net, int(g.bus), vm_pu=source_pu, controllable=True,
                                       min_q_mvar=-1e6, max_q_mvar=1e6, **limits)  # fmt: skip
            kind = "ext_grid"
        else:
            index = pp.create_sgen(
                net, int(g.bus), p_mw=0.0, q_mvar=0.0, controllable=True, min_q_mvar=0.0,
                max_q_mvar=0.0, name=str(name), **limits,
            )  # fmt: skip
            kind = "sgen"
        pp.create_poly_cost(net, index, kind, cp1_eur_per_mw=float(g.b),
                            cp2_eur_per_mw2=float(g.c), cp0_eur=float(g.a))  # fmt: skip
        elements.append((kind, int(index)))
    return elements
