"""A mosaik simulator that writes what it receives to a CSV file (``RecorderSim``,
event-based): one row each time it steps, one column ``<source entity full id>.<attribute>``
per input (units in the attribute names; empty where the input did not change), written when
the simulation ends. Outside a same-time loop's group it steps once per mosaik time, with the
values the loop settled on.

Model ``Recorder`` (one per simulator), any inputs; ``init`` param ``path`` (the CSV file).
The first column is ``time_s`` (mosaik time, seconds).
"""

from __future__ import annotations

import csv
from pathlib import Path

import mosaik_api_v3

META = {
    "api_version": "3.0",
    "type": "event-based",
    "models": {"Recorder": {"public": True, "any_inputs": True, "params": [], "attrs": []}},
}


class RecorderSim(mosaik_api_v3.Simulator):
    """The CSV writer (module docstring)."""

    def __init__(self):
        super().__init__(META)
        self.rows: list[dict] = []
        self.path: Path | None = None

    def init(self, sid, time_resolution=1.0, path=None):
        if path is None:
            raise ValueError("RecorderSim needs the file (init param 'path')")
        self.path = Path(path)
        return self.meta

    def create(self, num, model):
        if num != 1:
            raise ValueError("one Recorder per simulator")
        return [{"eid": "Recorder", "type": model}]

    def step(self, time, inputs, max_advance):
        row = {"time_s": time}
        for attrs in inputs.values():
            for attr, sources in attrs.items():
                for source, value in sources.items():
                    row[f"{source}.{attr}"] = value
        self.rows.append(row)
        return None

    def finalize(self):
        if self.path is None or not self.rows:
            return
        columns = ["time_s"] + sorted({k for r in self.rows for k in r} - {"time_s"})
        with self.path.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=columns)
            writer.writeheader()
            writer.writerows(self.rows)
