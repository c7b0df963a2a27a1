"""Every limit a run applies is echoed with its source, and an infeasible run names its real
cause (generator capacity, line limits, voltage limits), run for real in subprocesses on the
public feeders of ``../shared/feeders`` (or ``$POPDISPATCH_FEEDERS``).

Yardsticks: OpenDSS's own ``NormAmps`` and bus voltage bases (OpenDSSDirect.py) for IEEE 13's
ratings, OpenDSS's load total for the power a rating must carry, and a plain-numpy LinDistFlow
over networkx paths for the best voltage case69's bus 62 can reach.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import networkx as nx
import numpy as np
import pytest

from test_commands import assert_one_line_error, gens, run
from test_networks import FEEDERS

IEEE13 = FEEDERS / "opendss" / "ieee13" / "IEEE13Nodeckt.dss"
CASE69 = FEEDERS / "matpower" / "case69.m"
needs_ieee13 = pytest.mark.skipif(
    not IEEE13.is_file() or importlib.util.find_spec("opendssdirect") is None,
    reason="needs IEEE 13 (../shared/feeders or POPDISPATCH_FEEDERS) and the opendss extra",
)
needs_case69 = pytest.mark.skipif(not CASE69.is_file(), reason=f"{CASE69} not found")

#: The README's first IEEE 13 fleet: the cheap DGs leave 3466 - 500 kW to cross 650-632.
FLEET13 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
sourcebus,grid,50,0.1,0,5000
RG60,reg,10,0.1,0,1000
675,pv,5,0.1,0,500
"""
#: A dear DG below 650-632: the cheap power above it fills the rating, the DG the rest.
FLEET13_DEAR = FLEET13.replace("675,pv,5,0.1,0,500", "675,dg,60,0.1,0,800")
#: case69 with a 5 MW grid and three DGs (the issue's fleet).
FLEET69 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,grid,50,0.1,0,5000
27,pv27,10,0.1,0,300
50,bat50,20,0.2,0,500
65,dg65,5,0.1,0,400
"""


def opendss_650632() -> tuple[float, float]:
    """``(rating kW, total load kW)`` as OpenDSS has them: line 650632's NormAmps times its
    phases times the line-to-neutral base voltage of bus 632, and the sum of the loads' kW."""
    import opendssdirect

    dss = opendssdirect.NewContext()
    dss.Basic.AllowChangeDir(False)
    dss.Text.Command(f'compile "{IEEE13}"')
    dss.Lines.Name("650632")
    amps, phases = dss.Lines.NormAmps(), dss.Lines.Phases()
    dss.Circuit.SetActiveBus("632")
    kv_ln = dss.Bus.kVBase()
    load = 0.0
    for name in dss.Loads.AllNames():
        dss.Loads.Name(name)
        load += dss.Loads.kW()
    return phases * kv_ln * amps, load


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@needs_ieee13
def test_ieee13_ratings_are_echoed_and_the_binding_one_named(tmp_path):
    rating_kw, load_kw = opendss_650632()
    fleet = write(tmp_path, "fleet13.csv", FLEET13)
    result = run("snapshot", "--minute", "1", "--mode", "exact", "--fleet", str(fleet),
                 "--net", str(IEEE13), "-q")  # fmt: skip
    # infeasible, and the message says which rating and by how much (the 500 kW DG below it)
    assert_one_line_error(result, 1, "line limits", "rg60-632 at", "(rating of 650632)",
                          "--no-ratings")  # fmt: skip
    over = float(result.stderr.split("at least ")[1].split(" kW")[0])
    assert over == pytest.approx(load_kw - 500.0 - rating_kw, abs=1e-3)
    assert f"rg60-632 at {rating_kw:.6g} kW" in result.stderr
    assert "limits: none" not in result.stdout
    assert "limits: the network's ratings on 12 lines:" in result.stdout
    assert "given line limits" not in result.stdout + result.stderr
    # without the ratings the same run is feasible and says there are no limits
    free = run("snapshot", "--minute", "1", "--mode", "exact", "--fleet", str(fleet),
               "--net", str(IEEE13), "--no-ratings", "-q")  # fmt: skip
    assert free.returncode == 0, free.stderr
    assert "limits: none" in free.stdout


@needs_ieee13
def test_ieee13_binding_rating_in_json_and_text(tmp_path):
    rating_kw, load_kw = opendss_650632()
    fleet = write(tmp_path, "fleet13.csv", FLEET13_DEAR)
    result = run("opf", "--minute", "1", "--fleet", str(fleet), "--net", str(IEEE13),
                 "--json", "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    rows = {row["element"]: row for row in summary["limits_in_force"]}
    assert len(rows) == 12 and {row["source"] for row in rows.values()} == {"rating"}
    row = rows["650632"]
    assert (row["from_bus"], row["to_bus"]) == ("rg60", "632")  # OpenDSS names: text
    assert row["limit_kw"] == pytest.approx(rating_kw, rel=1e-9)
    assert row["binding_minutes"] == 1
    assert sum(r["binding_minutes"] for r in rows.values()) == 1
    # the cheap power above 650-632 fills it; the dear DG below covers the rest of the load
    assert gens(summary)["dg"]["p_kw"] == pytest.approx(load_kw - rating_kw, abs=1e-3)
    text = run("opf", "--minute", "1", "--fleet", str(fleet), "--net", str(IEEE13), "-q")
    assert f"rg60-632 {rating_kw:.6g} kW (650632) binding" in text.stdout


@needs_case69
def test_a_limit_option_and_a_capacity_shortage_are_named_as_such(tmp_path):
    fleet = write(tmp_path, "fleet69.csv", FLEET69)
    limited = run("opf", "--minute", "1", "--net", str(CASE69), "--fleet", str(fleet),
                  "--limit", "1:2=2000", "--json", "-q")  # fmt: skip
    # 3802.1 kW of load, 1200 kW of DGs below line 1-2: 602.1 kW more than 2000 kW must cross
    assert_one_line_error(limited, 1, "line limits", "--limit 1:2=2000 kW on 1-3",
                          "at least 602.100 kW over")  # fmt: skip
    why = json.loads(limited.stdout)["infeasibility"]
    assert why["cause"] == "line limits" and why["short_kw"] == pytest.approx(602.1, abs=1e-6)
    small = write(tmp_path, "small.csv", FLEET69.replace("0,5000", "0,2000"))
    short = run("opf", "--minute", "1", "--net", str(CASE69), "--fleet", str(small), "-q")
    assert_one_line_error(short, 1, "the demand 3802.100 kW exceeds the online generators' "
                          "capacity 3200.000 kW")  # fmt: skip
    assert "line limits" not in short.stderr


def lindistflow_best_pu(bus: int) -> float:
    """Plain-numpy LinDistFlow voltage of ``bus`` with every DG of :data:`FLEET69` at its
    maximum (the grid at the root supplies the rest; only injections below a line raise the
    voltages beyond it): ``v_j^2 = 1 - 2 sum_lines (r P + x Q) / V^2`` over networkx's path."""
    from popdispatch.readers import read_matpower

    feeder = read_matpower(CASE69)
    graph = nx.Graph()
    for row in feeder.lines.itertuples():
        graph.add_edge(int(row.from_bus), int(row.to_bus), r=row.r_ohm, x=row.x_ohm)
    tree = nx.bfs_tree(graph, feeder.source_bus)
    net_p = feeder.loads.groupby("bus").p_kw.sum().to_dict()
    net_q = feeder.loads.groupby("bus").q_kvar.sum().to_dict()
    for dg_bus, kw in ((27, 300.0), (50, 500.0), (65, 400.0)):
        net_p[dg_bus] = net_p.get(dg_bus, 0.0) - kw
    vn_kv = float(feeder.buses.vn_kv.iloc[0])
    path = nx.shortest_path(tree, feeder.source_bus, bus)
    v_sq = 1.0
    for a, b in zip(path[:-1], path[1:], strict=True):
        below = nx.descendants(tree, b) | {b}
        p_mw = sum(net_p.get(k, 0.0) for k in below) / 1000.0
        q_mvar = sum(net_q.get(k, 0.0) for k in below) / 1000.0
        edge = graph.edges[a, b]
        v_sq -= 2.0 * (edge["r"] * p_mw + edge["x"] * q_mvar) / vn_kv**2
    return math.sqrt(v_sq)


@needs_case69
def test_a_voltage_limit_out_of_reach_is_named_as_the_cause(tmp_path):
    fleet = write(tmp_path, "fleet69.csv", FLEET69)
    result = run("snapshot", "--minute", "1", "--mode", "exact", "--net", str(CASE69),
                 "--fleet", str(fleet), "--vmin", "0.95", "--json", "-q")  # fmt: skip
    assert_one_line_error(result, 1, "LinDistFlow OPF of minute 1 is infeasible",
                          "voltage limits: vmin 0.95 p.u. is out of reach at bus 62")  # fmt: skip
    assert "line limits" not in result.stderr  # no line limit was given, none applies
    summary = json.loads(result.stdout)
    why = summary["infeasibility"]
    assert why["cause"] == "voltage limits" and why["lines"] == []
    best = {row["bus"]: row["best_pu"] for row in why["buses"]}
    assert best[62] == pytest.approx(lindistflow_best_pu(62), abs=1e-6)
    assert max(best.values()) < 0.95
    text = run("snapshot", "--minute", "1", "--mode", "exact", "--net", str(CASE69),
               "--fleet", str(fleet), "--vmin", "0.95", "-q").stdout  # fmt: skip
    assert "congestion" not in text  # voltage mode without line limits
    assert "voltage prices ran away" in text and "line prices" not in text
    assert "first voltage price at iteration" in text
    assert np.isfinite(best[62])
