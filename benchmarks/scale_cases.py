"""The problems of the exact-mode scale study (issue 12): every built-in case, the MATPOWER
radial cases, synthetic feeders and a feeder scaled by 100, each without and with a binding
limit. Shared by ``benchmarks/bench_scale.py``, ``tests/test_exact_mode.py`` and
``tests/modes/test_price_law.py``.

Cases without a priced fleet get :func:`test_fleet`: the source and three DGs at the buses a
third, two thirds and all the way down the deepest path, with distinct costs and capacities
proportional to the demand (so the optimum uses all of them on any feeder size). The binding
variant (:func:`with_binding_limit`) limits the line above the DG that produces most in the
unconstrained DC-OPF to half of that line's unconstrained flow.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.feeder import Feeder
from popdispatch.feeder.generators import FLEET_COLUMNS, make_fleet
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.feeder.synthetic import synthetic_feeder, synthetic_load_kw
from popdispatch.feeder.tree import depths
from popdispatch.game.problem import DispatchProblem, build_problem_from_loads
from popdispatch.opf import solve_opf

#: ``$POPDISPATCH_FEEDERS/matpower``, else ``../shared/feeders/matpower`` beside the checkout.
MATPOWER_DIR = (
    Path(os.environ.get("POPDISPATCH_FEEDERS") or Path(__file__).resolve().parents[2] / "shared"
         / "feeders") / "matpower"
)  # fmt: skip
MATPOWER_CASES = ("case22", "case33bw", "case69", "case85")
#: Built-in cases of the study (``popdispatch.cases.builtin``; SimBench when installed is extra).
BUILT_IN = (
    "kerber-landnetz-freileitung-1", "kerber-landnetz-kabel-2", "kerber-dorfnetz",
    "kerber-vorstadtnetz-kabel-1", "dickert-lv-long", "cigre-lv-residential", "case33bw",
)  # fmt: skip


@dataclass(frozen=True)
class ScaleCase:
    """One problem of the study: its name, bus count and builder (one time step, minute 1)."""

    name: str
    buses: int
    build: Callable[[], DispatchProblem]


def test_fleet(feeder: Feeder) -> pd.DataFrame:
    """Source and three DGs down the deepest path (see the module docstring)."""
    tree = feeder.bus_tree()
    depth = depths(tree)
    far = int(np.argmax(depth))
    path = [far]
    while tree.parent[path[-1]] >= 0:
        path.append(int(tree.parent[path[-1]]))
    path = path[::-1]  # source .. far
    buses = feeder.buses.index
    at = [buses[path[max(1, len(path) * k // 3)]] for k in (1, 2)] + [buses[far]]
    mw = float(feeder.loads.p_kw.sum()) / 1000.0
    rows = [
        (feeder.source_bus, 0.0, 20.0, 2.0 / mw, 0.0, 2000.0 * mw),
        (at[0], 0.0, 12.0, 10.0 / mw, 0.0, 250.0 * mw),
        (at[1], 0.0, 14.0, 20.0 / mw, 0.0, 200.0 * mw),
        (at[2], 0.0, 10.0, 40.0 / mw, 0.0, 150.0 * mw),
    ]
    seen: dict = {}
    for row in rows:  # one generator per bus (short paths may repeat a bus)
        seen.setdefault(row[0], row)
    if all(isinstance(bus, (int, np.integer)) for bus in seen):
        return make_fleet(seen.values())
    table = pd.DataFrame(list(seen.values()), columns=FLEET_COLUMNS)  # OpenDSS bus names
    table.index = pd.Index([f"G{bus}" for bus in seen], name="generator")
    return table


def problem_of(feeder: Feeder, load_kw: np.ndarray | None = None) -> DispatchProblem:
    """One time step of ``feeder`` at its own loads (or ``load_kw`` per load, kW)."""
    load = feeder.loads.p_kw.to_numpy(float) if load_kw is None else load_kw
    return build_problem_from_loads(reduce_feeder(feeder), load[None, :], feeder.name)


def with_binding_limit(feeder: Feeder) -> Feeder:
    """``feeder`` without its own ratings and one line above a DG limited halfway between its
    flow in the unconstrained DC-OPF and the smallest flow the DGs below it can reach (the line
    where that gap is largest), so the limit binds and is feasible."""
    free = unlimited(feeder)
    p_kw = solve_opf(problem_of(free), 1).p_kw
    gens = feeder.generators
    tree = feeder.bus_tree()
    buses = feeder.buses.index
    nodes = buses.get_indexer(gens.bus)
    load = np.zeros(len(buses))
    np.add.at(load, buses.get_indexer(feeder.loads.bus), feeder.loads.p_kw.to_numpy(float))
    best, chosen = 0.0, None
    for i, node in enumerate(nodes):
        if gens.bus.iloc[i] == feeder.source_bus:
            continue
        flow, least = _subtree_flow(tree, node, load, nodes, p_kw, gens)
        if abs(flow) - least > best:
            best, chosen = abs(flow) - least, (node, 0.5 * (abs(flow) + least))
    if chosen is None:
        raise ValueError(f"{feeder.name}: no DG line can be made binding")
    node, limit_kw = chosen
    line = feeder.lines.index[int(tree.parent_line[node])]
    return free.with_line_limits(pd.Series({line: limit_kw}))


def _subtree_flow(tree, node, load, gen_nodes, p_kw, gens) -> tuple[float, float]:
    """Flow (kW, towards the subtree) on the line above ``node`` at set points ``p_kw``, and
    the smallest ``|flow|`` the generators in the subtree can reach within their limits."""
    start, stop = tree.start[node], tree.start[node] + tree.size[node]
    inside = np.zeros(len(load), dtype=bool)
    inside[tree.preorder[start:stop]] = True
    mine = inside[gen_nodes]
    demand = float(load[inside].sum())
    flow = demand - float(p_kw[mine].sum())
    low = demand - float(gens.pmax_kw.to_numpy()[mine].sum())
    high = demand - float(gens.pmin_kw.to_numpy()[mine].sum())
    least = 0.0 if low <= 0.0 <= high else min(abs(low), abs(high))
    return flow, least


def unlimited(feeder: Feeder) -> Feeder:
    """``feeder`` without any line limit."""
    return replace(feeder, lines=feeder.lines.assign(limit_kw=np.inf))


def scaled(problem: DispatchProblem, factor: float) -> DispatchProblem:
    """``problem`` with loads, generator limits and line limits times ``factor`` (costs kept)."""
    return replace(
        problem, demand=problem.demand * factor, load_flow=problem.load_flow * factor,
        pmin=problem.pmin * factor, pmax=problem.pmax * factor, limit=problem.limit * factor,
    )  # fmt: skip


def synthetic(n_buses: int, n_generators: int, factor: float = 1.0) -> DispatchProblem:
    """``synthetic_feeder(n_buses, n_generators, seed=1, limited_lines=1.0)`` at its peak load,
    times ``factor``."""
    feeder = synthetic_feeder(n_buses, n_generators, seed=1, limited_lines=1.0)
    load = synthetic_load_kw(feeder).loc[feeder.loads.index].to_numpy()
    problem = build_problem_from_loads(reduce_feeder(feeder), load[None, :], "synthetic peak")
    return problem if factor == 1.0 else scaled(problem, factor)


def _case_feeder(name: str) -> Feeder:
    from popdispatch.cases import builtin as cases

    feeder = cases.CASES[name].loader(None)  # no fleet of its own: described
    return cases.load_case(name, fleet=test_fleet(feeder))


def _matpower_feeder(name: str) -> Feeder:
    from popdispatch.readers import read_matpower

    path = MATPOWER_DIR / f"{name}.m"
    placeholder = read_matpower(path, fleet=make_fleet([(1, 0.0, 1.0, 0.0, 0.0, 1.0)]))
    return read_matpower(path, fleet=test_fleet(placeholder))


def matpower_missing(name: str) -> str | None:
    """Why case ``name`` cannot be built here (a MATPOWER case without its file), else None."""
    if name.startswith("matpower:") and not (MATPOWER_DIR / f"{name[9:]}.m").is_file():
        return f"MATPOWER case {name[9:]}.m not found in {MATPOWER_DIR} (set POPDISPATCH_FEEDERS)"
    return None


def network_cases(matpower: bool = True) -> Iterator[tuple[str, Callable[[], Feeder]]]:
    """``(name, feeder builder)`` of the built-in cases and (if present) the MATPOWER files."""
    for name in BUILT_IN:
        yield name, lambda n=name: _case_feeder(n)
    if matpower:  # building one needs MATPOWER_DIR (see matpower_missing)
        for name in MATPOWER_CASES:
            yield f"matpower:{name}", lambda n=name: _matpower_feeder(n)


def all_cases(
    sizes: tuple[int, ...] = (1000, 10000, 100000),
) -> Iterator[tuple[str, str, Callable[[], DispatchProblem]]]:
    """``(name, limits, problem builder)`` for every case of the study: each network without
    and with a binding limit, the synthetic feeders (10 DGs; 1000 at 100k buses) and the 1k
    feeder times 100."""
    from popdispatch.scenarios import CONGESTION_PATH, elv_problem

    yield "ieee-elv", "none", elv_problem  # minute 566's loads in every row
    yield "ieee-elv", "binding", lambda: elv_problem(limits=[CONGESTION_PATH])
    for name, build in network_cases():
        yield name, "none", lambda b=build: problem_of(unlimited(b()))
        yield name, "binding", lambda b=build: problem_of(with_binding_limit(b()))
    for n in sizes:
        gens = 1000 if n >= 100000 else 10
        yield f"synthetic-{n // 1000}k", "every line", lambda n=n, g=gens: synthetic(n, g)
        if n == 1000:
            yield "synthetic-1k x100", "every line", lambda n=n, g=gens: synthetic(n, g, 100.0)
