"""An OpenDSS circuit with a closed tie (a loop) runs in MATPOWER's DC model: the commands
read it through OpenDSS itself and land on pandapower's ``rundcopp`` of the same lines built
here from the script's own numbers (an independent DC-OPF), with the distance certificate."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings

import numpy as np
import pytest

pytest.importorskip("opendssdirect", reason='the opendss extra: pip install "popdispatch[opendss]"')
pp = pytest.importorskip("pandapower")

KV = 12.47
R1, X1 = 0.3, 0.6  # ohm/km, the linecode's positive sequence
#: (name, from bus, to bus, km): a ring src-a-b-c-a, its tie c-a closed.
LINES = [("sa", "src", "a", 2.0), ("ab", "a", "b", 3.0), ("bc", "b", "c", 2.0),
         ("tie", "c", "a", 4.0)]  # fmt: skip
LOADS_KW = {"b": 3000.0, "c": 2000.0}
#: name, bus, b EUR/MWh, c EUR/MW^2h, pmax kW
FLEET = [("gsrc", "src", 60.0, 1.0, 10000.0), ("ga", "a", 20.0, 5.0, 3000.0),
         ("gc", "c", 30.0, 3.0, 3000.0)]  # fmt: skip


def write_circuit(folder):
    lines = "".join(f"New Line.{n} bus1={a} bus2={b} linecode=lc length={km} units=km\n"
                    for n, a, b, km in LINES)  # fmt: skip
    loads = "".join(f"New Load.l{bus} bus1={bus} phases=3 kV={KV} kW={kw} pf=1\n"
                    for bus, kw in LOADS_KW.items())  # fmt: skip
    (folder / "ring.dss").write_text(
        "Clear\n"
        f"New Circuit.ring basekv={KV} bus1=src pu=1.0\n"
        f"New Linecode.lc nphases=3 r1={R1} x1={X1} r0={3 * R1} x0={3 * X1} units=km\n"
        + lines + loads + f"Set voltagebases=[{KV}]\nCalcvoltagebases\n"
    )
    rows = "".join(f"{bus},{name},0,{b},{c},0,{pmax}\n" for name, bus, b, c, pmax in FLEET)
    (folder / "fleet.csv").write_text("bus,name,a,b,c,pmin_kw,pmax_kw\n" + rows)
    return folder / "ring.dss", folder / "fleet.csv"


def rundcopp(limit_kw: dict[str, float]):
    """pandapower's DC-OPF of the same ring: set points (kW, FLEET order) and line flows."""
    net = pp.create_empty_network(sn_mva=1.0)
    bus = {name: pp.create_bus(net, vn_kv=KV, name=name) for name in ("src", "a", "b", "c")}
    for name, a, b, km in LINES:
        rating_ka = limit_kw.get(name, 1e6) / (np.sqrt(3) * KV) / 1e3
        pp.create_line_from_parameters(net, bus[a], bus[b], km, R1, X1, 0.0, 1e3, name=name,
                                       max_loading_percent=100.0 * rating_ka / 1e3)  # fmt: skip
    for bus_name, kw in LOADS_KW.items():
        pp.create_load(net, bus[bus_name], p_mw=kw / 1e3, controllable=False)
    gsrc = FLEET[0]
    grid = pp.create_ext_grid(net, bus["src"], min_p_mw=0.0, max_p_mw=gsrc[4] / 1e3)
    pp.create_poly_cost(net, grid, "ext_grid", cp1_eur_per_mw=gsrc[2], cp2_eur_per_mw2=gsrc[3])
    for _, bus_name, b, c, pmax in FLEET[1:]:
        g = pp.create_sgen(net, bus[bus_name], p_mw=0.0, min_p_mw=0.0, max_p_mw=pmax / 1e3,
                           controllable=True)  # fmt: skip
        pp.create_poly_cost(net, g, "sgen", cp1_eur_per_mw=b, cp2_eur_per_mw2=c)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    assert net.OPF_converged
    setpoints = np.r_[net.res_ext_grid.p_mw.to_numpy(), net.res_sgen.p_mw.to_numpy()] * 1e3
    return setpoints, dict(zip(net.line.name, net.res_line.p_from_mw * 1e3, strict=True))


def popdispatch(*args: str) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "popdispatch.cli", *args], capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return done


def test_a_closed_tie_runs_on_the_dc_model_and_lands_on_rundcopp(tmp_path):
    ring, fleet = write_circuit(tmp_path)
    _, free_flows = rundcopp({})
    limit = 0.9 * abs(free_flows["ab"])  # the line a-b below its unconstrained flow
    reference, flows = rundcopp({"ab": limit})
    assert abs(abs(flows["ab"]) - limit) < 1e-3  # it binds in pandapower's optimum
    common = ["--net", str(ring), "--fleet", str(fleet), "--no-ratings", "--minute", "1",
              "--limit", f"a:b={limit:.6f}"]  # fmt: skip
    done = popdispatch("snapshot", *common, "--mode", "exact", "--json")
    assert "ring is meshed" in done.stderr
    run = json.loads(done.stdout)
    accuracy = max(1e-3, 1e-6 * sum(LOADS_KW.values()))
    assert run["status"] == "converged" and run["distance_bound_kw"] <= accuracy
    ours = {g["name"]: g["setpoint_kw"] for g in run["generators"]}
    assert np.abs([ours[name] - kw for (name, *_), kw in zip(FLEET, reference,
                                                             strict=True)]).max() <= accuracy
    assert {g["bus"] for g in run["generators"]} == {"src", "a", "c"}  # OpenDSS's bus names


def test_feeder_describes_the_ring_by_its_opendss_names(tmp_path):
    ring, fleet = write_circuit(tmp_path)
    summary = json.loads(popdispatch("feeder", "--net", str(ring), "--fleet", str(fleet),
                                     "--json", "-q").stdout)  # fmt: skip
    assert summary["meshed"] is True and summary["loops"] == 1
    assert {(r["from_bus"], r["to_bus"]) for r in summary["line_table"]} == {
        (a, b) for _, a, b, _ in LINES
    }
    ohms = {r["name"]: r["x_pu"] * KV**2 for r in summary["line_table"]}  # x_pu on 1 MVA
    for name, _, _, km in LINES:
        assert ohms[name] == pytest.approx(X1 * km, rel=1e-9)
    assert summary["load_kw"] == pytest.approx(sum(LOADS_KW.values()))
    assert {r["name"]: r["bus"] for r in summary["load_table"]} == {"loadb": "b", "loadc": "c"}


def test_load_shapes_on_a_mesh_are_refused_in_one_line(tmp_path):
    ring, fleet = write_circuit(tmp_path)
    done = subprocess.run([sys.executable, "-m", "popdispatch.cli", "day", "--net", str(ring),
                           "--fleet", str(fleet), "--series", "daily"], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert "--series" in done.stderr.splitlines()[-1] and "meshed" in done.stderr.splitlines()[-1]
