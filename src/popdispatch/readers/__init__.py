"""Readers of external data: networks (MATPOWER, pandapower, OpenDSS), the IEEE European LV Test
Feeder's OpenDSS files and load profiles, load time series (CSV/Parquet tables, SimBench).

The readers are imported when first used (``popdispatch.readers.read_matpower`` imports
:mod:`popdispatch.readers.matpower` then): importing them all cost about 0.1 s of every
command's start-up, and most commands use one.
"""

from importlib import import_module

#: Where each public name lives (module under ``popdispatch.readers``).
_HOMES = {
    "PROFILES_ENV": "profiles",
    "default_profiles": "profiles",
    "read_profiles": "profiles",
    "resolve_profiles": "profiles",
    "read_matpower": "matpower",
    "read_opendss_feeder": "opendss",
    "read_opendss_master": "opendss_direct",
    "read_pandapower": "pandapower",
    "read_load_table": "series",
    "simbench_profiles": "series",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str):
    """The public name ``name`` from its reader module, imported on first use (PEP 562)."""
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f"{__name__}.{home}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
