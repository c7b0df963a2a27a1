"""Readers of external data: networks (MATPOWER, pandapower, OpenDSS), the IEEE European LV Test
Feeder's OpenDSS files and load profiles, load time series (CSV/Parquet tables, SimBench).

The readers are imported when first used (``popdispatch.readers.read_matpower`` imports
:mod:`popdispatch.readers.matpower` then): most commands use one, and importing them all
would add to every command's start-up.
"""

from popdispatch.lazy import lazy_namespace

#: Where each public name lives (module under ``popdispatch.readers``).
_HOMES = {
    "PROFILES_ENV": "profiles",
    "default_profiles": "profiles",
    "read_profiles": "profiles",
    "resolve_profiles": "profiles",
    "read_matpower": "matpower",
    "read_matpower_network": "matpower",
    "read_opendss_feeder": "opendss",
    "read_opendss_master": "opendss_direct",
    "read_opendss_network": "opendss_direct",
    "read_pandapower": "pandapower",
    "read_pandapower_network": "pandapower",
    "read_load_table": "series",
}

__getattr__, __dir__, __all__ = lazy_namespace(__name__, _HOMES)
