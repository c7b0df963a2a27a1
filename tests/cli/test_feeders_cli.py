"""Real feeders on the command line, run in subprocesses: ``feeder`` describing any network
without a fleet, buses named as the source format names them (text, JSON, ``--root``,
``--limit``), OpenDSS load shapes as the run's series (``--series``, fixed injections reported
per step), the export read back without ``--root``, one-line errors for bad OpenDSS input, and
the ckt24 year end to end. Data from ``../shared/feeders`` (or ``$POPDISPATCH_FEEDERS``) where
named; the rest writes its own small circuits."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from helpers import CKT24_OPEN_POINTS, FEEDERS_REASON, feeders_folder
from test_commands import assert_one_line_error, run

pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")

OPENDSS = feeders_folder() / "opendss"
IEEE13 = OPENDSS / "ieee13" / "IEEE13Nodeckt.dss"
CKT24 = OPENDSS / "ckt24" / "master_ckt24.dss"
needs_ieee13 = pytest.mark.skipif(not IEEE13.is_file(), reason=FEEDERS_REASON)
needs_ckt24 = pytest.mark.skipif(not CKT24.is_file(), reason=FEEDERS_REASON)

FLEET13 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
sourcebus,grid,50,0.1,0,5000
RG60,reg,10,0.1,0,1000
675,pv,5,0.1,0,500
"""

DAY = [0.5, 0.4, 0.4, 0.5, 0.6, 0.8, 1, 1, 0.9, 0.8, 0.8, 0.8, 0.8, 0.8, 0.8, 0.9, 1, 1, 0.9,
       0.8, 0.7, 0.6, 0.5, 0.5]  # fmt: skip
SUN = [0, 0, 0, 0, 0, 0, 0.1, 0.3, 0.5, 0.7, 0.9, 1, 1, 0.9, 0.7, 0.5, 0.3, 0.1, 0, 0, 0, 0, 0, 0]
SHAPED = """Clear
New Circuit.shaped basekV=12.47 pu=1.0 bus1=src MVAsc3=1e9 MVAsc1=1e9
New Linecode.lc nphases=3 r1=0.01 x1=0.02 r0=0.03 x0=0.06 units=km
New Line.l1 bus1=src bus2=a linecode=lc length=0.1
New Line.l2 bus1=a bus2=b linecode=lc length=0.1
New Loadshape.day npts=24 interval=1 mult=({day})
New Loadshape.sun npts=24 interval=1 mult=({sun})
New Load.a bus1=a kV=12.47 kW=300 pf=1 daily=day
New Load.b bus1=b kV=12.47 kW=200 pf=1 daily=day
New Generator.pv bus1=b kV=12.47 kW=100 pf=1 daily=sun
Set voltagebases=[12.47]
Calcvoltagebases
""".format(day=" ".join(map(str, DAY)), sun=" ".join(map(str, SUN)))
FLEET_SHAPED = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
src,grid,50,0.1,0,2000
b,dg,10,0.5,0,150
"""


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@needs_ieee13
def test_feeder_describes_an_opendss_network_without_a_fleet():
    result = run("feeder", "--net", str(IEEE13), "--json", "-q")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert s["source_bus"] == "sourcebus" and s["generators"] == []
    assert "--fleet" in s["fleet_note"]
    loads = {row["name"]: row for row in s["load_table"]}
    assert len(loads) == 15 and loads["671"]["bus"] == "671" and loads["671"]["p_kw"] == 1155.0
    lines = {row["name"]: row for row in s["line_table"]}
    assert lines["650632"]["from_bus"] == "rg60" and lines["650632"]["kv_base"] == 4.16
    assert lines["650632"]["limit_kw"] > 0 and lines["650632"]["r_ohm"] < 0.1  # own ohms
    # every bus in the JSON is a string: OpenDSS names its buses ("650" too)
    buses = [s["source_bus"], *s["key_node_buses"]] + [r["bus"] for r in s["load_table"]]
    assert all(isinstance(b, str) for b in buses)
    text = run("feeder", "--net", str(IEEE13), "-q").stdout
    assert "source bus sourcebus" in text and "generators: none" in text and "--fleet" in text
    assert "671" in text and "650632" in text


@needs_ieee13
def test_root_and_limits_take_opendss_bus_names(tmp_path):
    fleet = write(tmp_path / "fleet.csv", FLEET13)
    result = run("opf", "--minute", "1", "--net", str(IEEE13), "--fleet", str(fleet),
                 "--root", "SourceBus", "--no-ratings", "--limit", "sourcebus:rg60=3000",
                 "--json", "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert s["limits"][0]["from_bus"] == "sourcebus"
    assert {g["name"]: g["bus"] for g in s["generators"]} == {
        "grid": "sourcebus", "reg": "rg60", "pv": "675"}  # fmt: skip
    for bad, option in (("--root", "nowhere"), ("--limit", "nowhere:632=5")):
        args = ["opf", "--minute", "1", "--net", str(IEEE13), "--fleet", str(fleet), bad, option]
        assert_one_line_error(run(*args), 2, option.split(":")[0].split("=")[0])


def test_run_needs_a_fleet_with_one_line_naming_the_option(tmp_path):
    net = write(tmp_path / "shaped.dss", SHAPED)
    assert_one_line_error(run("opf", "--minute", "1", "--net", str(net), "-q"), 1,
                          "no generator to dispatch", "--fleet FILE")  # fmt: skip


def test_series_runs_the_load_shapes_with_fixed_injections(tmp_path):
    net = write(tmp_path / "shaped.dss", SHAPED)
    fleet = write(tmp_path / "fleet.csv", FLEET_SHAPED)
    out = tmp_path / "out"
    result = run("day", "--mode", "exact", "--net", str(net), "--fleet", str(fleet),
                 "--no-ratings", "--series", "daily", "--out", str(out), "--json",
                 "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert s["steps"] == 24 and s["step_minutes"] == 60.0 and s["last_time"] == "23:00:00"
    assert s["fixed_injection_kwh"] == pytest.approx(100 * sum(SUN))
    table = pd.read_csv(out / "day.csv")
    assert table["fixed_injection_kw"].tolist() == pytest.approx([100 * v for v in SUN])
    net_kw = [500 * d - 100 * v for d, v in zip(DAY, SUN, strict=True)]
    assert table["demand_kw"].tolist() == pytest.approx(net_kw)
    snap = run("opf", "--step", "12", "--net", str(net), "--fleet", str(fleet), "--no-ratings")
    assert snap.returncode == 0, snap.stderr
    assert "fixed injections (not dispatched): 100.000 kW" in snap.stdout
    assert_one_line_error(
        run("opf", "--minute", "1", "--series", "yearly", "--profiles", str(tmp_path)),
        2,
        "--series",
    )


def test_export_pandapower_reads_back_without_root(tmp_path):
    out = tmp_path / "elv566.json"
    exported = run("export", "--minute", "566", "--format", "pandapower", "--out", str(out), "-q")
    assert exported.returncode == 0, exported.stderr
    original = json.loads(run("opf", "--minute", "566", "--json", "-q").stdout)
    back = run("opf", "--minute", "1", "--net", str(out), "--json", "-q")
    assert back.returncode == 0, back.stderr
    s = json.loads(back.stdout)
    assert [g["bus"] for g in s["generators"]] == [g["bus"] for g in original["generators"]]
    assert s["cost_eur_per_h"] == pytest.approx(original["cost_eur_per_h"], rel=1e-8)
    assert json.loads(run("feeder", "--net", str(out), "--json", "-q").stdout)["source_bus"] == 1


BAD_MASTER = """Clear
New Circuit.bad basekV=12.47 bus1=src
New Line.l1 bus1=src bus2=a length=1
{extra}
"""


@pytest.mark.parametrize(
    ("extra", "code", "words"),
    [
        ("New Line.l2 bus1=a bus2=b lenght=1", 1, ["bad.dss:4", "lenght", "Line.l2"]),
        ("New AutoTrans.at buses=[a b] kVs=[12.47 6]", 1,
         ["bad.dss:4", "AutoTrans.at", "unsupported series element"]),
    ],
    ids=["syntax", "unsupported"],
)  # fmt: skip
def test_bad_opendss_input_is_one_line_naming_file_line_and_element(tmp_path, extra, code, words):
    net = write(tmp_path / "bad.dss", BAD_MASTER.format(extra=extra))
    assert_one_line_error(run("feeder", "--net", str(net), "-q"), code, *words)


def test_a_circuit_with_a_loop_is_described_as_a_mesh(tmp_path):
    """A loop is no error on the command line: the circuit is read into the DC model
    (docs/meshed.md) and a note says so."""
    extra = "New Line.l2 bus1=a bus2=b\nNew Line.l3 bus1=b bus2=src"
    net = write(tmp_path / "ring.dss", BAD_MASTER.format(extra=extra))
    done = run("feeder", "--net", str(net), "--json")
    assert done.returncode == 0, done.stderr
    assert "bad is meshed" in done.stderr
    summary = json.loads(done.stdout)
    assert summary["meshed"] is True and summary["loops"] == 1
    assert {r["name"] for r in summary["line_table"]} == {"l1", "l2", "l3"}


def test_missing_opendss_file_on_the_command_line_is_usage(tmp_path):
    assert_one_line_error(run("feeder", "--net", str(tmp_path / "nowhere.dss")), 2, "nowhere.dss")


@needs_ckt24
@pytest.mark.slow
def test_ckt24_year_runs_end_to_end(tmp_path):
    script = write(tmp_path / "ckt24_radial.dss", f"Compile ({CKT24})\n" +
                   "".join(f"Open {e} 1\n" for e in CKT24_OPEN_POINTS))  # fmt: skip
    fleet = write(tmp_path / "fleet.csv", (
        "bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw\n"
        "sourcebus,grid,60,0.002,0,80000\nn274191,dg1,10,0.01,0,900\n"
        "n274364,dg2,15,0.01,0,900\nn283927,dg3,20,0.01,0,900\n"))  # fmt: skip
    result = run("day", "--mode", "exact", "--net", str(script), "--fleet", str(fleet),
                 "--no-ratings", "--json", "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert (s["steps"], s["step_minutes"], s["last_time"]) == (8760, 60.0, "364 days 23:00:00")
    assert s["profile_source"].startswith("ckt24 yearly load shapes")
    assert s["status"] == "converged" and s["converged_minutes"] == 8760
    assert s["max_abs_error_kw"] < 1e-6 * 60000
