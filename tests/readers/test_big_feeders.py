"""The IEEE 8500-node feeder (its ``Master.dss`` and the run script as shipped) and EPRI's ckt24
read as OpenDSS reads them, and exact mode on them with a fleet.

Yardsticks: OpenDSSDirect.py's own compile of the same files (bus and load counts, total kW), and
a DC-OPF written here from OpenDSSDirect's own topology (networkx for the subtree below a limited
element, Clarabel for the QP): nothing of popdispatch's reduction, problem or OPF is used. Data
from ``../shared/feeders/opendss`` (or ``$POPDISPATCH_FEEDERS/opendss``); skipped when absent.
"""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pandas as pd
import pytest

from helpers import CKT24_OPEN_POINTS, FEEDERS_REASON, feeders_folder

opendssdirect = pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")
clarabel = pytest.importorskip("clarabel")
nx = pytest.importorskip("networkx")

from popdispatch.errors import MeshedError  # noqa: E402
from popdispatch.feeder.generators import make_fleet  # noqa: E402
from popdispatch.feeder.profiles import single_minute_profiles  # noqa: E402
from popdispatch.feeder.reduction import reduce_feeder  # noqa: E402
from popdispatch.game.problem import build_problem  # noqa: E402
from popdispatch.online import RunSettings, run_snapshot  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402
from popdispatch.readers.dss_script import compiled_script  # noqa: E402
from popdispatch.readers.opendss_direct import read_opendss_master  # noqa: E402

OPENDSS = feeders_folder() / "opendss"
IEEE8500 = OPENDSS / "ieee8500"
CKT24 = OPENDSS / "ckt24" / "master_ckt24.dss"
OPENED = tuple(f"open {element} 1" for element in CKT24_OPEN_POINTS)
needs_big = pytest.mark.skipif(not (IEEE8500 / "Master.dss").is_file() or not CKT24.is_file(),
                               reason=FEEDERS_REASON)  # fmt: skip


def ckt24_radial(folder) -> object:
    """A run script compiling ckt24 with its two loops opened where OpenDSS's own solution
    carries least (the reader's suggestion): the radial ckt24."""
    path = folder / "run_ckt24_radial.dss"
    path.write_text(f"Compile ({CKT24})\n" + "".join(f"Open {e} 1\n" for e in CKT24_OPEN_POINTS))
    return path


@functools.cache
def opendss_circuit(path, commands=()) -> dict:
    """OpenDSS's own view of ``path`` compiled natively (then ``commands``): buses, loads (name
    -> bus, kW) and the radial graph of its enabled, closed series elements. Once per process:
    ckt24's regulator keeps its debug-trace file open, so a second native compile fails."""
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{path}"')
    for command in commands:
        ctx.Text.Command(command)
    ctx.Text.Command("makebuslist")
    loads = {}
    for name in ctx.Loads.AllNames():
        ctx.Loads.Name(name)
        loads[name] = (ctx.CktElement.BusNames()[0].split(".")[0].lower(), ctx.Loads.kW())
    graph = nx.MultiGraph()
    graph.add_nodes_from(b.lower() for b in ctx.Circuit.AllBusNames())
    for element in ctx.Circuit.AllElementNames():
        ctx.Circuit.SetActiveElement(element)
        buses = [b.split(".")[0].lower() for b in ctx.CktElement.BusNames()]
        if ctx.CktElement.NumTerminals() < 2 or len(set(buses[:2])) < 2:
            continue
        if not ctx.CktElement.Enabled() or element.split(".")[0] in ("Fuse", "Relay"):
            continue
        phases = ctx.CktElement.NumPhases()
        opened = any(
            all(ctx.CktElement.IsOpen(t, k) for k in range(1, phases + 1))
            for t in range(1, ctx.CktElement.NumTerminals() + 1)
        )
        if not opened:
            graph.add_edge(buses[0], buses[1], element=element)
    source = ctx.Vsources.AllNames()[0]
    ctx.Vsources.Name(source)
    return {
        "buses": {b.lower() for b in ctx.Circuit.AllBusNames()},
        "loads": loads,
        "graph": graph,
        "source": ctx.CktElement.BusNames()[0].split(".")[0].lower(),
    }


def independent_opf(circuit: dict, fleet: pd.DataFrame, limit: tuple | None) -> np.ndarray:
    """The DC-OPF (kW) of ``fleet`` (``bus`` = OpenDSS bus name) on OpenDSS's own topology with
    ``limit = (bus, kW)``: the flow into ``bus`` from its parent bounded by ``kW``."""
    load_at: dict[str, float] = {}
    for bus, kw in circuit["loads"].values():
        load_at[bus] = load_at.get(bus, 0.0) + kw
    demand = sum(load_at.values()) / 1e3
    n = len(fleet)
    b, c = fleet.b.to_numpy(float), fleet.c.to_numpy(float)
    rows, rhs, cones = [np.ones((1, n))], [demand], [clarabel.ZeroConeT(1)]
    rows += [np.eye(n), -np.eye(n)]
    rhs += list(fleet.pmax_kw / 1e3) + list(-fleet.pmin_kw / 1e3)
    cones.append(clarabel.NonnegativeConeT(2 * n))
    if limit is not None:
        bus, kw = limit
        tree = nx.bfs_tree(nx.Graph(circuit["graph"]), circuit["source"])
        below = nx.descendants(tree, bus) | {bus}
        sub_load = sum(load_at.get(b_, 0.0) for b_ in below) / 1e3
        inside = np.array([g in below for g in fleet.bus], dtype=float)
        # flow = sub_load - inside @ p within [-U, U]
        rows += [-inside[None, :], inside[None, :]]
        rhs += [kw / 1e3 - sub_load, kw / 1e3 + sub_load]
        cones.append(clarabel.NonnegativeConeT(2))
    from scipy import sparse

    a = sparse.csc_matrix(np.vstack(rows))
    p = sparse.csc_matrix(np.diag(2 * c))
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    solution = clarabel.DefaultSolver(p, b, a, np.array(rhs), cones, settings).solve()
    assert str(solution.status) == "Solved"
    return np.asarray(solution.x) * 1e3


@needs_big
@pytest.mark.parametrize("name", ["Master.dss", "Run_8500Node.dss"])
def test_ieee8500_reads_with_opendss_own_counts_and_totals(name):
    own = opendss_circuit(IEEE8500 / "Master.dss")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # as shipped: no file missing, nothing to say
        f = read_opendss_master(IEEE8500 / name)
    if name.startswith("Run"):  # compiled in place: its Compile (master.dss), Show, Plot ...
        with compiled_script(IEEE8500 / name) as script:
            assert {"solve", "show", "export", "plot"} <= set(script.skipped)
    assert set(f.buses.name) == own["buses"] and len(f.buses) == 4876
    assert len(f.lines) == len(f.buses) - 1  # radial (the Feeder checked it)
    assert len(f.loads) == len(own["loads"]) == 1177
    kw = sum(v for _, v in own["loads"].values())
    assert f.loads.p_kw.sum() == pytest.approx(kw, rel=1e-12)
    assert f.loads.p_kw.sum() == pytest.approx(10773.17, abs=0.01)
    bus_of = dict(zip(f.buses.index, f.buses.name, strict=True))
    assert {name: bus_of[b] for name, b in f.loads.bus.items()} == {
        name: bus for name, (bus, _) in own["loads"].items()
    }
    kinds = f.lines.kind.value_counts().to_dict()
    assert kinds["reactor"] == 1 and kinds["transformer"] == 1178  # 1177 split-phase units
    reactor = f.lines.loc["Reactor.hvmv_sub_hsb"]
    assert reactor.x_ohm == pytest.approx(14.7983, rel=1e-4)  # its x= expression, at 115 kV
    assert f.buses.loc[f.source_bus, "name"] == "sourcebus"


@needs_big
def test_ckt24_is_meshed_as_shipped_and_names_where_to_open():
    with pytest.raises(MeshedError) as exc:
        read_opendss_master(CKT24)
    message = str(exc.value)
    assert "closes a loop" in message and "\n" not in message
    assert any(f"`Open {e} 1`" in message for e in CKT24_OPEN_POINTS)


@needs_big
def test_ckt24_radial_reads_with_opendss_own_totals(tmp_path):
    own = opendss_circuit(CKT24, OPENED)
    f = read_opendss_master(ckt24_radial(tmp_path))
    assert set(f.buses.name) == own["buses"] and len(f.buses) == 6058
    assert len(f.loads) == len(own["loads"]) == 3891
    kw = sum(v for _, v in own["loads"].values())
    assert f.loads.p_kw.sum() == pytest.approx(kw, rel=1e-12)
    assert f.loads.p_kw.sum() == pytest.approx(50941.74, abs=0.01)
    # parallel and phase-split lines merged into one branch each
    assert "05410_339741oh_1+05410_339741oh_2" in f.lines.index
    # every load follows a yearly shape of 8760 hours
    assert set(f.loads.yearly) == {"ls_phasea", "ls_phaseb", "ls_phasec", "ls_threephase",
                                   "other_bus_load"}  # fmt: skip
    assert {len(s.mult) for s in f.shapes.values()} == {8760}


def _fleet(names: list[str], source: str) -> pd.DataFrame:
    """A priced source and cheap DGs at the named buses (``bus`` = OpenDSS name)."""
    rows = [(source, 0.0, 60.0, 0.002, 0.0, 80000.0)]
    rows += [(bus, 0.0, 10.0 + 5 * k, 0.01, 0.0, 900.0) for k, bus in enumerate(names)]
    table = make_fleet([(0, *r[1:]) for r in rows], [f"G{k}" for k in range(len(rows))])
    table["bus"] = [r[0] for r in rows]
    return table


def _exact_vs_independent(path, fleet, limit, ratings=False, native=None):
    feeder = read_opendss_master(path, fleet=fleet, ratings=ratings)
    if limit is not None:
        bus, kw = limit
        child = feeder.bus_id(bus)
        parent = feeder.buses.index[feeder.bus_tree().parent[feeder.buses.index.get_loc(child)]]
        lines = feeder.path_lines(int(parent), child)
        feeder = feeder.with_line_limits(pd.Series(kw, index=lines))
    profiles = single_minute_profiles(1, feeder.loads.p_kw, feeder.name)
    problem = build_problem(reduce_feeder(feeder), profiles)
    opf = solve_opf(problem, 1)
    snapshot = run_snapshot(problem, 1, RunSettings(mode="exact"))
    theirs = independent_opf(native or opendss_circuit(path), fleet, limit)
    return problem, opf, snapshot, theirs


@needs_big
@pytest.mark.parametrize("limit", [None, ("l3312692", 200.0)], ids=["free", "binding"])
def test_ieee8500_exact_mode_equals_an_independent_dc_opf(limit):
    fleet = _fleet(["l3312692", "l3029183", "m1026736"], "sourcebus")
    problem, opf, snapshot, theirs = _exact_vs_independent(IEEE8500 / "Master.dss", fleet, limit)
    tolerance = max(1e-6 * opf.demand_kw, 1e-3)
    assert snapshot.status == "converged"
    np.testing.assert_allclose(opf.p_kw, theirs, atol=tolerance)
    np.testing.assert_allclose(snapshot.setpoints_kw, theirs, atol=tolerance)
    assert (np.abs(opf.line_price) > 1e-3).any() == (limit is not None)


@needs_big
@pytest.mark.parametrize("limit", [None, ("n274191", 300.0)], ids=["free", "binding"])
def test_ckt24_exact_mode_equals_an_independent_dc_opf(tmp_path, limit):
    fleet = _fleet(["n274191", "n274364", "n283927"], "sourcebus")
    path = ckt24_radial(tmp_path)
    native = opendss_circuit(CKT24, OPENED)
    problem, opf, snapshot, theirs = _exact_vs_independent(path, fleet, limit, native=native)
    tolerance = max(1e-6 * opf.demand_kw, 1e-3)
    assert snapshot.status == "converged"
    np.testing.assert_allclose(opf.p_kw, theirs, atol=tolerance)
    np.testing.assert_allclose(snapshot.setpoints_kw, theirs, atol=tolerance)
    assert (np.abs(opf.line_price) > 1e-3).any() == (limit is not None)
