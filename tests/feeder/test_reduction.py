"""Key-node reduction: the IEEE European LV feeder and random small feeders.

The key check: with injections only at load and generator buses, every reduced line carries
exactly the flow of each original line it replaces, and pruned lines carry nothing.
"""

import networkx as nx
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.cases import elv_snapshot_566_kw
from popdispatch.feeder import Feeder, make_fleet, reduce_feeder
from popdispatch.feeder.tree import build_tree, line_flows

GENERATOR_BUSES = [1, 114, 578, 739, 817, 835]


def original_flows(feeder: Feeder, load_kw: pd.Series, gen_kw: pd.Series) -> pd.Series:
    """DC flows (kW, positive away from the source) of the unreduced feeder, per line name."""
    position = pd.Series(np.arange(len(feeder.buses)), index=feeder.buses.index)
    tree = build_tree(
        len(position),
        position[feeder.lines.from_bus].to_numpy(),
        position[feeder.lines.to_bus].to_numpy(),
        int(position[feeder.source_bus]),
    )
    injection = np.zeros(len(position))
    np.add.at(
        injection, position[feeder.generators.bus].to_numpy(), gen_kw[feeder.generators.index]
    )
    np.add.at(injection, position[feeder.loads.bus].to_numpy(), -load_kw[feeder.loads.index])
    return pd.Series(line_flows(tree, injection), index=feeder.lines.index)


def reduced_flows(reduced, load_kw: pd.Series, gen_kw: pd.Series) -> np.ndarray:
    injection = -reduced.load_injection_kw(load_kw[reduced.loads.index].to_numpy())
    np.add.at(injection, reduced.generators["node"].to_numpy(), gen_kw[reduced.generators.index])
    return line_flows(reduced.tree, injection)


def reduced_degree(reduced) -> np.ndarray:
    ends = np.concatenate([reduced.lines.from_node, reduced.lines.to_node])
    return np.bincount(ends, minlength=reduced.n_nodes)


def check_chains(feeder: Feeder, reduced) -> None:
    """Each reduced line replaces exactly the original lines between its end buses."""
    for k, line in reduced.lines.iterrows():
        mapped = set(reduced.line_map.index[reduced.line_map == k])
        assert mapped == set(feeder.path_lines(line.from_bus, line.to_bus)), k
        assert line.n_original == len(mapped)
        originals = feeder.lines.loc[sorted(mapped)]
        for column in ("length_km", "r_ohm", "x_ohm"):
            assert line[column] == pytest.approx(originals[column].sum(), rel=1e-12)
        assert line.limit_kw == originals.limit_kw.min()


# --- IEEE European LV feeder -------------------------------------------------------------------


def test_elv_reduces_to_110_nodes_109_lines(elv, elv_reduced):
    r = elv_reduced
    assert (r.n_nodes, r.n_lines) == (110, 109)
    assert r.tree.n_nodes == 110 and r.tree.n_lines == 109
    assert r.nodes.loc[0, "bus"] == 1 == elv.source_bus
    assert r.nodes.index.tolist() == list(range(110))
    assert r.lines.index.tolist() == list(range(109))
    # Reduced line k feeds node k + 1 from its parent (towards the source).
    np.testing.assert_array_equal(r.lines.to_node, np.arange(1, 110))
    np.testing.assert_array_equal(r.tree.line_parent, r.lines.from_node)
    np.testing.assert_array_equal(r.tree.line_child, r.lines.to_node)
    np.testing.assert_array_equal(r.lines.from_bus, r.nodes.bus[r.lines.from_node])
    np.testing.assert_array_equal(r.lines.to_bus, r.nodes.bus[r.lines.to_node])
    # bus_node is the inverse of nodes.bus, -1 elsewhere.
    np.testing.assert_array_equal(r.bus_node[r.nodes.bus].to_numpy(), np.arange(110))
    assert (r.bus_node >= 0).sum() == 110
    assert (r.bus_node == -1).sum() == len(elv.buses) - 110
    np.testing.assert_array_equal(
        r.nodes[["x", "y"]].to_numpy(), elv.buses.loc[r.nodes.bus, ["x", "y"]].to_numpy()
    )


def test_elv_key_nodes(elv, elv_reduced):
    r = elv_reduced
    key_buses = set(r.nodes.bus)
    assert set(GENERATOR_BUSES) <= key_buses
    assert sorted(r.generators.bus) == GENERATOR_BUSES
    assert set(elv.loads.bus) <= key_buses
    np.testing.assert_array_equal(r.generators.node, r.bus_node[r.generators.bus].to_numpy())
    np.testing.assert_array_equal(r.loads.node, r.bus_node[r.loads.bus].to_numpy())
    assert (r.loads.node > 0).all()
    assert r.generators.loc["G1", "node"] == 0
    degree = reduced_degree(r)
    essential = set(elv.loads.bus) | set(GENERATOR_BUSES) | {elv.source_bus}
    branch = r.nodes.index[~r.nodes.bus.isin(essential)]
    assert len(branch) > 0
    assert (degree[branch] >= 3).all()
    # 55 loads on 55 distinct buses; generators 817 and 835 share a load bus, 114, 578 and 739
    # do not: 110 - 1 - 55 - 3 = 51 key nodes are pure branching points.
    assert elv.loads.bus.nunique() == 55
    assert set(elv.loads.bus) & set(GENERATOR_BUSES) == {817, 835}
    assert len(essential) == 59
    assert len(branch) == 51


def test_elv_line_totals(elv, elv_reduced):
    r = elv_reduced
    kept = r.line_map >= 0
    assert kept.sum() == 700
    assert r.lines.n_original.sum() == 700
    for column in ("length_km", "r_ohm", "x_ohm"):
        assert r.lines[column].sum() == pytest.approx(elv.lines.loc[kept, column].sum(), rel=1e-12)
        assert r.lines[column].sum() < elv.lines[column].sum()  # something was pruned
    np.testing.assert_array_equal(
        np.bincount(r.line_map[kept], minlength=r.n_lines), r.lines.n_original
    )
    assert r.line_map.max() == 108
    assert np.isinf(r.lines.limit_kw).all()
    assert r.lines.loc[0, "n_original"] == 19
    check_chains(elv, r)


def test_elv_pruned_branches_carry_no_load_or_generator(elv, elv_reduced):
    g = elv.graph()
    pruned = elv_reduced.line_map.index[elv_reduced.line_map < 0]
    g.remove_edges_from(
        (f, t) for f, t in elv.lines.loc[pruned, ["from_bus", "to_bus"]].itertuples(index=False)
    )
    main = nx.node_connected_component(g, elv.source_bus)
    assert set(elv.loads.bus) <= main and set(GENERATOR_BUSES) <= main
    # What remains connected to the source is exactly the buses of the kept lines.
    kept = elv.lines[elv_reduced.line_map >= 0]
    assert main == set(kept.from_bus) | set(kept.to_bus)


def test_elv_snapshot_566_flows(elv, elv_reduced):
    load = elv_snapshot_566_kw()
    assert load.sum() == pytest.approx(57.358, abs=1e-5)
    gen = pd.Series(0.0, index=elv.generators.index)
    flows = reduced_flows(elv_reduced, load, gen)
    root_lines = elv_reduced.lines.from_node.to_numpy() == 0
    assert root_lines.sum() == 1
    assert flows[root_lines].sum() == pytest.approx(57.358, abs=1e-5)
    assert (flows >= -1e-12).all()  # no generation: everything flows away from the source
    # Lines feeding a single load carry that load.
    for name, bus in elv.loads.bus.items():
        node = elv_reduced.bus_node[bus]
        if not (elv_reduced.lines.from_node == node).any():  # a leaf
            assert flows[node - 1] == pytest.approx(load[name], rel=1e-12)


@pytest.mark.parametrize("scale", [0.0, 0.5, 1.0])
def test_elv_reduced_flows_equal_original_flows(elv, elv_reduced, scale):
    load = elv_snapshot_566_kw()
    gen = scale * elv.generators.pmax_kw  # 65 kW at full output: reverse flows appear
    flows = reduced_flows(elv_reduced, load, gen)
    original = original_flows(elv, load, gen)
    mapped = elv_reduced.line_map
    np.testing.assert_allclose(
        original[mapped >= 0].to_numpy(), flows[mapped[mapped >= 0]], rtol=1e-10, atol=1e-10
    )
    np.testing.assert_array_equal(original[mapped < 0].to_numpy(), 0.0)
    if scale == 1.0:
        assert (flows < 0).any()


def test_elv_reduced_flows_over_minutes(elv_reduced):
    # Leading axes: several minutes at once give the same flows as one at a time.
    load = elv_snapshot_566_kw()[elv_reduced.loads.index].to_numpy()
    minutes = np.stack([load, 0.5 * load, np.roll(load, 7)])
    nodal = elv_reduced.load_injection_kw(minutes)
    assert nodal.shape == (3, 110)
    np.testing.assert_allclose(nodal.sum(axis=1), minutes.sum(axis=1))
    flows = line_flows(elv_reduced.tree, -nodal)
    for m in range(3):
        np.testing.assert_allclose(flows[m], line_flows(elv_reduced.tree, -nodal[m]), atol=1e-12)
    np.testing.assert_allclose(flows[1], 0.5 * flows[0], atol=1e-12)


def test_elv_line_limits_take_chain_minimum(elv):
    rng = np.random.default_rng(566)
    names = rng.choice(elv.lines.index.to_numpy(), size=300, replace=False)
    limits = pd.Series(rng.uniform(1.0, 100.0, size=len(names)), index=names)
    limited = elv.with_line_limits(limits)
    # A second call keeps the smaller limit.
    limited = limited.with_line_limits(pd.Series([1e6, 0.25], index=names[:2]))
    assert limited.lines.loc[names[0], "limit_kw"] == limits[names[0]]
    assert limited.lines.loc[names[1], "limit_kw"] == 0.25
    r = reduce_feeder(limited)
    assert (r.n_nodes, r.n_lines) == (110, 109)
    for k in range(r.n_lines):
        chain = r.line_map.index[r.line_map == k]
        assert r.lines.loc[k, "limit_kw"] == limited.lines.loc[chain, "limit_kw"].min()
    assert np.isfinite(r.lines.limit_kw).any() and np.isinf(r.lines.limit_kw).any()
    # One limit in the 19-line chain leaving the source limits reduced line 0.
    first_chain = r.line_map.index[r.line_map == 0]
    one = reduce_feeder(elv.with_line_limits(pd.Series([42.0], index=[first_chain[5]])))
    assert one.lines.loc[0, "limit_kw"] == 42.0
    assert np.isinf(one.lines.limit_kw.iloc[1:]).all()


def test_elv_path_lines(elv, elv_reduced):
    path = elv.path_lines(505, 666)
    assert len(path) == 21
    lines = elv_reduced.path_lines(505, 666)
    assert (lines >= 0).all()
    covered = elv_reduced.line_map.index[elv_reduced.line_map.isin(lines)]
    assert set(covered) == set(path)
    # Between key nodes it agrees with the reduced tree's own path.
    from popdispatch.feeder.tree import path_lines

    a, b = elv_reduced.bus_node[[505, 666]]
    assert sorted(path_lines(elv_reduced.tree, a, b).tolist()) == lines.tolist()


def test_elv_path_lines_from_pruned_bus(elv, elv_reduced):
    # A bus on a pruned dead end: its path still maps only to real reduced lines.
    pruned_line = elv_reduced.line_map.index[elv_reduced.line_map < 0][0]
    row = elv.lines.loc[pruned_line]
    bus = row.to_bus if elv_reduced.bus_node[row.to_bus] < 0 else row.from_bus
    path = elv.path_lines(bus, 666)
    lines = elv_reduced.path_lines(bus, 666)
    assert len(lines) > 0 and (lines >= 0).all()
    expected = elv_reduced.line_map[path]
    assert set(lines.tolist()) == set(expected[expected >= 0].tolist())


# --- random small feeders ----------------------------------------------------------------------


@st.composite
def random_feeders(draw):
    n = draw(st.integers(1, 25))
    labels = draw(st.lists(st.integers(1, 999), min_size=n, max_size=n, unique=True))
    parent = [draw(st.integers(0, i - 1)) for i in range(1, n)]
    order = draw(st.permutations(range(n - 1))) if n > 1 else []
    rows = []
    for k in order:
        child, par = labels[k + 1], labels[parent[k]]
        ends = (child, par) if draw(st.booleans()) else (par, child)
        length = draw(st.floats(0.001, 1.0))
        limit = draw(st.sampled_from([np.inf, 5.0, 10.0, 20.0]))
        rows.append((*ends, length, 0.3 * length, 0.1 * length, limit))
    lines = pd.DataFrame(
        rows,
        columns=["from_bus", "to_bus", "length_km", "r_ohm", "x_ohm", "limit_kw"],
        index=pd.Index([f"L{k}" for k in range(n - 1)], name="line"),
    )
    buses = pd.DataFrame(
        {"x": np.arange(n, dtype=float), "y": np.zeros(n)},
        index=pd.Index(labels, name="bus"),
    )
    load_buses = draw(st.lists(st.sampled_from(labels), max_size=8))
    loads = pd.DataFrame(
        {"bus": np.array(load_buses, dtype=np.int64)},
        index=pd.Index([f"LOAD{i}" for i in range(len(load_buses))], name="load"),
    )
    gen_buses = draw(st.lists(st.sampled_from(labels), min_size=1, max_size=4))
    fleet = make_fleet(
        [(b, 0.0, 1.0, 0.01, 0.0, 10.0) for b in gen_buses],
        names=[f"G{i}" for i in range(len(gen_buses))],
    )
    source = draw(st.sampled_from(labels))
    feeder = Feeder("random", buses, lines, loads, source, fleet)
    load_kw = pd.Series(
        draw(st.lists(st.floats(0.0, 50.0), min_size=len(loads), max_size=len(loads))),
        index=loads.index,
        dtype=float,
    )
    gen_kw = pd.Series(
        draw(st.lists(st.floats(0.0, 10.0), min_size=len(fleet), max_size=len(fleet))),
        index=fleet.index,
        dtype=float,
    )
    return feeder, load_kw, gen_kw


@settings(max_examples=120, deadline=None)
@given(case=random_feeders(), data=st.data())
def test_random_reduction_keeps_flows(case, data):
    feeder, load_kw, gen_kw = case
    r = reduce_feeder(feeder)
    flows = reduced_flows(r, load_kw, gen_kw)
    original = original_flows(feeder, load_kw, gen_kw)
    kept = r.line_map >= 0
    np.testing.assert_allclose(
        original[kept].to_numpy(), flows[r.line_map[kept]], rtol=1e-10, atol=1e-9
    )
    np.testing.assert_array_equal(original[~kept].to_numpy(), 0.0)

    # Brute-force key nodes: the buses on source-to-essential paths are retained; key nodes are
    # the essential buses plus retained buses joining three or more retained lines.
    g = feeder.graph()
    essential = set(feeder.loads.bus) | set(feeder.generators.bus) | {feeder.source_bus}
    retained = set().union(*(nx.shortest_path(g, feeder.source_bus, e) for e in essential))
    sub = g.subgraph(retained)
    key = essential | {b for b in retained if sub.degree(b) >= 3}
    assert set(r.nodes.bus) == key
    assert r.nodes.loc[0, "bus"] == feeder.source_bus
    assert r.n_lines == r.n_nodes - 1 == len(key) - 1
    retained_lines = {sub.edges[e]["line"] for e in sub.edges}
    assert set(r.line_map.index[kept]) == retained_lines
    degree = reduced_degree(r)
    for node, bus in r.nodes.bus.items():
        if bus not in essential:
            assert degree[node] >= 3
    np.testing.assert_array_equal(
        np.bincount(r.line_map[kept], minlength=r.n_lines), r.lines.n_original
    )
    check_chains(feeder, r)

    # Paths between any two buses map onto reduced lines covering the kept part of the path.
    a = data.draw(st.sampled_from(feeder.buses.index.tolist()))
    b = data.draw(st.sampled_from(feeder.buses.index.tolist()))
    path = feeder.path_lines(a, b)
    lines = r.path_lines(a, b)
    assert (lines >= 0).all()
    assert set(lines.tolist()) == {r.line_map[n] for n in path if r.line_map[n] >= 0}
    if a in key and b in key:
        covered = set(r.line_map.index[r.line_map.isin(lines)])
        assert covered == set(path)


def test_reduction_to_the_source_alone():
    # The only generator sits at the source and there are no loads: everything is pruned.
    buses = pd.DataFrame({"x": [0.0, 1.0, 2.0], "y": 0.0}, index=pd.Index([7, 8, 9], name="bus"))
    lines = pd.DataFrame(
        {
            "from_bus": [7, 8],
            "to_bus": [8, 9],
            "length_km": 0.1,
            "r_ohm": 0.01,
            "x_ohm": 0.01,
            "limit_kw": np.inf,
        },
        index=pd.Index(["A", "B"], name="line"),
    )
    loads = pd.DataFrame({"bus": pd.Series([], dtype=np.int64)}, index=pd.Index([], name="load"))
    feeder = Feeder("tiny", buses, lines, loads, 7, make_fleet([(7, 0.0, 1.0, 0.0, 0.0, 5.0)]))
    r = reduce_feeder(feeder)
    assert (r.n_nodes, r.n_lines) == (1, 0)
    assert r.line_map.tolist() == [-1, -1]
    assert r.bus_node.tolist() == [0, -1, -1]
    assert r.path_lines(7, 9).tolist() == []
