"""The plant of a co-simulation: the full feeder as a pandapower net, AC power flow each step
(mosaik simulator ``GridSim``, event-based: it steps whenever a load or a set point changes).

The net is :func:`popdispatch.ac.pandapower_net.pandapower_network`'s ``sgen`` form: every bus
and line of the feeder on its nominal voltage, loads at constant power with the feeder's power
factor (ieee-elv: 0.95 lagging), the generator at the source bus the ``ext_grid`` (the slack:
it supplies whatever the loads and losses need beyond the other generators, so its set point
is not applied), every other generator a static generator at unity power factor producing its
set point. ``pandapower.runpp`` (Newton-Raphson) solves each step.

Models (attributes in kW, kvar and p.u.; mosaik entity ids in brackets):

- ``Load`` (``Load-<name>``), param ``name`` (the feeder's load name): input ``p_kw``
  (demand), output ``p_kw`` (applied), ``q_kvar``.
- ``DG`` (``DG-<name>``), param ``name`` (the fleet's generator name): input ``p_kw`` (set
  point), outputs ``p_kw`` (produced: the set point, or the slack's supply at the source bus),
  ``setpoint_kw``.
- ``Branch`` (``Branch-<top>-<bottom>``), params ``top_bus``, ``bottom_bus`` (original buses,
  the chain of lines between them): outputs ``p_kw`` (the active flow of largest magnitude
  along the chain, positive away from the source: what a meter holding the chain's limit
  reads), ``p_top_kw`` (entering at the top), ``p_bottom_kw`` (leaving at the bottom),
  ``loss_kw``.
- ``Network`` (``Network``): outputs ``losses_kw`` (all lines), ``v_min_pu``, ``v_max_pu``,
  ``source_kw`` (the slack's supply), ``power_flows`` (run so far).
"""

from __future__ import annotations

import mosaik_api_v3
import networkx as nx
import numpy as np

from popdispatch.ac.network import load_q_per_kw, nominal_kv
from popdispatch.ac.pandapower_net import pandapower_network, with_q
from popdispatch.constants import KW_PER_MW
from popdispatch.feeder.model import Feeder

META = {
    "api_version": "3.0",
    "type": "event-based",
    "models": {
        "Load": {"public": True, "params": ["name"], "attrs": ["p_kw", "q_kvar"]},
        "DG": {"public": True, "params": ["name"], "attrs": ["p_kw", "setpoint_kw"]},
        "Branch": {
            "public": True,
            "params": ["top_bus", "bottom_bus"],
            "attrs": ["p_kw", "p_top_kw", "p_bottom_kw", "loss_kw"],
        },
        "Network": {
            "public": True,
            "params": [],
            "attrs": ["losses_kw", "v_min_pu", "v_max_pu", "source_kw", "power_flows"],
        },
    },
}


class GridSim(mosaik_api_v3.Simulator):
    """The pandapower plant (module docstring). ``init`` params: ``feeder`` (a
    :class:`~popdispatch.feeder.model.Feeder`, the full network), optional ``vn_kv``,
    ``load_pf`` (as the AC check's, :func:`popdispatch.ac.network.load_q_per_kw`)."""

    def __init__(self):
        super().__init__(META)
        self.net = None
        self.entities: dict[str, tuple[str, object]] = {}
        self.power_flows = 0
        self.setpoints: dict[str, float] = {}

    def init(self, sid, time_resolution=1.0, feeder: Feeder | None = None, vn_kv=None,
             load_pf=None):  # fmt: skip
        if feeder is None:
            raise ValueError("GridSim needs the feeder (init param 'feeder')")
        self.feeder = feeder
        self.q_per_kw, _ = load_q_per_kw(feeder, load_pf)
        kv = nominal_kv(feeder, vn_kv)
        zero = np.zeros(len(feeder.loads))
        self.net, elements = pandapower_network(
            feeder.buses.index, feeder.lines_on_base(kv), with_q(feeder.loads, zero, self.q_per_kw),
            feeder.generators, int(feeder.source_bus), kv, dispatchable="sgen", name=feeder.name,
        )  # fmt: skip
        self.generator_element = dict(zip(feeder.generators.index.astype(str), elements,
                                          strict=True))  # fmt: skip
        self.load_row = {str(name): i for i, name in enumerate(feeder.loads.index)}
        self.graph = nx.Graph()
        for name, line in feeder.lines.iterrows():
            self.graph.add_edge(int(line.from_bus), int(line.to_bus), name=name)
        self.line_row = {name: i for i, name in enumerate(feeder.lines.index)}
        return self.meta

    def create(self, num, model, **params):
        return [self._create(model, **params) for _ in range(num)]

    def _create(self, model, name=None, top_bus=None, bottom_bus=None) -> dict:
        if model == "Load":
            if str(name) not in self.load_row:
                raise ValueError(f"no load {name!r} in feeder {self.feeder.name}")
            eid, target = f"Load-{name}", self.load_row[str(name)]
        elif model == "DG":
            if str(name) not in self.generator_element:
                raise ValueError(f"no generator {name!r} in feeder {self.feeder.name}")
            eid, target = f"DG-{name}", self.generator_element[str(name)]
        elif model == "Branch":
            eid, target = f"Branch-{top_bus}-{bottom_bus}", self._chain(top_bus, bottom_bus)
        else:
            eid, target = "Network", None
        self.entities[eid] = (model, target)
        return {"eid": eid, "type": model}

    def _chain(self, top_bus, bottom_bus) -> tuple[int, bool, int, bool]:
        """The chain's end lines (rows) and orientation: ``(top line, its from_bus is the top,
        bottom line, its to_bus is the bottom)``; the top is the end nearer the source."""
        source = int(self.feeder.source_bus)
        a, b = int(top_bus), int(bottom_bus)
        lengths = nx.single_source_shortest_path_length(self.graph, source)
        if lengths[a] > lengths[b]:
            a, b = b, a
        path = nx.shortest_path(self.graph, a, b)
        first = self.graph.edges[path[0], path[1]]["name"]
        last = self.graph.edges[path[-2], path[-1]]["name"]
        lines = self.feeder.lines
        return (self.line_row[first], int(lines.at[first, "from_bus"]) == path[0],
                self.line_row[last], int(lines.at[last, "to_bus"]) == path[-1])  # fmt: skip

    def step(self, time, inputs, max_advance):
        for eid, attrs in inputs.items():
            model, target = self.entities[eid]
            value = sum(attrs.get("p_kw", {}).values())
            if model == "Load":
                self.net.load.at[target, "p_mw"] = value / KW_PER_MW
                self.net.load.at[target, "q_mvar"] = value * self.q_per_kw[target] / KW_PER_MW
            elif model == "DG":
                kind, index = target
                if kind == "sgen":
                    self.net.sgen.at[index, "p_mw"] = value / KW_PER_MW
                self.setpoints[eid] = value
        self._solve()
        return None

    def _solve(self) -> None:
        import pandapower as pp

        init = "results" if self.power_flows else "auto"
        pp.runpp(self.net, algorithm="nr", init=init, tolerance_mva=1e-9, numba=False)
        self.power_flows += 1

    def get_data(self, outputs):
        return {eid: self._values(eid, attrs) for eid, attrs in outputs.items()}

    def _values(self, eid, attrs) -> dict:
        model, target = self.entities[eid]
        net = self.net
        if model == "Load":
            values = {"p_kw": net.load.at[target, "p_mw"] * KW_PER_MW,
                      "q_kvar": net.load.at[target, "q_mvar"] * KW_PER_MW}  # fmt: skip
        elif model == "DG":
            kind, index = target
            table = net.res_ext_grid if kind == "ext_grid" else net.res_sgen
            values = {"p_kw": float(table.at[index, "p_mw"]) * KW_PER_MW,
                      "setpoint_kw": self.setpoints.get(eid)}  # fmt: skip
        elif model == "Branch":
            values = self._branch(*target)
        else:
            values = {
                "losses_kw": float(net.res_line.pl_mw.sum()) * KW_PER_MW,
                "v_min_pu": float(net.res_bus.vm_pu.min()),
                "v_max_pu": float(net.res_bus.vm_pu.max()),
                "source_kw": float(net.res_ext_grid.p_mw.sum()) * KW_PER_MW,
                "power_flows": self.power_flows,
            }
        return {attr: values[attr] for attr in attrs}

    def _branch(self, top, top_from, bottom, bottom_to) -> dict:
        res = self.net.res_line
        p_top = res.p_from_mw.iat[top] if top_from else res.p_to_mw.iat[top]
        p_bottom = -(res.p_to_mw.iat[bottom] if bottom_to else res.p_from_mw.iat[bottom])
        p = p_top if abs(p_top) >= abs(p_bottom) else p_bottom
        return {"p_kw": float(p) * KW_PER_MW, "p_top_kw": float(p_top) * KW_PER_MW,
                "p_bottom_kw": float(p_bottom) * KW_PER_MW,
                "loss_kw": float(p_top - p_bottom) * KW_PER_MW}  # fmt: skip
