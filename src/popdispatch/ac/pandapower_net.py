"""The one pandapower network builder: the AC OPF anchor (:mod:`popdispatch.ac.runopp`, the
full feeder) and the pandapower export (:mod:`popdispatch.export`, the reduced feeder) both
build their nets here from plain tables.

Every bus on one nominal voltage ``vn_kv`` (index and name: the bus number), optionally held
within voltage limits (the source bus at ``source_pu``); lines as series ``r + j x`` (ohm;
``x`` at least 1e-9 ohm, which pandapower's DC model divides by) rated at the current of their
``limit_kw`` at nominal voltage and unity power factor (:func:`~popdispatch.ac.network.
rated_current_a`, as the AC check rates them), :data:`UNLIMITED_KA` where unlimited; loads at
constant power; the generators with their polynomial costs (EUR/h, P in MW), in one of two
forms (``dispatchable``):

- ``"gen"`` (the export): every generator a controllable ``gen``, the one at the source bus
  the slack; without one, an ``ext_grid`` at the source that supplies nothing;
- ``"sgen"`` (the anchor): the generator at the source bus prices a controllable ``ext_grid``
  (which also supplies the losses), every other one a controllable ``sgen`` at unity power
  factor (``q = 0``); exactly one generator must sit at the source bus.

pandapower is imported when a net is built (it is an optional dependency).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from popdispatch.ac.network import rated_current_a
from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FeederError

#: Current rating (kA) of a line without a limit: far above anything a feeder carries, yet
#: finite enough for PIPS (measured on case33bw: 1e6 kA made runopp fail to converge, 1, 10
#: and 100 kA give the same optimum).
UNLIMITED_KA = 100.0

#: Smallest line reactance, ohm (pandapower's DC power flow divides by x).
MIN_X_OHM = 1e-9

DISPATCHABLE = ("gen", "sgen")


def pandapower_network(
    buses: Sequence[int],
    lines: pd.DataFrame,
    loads: pd.DataFrame,
    generators: pd.DataFrame,
    source_bus: int,
    vn_kv: float,
    *,
    dispatchable: str = "gen",
    voltage_limits_pu: tuple[float, float] | None = None,
    source_pu: float = 1.0,
    name: str = "",
) -> tuple[Any, list[tuple[str, int]]]:
    """The pandapower net and, per generator (row order), its element ``(kind, index)``.

    ``lines``: ``from_bus``, ``to_bus``, ``r_ohm``, ``x_ohm``, ``limit_kw`` (``inf``:
    unlimited), optional ``length_km`` (default 1; the impedances are the line's totals),
    named by their index. ``loads``: ``bus``, ``p_kw``, optional ``q_kvar``, named by their
    index. ``generators``: ``bus``, ``pmin_kw``, ``pmax_kw``, ``a`` (EUR/h), ``b`` (EUR/MWh),
    ``c`` (EUR/MW^2h), optional ``online``, named by their index. ``voltage_limits_pu``:
    ``(vmin, vmax)`` of every bus but the source (an OPF's constraint; none without).
    """
    import pandapower as pp

    if dispatchable not in DISPATCHABLE:
        raise ValueError(f"unknown generator form {dispatchable!r} (known: gen, sgen)")
    net = pp.create_empty_network(name=name, sn_mva=1.0)
    for bus in buses:
        limits = {}
        if voltage_limits_pu is not None:
            low, high = (source_pu,) * 2 if bus == source_bus else voltage_limits_pu
            limits = {"min_vm_pu": low, "max_vm_pu": high}
        pp.create_bus(net, vn_kv=vn_kv, index=int(bus), name=str(bus), **limits)
    _add_lines(net, lines, vn_kv)
    q = loads["q_kvar"] if "q_kvar" in loads else pd.Series(0.0, loads.index)
    for (label, load), q_kvar in zip(loads.iterrows(), q, strict=True):
        pp.create_load(net, int(load.bus), p_mw=load.p_kw / KW_PER_MW, q_mvar=q_kvar / KW_PER_MW,
                       name=str(label), controllable=False)  # fmt: skip
    add = _add_gens if dispatchable == "gen" else _add_sgens
    return net, add(net, generators, int(source_bus), source_pu)


def _add_lines(net, lines: pd.DataFrame, vn_kv: float) -> None:
    import pandapower as pp

    lengths = lines["length_km"] if "length_km" in lines else pd.Series(1.0, lines.index)
    rated_ka = rated_current_a(lines.limit_kw.to_numpy(float), vn_kv) / 1e3
    for (label, ln), length, ka in zip(lines.iterrows(), lengths, rated_ka, strict=True):
        length = max(float(length), 1e-6)
        pp.create_line_from_parameters(
            net, int(ln.from_bus), int(ln.to_bus), length_km=length,
            r_ohm_per_km=ln.r_ohm / length, x_ohm_per_km=max(ln.x_ohm, MIN_X_OHM) / length,
            c_nf_per_km=0.0, max_i_ka=float(ka) if math.isfinite(ka) else UNLIMITED_KA,
            max_loading_percent=100.0, name=str(label),
        )  # fmt: skip


def _cost(net, index: int, kind: str, g) -> None:
    import pandapower as pp

    pp.create_poly_cost(net, index, kind, cp1_eur_per_mw=float(g.b),
                        cp2_eur_per_mw2=float(g.c), cp0_eur=float(g.a))  # fmt: skip


def _limits(g) -> dict:
    return {"min_p_mw": g.pmin_kw / KW_PER_MW, "max_p_mw": g.pmax_kw / KW_PER_MW}


def _add_gens(net, generators: pd.DataFrame, source: int, source_pu: float) -> list:
    """Every generator a controllable ``gen`` (the one at the source: the slack)."""
    import pandapower as pp

    elements = []
    for label, g in generators.iterrows():
        index = pp.create_gen(
            net, int(g.bus), p_mw=0.0, vm_pu=source_pu, name=str(label), controllable=True,
            slack=int(g.bus) == source, in_service=bool(getattr(g, "online", True)), **_limits(g),
        )  # fmt: skip
        _cost(net, index, "gen", g)
        elements.append(("gen", int(index)))
    if not (generators.bus == source).any():  # a reference bus that supplies nothing
        pp.create_ext_grid(net, source, min_p_mw=0.0, max_p_mw=0.0, controllable=True)
    return elements


def _add_sgens(net, generators: pd.DataFrame, source: int, source_pu: float) -> list:
    """The source generator as the priced ``ext_grid``, the others unity-pf ``sgen``."""
    import pandapower as pp

    at_source = (generators.bus == source).to_numpy()
    if at_source.sum() != 1:
        raise FeederError(
            f"the AC OPF anchor needs exactly one generator at the source bus {source} of "
            f"feeder {net.name!r} (it prices the external grid); found {int(at_source.sum())}"
        )
    elements = []
    for (label, g), is_source in zip(generators.iterrows(), at_source, strict=True):
        if is_source:
            index = pp.create_ext_grid(net, int(g.bus), vm_pu=source_pu, controllable=True,
                                       min_q_mvar=-1e6, max_q_mvar=1e6, **_limits(g))  # fmt: skip
            kind = "ext_grid"
        else:
            index = pp.create_sgen(net, int(g.bus), p_mw=0.0, q_mvar=0.0, controllable=True,
                                   min_q_mvar=0.0, max_q_mvar=0.0, name=str(label),
                                   in_service=bool(getattr(g, "online", True)),
                                   **_limits(g))  # fmt: skip
            kind = "sgen"
        _cost(net, index, kind, g)
        elements.append((kind, int(index)))
    return elements


def with_q(loads: pd.DataFrame, p_kw: np.ndarray, q_per_kw: np.ndarray) -> pd.DataFrame:
    """``loads`` (index and ``bus``) with ``p_kw`` and ``q_kvar = p_kw q_per_kw`` (kW, kvar)."""
    p_kw = np.asarray(p_kw, dtype=float)
    q_kvar = p_kw * np.asarray(q_per_kw, dtype=float)
    return pd.DataFrame({"bus": loads.bus.to_numpy(), "p_kw": p_kw, "q_kvar": q_kvar}, loads.index)
