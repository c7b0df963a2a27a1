"""Shared by the meshed-network tests: a network's lines limited below their unconstrained
flows, and pandapower's ``rundcopp`` of its own copy of a MATPOWER case as the yardstick."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pandas as pd

from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.game.mesh import build_mesh_problem
from popdispatch.opf import solve_opf


def congested(net: DcNetwork, lines: list[str], fraction: float) -> DcNetwork:
    """``net`` with ``lines`` limited to ``fraction`` of their flow at the unconstrained
    DC-OPF (kW)."""
    free = build_mesh_problem(replace(net, lines=net.lines.assign(limit_kw=np.inf)))
    p = solve_opf(free, 1).p_kw / 1e3
    positions = net.lines.index.get_indexer(lines)
    injection = -(net.buses.pd_mw + net.buses.gs_mw).to_numpy(float)
    np.add.at(injection, net.buses.index.get_indexer(net.generators.bus), p)
    flows = net.model.flows_mw(injection, positions)[:, 0]
    limits = net.lines.limit_kw.copy()
    limits.iloc[positions] = np.minimum(limits.iloc[positions], fraction * np.abs(flows) * 1e3)
    return replace(net, lines=net.lines.assign(limit_kw=limits))


def pandapower_case(case: str, limits_mw: dict[tuple[int, int], float]):
    """pandapower's own copy of a MATPOWER case with the lines between the given MATPOWER
    buses limited (MW), solved by ``rundcopp``: set points in MATPOWER's generator order
    (ext_grid first, then gens; the slack is the cases' first generator) and the cost."""
    import pandapower.networks as pn

    return rundcopp(getattr(pn, case)(), limits_mw)


def rundcopp(net, limits_mw: dict[tuple[int, int], float]):
    """:func:`pandapower_case` of a pandapower copy ``net`` of a MATPOWER case (changed)."""
    limited_rundcopp(net, limits_mw, pd.Series(net.bus.index + 1, index=net.bus.index))
    return np.r_[net.res_ext_grid.p_mw.to_numpy(), net.res_gen.p_mw.to_numpy()], net.res_cost


def limited_rundcopp(net, limits_mw: dict[tuple[int, int], float], number: pd.Series) -> None:
    """Limit ``net``'s line between each pair of buses of ``limits_mw`` (MW; ``number``: each
    pandapower bus's MATPOWER number) and solve it by pandapower's ``rundcopp``."""
    import pandapower as pp

    ends = number[net.line.from_bus].to_numpy(), number[net.line.to_bus].to_numpy()
    for (a, b), mw in limits_mw.items():
        pair = ((ends[0] == a) & (ends[1] == b)) | ((ends[0] == b) & (ends[1] == a))
        assert pair.sum() == 1
        k = net.line.index[pair][0]
        rating = net.line.max_i_ka[k] * net.bus.vn_kv[net.line.from_bus[k]] * np.sqrt(3)
        net.line.loc[k, "max_loading_percent"] = min(100.0, 100.0 * mw / rating)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    assert net.OPF_converged


def rundcopp_at_buses(case: str, limits_mw: dict[tuple[int, int], float]) -> pd.Series:
    """pandapower's ``rundcopp`` of its own copy of MATPOWER case ``case`` with the lines
    between the given buses limited (MW; buses numbered as the case numbers them, which
    pandapower keeps as the buses' names): the output of each generator bus, MW, indexed by
    its MATPOWER number."""
    import pandapower.networks as pn

    net = getattr(pn, case)()
    number = net.bus.name.astype(int)
    limited_rundcopp(net, limits_mw, number)
    out = pd.concat([pd.Series(net.res_ext_grid.p_mw.to_numpy(), number[net.ext_grid.bus]),
                     pd.Series(net.res_gen.p_mw.to_numpy(), number[net.gen.bus])])  # fmt: skip
    return out.groupby(level=0).sum()
