"""The networks a run takes: the built-in cases (:mod:`~popdispatch.cases.builtin`: ieee-elv,
the pandapower and SimBench grids, the MATPOWER and OpenDSS cases found on disk), a run's
feeder from its options (:mod:`~popdispatch.cases.sources`: a network file, a case, the ELV's
OpenDSS folder, a fleet) and the cached ieee-elv problem (:mod:`~popdispatch.cases.cached`).
Above the readers (:mod:`popdispatch.readers`) and the feeder model (:mod:`popdispatch.feeder`),
which know no case.

The submodules are imported when a name is first used (PEP 562).
"""

from popdispatch.lazy import lazy_namespace

#: Where each public name lives (module under ``popdispatch.cases``).
_HOMES = {
    "PEAK_MINUTE": "builtin",
    "elv_snapshot_566_kw": "builtin",
    "ieee_elv": "builtin",
    "list_cases": "builtin",
    "load_case": "builtin",
    "FeederSource": "sources",
    "load_feeder": "sources",
}

__getattr__, __dir__, __all__ = lazy_namespace(__name__, _HOMES)
