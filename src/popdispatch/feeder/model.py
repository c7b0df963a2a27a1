"""The original radial feeder as plain tables, in the spirit of a pandapower net.

Units: lengths in km, impedances in ohm, powers and limits in kW (people's unit; the engine
converts to MW). Buses are identified by integer ids (the IEEE numbers for ``ieee-elv``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import networkx as nx
import numpy as np
import pandas as pd

from popdispatch.errors import FeederError

BUS_COLUMNS = ["x", "y"]
LINE_COLUMNS = ["from_bus", "to_bus", "length_km", "r_ohm", "x_ohm", "limit_kw"]
LOAD_COLUMNS = ["bus"]


@dataclass(frozen=True)
class Feeder:
    """A radial distribution feeder.

    Attributes
    ----------
    name : case name, e.g. ``"ieee-elv"``.
    buses : index ``bus`` (int id); columns ``x``, ``y`` (plot coordinates, m).
    lines : index line name; columns ``from_bus``, ``to_bus``, ``length_km``, ``r_ohm``,
        ``x_ohm`` (series impedance of the whole line, ohm) and ``limit_kw`` (flow limit in kW,
        ``inf`` for no limit).
    loads : index load name; column ``bus``.
    source_bus : the bus fed by the substation (the root of the tree).
    generators : the fleet (see :mod:`popdispatch.feeder.generators`), index generator name.
    """

    name: str
    buses: pd.DataFrame
    lines: pd.DataFrame
    loads: pd.DataFrame
    source_bus: int
    generators: pd.DataFrame

    def __post_init__(self) -> None:
        validate_feeder(self)

    def with_generators(self, generators: pd.DataFrame) -> Feeder:
        """Return the same feeder with another fleet (validated against its buses)."""
        return replace(self, generators=generators)

    def with_line_limits(self, limits_kw: pd.Series) -> Feeder:
        """Return the feeder with ``limit_kw`` set for the lines named in ``limits_kw``.

        Where a line already has a limit the smaller one is kept.
        """
        unknown = limits_kw.index.difference(self.lines.index)
        if len(unknown):
            raise FeederError(f"line limit given for unknown line {unknown[0]!r}")
        lines = self.lines.copy()
        current = lines.loc[limits_kw.index, "limit_kw"].to_numpy()
        lines.loc[limits_kw.index, "limit_kw"] = np.minimum(current, limits_kw.to_numpy(float))
        return replace(self, lines=lines)

    def graph(self) -> nx.Graph:
        """The feeder as an undirected networkx graph; edges carry the line name as ``line``."""
        g = nx.Graph()
        g.add_nodes_from(self.buses.index)
        g.add_edges_from(
            (f, t, {"line": name})
            for name, f, t in zip(
                self.lines.index, self.lines.from_bus, self.lines.to_bus, strict=True
            )
        )
        return g

    def path_lines(self, bus_a: int, bus_b: int) -> list[str]:
        """Names of the original lines on the (unique) path between two buses."""
        for bus in (bus_a, bus_b):
            if bus not in self.buses.index:
                raise FeederError(f"unknown bus {bus} in path query on feeder {self.name!r}")
        g = self.graph()
        path = nx.shortest_path(g, bus_a, bus_b)
        return [g.edges[u, v]["line"] for u, v in zip(path[:-1], path[1:], strict=True)]


def validate_feeder(feeder: Feeder) -> None:
    """Raise :class:`FeederError` unless the feeder is a connected tree with sane line data."""
    buses, lines = feeder.buses, feeder.lines
    if feeder.source_bus not in buses.index:
        raise FeederError(f"source bus {feeder.source_bus} is not a bus of feeder {feeder.name!r}")
    if buses.index.has_duplicates:
        raise FeederError(f"bus {buses.index[buses.index.duplicated()][0]} is defined twice")
    for end in ("from_bus", "to_bus"):
        bad = ~lines[end].isin(buses.index)
        if bad.any():
            name = lines.index[bad][0]
            raise FeederError(f"line {name!r} ends at unknown bus {lines.loc[name, end]}")
    for column in ("length_km", "r_ohm", "x_ohm", "limit_kw"):
        values = lines[column].to_numpy(float)
        bad = np.isnan(values) | (values < 0)
        if bad.any():
            name = lines.index[bad][0]
            raise FeederError(f"line {name!r} has invalid {column} = {lines.loc[name, column]}")
    self_loops = lines.from_bus == lines.to_bus
    if self_loops.any():
        raise FeederError(f"line {lines.index[self_loops][0]!r} connects bus to itself")
    _check_radial(feeder)
    bad_loads = ~feeder.loads.bus.isin(buses.index)
    if bad_loads.any():
        name = feeder.loads.index[bad_loads][0]
        raise FeederError(f"load {name!r} is on unknown bus {feeder.loads.loc[name, 'bus']}")
    from popdispatch.feeder.generators import validate_fleet

    validate_fleet(feeder.generators, buses.index)


def _check_radial(feeder: Feeder) -> None:
    g = feeder.graph()
    if g.number_of_edges() != len(feeder.lines):
        dup = feeder.lines[
            feeder.lines[["from_bus", "to_bus"]]
            .apply(lambda r: tuple(sorted(r)), axis=1)
            .duplicated()
        ].index[0]
        raise FeederError(
            f"line {dup!r} is parallel to another line: feeder is meshed "
            "(popdispatch supports radial feeders only)"
        )
    reachable = nx.node_connected_component(g, feeder.source_bus)
    if len(reachable) != g.number_of_nodes():
        lonely = next(b for b in feeder.buses.index if b not in reachable)
        raise FeederError(
            f"bus {lonely} is not connected to source bus {feeder.source_bus}: feeder is "
            "disconnected (popdispatch supports connected radial feeders only)"
        )
    if g.number_of_edges() != g.number_of_nodes() - 1:
        cycle = nx.find_cycle(g, feeder.source_bus)
        # Name the loop's last line in table order: the one that closes it.
        order = {name: k for k, name in enumerate(feeder.lines.index)}
        u, v = max((e[:2] for e in cycle), key=lambda e: order[g.edges[e]["line"]])
        raise FeederError(
            f"line {g.edges[u, v]['line']!r} closes a loop through buses "
            f"{[e[0] for e in cycle]}: feeder is meshed (popdispatch supports radial feeders only)"
        )
