"""Built-in cases. ``ieee-elv``: the IEEE European LV Test Feeder as shipped by pandapower.

pandapower is slow to import and to load the network (about 2-4 s together), so the tables
popdispatch derives from it (buses, lines, loads, source bus, the minute-566 loads) are kept in
the on-disk cache (:mod:`popdispatch.cache`); a process that finds them there never imports
pandapower. The cache key holds :data:`ELV_FORMAT`, the pandapower and popdispatch versions and
a hash of this file, so upgrading pandapower or changing how the tables are derived rebuilds
them; a missing, corrupt or inconsistent cache file is rebuilt too.
"""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch import cache
from popdispatch.feeder.generators import paper_fleet
from popdispatch.feeder.model import Feeder

CASES = ("ieee-elv",)
#: Cache entry of the ieee-elv tables, and the version of its layout (bump on any change).
ELV_CACHE, ELV_FORMAT = "ieee-elv", 1
#: The arrays of the ieee-elv tables and their dtype kinds (``i`` int, ``f`` float, ``U`` text).
ELV_ARRAYS = {
    "bus": "i", "x": "f", "y": "f",
    "line": "U", "from_bus": "i", "to_bus": "i", "length_km": "f", "r_ohm": "f", "x_ohm": "f",
    "load": "U", "load_bus": "i", "load_p_kw": "f",
    "source_bus": "i",
}  # fmt: skip
_LENGTHS = {
    "bus": ("x", "y"),
    "line": ("from_bus", "to_bus", "length_km", "r_ohm", "x_ohm"),
    "load": ("load_bus", "load_p_kw"),
}


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
    return _feeder(_elv_arrays())


def elv_snapshot_566_kw() -> pd.Series:
    """Per-load demand (kW) of minute 566 from pandapower's ``on_peak_566`` snapshot.

    These are the official loads of that minute (they sum to 57.358 kW); no profile folder needed.
    """
    a = _elv_arrays()
    return pd.Series(
        a["load_p_kw"].copy(), index=pd.Index(a["load"].tolist(), name="load"), name="p_kw"
    )


def _feeder(a: dict[str, np.ndarray]) -> Feeder:
    """The Feeder of the ieee-elv arrays (new DataFrames on every call: callers may edit them)."""
    buses = pd.DataFrame(
        {"x": a["x"].copy(), "y": a["y"].copy()}, index=pd.Index(a["bus"].copy(), name="bus")
    )
    lines = pd.DataFrame(
        {
            "from_bus": a["from_bus"].copy(),
            "to_bus": a["to_bus"].copy(),
            "length_km": a["length_km"].copy(),
            "r_ohm": a["r_ohm"].copy(),
            "x_ohm": a["x_ohm"].copy(),
            "limit_kw": np.inf,
        },
        index=pd.Index(a["line"].tolist(), name="line"),
    )
    loads = pd.DataFrame(
        {"bus": a["load_bus"].copy()}, index=pd.Index(a["load"].tolist(), name="load")
    )
    return Feeder("ieee-elv", buses, lines, loads, int(a["source_bus"]), paper_fleet())


@lru_cache(maxsize=1)
def _elv_arrays() -> dict[str, np.ndarray]:
    """The ieee-elv tables as arrays: from the on-disk cache if it holds a sound copy, else
    derived from pandapower (and stored in the cache for the next process)."""
    key = elv_cache_key()
    arrays = cache.load_arrays(ELV_CACHE, key)
    if arrays is not None and _sound(arrays):
        try:
            _feeder(arrays)  # a cached copy must also make a valid feeder
            return arrays
        except Exception:
            pass  # rebuilt below
    arrays = elv_arrays_from_pandapower()
    cache.save_arrays(ELV_CACHE, key, arrays)
    return arrays


def elv_cache_key() -> dict:
    """What the cached ieee-elv tables depend on (see the module docstring)."""
    from importlib.metadata import PackageNotFoundError, version

    from popdispatch import __version__

    try:
        pandapower = version("pandapower")
    except PackageNotFoundError:
        pandapower = None
    try:
        code = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
    except OSError:
        code = None
    return {
        "case": "ieee-elv on_peak_566",
        "format": ELV_FORMAT,
        "pandapower": pandapower,
        "popdispatch": __version__,
        "code": code,
    }


def _sound(a: dict[str, np.ndarray]) -> bool:
    """Whether cached arrays have the expected names, kinds, shapes and finite values."""
    if set(a) != set(ELV_ARRAYS):
        return False
    for name, kind in ELV_ARRAYS.items():
        value = a[name]
        if value.dtype.kind != kind or value.ndim != (0 if name == "source_bus" else 1):
            return False
        if kind == "f" and not np.isfinite(value).all():
            return False
    return all(
        len(a[other]) == len(a[head]) > 0 for head, others in _LENGTHS.items() for other in others
    )


def elv_arrays_from_pandapower() -> dict[str, np.ndarray]:
    """Derive the ieee-elv arrays from pandapower's network (slow: imports pandapower)."""
    net = _elv_net()
    lv = net.bus.name != "SOURCEBUS"
    bus_id = pd.Series(pd.to_numeric(net.bus.name.where(lv), errors="coerce"), index=net.bus.index)
    coords = np.array([json.loads(g)["coordinates"] for g in net.bus.geo[lv]], dtype=float)
    line = net.line
    load = net.asymmetric_load
    return {
        "bus": bus_id[lv].astype(np.int64).to_numpy(),
        "x": coords[:, 0].copy(),
        "y": coords[:, 1].copy(),
        "line": line.name.to_numpy(dtype=str),
        "from_bus": bus_id[line.from_bus].astype(np.int64).to_numpy(),
        "to_bus": bus_id[line.to_bus].astype(np.int64).to_numpy(),
        "length_km": line.length_km.to_numpy(dtype=float),
        "r_ohm": (line.r_ohm_per_km * line.length_km / line.parallel).to_numpy(dtype=float),
        "x_ohm": (line.x_ohm_per_km * line.length_km / line.parallel).to_numpy(dtype=float),
        "load": load.name.to_numpy(dtype=str),
        "load_bus": bus_id[load.bus].astype(np.int64).to_numpy(),
        "load_p_kw": (load.p_a_mw + load.p_b_mw + load.p_c_mw).to_numpy(dtype=float) * 1000.0,
        "source_bus": np.array(int(bus_id[net.trafo.lv_bus.iloc[0]]), dtype=np.int64),
    }
