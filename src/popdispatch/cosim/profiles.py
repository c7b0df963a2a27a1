"""Load profiles as a mosaik simulator (``ProfileSim``, time-based): one ``Load`` entity per
load of a :class:`~popdispatch.feeder.profiles.LoadProfiles` series, stepping once per step of
the series (``step_seconds``, default 60: the ELV's minutes).

Model ``Load`` (``Load-<name>``), param ``name`` (the series' column): output ``p_kw`` (kW,
the series' value at the step). mosaik time ``t`` (s) is step ``first + t // step_seconds``
(1-based steps of the series; ``first``: init param, default 1).
"""

from __future__ import annotations

import mosaik_api_v3
import numpy as np

META = {
    "api_version": "3.0",
    "type": "time-based",
    "models": {"Load": {"public": True, "params": ["name"], "attrs": ["p_kw"]}},
}


class ProfileSim(mosaik_api_v3.Simulator):
    """The load series (module docstring). ``init`` params: ``kw`` (a DataFrame, one column
    per load, one row per step, kW), ``first`` (1-based step at mosaik time 0),
    ``step_seconds``."""

    def __init__(self):
        super().__init__(META)
        self.columns: dict[str, int] = {}

    def init(self, sid, time_resolution=1.0, kw=None, first=1, step_seconds=60):
        if kw is None:
            raise ValueError("ProfileSim needs the load series (init param 'kw')")
        self.kw = np.asarray(kw, dtype=float)
        self.names = [str(c) for c in kw.columns]
        self.first, self.step_seconds = int(first), int(step_seconds)
        self.row = self.first - 1
        return self.meta

    def create(self, num, model, name=None):
        if str(name) not in self.names:
            raise ValueError(f"no load {name!r} in the series")
        eid = f"Load-{name}"
        self.columns[eid] = self.names.index(str(name))
        return [{"eid": eid, "type": model}]

    def step(self, time, inputs, max_advance):
        self.row = self.first - 1 + time // self.step_seconds
        return time + self.step_seconds

    def get_data(self, outputs):
        return {eid: {"p_kw": float(self.kw[self.row, self.columns[eid]])} for eid in outputs}
