"""The original radial feeder as plain tables, in the spirit of a pandapower net.

Units: lengths in km, impedances in ohm, powers and limits in kW (people's unit; the engine
converts to MW). Buses are identified by integer ids (the IEEE numbers for ``ieee-elv``); a
format that names its buses (OpenDSS) keeps the names in the buses' ``name`` column, and
people see those names (:func:`bus_labels`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from scipy.sparse import csr_array

from popdispatch.errors import FeederError, MeshedError
from popdispatch.feeder.tree import Tree, build_tree
from popdispatch.feeder.tree import path_lines as tree_path_lines

if TYPE_CHECKING:
    import networkx as nx

BUS_COLUMNS = ["x", "y"]
LINE_COLUMNS = ["from_bus", "to_bus", "length_km", "r_ohm", "x_ohm", "limit_kw"]
LOAD_COLUMNS = ["bus"]


@dataclass(frozen=True)
class Feeder:
    """A radial distribution feeder.

    Attributes
    ----------
    name : case name, e.g. ``"ieee-elv"``.
    buses : index ``bus`` (int id); columns ``x``, ``y`` (plot coordinates, m); optional
        ``vn_kv`` (nominal line-to-line voltage, kV: the AC check's base at the source bus)
        and ``name`` (the source format's name of the bus, where it names them).
    lines : index line name; columns ``from_bus``, ``to_bus``, ``length_km``, ``r_ohm``,
        ``x_ohm`` (series impedance of the whole line, ohm) and ``limit_kw`` (flow limit in kW,
        ``inf`` for no limit). Optional ``kv_base``: the line-to-line voltage (kV) on which
        the line's ohms are stated (its own side of any transformer); without it every line's
        ohms are on one base, the source's (:meth:`lines_on_base` refers them to one).
    loads : index load name; column ``bus``. Optional ``p_kw`` (kW of the network's own
        snapshot; a negative value is a fixed injection, e.g. a generator without cost data),
        ``kind`` (``load`` or what injects) and the names of the load shapes of each series
        (``daily``, ``yearly``, ``duty``). Other columns (e.g. ``peak_kw`` of the synthetic
        feeders, kW) are carried along unchecked and ignored by the engine.
    source_bus : the bus fed by the substation (the root of the tree).
    generators : the fleet (see :mod:`popdispatch.feeder.generators`), index generator name;
        may be empty (a network described without a fleet: nothing to dispatch).
    shapes : load shapes by name (:class:`popdispatch.feeder.shapes.LoadShape`) for the
        loads' series columns; empty when the network has none.
    """

    name: str
    buses: pd.DataFrame
    lines: pd.DataFrame
    loads: pd.DataFrame
    source_bus: int
    generators: pd.DataFrame
    shapes: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        validate_feeder(self)

    def with_generators(self, generators: pd.DataFrame) -> Feeder:
        """Return the same feeder with another fleet (validated against its buses)."""
        return replace(self, generators=generators)

    def with_line_limits(self, limits_kw: pd.Series) -> Feeder:
        """Return the feeder with ``limit_kw`` set for the lines named in ``limits_kw``.

        Where a line already has a limit the smaller one is kept.
        """
        return replace(self, lines=tighter_limits(self.lines, limits_kw))

    @property
    def base_kv(self) -> float | None:
        """The source bus's nominal line-to-line voltage (kV) where the buses table states it
        (``vn_kv``), else ``None``."""
        if "vn_kv" not in self.buses.columns:
            return None
        value = float(self.buses.at[self.source_bus, "vn_kv"])
        return value if np.isfinite(value) and value > 0 else None

    def lines_on_base(self, kv: float | None = None) -> pd.DataFrame:
        """The lines with ``r_ohm``/``x_ohm`` referred to one voltage base: ohm x (``kv`` /
        ``kv_base``)^2 (``kv``: line-to-line kV, default :attr:`base_kv`). Unchanged where the
        table has no ``kv_base`` (its ohms already share one base) or no base is known."""
        kv = self.base_kv if kv is None else kv
        if "kv_base" not in self.lines.columns or kv is None:
            return self.lines
        own = self.lines["kv_base"].to_numpy(float)
        scale = np.where(own > 0, (kv / np.where(own > 0, own, 1.0)) ** 2, 1.0)
        return self.lines.assign(
            r_ohm=self.lines["r_ohm"].to_numpy(float) * scale,
            x_ohm=self.lines["x_ohm"].to_numpy(float) * scale,
        )

    def bus_labels(self, buses) -> list[int | str]:
        """The source format's names of ``buses`` (int ids): the ``name`` column where the
        buses table has one (every bus then a string, ``"650"`` too), else the ids."""
        return bus_labels(self, buses)

    def bus_id(self, label: int | str) -> int:
        """The int id of a bus the user names as the source format does (an OpenDSS name, case
        ignored; a number); :class:`FeederError` naming it when the feeder has no such bus."""
        return bus_id(self, label)

    def graph(self) -> nx.Graph:
        """The feeder as an undirected networkx graph; edges carry the line name as ``line``."""
        import networkx as nx  # only here: importing networkx is slow and most runs never need it

        g = nx.Graph()
        g.add_nodes_from(self.buses.index.tolist())
        g.add_edges_from(
            zip(
                self.lines.from_bus.tolist(),
                self.lines.to_bus.tolist(),
                ({"line": name} for name in self.lines.index.tolist()),
                strict=True,
            )
        )
        return g

    def bus_tree(self) -> Tree:
        """The feeder as a :class:`~popdispatch.feeder.tree.Tree` rooted at the source bus.

        Node ``j`` is the bus ``buses.index[j]`` and line ``k`` the line ``lines.index[k]``.
        """
        ends_a = self.buses.index.get_indexer(self.lines.from_bus)
        ends_b = self.buses.index.get_indexer(self.lines.to_bus)
        root = self.buses.index.get_loc(self.source_bus)
        return build_tree(len(self.buses), ends_a, ends_b, int(root))

    def path_lines(self, bus_a: int | str, bus_b: int | str) -> list[str]:
        """Names of the original lines on the (unique) path between two buses, from ``bus_a``
        (ids, or names as :meth:`bus_id` reads them)."""
        ends = []
        for bus in (bus_a, bus_b):
            try:
                ends.append(self.bus_id(bus))
            except FeederError:
                raise FeederError(
                    f"unknown bus {bus} in path query on feeder {self.name!r}"
                ) from None
        a, b = self.buses.index.get_indexer(ends)
        return self.lines.index[tree_path_lines(self.bus_tree(), a, b)].tolist()


def tighter_limits(lines: pd.DataFrame, limits_kw: pd.Series) -> pd.DataFrame:
    """A copy of the lines table ``lines`` with ``limit_kw`` of the lines named in
    ``limits_kw`` (kW) set, the smaller kept where a line already has a limit;
    :class:`FeederError` naming a line the table lacks."""
    unknown = limits_kw.index.difference(lines.index)
    if len(unknown):
        raise FeederError(f"line limit given for unknown line {unknown[0]!r}")
    lines = lines.copy()
    current = lines.loc[limits_kw.index, "limit_kw"].to_numpy(float)
    lines.loc[limits_kw.index, "limit_kw"] = np.minimum(current, limits_kw.to_numpy(float))
    return lines


def bus_labels(feeder: Feeder, buses) -> list[int | str]:
    """See :meth:`Feeder.bus_labels`."""
    numbers = [int(b) for b in buses]
    if "name" not in feeder.buses.columns:
        return numbers
    names = feeder.buses["name"]
    return [str(names.get(b, b)) for b in numbers]


def bus_id(feeder: Feeder, label: int | str) -> int:
    """See :meth:`Feeder.bus_id`: a bus name (case ignored) where the buses have names, else
    (or when no bus has that name) the int id it spells."""
    index = feeder.buses.index
    if not isinstance(label, str) and np.ndim(label) == 0 and float(label).is_integer():
        label = int(label)  # 650, np.int64(650) and 650.0 name the same bus
    if "name" in feeder.buses.columns:
        key = str(label).strip().lower()
        found = np.flatnonzero(feeder.buses["name"].astype(str).str.lower().to_numpy() == key)
        if len(found):
            return int(index[found[0]])
    text = str(label).strip()
    if text.lstrip("-").isdigit() and int(text) in index:
        return int(text)
    raise FeederError(f"feeder {feeder.name!r} has no bus {label!r}")


def validate_feeder(feeder: Feeder) -> None:
    """Raise :class:`FeederError` unless the feeder is a connected tree with sane line data.

    Vectorised (pandas, numpy, :mod:`scipy.sparse.csgraph`): a 100,000-bus feeder validates in
    a fraction of a second. The first problem found is reported, naming its element.
    """
    _check_columns(feeder)
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


def _check_columns(feeder: Feeder) -> None:
    """One line naming every required column a table lacks (``limit_kw``: ``inf`` = no limit)."""
    for table, required in (
        ("buses", BUS_COLUMNS), ("lines", LINE_COLUMNS), ("loads", LOAD_COLUMNS),
    ):  # fmt: skip
        columns = getattr(feeder, table).columns
        missing = [column for column in required if column not in columns]
        if missing:
            hint = "; limit_kw inf means no limit" if "limit_kw" in missing else ""
            plural = "s" if len(missing) > 1 else ""
            raise FeederError(
                f"the {table} table of feeder {feeder.name!r} lacks column{plural} "
                f"{', '.join(missing)} (required: {', '.join(required)}{hint})"
            )


def _check_radial(feeder: Feeder) -> None:
    """Parallel lines, then unreachable buses, then loops; scipy graph code, no networkx."""
    buses, lines = feeder.buses, feeder.lines
    n = len(buses)
    ends_a = buses.index.get_indexer(lines.from_bus)
    ends_b = buses.index.get_indexer(lines.to_bus)
    low, high = np.minimum(ends_a, ends_b), np.maximum(ends_a, ends_b)
    parallel = pd.Series(low * n + high).duplicated().to_numpy()  # later copies of a bus pair
    if parallel.any():
        raise MeshedError(
            f"line {lines.index[parallel.argmax()]!r} is parallel to another line: feeder is "
            "meshed (a radial reader; any network: docs/meshed.md)",
            [str(lines.index[parallel.argmax()])],
        )
    # imported here: scipy.sparse.csgraph imports scipy.linalg (slow to import), which a run on
    # a cached problem (popdispatch.cases.cached) never needs
    from scipy.sparse.csgraph import connected_components

    graph = csr_array((np.ones(len(lines), dtype=np.int8), (ends_a, ends_b)), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    source = buses.index.get_loc(feeder.source_bus)
    reached = component == component[source]
    if not reached.all():
        lonely, source_label = bus_labels(feeder, [buses.index[~reached][0], feeder.source_bus])
        raise FeederError(
            f"bus {lonely} is not connected to source bus {source_label}: feeder is "
            "disconnected (popdispatch supports connected radial feeders only)"
        )
    if len(lines) != n - 1:
        raise _loop_error(feeder, ends_a, ends_b, int(source))


def _loop_error(feeder: Feeder, ends_a: np.ndarray, ends_b: np.ndarray, source: int) -> MeshedError:
    """The error naming the first line, in table order, that closes a loop, and the buses of
    that loop (``loop_lines``: that line, then the loop's other lines).

    Kruskal's algorithm with the table order as weights keeps a line iff it joins two parts not
    yet connected by earlier lines: the first line it rejects closes a loop with earlier lines
    only, the path between its ends in the spanning tree.
    """
    from scipy.sparse.csgraph import minimum_spanning_tree

    n = len(feeder.buses)
    order = np.arange(1, len(ends_a) + 1, dtype=float)  # weights must be positive
    spanning = minimum_spanning_tree(csr_array((order, (ends_a, ends_b)), shape=(n, n)))
    kept = np.zeros(len(ends_a), dtype=bool)
    kept[np.rint(spanning.data).astype(np.int64) - 1] = True
    closing = int(np.flatnonzero(~kept)[0])
    tree_lines = np.flatnonzero(kept)
    tree = build_tree(n, ends_a[tree_lines], ends_b[tree_lines], source)
    path = tree_path_lines(tree, int(ends_a[closing]), int(ends_b[closing]))
    loop = [int(ends_a[closing])]
    for k in tree_lines[path]:
        loop.append(int(ends_b[k] if ends_a[k] == loop[-1] else ends_a[k]))
    buses = bus_labels(feeder, feeder.buses.index[loop])
    shown = "[" + ", ".join(repr(b) for b in buses) + "]"
    names = [feeder.lines.index[closing], *feeder.lines.index[tree_lines[path]]]
    return MeshedError(
        f"line {feeder.lines.index[closing]!r} closes a loop through buses {shown}: "
        "feeder is meshed (a radial reader; any network: docs/meshed.md)",
        [str(n) for n in names],
    )
