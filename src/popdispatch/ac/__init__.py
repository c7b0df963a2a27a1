"""The AC check of a dispatch: an AC power flow of the full feeder.

power-grid-model (optional extra ``ac``: ``pip install "popdispatch[ac]"``, imported only when
a check runs) builds the positive-sequence network straight from the feeder's tables
(:mod:`popdispatch.ac.network`) and computes every time step of a run in one batch
(:mod:`popdispatch.ac.check`). Model, rules, units and measured accuracy and speed:
``docs/ac.md``.
"""

from popdispatch.ac.check import (
    STEP_COLUMNS,
    ACDay,
    ACFlows,
    ACSnapshot,
    check_day,
    check_setpoints,
    check_snapshot,
    power_flow,
)
from popdispatch.ac.lindistflow import shared_path_ohm, voltage_sensitivity
from popdispatch.ac.network import ACModel, ACNetwork, build_network, nominal_kv

__all__ = [
    "STEP_COLUMNS", "ACDay", "ACFlows", "ACModel", "ACNetwork", "ACSnapshot", "build_network",
    "check_day", "check_setpoints", "check_snapshot", "nominal_kv", "power_flow",
    "shared_path_ohm", "voltage_sensitivity",
]  # fmt: skip
