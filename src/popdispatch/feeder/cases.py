"""Built-in cases. ``ieee-elv``: the IEEE European LV Test Feeder as shipped by pandapower."""

from __future__ import annotations

import json
from functools import lru_cache

import numpy as np
import pandas as pd

from popdispatch.feeder.generators import paper_fleet
from popdispatch.feeder.model import Feeder

CASES = ("ieee-elv",)


@lru_cache(maxsize=1)
def _elv_net():
    import pandapower.networks as pn

    return pn.ieee_european_lv_asymmetric("on_peak_566")


def load_case(name: str) -> Feeder:
    """Load a built-in case by name (see :data:`CASES`)."""
    if name != "ieee-elv":
        from popdispatch.errors import FeederError

        raise FeederError(f"unknown case {name!r} (known: {', '.join(CASES)})")
    return ieee_elv()


def ieee_elv() -> Feeder:
    """The IEEE European LV Test Feeder (906 buses, 905 lines, 55 loads) with the paper's fleet.

    Topology, line impedances and bus coordinates come from
    ``pandapower.networks.ieee_european_lv_asymmetric``; buses keep their IEEE numbers 1..906
    (bus 1 is the transformer's LV side, the source of the radial feeder).
    """
    net = _elv_net()
    lv = net.bus.name != "SOURCEBUS"
    bus_id = pd.Series(pd.to_numeric(net.bus.name.where(lv), errors="coerce"), index=net.bus.index)
    coords = np.array([json.loads(g)["coordinates"] for g in net.bus.geo[lv]])
    buses = pd.DataFrame(
        {"x": coords[:, 0], "y": coords[:, 1]},
        index=pd.Index(bus_id[lv].astype(int).to_numpy(), name="bus"),
    )
    line = net.line
    lines = pd.DataFrame(
        {
            "from_bus": bus_id[line.from_bus].astype(int).to_numpy(),
            "to_bus": bus_id[line.to_bus].astype(int).to_numpy(),
            "length_km": line.length_km.to_numpy(),
            "r_ohm": (line.r_ohm_per_km * line.length_km / line.parallel).to_numpy(),
            "x_ohm": (line.x_ohm_per_km * line.length_km / line.parallel).to_numpy(),
            "limit_kw": np.inf,
        },
        index=pd.Index(line.name.to_numpy(), name="line"),
    )
    loads = pd.DataFrame(
        {"bus": bus_id[net.asymmetric_load.bus].astype(int).to_numpy()},
        index=pd.Index(net.asymmetric_load.name.to_numpy(), name="load"),
    )
    source = int(bus_id[net.trafo.lv_bus.iloc[0]])
    return Feeder("ieee-elv", buses, lines, loads, source, paper_fleet())


def elv_snapshot_566_kw() -> pd.Series:
    """Per-load demand (kW) of minute 566 from pandapower's ``on_peak_566`` snapshot.

    These are the official loads of that minute (they sum to 57.358 kW); no profile folder needed.
    """
    load = _elv_net().asymmetric_load
    kw = (load.p_a_mw + load.p_b_mw + load.p_c_mw).to_numpy() * 1000.0
    return pd.Series(kw, index=pd.Index(load.name.to_numpy(), name="load"), name="p_kw")
