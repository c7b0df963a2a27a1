"""Synthetic radial feeders: seeded, exact sizes, valid, feasible, reducible (small sizes only)."""

import networkx as nx
import numpy as np
import pandas as pd
import pytest

from popdispatch.errors import FeederError
from popdispatch.feeder import (
    Feeder,
    depths,
    line_flows,
    reduce_feeder,
    synthetic_feeder,
    synthetic_load_kw,
    synthetic_profiles,
)
from popdispatch.feeder.generators import FLEET_COLUMNS
from popdispatch.feeder.model import LINE_COLUMNS, validate_feeder
from popdispatch.feeder.synthetic import DEMAND_SHARE, DEVIATION, daily_shape

from helpers import random_feeder

N_BUSES, N_GENS = 2000, 20


@pytest.fixture(scope="module")
def feeder():
    return synthetic_feeder(N_BUSES, N_GENS, seed=7)


@pytest.fixture(scope="module")
def limited():
    return synthetic_feeder(N_BUSES, N_GENS, seed=7, limited_lines=0.5)


def tables(f: Feeder):
    return f.buses, f.lines, f.loads, f.generators


def bus_injection_kw(f: Feeder, load_kw: np.ndarray, gen_kw: np.ndarray) -> np.ndarray:
    """Injections (kW, generation minus load) per bus position; leading axes of load_kw kept."""
    index = f.buses.index
    injection = np.zeros(np.shape(load_kw)[:-1] + (len(index),))
    np.add.at(injection.T, index.get_indexer(f.loads.bus), -np.moveaxis(load_kw, -1, 0))
    np.add.at(injection.T, index.get_indexer(f.generators.bus), np.moveaxis(gen_kw, -1, 0))
    return injection


def proportional_kw(f: Feeder, demand_kw: np.ndarray) -> np.ndarray:
    """Every generator at the same share of its pmax_kw, matching demand (kW, last axis gens)."""
    pmax = f.generators.pmax_kw.to_numpy()
    return np.multiply.outer(np.asarray(demand_kw), pmax / pmax.sum())


def economic_dispatch_kw(f: Feeder, demand_kw: float) -> np.ndarray:
    """Unconstrained economic dispatch (kW) of the fleet, by bisection on the marginal price."""
    b, c = f.generators.b.to_numpy(), f.generators.c.to_numpy()
    pmax_mw = f.generators.pmax_kw.to_numpy() / 1000
    low, high = 0.0, 1e4
    for _ in range(200):
        price = (low + high) / 2
        p_mw = np.clip((price - b) / (2 * c), 0.0, pmax_mw)
        low, high = (price, high) if p_mw.sum() * 1000 < demand_kw else (low, price)
    return p_mw * 1000


# --- determinism ---------------------------------------------------------------------------------


def test_same_seed_same_tables(feeder):
    again = synthetic_feeder(N_BUSES, N_GENS, seed=7)
    assert again.name == feeder.name and again.source_bus == feeder.source_bus == 1
    for ours, theirs in zip(tables(feeder), tables(again), strict=True):
        pd.testing.assert_frame_equal(ours, theirs, check_exact=True)


def test_different_seed_different_tables(feeder):
    other = synthetic_feeder(N_BUSES, N_GENS, seed=8)
    assert other.name != feeder.name
    assert not np.array_equal(other.lines.from_bus, feeder.lines.from_bus)
    assert not np.array_equal(other.lines.length_km, feeder.lines.length_km)
    assert not np.array_equal(other.loads.bus, feeder.loads.bus)
    assert not np.array_equal(other.generators.bus, feeder.generators.bus)
    assert not np.array_equal(other.generators.b, feeder.generators.b)
    assert not np.allclose(other.buses.x, feeder.buses.x)


def test_limits_change_nothing_else(feeder, limited):
    assert limited.name == feeder.name
    for ours, theirs in zip(tables(feeder), tables(limited), strict=True):
        pd.testing.assert_frame_equal(
            ours.drop(columns="limit_kw", errors="ignore"),
            theirs.drop(columns="limit_kw", errors="ignore"),
            check_exact=True,
        )
    assert np.isinf(feeder.lines.limit_kw).all()
    assert np.isfinite(limited.lines.limit_kw).any()


# --- sizes and validity --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("n_buses", "n_gens"), [(1000, 10), (N_BUSES, N_GENS), (120, 120), (2, 1), (7, 3)]
)
def test_sizes_and_validity(n_buses, n_gens):
    f = synthetic_feeder(n_buses, n_gens, seed=1)
    assert f.buses.index.tolist() == list(range(1, n_buses + 1))
    assert f.source_bus == 1
    assert len(f.lines) == n_buses - 1 and f.lines.index.is_unique
    assert len(f.generators) == n_gens
    assert len(f.loads) == max(1, round(n_buses / 3))
    assert list(f.lines.columns) == LINE_COLUMNS
    assert list(f.loads.columns) == ["bus", "peak_kw"]
    assert list(f.generators.columns) == FLEET_COLUMNS
    validate_feeder(f)
    assert nx.is_tree(f.graph())  # independent check of radiality
    assert f.generators.bus.is_unique and f.loads.bus.is_unique
    assert f.loads.index.is_unique and f.generators.index.is_unique
    assert (f.loads.bus != f.source_bus).all()
    assert np.isfinite(f.buses.to_numpy()).all()


def test_plausible_lines_and_costs(feeder):
    lines, fleet = feeder.lines, feeder.generators
    assert lines.length_km.between(0.005, 0.1).all()
    ohm_per_km = lines.r_ohm / lines.length_km
    assert ohm_per_km.between(0.1, 1.2).all()
    assert (lines.x_ohm / lines.length_km).between(0.07, 0.1).all()
    assert ohm_per_km.nunique() > 3  # trunk and lateral cables
    assert (fleet.a == 0).all() and (fleet.pmin_kw == 0).all()
    assert fleet.b.between(1, 5).all() and fleet.c.between(0.005, 0.03).all()
    assert fleet.pmax_kw.between(5, 20).all()
    assert fleet.b.nunique() > len(fleet) / 2  # drawn, not constant
    # Coordinates (m) follow the lines: each bus sits one line length from its parent.
    xy = feeder.buses[["x", "y"]]
    step = xy.loc[lines.to_bus].to_numpy() - xy.loc[lines.from_bus].to_numpy()
    np.testing.assert_allclose(np.hypot(*step.T), 1000 * lines.length_km, rtol=1e-9)


def test_looks_like_a_feeder_not_a_random_tree(feeder):
    deep = depths(feeder.bus_tree())
    uniform = random_feeder(np.random.default_rng(7), N_BUSES, N_GENS)
    shallow = depths(uniform.bus_tree())
    assert deep.max() > 3 * shallow.max()  # about 100 vs 20 lines at 2000 buses
    children = np.bincount(feeder.lines.from_bus, minlength=N_BUSES + 1)[1:]
    assert 0.6 < (children == 1).mean() < 0.85  # mostly chains, like the IEEE LV feeder
    assert (children == 0).mean() < 0.25
    assert children[0] >= 3  # trunks leave the source


def test_capacity_above_peak_demand(feeder):
    peak = synthetic_load_kw(feeder)
    capacity = feeder.generators.pmax_kw.sum()
    assert peak.sum() == pytest.approx(DEMAND_SHARE * capacity, rel=1e-12)
    assert peak.sum() < 0.75 * capacity
    assert (peak > 0).all()
    pd.testing.assert_index_equal(peak.index, feeder.loads.index)
    np.testing.assert_allclose(synthetic_load_kw(feeder, 0.25), 0.25 * peak, rtol=1e-15)


# --- reduction -------------------------------------------------------------------------------


def test_reduction_conserves_load_and_flows(limited):
    r = reduce_feeder(limited)
    load_kw = synthetic_load_kw(limited).to_numpy()
    nodal = r.load_injection_kw(load_kw)
    assert nodal.sum() == pytest.approx(load_kw.sum(), rel=1e-12)
    assert r.n_nodes < N_BUSES and r.n_lines == r.n_nodes - 1
    assert set(limited.generators.bus) <= set(r.nodes.bus)
    # Flows of the economic dispatch: every kept original line carries its reduced line's flow.
    gen_kw = economic_dispatch_kw(limited, load_kw.sum())
    original = line_flows(limited.bus_tree(), bus_injection_kw(limited, load_kw, gen_kw))
    injection = -nodal
    np.add.at(injection, r.generators.node.to_numpy(), gen_kw)
    reduced = line_flows(r.tree, injection)
    kept = r.line_map.to_numpy() >= 0
    np.testing.assert_allclose(original[kept], reduced[r.line_map[kept]], atol=1e-9)
    np.testing.assert_allclose(original[~kept], 0.0, atol=1e-9)
    # Lines leaving the source carry what the source bus injects: its own generation, or the
    # whole load when no generator runs.
    leaving = (r.lines.from_node == 0).to_numpy()
    at_source = gen_kw[(limited.generators.bus == 1).to_numpy()].sum()
    assert reduced[leaving].sum() == pytest.approx(at_source, abs=1e-9)
    no_generation = line_flows(r.tree, -nodal)
    assert no_generation[leaving].sum() == pytest.approx(load_kw.sum(), rel=1e-12)
    # Each reduced line's limit is the smallest limit of its chain.
    chain_min = limited.lines.limit_kw[kept].groupby(r.line_map[kept]).min()
    np.testing.assert_array_equal(r.lines.limit_kw, chain_min.sort_index())


# --- line limits ---------------------------------------------------------------------------------


@pytest.mark.parametrize("limited_lines", [0, 1, 25, 0.1, 1.0])
def test_limited_lines_count(limited_lines):
    f = synthetic_feeder(1000, 10, seed=3, limited_lines=limited_lines)
    tree = f.bus_tree()
    capacity = np.bincount(
        f.buses.index.get_indexer(f.generators.bus), weights=f.generators.pmax_kw, minlength=1000
    )
    from popdispatch.feeder import subtree_sums

    has_generator_below = subtree_sums(tree, capacity)[tree.line_child] > 0
    limit = f.lines.limit_kw.to_numpy()
    finite = np.isfinite(limit)
    if isinstance(limited_lines, float):
        assert finite.sum() == round(limited_lines * has_generator_below.sum())
    else:
        assert finite.sum() == limited_lines
    assert (limit[finite] > 0).all()
    assert np.isinf(limit[~finite]).all()
    assert has_generator_below[finite].all()


def test_limits_are_feasible_and_can_bind(limited):
    tree = limited.bus_tree()
    limit = limited.lines.limit_kw.to_numpy()
    finite = np.isfinite(limit)
    assert finite.sum() > 20
    # The proportional dispatch meets every limit at the peak ...
    load_kw = synthetic_load_kw(limited).to_numpy()
    gen_kw = proportional_kw(limited, load_kw.sum())
    flows = line_flows(tree, bus_injection_kw(limited, load_kw, gen_kw))
    assert (np.abs(flows[finite]) <= limit[finite]).all()
    # ... while the unconstrained economic dispatch overloads some limited lines.
    cheap = economic_dispatch_kw(limited, load_kw.sum())
    assert cheap.sum() == pytest.approx(load_kw.sum())
    flows = line_flows(tree, bus_injection_kw(limited, load_kw, cheap))
    assert (np.abs(flows[finite]) > limit[finite]).sum() >= 3


def test_limits_hold_every_minute_of_a_synthetic_day():
    f = synthetic_feeder(1000, 10, seed=4, limited_lines=1.0)
    profiles = synthetic_profiles(f, seed=11)
    load_kw = profiles.kw.to_numpy()
    gen_kw = proportional_kw(f, load_kw.sum(axis=1))
    assert (gen_kw.sum(axis=1) <= f.generators.pmax_kw.sum()).all()
    finite = np.isfinite(f.lines.limit_kw.to_numpy())
    flows = line_flows(f.bus_tree(), bus_injection_kw(f, load_kw, gen_kw))[:, finite]
    ratio = np.abs(flows) / f.lines.limit_kw.to_numpy()[finite]
    assert ratio.max() <= 1.0
    assert ratio.max() > 0.5  # the limits are not absurdly loose either


# --- profiles and snapshots --------------------------------------------------------------------


def test_profiles_shape_bounds_and_seeds():
    f = synthetic_feeder(600, 6, seed=2)
    day = synthetic_profiles(f, seed=5)
    assert day.kw.shape == (1440, len(f.loads))
    assert day.kw.index.tolist() == list(range(1, 1441))
    pd.testing.assert_index_equal(day.kw.columns, f.loads.index)
    assert "seed 5" in day.source
    per_unit = day.kw.to_numpy() / f.loads.peak_kw.to_numpy()
    assert (per_unit >= 0).all()
    assert np.abs(per_unit - daily_shape()[:, None]).max() <= DEVIATION + 1e-12
    assert per_unit.std(axis=1).mean() > 0.05  # loads differ from each other
    total = day.total_kw()
    assert total.max() <= (1 + DEVIATION) * f.loads.peak_kw.sum()
    assert total.idxmax() > 17 * 60 and total.idxmin() < 7 * 60  # evening peak, night trough
    pd.testing.assert_frame_equal(synthetic_profiles(f, seed=5).kw, day.kw, check_exact=True)
    assert not np.allclose(synthetic_profiles(f, seed=6).kw, day.kw)


def test_daily_shape():
    shape = daily_shape()
    assert shape.shape == (1440,) and shape.max() == 1.0
    assert 0.25 < shape.min() < 0.4
    assert abs(shape[0] - shape[-1]) < 0.01  # periodic over midnight


# --- errors -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"n_buses": 1}, "at least 2 buses"),
        ({"n_generators": 0}, "n_generators"),
        ({"n_generators": 101}, "n_generators"),
        ({"load_fraction": 0.0}, "load_fraction"),
        ({"demand_share": 0.9}, "demand_share"),
        ({"limit_factor": 0.5}, "limit_factor"),
        ({"n_trunks": 100}, "n_trunks"),
        ({"limited_lines": 10**6}, "limited_lines"),
        ({"limited_lines": -1}, "limited_lines"),
        ({"limited_lines": 1.5}, "limited_lines"),
    ],
)
def test_bad_arguments(kwargs, message):
    arguments = {"n_buses": 100, "n_generators": 5} | kwargs
    with pytest.raises(ValueError, match=message):
        synthetic_feeder(**arguments)


def test_limited_lines_is_not_a_bool():
    with pytest.raises(TypeError, match="bool"):
        synthetic_feeder(100, 5, limited_lines=True)


def test_loads_and_profiles_need_peaks():
    plain = random_feeder(np.random.default_rng(0), 50, 3)
    with pytest.raises(ValueError, match="peak_kw"):
        synthetic_load_kw(plain)
    with pytest.raises(ValueError, match="peak_kw"):
        synthetic_profiles(plain)
    with pytest.raises(ValueError, match="level"):
        synthetic_load_kw(synthetic_feeder(50, 3), 1.5)
    with pytest.raises(ValueError, match="max_loads"):
        synthetic_profiles(synthetic_feeder(300, 3), max_loads=50)


# --- validation errors on a big feeder (vectorised paths) ----------------------------------


def _with_lines(f: Feeder, lines: pd.DataFrame) -> tuple:
    return (f.name, f.buses, lines, f.loads, f.source_bus, f.generators)


def test_big_feeder_loop_is_named(feeder):
    loop = pd.DataFrame(
        {"from_bus": [1500], "to_bus": [900], "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001},
        index=pd.Index(["LOOPER"], name="line"),
    ).assign(limit_kw=np.inf)
    with pytest.raises(FeederError, match="closes a loop") as exc:
        Feeder(*_with_lines(feeder, pd.concat([feeder.lines, loop])))
    message = str(exc.value)
    assert "'LOOPER'" in message and "1500" in message and "900" in message
    loop_buses = [int(b) for b in message.split("[")[1].split("]")[0].split(",")]
    path = feeder.path_lines(1500, 900)
    assert len(loop_buses) == len(path) + 1  # the tree path plus the closing line
    assert loop_buses[0] == 1500 and loop_buses[-1] == 900


def test_big_feeder_parallel_and_disconnected(feeder):
    twin = feeder.lines.iloc[[1200]].rename(index=lambda _: "TWIN")
    twin[["from_bus", "to_bus"]] = twin[["to_bus", "from_bus"]].to_numpy()
    with pytest.raises(FeederError, match="'TWIN' is parallel"):
        Feeder(*_with_lines(feeder, pd.concat([feeder.lines, twin])))
    # Drop the line feeding bus 1400: its subtree is cut off; the lowest bus id there is named.
    cut = feeder.lines.to_bus == 1400
    tree = feeder.bus_tree()
    position = feeder.buses.index.get_loc(1400)
    below = tree.preorder[tree.start[position] : tree.start[position] + tree.size[position]]
    lonely = feeder.buses.index[np.sort(below)[0]]
    with pytest.raises(FeederError, match=f"bus {lonely} is not connected"):
        Feeder(*_with_lines(feeder, feeder.lines[~cut]))
