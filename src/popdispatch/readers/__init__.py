"""Readers of external data: the IEEE European LV Test Feeder's OpenDSS files and load profiles."""

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

__all__ = [
    "PROFILES_ENV",
    "default_profiles",
    "read_matpower",
    "read_opendss_feeder",
    "read_opendss_master",
    "read_pandapower",
    "read_profiles",
    "resolve_profiles",
]
