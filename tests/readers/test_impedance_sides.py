"""Impedances on both sides of an in-feeder transformer: each reader states a branch's own ohms
on its own voltage (``kv_base``), and the AC check refers them to one base. The transformers
have windings of different kVA (OpenDSS states every winding's %R on winding 1's kVA). The
yardstick is the format's own power flow of the same balanced network: OpenDSS's solution,
pandapower's ``runpp``; voltages (p.u.) and losses (kW) must agree on both sides of the
transformer."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from popdispatch.feeder.generators import make_fleet

pytest.importorskip("power_grid_model", reason="needs popdispatch[ac]")

from popdispatch.ac.check import check_setpoints, snapshot_of  # noqa: E402

BALANCED = """Clear
New Circuit.sides basekV=12.47 pu=1.0 bus1=src MVAsc3=1e12 MVAsc1=1e12
New Line.mv bus1=src bus2=hv phases=3 r1=0.3 x1=0.6 r0=0.9 x0=1.8 c1=0 c0=0 length=2 units=km
New Transformer.t phases=3 windings=2 buses=[hv lv] conns=[wye wye] kVs=[12.47 4.16]
~ kVAs=[2000 1500] %Rs=[0.5 0.8] XHL=6 %noloadloss=0 %imag=0
New Line.lv bus1=lv bus2=far phases=3 r1=0.2 x1=0.3 r0=0.6 x0=0.9 c1=0 c0=0 length=1 units=km
New Load.hv bus1=hv phases=3 kV=12.47 kW=600 kvar=200 model=1 vminpu=0.5
New Load.lv bus1=far phases=3 kV=4.16 kW=900 kvar=300 model=1 vminpu=0.5
Set voltagebases=[12.47 4.16]
Calcvoltagebases
"""


def test_opendss_reader_both_sides_of_a_transformer_against_opendss_power_flow(tmp_path):
    opendssdirect = pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")
    from popdispatch.readers.opendss_direct import read_opendss_master

    path = tmp_path / "sides.dss"
    path.write_text(BALANCED)
    feeder = read_opendss_master(path, ratings=False)
    lines = feeder.lines
    assert lines.loc["mv", "kv_base"] == pytest.approx(12.47, rel=1e-6)
    assert lines.loc["lv", "kv_base"] == pytest.approx(4.16, rel=1e-6)
    assert lines.loc["lv", ["r_ohm", "x_ohm"]].tolist() == pytest.approx([0.2, 0.3])  # its own
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{path}"')
    ctx.Text.Command("set tolerance=1e-12 maxiterations=100")  # its default is 1e-4 p.u.
    ctx.Text.Command("solve")
    theirs_v = {}
    for bus in ("hv", "lv", "far"):
        ctx.Circuit.SetActiveBus(bus)
        theirs_v[bus] = float(np.mean(ctx.Bus.puVmagAngle()[0::2]))
    theirs_loss = 0.0
    more = ctx.PDElements.First()
    while more:
        theirs_loss += ctx.CktElement.Losses()[0] / 1e3
        more = ctx.PDElements.Next()
    feeder = feeder.with_generators(make_fleet([(feeder.source_bus, 0, 1, 0, 0, 1e4)]))
    ac = snapshot_of(check_setpoints(feeder, feeder.loads.p_kw.to_numpy()[None], np.zeros((1, 1))))
    ours_v = ac.buses.v_pu.rename(dict(zip(feeder.buses.index, feeder.buses.name, strict=True)))
    for bus, v in theirs_v.items():
        assert ours_v[bus] == pytest.approx(v, abs=1e-6), bus
    assert ac.summary()["losses_kw"] == pytest.approx(theirs_loss, rel=1e-5)


def test_pandapower_reader_both_sides_of_a_transformer_against_runpp():
    pp = pytest.importorskip("pandapower")
    from popdispatch.readers.pandapower import read_pandapower

    net = pp.create_empty_network()
    b0, b1 = pp.create_bus(net, 20.0), pp.create_bus(net, 20.0)
    b2, b3 = pp.create_bus(net, 0.4), pp.create_bus(net, 0.4)
    pp.create_ext_grid(net, b0, vm_pu=1.0, s_sc_max_mva=1e9, rx_max=0.1)
    pp.create_line_from_parameters(net, b0, b1, 3.0, r_ohm_per_km=0.2, x_ohm_per_km=0.35,
                                   c_nf_per_km=0.0, max_i_ka=0.3)  # fmt: skip
    pp.create_transformer_from_parameters(net, b1, b2, sn_mva=0.63, vn_hv_kv=20.0, vn_lv_kv=0.4,
                                          vkr_percent=1.2, vk_percent=6.0, pfe_kw=0.0,
                                          i0_percent=0.0)  # fmt: skip
    pp.create_line_from_parameters(net, b2, b3, 0.2, r_ohm_per_km=0.3, x_ohm_per_km=0.08,
                                   c_nf_per_km=0.0, max_i_ka=0.4)  # fmt: skip
    pp.create_load(net, b1, p_mw=0.5, q_mvar=0.1)
    pp.create_load(net, b3, p_mw=0.2, q_mvar=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.runpp(net, trafo_model="t", tolerance_mva=1e-10)
    feeder = read_pandapower(net, root=b0, fleet=make_fleet([(b0, 0, 1, 0, 0, 1e4)]),
                             ratings=False)  # fmt: skip
    assert feeder.lines.loc["line1", "kv_base"] == 0.4
    assert feeder.lines.loc["line1", "r_ohm"] == pytest.approx(0.06)  # its own 0.4 kV ohms
    ac = snapshot_of(check_setpoints(feeder, feeder.loads.p_kw.to_numpy()[None], np.zeros((1, 1))))
    for bus in (b1, b2, b3):
        assert ac.buses.v_pu[bus] == pytest.approx(net.res_bus.vm_pu[bus], abs=1e-5), bus
    theirs = float(net.res_line.pl_mw.sum() + net.res_trafo.pl_mw.sum()) * 1e3
    assert ac.summary()["losses_kw"] == pytest.approx(theirs, rel=1e-4)


THREE_WINDING = """Clear
New Circuit.star basekV=12.47 pu=1.0 bus1=src MVAsc3=1e12 MVAsc1=1e12
New Transformer.t phases=3 windings=3 buses=[src a b] conns=[wye wye wye]
~ kVs=[12.47 4.16 0.48] kVAs=[3000 2000 1000] %Rs=[0.4 0.6 0.8] XHL=7 XHT=9 XLT=5
~ %noloadloss=0 %imag=0
New Load.a bus1=a phases=3 kV=4.16 kW=1200 kvar=400 model=1 vminpu=0.5
New Load.b bus1=b phases=3 kV=0.48 kW=600 kvar=150 model=1 vminpu=0.5
Set voltagebases=[12.47 4.16 0.48]
Calcvoltagebases
"""


def test_three_winding_star_against_opendss_power_flow(tmp_path):
    """A three-winding transformer between three buses read as its star equivalent (a star
    bus, one branch per winding) loses and drops what OpenDSS's own solution says."""
    opendssdirect = pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")
    from popdispatch.readers.opendss_direct import read_opendss_master

    path = tmp_path / "star.dss"
    path.write_text(THREE_WINDING)
    feeder = read_opendss_master(path, ratings=False)
    assert "transformer.t.star" in set(feeder.buses.name)
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{path}"')
    ctx.Text.Command("set tolerance=1e-12 maxiterations=100")
    ctx.Text.Command("solve")
    theirs_v = {}
    for bus in ("a", "b"):
        ctx.Circuit.SetActiveBus(bus)
        theirs_v[bus] = float(np.mean(ctx.Bus.puVmagAngle()[0::2]))
    ctx.Circuit.SetActiveElement("Transformer.t")
    theirs_loss = ctx.CktElement.Losses()[0] / 1e3
    feeder = feeder.with_generators(make_fleet([(feeder.source_bus, 0, 1, 0, 0, 1e4)]))
    ac = snapshot_of(check_setpoints(feeder, feeder.loads.p_kw.to_numpy()[None], np.zeros((1, 1))))
    ours_v = ac.buses.v_pu.rename(dict(zip(feeder.buses.index, feeder.buses.name, strict=True)))
    for bus, v in theirs_v.items():
        assert ours_v[bus] == pytest.approx(v, abs=1e-6), bus
    assert ac.summary()["losses_kw"] == pytest.approx(theirs_loss, rel=1e-5)
