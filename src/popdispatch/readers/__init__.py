"""Readers of external data: networks (MATPOWER, pandapower, OpenDSS), the IEEE European LV Test
Feeder's OpenDSS files and load profiles, load time series (CSV/Parquet tables, SimBench)."""

from popdispatch.readers.matpower import read_matpower
from popdispatch.readers.opendss import read_opendss_feeder
from popdispatch.readers.opendss_direct import read_opendss_master
from popdispatch.readers.pandapower import read_pandapower
from popdispatch.readers.profiles import (
    PROFILES_ENV,
    default_profiles,
    read_profiles,
    resolve_profiles,
)
from popdispatch.readers.series import read_load_table, simbench_profiles

__all__ = [
    "PROFILES_ENV",
    "default_profiles",
    "read_matpower",
    "read_opendss_feeder",
    "read_opendss_master",
    "read_pandapower",
    "read_load_table",
    "read_profiles",
    "resolve_profiles",
    "simbench_profiles",
]
