"""The dispatcher as a mosaik simulator (``DispatcherSim``, event-based), around
:class:`~popdispatch.cosim.dispatcher.OnlineDispatcher`.

Models (mosaik entity ids in brackets; powers in kW):

- ``Dispatcher`` (``Dispatcher``), one: input ``load_kw`` (every load's demand, connected from
  each load entity whose id ends in ``Load-<name>``, the feeder's load name); outputs
  ``status`` (the last run's: ``converged`` when certified within the accuracy of the DC-OPF
  of the offset-corrected problem), ``iterations`` (of the dynamics, last run), ``rounds``
  (runs in the step so far).
- ``Controller`` (``Controller-<from_bus>-<to_bus>``), one per limited line of the problem,
  params ``from_bus``, ``to_bus`` (the reduced line's original end buses): input ``flow_kw``
  (the measured active flow, positive away from the source); outputs ``offset_kw`` (measured
  minus the DC model at the set points sent), ``limit_kw``.
- ``DG`` (``DG-<name>``), one per generator, param ``name``: output ``p_kw`` (set point).

Stepping: a new mosaik time with new demand starts a step (the dynamics' first run, with the
last step's offsets) and sends every set point. Measured flows at the same time (a weak
connection from the plant: mosaik's same-time loop) rerun the step with the new offsets and
send the new set points, until the offsets move by less than
:data:`~popdispatch.cosim.dispatcher.OFFSET_TOL_KW`: then nothing is sent and the loop ends.
"""

from __future__ import annotations

import mosaik_api_v3
import numpy as np

from popdispatch.cosim.dispatcher import OnlineDispatcher, StepResult

META = {
    "api_version": "3.0",
    "type": "event-based",
    "models": {
        "Dispatcher": {"public": True, "params": [],
                       "attrs": ["load_kw", "status", "iterations", "rounds"]},
        "Controller": {"public": True, "params": ["from_bus", "to_bus"],
                       "attrs": ["flow_kw", "offset_kw", "limit_kw"]},
        "DG": {"public": True, "params": ["name"], "attrs": ["p_kw"]},
    },
}  # fmt: skip


class DispatcherSim(mosaik_api_v3.Simulator):
    """The dispatcher (module docstring). ``init`` params: ``problem`` (a
    :class:`~popdispatch.game.problem.DispatchProblem` of the feeder, limits in force),
    ``settings`` (:class:`~popdispatch.online.RunSettings`), optional ``log`` (a list
    each run of the dynamics is appended to: ``time_s``, ``rounds``, ``status``,
    ``iterations``, ``setpoints_kw``, ``offset_kw``)."""

    def __init__(self):
        super().__init__(META)
        self.time = -1
        self.result: StepResult | None = None
        self.sent = False
        self.history: list[dict] = []

    def init(self, sid, time_resolution=1.0, problem=None, settings=None, log=None):
        if problem is None or settings is None:
            raise ValueError("DispatcherSim needs init params 'problem' and 'settings'")
        if log is not None:
            self.history = log  # every run appended (in-process simulators share the list)
        self.dispatcher = OnlineDispatcher(problem, settings)
        self.load_names = [str(n) for n in problem.feeder.original.loads.index]
        self.load_kw = dict.fromkeys(self.load_names, np.nan)
        lines = problem.feeder.lines.loc[problem.lines]
        self.line_ends = [(int(a), int(b)) for a, b in zip(lines.from_bus, lines.to_bus,
                                                           strict=True)]  # fmt: skip
        self.flow_kw = np.full(len(self.line_ends), np.nan)
        self.generators = [str(g) for g in problem.generators]
        self.eids: dict[str, tuple[str, int]] = {}
        return self.meta

    def create(self, num, model, **params):
        return [self._create(model, **params) for _ in range(num)]

    def _create(self, model, from_bus=None, to_bus=None, name=None) -> dict:
        if model == "Dispatcher":
            eid, index = "Dispatcher", 0
        elif model == "Controller":
            ends = (int(from_bus), int(to_bus))
            if ends not in self.line_ends:
                raise ValueError(f"no limited line {from_bus}-{to_bus} (limited: "
                                 f"{self.line_ends})")  # fmt: skip
            eid, index = f"Controller-{from_bus}-{to_bus}", self.line_ends.index(ends)
        else:
            if str(name) not in self.generators:
                raise ValueError(f"no generator {name!r} in the fleet {self.generators}")
            eid, index = f"DG-{name}", self.generators.index(str(name))
        self.eids[eid] = (model, index)
        return {"eid": eid, "type": model}

    def step(self, time, inputs, max_advance):
        flows = False
        for eid, attrs in inputs.items():
            model, index = self.eids[eid]
            for source, value in attrs.get("load_kw", {}).items():
                self.load_kw[source.rsplit("Load-", 1)[-1]] = float(value)
            if model == "Controller" and attrs.get("flow_kw"):
                self.flow_kw[index] = sum(attrs["flow_kw"].values())
                flows = True
        if time != self.time:
            self.time = time
            loads = np.array([self.load_kw[n] for n in self.load_names])
            if np.isnan(loads).any():
                missing = self.load_names[int(np.flatnonzero(np.isnan(loads))[0])]
                raise ValueError(f"no demand for load {missing} at time {time}")
            self._record(self.dispatcher.start_step(loads))
        elif flows and not np.isnan(self.flow_kw).any():
            self._record(self.dispatcher.measured(self.flow_kw))
        else:
            self.sent = False
        return None

    def _record(self, result: StepResult | None) -> None:
        self.sent = result is not None
        if result is not None:
            self.result = result
            self.history.append({"time_s": self.time, "rounds": self.dispatcher.rounds,
                                 "status": result.status, "iterations": result.iterations,
                                 "setpoints_kw": result.setpoints_kw.tolist(),
                                 "offset_kw": result.offset_kw.tolist()})  # fmt: skip

    def get_data(self, outputs):
        if not self.sent or self.result is None:
            return {}
        r = self.result
        data = {}
        for eid, attrs in outputs.items():
            model, index = self.eids[eid]
            if model == "Dispatcher":
                values = {"status": r.status, "iterations": r.iterations,
                          "rounds": self.dispatcher.rounds}  # fmt: skip
            elif model == "Controller":
                values = {"offset_kw": float(r.offset_kw[index]),
                          "limit_kw": float(self.dispatcher.limit_kw[index])}  # fmt: skip
            else:
                values = {"p_kw": float(r.setpoints_kw[index])}
            data[eid] = {a: values[a] for a in attrs if a in values}
        return data
