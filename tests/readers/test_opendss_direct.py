"""Any OpenDSS master through OpenDSSDirect.py (popdispatch.readers.opendss_direct).

Totals are compared with OpenDSS's own (a separate OpenDSSDirect.py context in the test), the
ELV with the pandapower feeder, and an exact-mode snapshot with our DC-OPF.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch.errors import FeederError, FleetError, OptionError

opendssdirect = pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")

from popdispatch.readers.opendss_direct import (  # noqa: E402
    _opendss,
    bus_ids,
    read_opendss_master,
)

FEEDERS_ENV = "POPDISPATCH_FEEDERS"


def _feeders() -> Path:
    if os.environ.get(FEEDERS_ENV):
        return Path(os.environ[FEEDERS_ENV])
    return Path(__file__).resolve().parents[3] / "shared" / "feeders"


FEEDERS = _feeders()
IEEE13 = FEEDERS / "opendss" / "ieee13" / "IEEE13Nodeckt.dss"
IEEE34 = FEEDERS / "opendss" / "ieee34" / "ieee34Mod1.dss"
ELV = FEEDERS.parent / "ieee-elv" / "Master.dss"

needs_feeders = pytest.mark.skipif(
    not IEEE13.is_file(),
    reason=f"test feeders not found at {FEEDERS} (set {FEEDERS_ENV} to the feeders folder)",
)
needs_elv = pytest.mark.skipif(
    not ELV.is_file(),
    reason=f"ELV OpenDSS folder not found at {ELV.parent} (next to ${FEEDERS_ENV})",
)


def opendss_totals(master: Path) -> dict:
    """OpenDSS's own view of a compiled master: bus names and per-load kW, kvar."""
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{master}"')
    ctx.Text.Command("makebuslist")  # elements defined after the master's last solve
    kw, kvar = [], []
    for name in ctx.Loads.AllNames():
        ctx.Loads.Name(name)
        kw.append(ctx.Loads.kW())
        kvar.append(ctx.Loads.kvar())
    lines = []
    for name in ctx.Lines.AllNames():
        ctx.Lines.Name(name)
        lines.append(name)
    return {
        "buses": [b.lower() for b in ctx.Circuit.AllBusNames()],
        "kw": float(np.sum(kw)),
        "kvar": float(np.sum(kvar)),
        "n_loads": len(kw),
        "lines": lines,
    }


def fleet(rows: list[tuple]) -> pd.DataFrame:
    """A fleet with OpenDSS bus names: rows ``(name, bus, b, c, pmax_kw)``, a = pmin = 0."""
    return pd.DataFrame(
        {
            "bus": [r[1] for r in rows],
            "a": 0.0,
            "b": [r[2] for r in rows],
            "c": [r[3] for r in rows],
            "pmin_kw": 0.0,
            "pmax_kw": [r[4] for r in rows],
        },
        index=pd.Index([r[0] for r in rows], name="generator"),
    )


#: A small IEEE 13 fleet: an interior optimum, no limit binding.
FLEET13 = fleet([
    ("G1", "sourcebus", 5.0, 1.0, 3000.0),
    ("G2", "675", 3.0, 2.0, 2000.0),
    ("G3", "634", 4.0, 5.0, 300.0),
    ("G4", 652, 6.0, 1.0, 1000.0),
])  # fmt: skip

#: Cheap, large G3 behind the 500 kVA transformer XFM1: its rating binds.
FLEET13_BINDING = fleet([
    ("G1", "sourcebus", 5.0, 1.0, 3000.0),
    ("G2", "675", 3.0, 2.0, 2000.0),
    ("G3", "634", 1.0, 1.0, 1500.0),
])  # fmt: skip


@pytest.fixture(scope="module")
def ieee13():
    return read_opendss_master(IEEE13, fleet=FLEET13)


def test_missing_package_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "opendssdirect", None)
    with pytest.raises(ImportError, match=r"pip install popdispatch\[opendss\]"):
        _opendss()


def test_bus_ids_keep_integer_names():
    ids = bus_ids(["sourcebus", "650", "rg60", "007", "1"])
    assert ids == {"sourcebus": 651, "650": 650, "rg60": 652, "007": 653, "1": 1}
    assert bus_ids(["a", "b"]) == {"a": 1, "b": 2}


@needs_feeders
def test_ieee13_against_opendss(ieee13):
    own = opendss_totals(IEEE13)
    f = ieee13
    assert len(own["buses"]) == 16
    assert len(f.buses) == len(own["buses"])  # no bus dropped
    assert sorted(f.buses.name) == sorted(own["buses"])
    assert len(f.loads) == own["n_loads"] == 15
    assert f.loads.p_kw.sum() == pytest.approx(own["kw"], rel=1e-12)
    assert f.loads.p_kw.sum() == pytest.approx(3466.0)
    assert f.loads.q_kvar.sum() == pytest.approx(own["kvar"], rel=1e-12)
    # 12 lines (11 + the closed switch 671-692) and 3 transformer branches (Sub, the
    # regulator bank Reg1-3, XFM1): 15 = 16 buses - 1, radial (the Feeder validated it)
    assert len(own["lines"]) == 12
    assert len(f.lines) == 12 + 3 == len(f.buses) - 1
    assert f.lines.kind.value_counts().to_dict() == {
        "line": 11, "transformer": 2, "switch": 1, "regulator": 1,
    }  # fmt: skip
    ids = dict(zip(f.buses.name, f.buses.index, strict=True))
    assert ids["650"] == 650 and ids["sourcebus"] == 693 and ids["rg60"] == 694
    assert f.source_bus == ids["sourcebus"]
    switch = f.lines.loc["671692"]
    assert (switch.from_bus, switch.to_bus, switch.kind) == (671, 692, "switch")
    bank = f.lines.loc["Transformer.reg1+reg2+reg3"]
    assert (bank.from_bus, bank.to_bus) == (650, 694)
    assert f.loads.loc["671", "bus"] == 671 and f.loads.loc["634a", "bus"] == 634
    # coordinates from IEEE13Node_BusXY.csv (BusCoords in the master)
    assert tuple(f.buses.loc[650, ["x", "y"]]) == (200.0, 350.0)


@needs_feeders
def test_ieee13_impedances_on_each_branchs_own_side(ieee13):
    f = ieee13
    # mtx601 (ohm/mile): Z1 = mean(diagonal) - mean(off-diagonal); 2000 ft
    diag = (0.3465 + 1.0179j + 0.3375 + 1.0478j + 0.3414 + 1.0348j) / 3
    off = (0.1560 + 0.5017j + 0.1580 + 0.4236j + 0.1535 + 0.3849j) / 3
    z = (diag - off) * 2000 / 5280
    # the 4.16 kV lines' own ohms (about 0.07 ohm, not referred to the 115 kV source)
    assert f.buses.loc[f.source_bus, "vn_kv"] == pytest.approx(115.0)
    line = f.lines.loc["650632"]
    assert line.length_km == pytest.approx(2000 * 0.3048e-3, rel=1e-12)
    assert line.kv_base == pytest.approx(4.16, rel=1e-3)  # the bus's base, OpenDSS's own
    assert line.r_ohm == pytest.approx(z.real, rel=1e-9)
    assert line.x_ohm == pytest.approx(z.imag, rel=1e-9)
    # one-phase matrix line 684-611 (mtx605): its self impedance, 300 ft
    assert f.lines.loc["684611", "r_ohm"] == pytest.approx(1.3292 * 300 / 5280, rel=1e-9)
    # XFM1 (4.16/0.48 kV): %R 0.55 + 0.55, XHL 2 % on 500 kVA, on its winding 1's 4.16 kV
    xfm = f.lines.loc["Transformer.xfm1"]
    kv = xfm.kv_base
    assert kv == pytest.approx(4.16, rel=1e-3)
    assert xfm.r_ohm == pytest.approx(0.011 * kv**2 / 0.5, rel=1e-9)
    assert xfm.x_ohm == pytest.approx(0.02 * kv**2 / 0.5, rel=1e-9)
    assert (xfm.length_km, xfm.limit_kw) == (0.0, 500.0)
    # the lines behind XFM1 are 0.48 kV lines: none in IEEE 13 but the load bus 634
    assert f.buses.set_index("name").loc["634", "vn_kv"] == pytest.approx(0.48, rel=1e-3)
    # the regulator bank: three one-phase 1666 kVA units, XHL 0.01 %: per phase on V_LN^2
    bank = f.lines.loc["Transformer.reg1+reg2+reg3"]
    assert bank.x_ohm == pytest.approx(1e-4 * (bank.kv_base / math.sqrt(3)) ** 2 / 1.666,
                                       rel=1e-9)  # fmt: skip
    # referred to the 115 kV source, as the AC check and the reduction use them
    on_source = f.lines_on_base()
    assert on_source.loc["650632", "r_ohm"] == pytest.approx(z.real * (115 / kv) ** 2, rel=1e-9)
    # NormAmps 400 A (OpenDSS's default) at 4.16 kV: sqrt(3) * 4.16 * 400 kW, 1 phase: V_LN I
    assert line.limit_kw == pytest.approx(math.sqrt(3) * 4.16 * 400, rel=1e-6)
    assert f.lines.loc["684611", "limit_kw"] == pytest.approx(4.16 / math.sqrt(3) * 400, rel=1e-6)
    assert f.lines.loc["Transformer.reg1+reg2+reg3", "limit_kw"] == 3 * 1666.0
    unrated = read_opendss_master(IEEE13, fleet=FLEET13, ratings=False)
    assert np.isinf(unrated.lines.limit_kw).all()


@needs_feeders
def test_ieee13_lines_equal_opendss_own_positive_sequence():
    """Every multi-phase line's ohms are OpenDSS's own positive-sequence ``R1 x Length`` after
    its ``MakePosSeq`` (an independent computation); a one-phase line is its self impedance
    (``RMatrix``), the rule stated in the reader."""
    f = read_opendss_master(IEEE13)
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{IEEE13}"')
    self_z = {}
    for name in ctx.Lines.AllNames():
        ctx.Lines.Name(name)
        if ctx.Lines.Phases() == 1:
            self_z[name] = (ctx.Lines.RMatrix()[0] * ctx.Lines.Length(),
                            ctx.Lines.XMatrix()[0] * ctx.Lines.Length())  # fmt: skip
    ctx.Text.Command("makeposseq")
    checked = 0
    for name in ctx.Lines.AllNames():
        ctx.Lines.Name(name)
        if ctx.Lines.IsSwitch():
            continue
        ours = f.lines.loc[name, ["r_ohm", "x_ohm"]].tolist()
        length = ctx.Lines.Length()
        theirs = self_z.get(name, (ctx.Lines.R1() * length, ctx.Lines.X1() * length))
        assert ours == pytest.approx(list(theirs), rel=1e-9), name
        checked += 1
    assert checked == 11 and len(self_z) == 2


@needs_feeders
def test_ieee13_fleet_by_opendss_bus_name(ieee13):
    g = ieee13.generators
    assert g.bus.to_dict() == {"G1": 693, "G2": 675, "G3": 634, "G4": 652}
    with pytest.raises(FleetError, match="unknown OpenDSS bus 'nowhere'"):
        read_opendss_master(IEEE13, fleet=fleet([("G1", "nowhere", 1.0, 1.0, 10.0)]))
    described = read_opendss_master(IEEE13)  # no fleet: described, nothing to dispatch
    assert described.generators.empty and len(described.loads) == 15


@needs_feeders
def test_ieee13_root(ieee13):
    f = read_opendss_master(IEEE13, fleet=FLEET13, root="650")
    assert f.source_bus == 650 and len(f.buses) == 16
    assert read_opendss_master(IEEE13, fleet=FLEET13, root="SourceBus").source_bus == 693
    # rooted at the 4.16 kV bus 650, the 4.16 kV base is the common one
    own = (0.3465 + 0.3375 + 0.3414 - 0.1560 - 0.1580 - 0.1535) / 3 * 2000 / 5280
    assert f.lines_on_base().loc["650632", "r_ohm"] == pytest.approx(own, rel=1e-3)


@needs_feeders
def test_open_switch_generators_and_unsupported(tmp_path):
    def master(*lines: str) -> Path:
        path = tmp_path / "extra.dss"
        path.write_text(f'redirect "{IEEE13}"\n' + "\n".join(lines) + "\n")
        return path

    # the switch 671-692 opened: 692 and 675 (loads) are cut off
    with pytest.raises(FeederError, match="bus '692' is not connected to source bus"):
        read_opendss_master(master("open Line.671692 1"), fleet=FLEET13)
    # an open switch cutting off an empty bus: line removed, bus dropped with a warning
    spur = master(
        "New Line.spur Bus1=680 Bus2=spur1 Phases=3 R1=0.1 X1=0.2 R0=0.3 X0=0.6 Length=0.2 "
        "units=km",
        "New Line.spursw Bus1=spur1 Bus2=spur2 Phases=3 Switch=y",
        "New Generator.g5 Bus1=675 kV=4.16 kW=500 PF=1",
        "New PVSystem.pv1 Bus1=652.1 phases=1 kV=2.4 kVA=100 Pmpp=80",
        "open Line.spursw 1",
    )
    dropped = r"dropped 1 bus\(es\).*'spur2'"
    with pytest.warns(UserWarning, match=dropped):
        described = read_opendss_master(spur)
    # without a fleet the generator and the PV system are fixed injections (no cost data)
    fixed = described.loads.loc[["Generator.g5", "PVSystem.pv1"]]
    assert fixed.kind.tolist() == ["generator", "pvsystem"]
    assert fixed.p_kw.tolist() == pytest.approx([-500.0, -80.0])  # Pmpp x irradiance 1
    own = opendss_totals(spur)
    with_candidates = fleet([("G1", "sourcebus", 5.0, 1.0, 3000.0), ("g5", None, 3.0, 1.0, None)])
    with pytest.warns(UserWarning, match="spur2"):
        f = read_opendss_master(spur, fleet=with_candidates)
    assert len(f.buses) == len(own["buses"]) - 1 == 17
    assert "spursw" not in f.lines.index and "spur" in f.lines.index
    # the spur is at 4.16 kV (CalcVoltageBases): its own ohms
    assert f.lines.loc["spur", ["r_ohm", "x_ohm"]].tolist() == pytest.approx([0.02, 0.04])
    g5 = f.generators.loc["g5"]
    assert (g5.bus, g5.pmin_kw, g5.pmax_kw) == (675, 0.0, pytest.approx(500.0, rel=1e-12))
    assert "Generator.g5" not in f.loads.index  # dispatched, not fixed
    assert f.loads.loc["PVSystem.pv1", "p_kw"] == pytest.approx(-80.0)
    # a series reactor is a branch with its own impedance (R + jX per phase)
    reactor = read_opendss_master(master("New Reactor.r1 Bus1=680 Bus2=x9 R=1 X=2"))
    assert reactor.lines.loc["Reactor.r1", ["r_ohm", "x_ohm", "kind"]].tolist() == [
        pytest.approx(1.0), pytest.approx(2.0), "reactor"]  # fmt: skip
    # a three-winding transformer between three buses: its star equivalent, a bus of its own
    three = (
        "New Transformer.t3 Phases=3 Windings=3 Buses=[680 x1 x2] kVs=[4.16 0.48 0.48] "
        "kVAs=[500 250 250]"
    )
    star = read_opendss_master(master(three))
    assert "transformer.t3.star" in set(star.buses.name)
    assert {"Transformer.t3:w1", "Transformer.t3:w2", "Transformer.t3:w3"} <= set(star.lines.index)
    assert len(star.lines) == len(star.buses) - 1
    with pytest.raises(OptionError, match="root bus .x. is not a bus of the OpenDSS circuit"):
        read_opendss_master(IEEE13, fleet=FLEET13, root="x")


@needs_feeders
def test_ieee34_against_opendss():
    own = opendss_totals(IEEE34)
    f = read_opendss_master(IEEE34, fleet=fleet([("G1", "sourcebus", 5.0, 1.0, 3000.0)]))
    assert len(own["buses"]) == 37 and len(f.buses) == 37
    assert {"814r", "852r", "sourcebus"} <= set(f.buses.name)
    assert len(f.loads) == own["n_loads"] == 68
    assert f.loads.p_kw.sum() == pytest.approx(own["kw"], rel=1e-12)
    assert f.loads.p_kw.sum() == pytest.approx(1769.0)
    assert f.loads.q_kvar.sum() == pytest.approx(own["kvar"], rel=1e-12)
    # 32 lines + SubXF, XFM1 and the two regulator banks (three one-phase units each)
    assert len(f.lines) == len(own["lines"]) + 4 == 36 == len(f.buses) - 1
    assert (f.lines.kind == "regulator").sum() == 2
    assert "Transformer.reg1a+reg1b+reg1c" in f.lines.index
    # long 24.9 kV lines: L3 is 32.23 kft
    assert f.lines.loc["l3", "length_km"] == pytest.approx(32.23 * 0.3048, rel=1e-12)
    # no BusCoords in ieee34Mod1.dss: schematic layout, the source on top
    assert f.buses.loc[f.source_bus, "y"] == 0.0 and (f.buses.y <= 0).all()


@needs_feeders
def test_master_with_reports_writes_nothing_beside_it(tmp_path):
    # Run_IEEE34Mod1.dss compiles ieee34Mod1.dss twice and has Show/Plot commands: compiled
    # from a temporary copy, its reports go there, not into the master's folder
    for path in IEEE34.parent.iterdir():
        (tmp_path / path.name).write_bytes(path.read_bytes())
    before = sorted(p.name for p in tmp_path.iterdir())
    f = read_opendss_master(
        tmp_path / "Run_IEEE34Mod1.dss", fleet=fleet([("G1", "sourcebus", 5.0, 1.0, 3000.0)])
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert (len(f.buses), len(f.lines), f.loads.p_kw.sum()) == (37, 36, pytest.approx(1769.0))


@needs_elv
def test_elv_same_reduction_as_pandapower():
    from popdispatch.cases import ieee_elv
    from popdispatch.feeder import paper_fleet, reduce_feeder

    with pytest.warns(UserWarning, match=r"Master.dss:13: redirect of a missing file "
                      r"'Monitors.txt' skipped \(OpenDSS error 243\)$"):  # fmt: skip
        f = read_opendss_master(ELV, fleet=paper_fleet(), root="1", ratings=False)
    reference = ieee_elv()
    # OpenDSS's buses: 1..906 plus the transformer's 11 kV sourcebus (id 907, a dead end
    # above the root 1 that the reduction prunes)
    assert len(f.buses) == 907 and f.buses.loc[907, "name"] == "sourcebus"
    assert f.source_bus == reference.source_bus == 1
    # TR1 (800 kVA, XHL 4 %) on its winding 1's 11 kV; the lines on their own 0.416 kV
    assert f.lines.loc["Transformer.tr1", "x_ohm"] == pytest.approx(0.04 * 11**2 / 0.8)
    assert f.lines_on_base().loc["Transformer.tr1", "x_ohm"] == pytest.approx(0.04 * 0.416**2
                                                                              / 0.8)  # fmt: skip
    assert f.loads.p_kw.sum() == pytest.approx(55.0)  # kW=1 per load (shapes not applied)
    assert f.loads.bus.tolist() == reference.loads.bus.tolist()
    assert f.loads.index.tolist() == [n.lower() for n in reference.loads.index]
    ours, theirs = reduce_feeder(f), reduce_feeder(reference)
    assert (ours.n_nodes, ours.n_lines) == (theirs.n_nodes, theirs.n_lines) == (110, 109)
    assert ours.nodes.bus.tolist() == theirs.nodes.bus.tolist()
    for column in ("from_bus", "to_bus", "n_original"):
        assert ours.lines[column].tolist() == theirs.lines[column].tolist()
    np.testing.assert_allclose(
        ours.lines[["length_km", "r_ohm", "x_ohm"]], theirs.lines[["length_km", "r_ohm", "x_ohm"]],
        rtol=1e-6,  # the pandapower data carry lengths to about 8 digits
    )  # fmt: skip
    np.testing.assert_allclose(
        f.buses.loc[reference.buses.index, ["x", "y"]], reference.buses[["x", "y"]], rtol=1e-12
    )


def _exact_vs_opf(feeder):
    from popdispatch.feeder import reduce_feeder
    from popdispatch.feeder.profiles import single_minute_profiles
    from popdispatch.game.problem import build_problem
    from popdispatch.online import RunSettings, run_snapshot
    from popdispatch.opf import solve_opf

    profiles = single_minute_profiles(1, feeder.loads.p_kw, "IEEE 13 loads")
    problem = build_problem(reduce_feeder(feeder), profiles)
    opf = solve_opf(problem, 1)
    snapshot = run_snapshot(problem, 1, RunSettings(mode="exact"))
    return problem, opf, snapshot


@needs_feeders
@pytest.mark.parametrize(
    ("fleet13", "binding"), [(FLEET13, False), (FLEET13_BINDING, True)], ids=["free", "binding"]
)
def test_ieee13_exact_snapshot_equals_dc_opf(fleet13, binding):
    feeder = read_opendss_master(IEEE13, fleet=fleet13)
    problem, opf, snapshot = _exact_vs_opf(feeder)
    assert opf.status == "optimal"
    assert (np.abs(opf.line_price) > 1e-6).any() == binding
    assert snapshot.status == "converged"
    np.testing.assert_allclose(snapshot.setpoints_kw, opf.p_kw, rtol=0, atol=1e-3)


@needs_feeders
def test_fleet_given_as_a_file_path(tmp_path):
    path = tmp_path / "fleet13.csv"
    path.write_text(
        "bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw\n"
        "sourcebus,grid,50,0.1,0,5000\nRG60,reg,10,0.1,0,1000\n675,pv,5,0.1,0,500\n"
    )
    for given in (str(path), path):
        f = read_opendss_master(IEEE13, fleet=given)
        assert f.generators.bus.to_dict() == {"grid": 693, "reg": 694, "pv": 675}
    with pytest.raises(FleetError, match=r"a fleet is a table .* or the path of a CSV or TOML"):
        read_opendss_master(IEEE13, fleet=42)
