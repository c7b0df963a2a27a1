"""Key-node reduction (paper sections II and III).

Node controllers sit only at key nodes. The reduction

1. prunes dead-end branches that carry neither load nor generator,
2. keeps the source bus, every generator bus, every load bus and every bus that joins more than
   two lines of the pruned feeder (a branching point),
3. replaces each chain of series lines between two kept buses by one line with the summed
   length and impedance and the smallest flow limit along the chain.

With the paper's six generator buses the IEEE European LV feeder reduces to 110 nodes and
109 lines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from popdispatch.feeder.model import Feeder
from popdispatch.feeder.tree import Tree, build_tree, downstream, subtree_sums


@dataclass(frozen=True)
class ReducedFeeder:
    """A feeder reduced to its key nodes.

    Attributes
    ----------
    original : the feeder it was reduced from.
    nodes : index node number (0 = source); columns ``bus`` (original id), ``x``, ``y``.
    lines : index reduced line number; columns ``from_node`` (parent side), ``to_node`` (child
        side), ``from_bus``, ``to_bus``, ``length_km``, ``r_ohm``, ``x_ohm``, ``limit_kw`` and
        ``n_original`` (how many original lines it replaces).
    loads : the original loads with a ``node`` column.
    generators : the fleet with a ``node`` column.
    bus_node : original bus id -> node number, ``-1`` for buses that are not key nodes.
    line_map : original line name -> reduced line number, ``-1`` for pruned lines.
    tree : the rooted tree of the reduced feeder (flows, sides, paths).
    """

    original: Feeder
    nodes: pd.DataFrame
    lines: pd.DataFrame
    loads: pd.DataFrame
    generators: pd.DataFrame
    bus_node: pd.Series
    line_map: pd.Series
    tree: Tree

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_lines(self) -> int:
        return len(self.lines)

    def generator_downstream(self) -> np.ndarray:
        """Boolean ``(lines, generators)``: generator below the line (on its child side)."""
        return downstream(self.tree, self.generators["node"].to_numpy())

    def path_lines(self, bus_a: int, bus_b: int) -> np.ndarray:
        """Reduced lines on the path between two original buses (any bus, key node or not)."""
        names = self.original.path_lines(bus_a, bus_b)
        reduced = self.line_map.loc[names].to_numpy()
        return np.unique(reduced[reduced >= 0])  # pruned lines (-1) have no reduced line

    def load_injection_kw(self, load_kw: np.ndarray) -> np.ndarray:
        """Nodal load (kW) from per-load values (last axis in the order of ``original.loads``)."""
        load_kw = np.asarray(load_kw, dtype=float)
        out = np.zeros(load_kw.shape[:-1] + (self.n_nodes,))
        np.add.at(out.T, self.loads["node"].to_numpy(), np.moveaxis(load_kw, -1, 0))
        return out


def reduce_feeder(feeder: Feeder) -> ReducedFeeder:
    """Reduce ``feeder`` to its key nodes (see module docstring)."""
    buses = feeder.buses.index.to_numpy()
    position = pd.Series(np.arange(len(buses)), index=feeder.buses.index)
    root = int(position[feeder.source_bus])
    ends_a = position[feeder.lines.from_bus].to_numpy()
    ends_b = position[feeder.lines.to_bus].to_numpy()
    tree = build_tree(len(buses), ends_a, ends_b, root)

    essential = np.zeros(len(buses))
    essential[position[feeder.loads.bus].to_numpy()] = 1
    essential[position[feeder.generators.bus].to_numpy()] = 1
    essential[root] = 1
    retained = subtree_sums(tree, essential) > 0
    retained_children = np.bincount(
        tree.parent[retained & (tree.parent >= 0)], minlength=len(buses)
    )
    degree = retained_children + (tree.parent >= 0)
    key = (essential > 0) | (retained & (degree > 2))

    bottom = _chain_bottoms(tree, retained, key)
    line_of_child = bottom[tree.line_child]
    kept_line = retained[tree.line_child]
    others = np.flatnonzero(key)
    others = others[others != root]
    key_positions = np.concatenate([[root], others[np.argsort(buses[others])]])
    node_of_position = np.full(len(buses), -1, dtype=np.int64)
    node_of_position[key_positions] = np.arange(len(key_positions))

    reduced_line = np.where(kept_line, node_of_position[line_of_child] - 1, -1)
    lines = _merge_lines(feeder, tree, reduced_line, node_of_position, buses, len(key_positions))
    reduced_tree = build_tree(
        len(key_positions), lines.from_node.to_numpy(), lines.to_node.to_numpy(), 0
    )
    nodes = pd.DataFrame(
        {"bus": buses[key_positions]}, index=pd.RangeIndex(len(key_positions), name="node")
    )
    nodes[["x", "y"]] = feeder.buses.loc[nodes.bus, ["x", "y"]].to_numpy()
    bus_node = pd.Series(node_of_position, index=feeder.buses.index, name="node")
    loads = feeder.loads.assign(node=bus_node[feeder.loads.bus].to_numpy())
    generators = feeder.generators.assign(node=bus_node[feeder.generators.bus].to_numpy())
    line_map = pd.Series(reduced_line, index=feeder.lines.index, name="reduced_line")
    return ReducedFeeder(feeder, nodes, lines, loads, generators, bus_node, line_map, reduced_tree)


def _chain_bottoms(tree: Tree, retained: np.ndarray, key: np.ndarray) -> np.ndarray:
    """For each retained bus, the first key bus at or below it along its chain."""
    bottom = np.where(key, np.arange(len(key)), -1)
    # Reverse pre-order visits children before parents; a retained non-key bus has exactly one
    # retained child, so it inherits that child's bottom. Build-time only (not a hot path).
    for node in tree.preorder[::-1]:
        par = tree.parent[node]
        if par >= 0 and retained[node] and not key[par]:
            bottom[par] = bottom[node]
    return bottom


def _merge_lines(
    feeder: Feeder,
    tree: Tree,
    reduced_line: np.ndarray,
    node_of_position: np.ndarray,
    buses: np.ndarray,
    n_nodes: int,
) -> pd.DataFrame:
    table = feeder.lines.assign(reduced=reduced_line)
    table = table[table.reduced >= 0]
    merged = table.groupby("reduced").agg(
        length_km=("length_km", "sum"),
        r_ohm=("r_ohm", "sum"),
        x_ohm=("x_ohm", "sum"),
        limit_kw=("limit_kw", "min"),
        n_original=("length_km", "size"),
    )
    merged = merged.reindex(pd.RangeIndex(n_nodes - 1, name="line"))
    to_node = merged.index.to_numpy() + 1
    # The parent node of a chain: the key node reached by walking up from the chain's top bus.
    child_position = np.empty(n_nodes, dtype=np.int64)
    child_position[node_of_position[node_of_position >= 0]] = np.flatnonzero(node_of_position >= 0)
    from_node = np.array(
        [_key_ancestor(tree, node_of_position, p) for p in child_position[1:]], dtype=np.int64
    )
    merged.insert(0, "from_node", from_node)
    merged.insert(1, "to_node", to_node)
    merged.insert(2, "from_bus", buses[child_position[from_node]])
    merged.insert(3, "to_bus", buses[child_position[to_node]])
    merged["n_original"] = merged["n_original"].astype(int)
    return merged


def _key_ancestor(tree: Tree, node_of_position: np.ndarray, position: int) -> int:
    current = tree.parent[position]
    while node_of_position[current] < 0:
        current = tree.parent[current]
    return int(node_of_position[current])
