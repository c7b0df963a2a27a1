"""The pandapower reader (issue 12): pandapower's own radial grids read with the counts and totals
of pandapower's tables; switches, out-of-service elements, transformers, asymmetric loads and
ratings follow the documented rules; meshed, multi-source and unsupported nets give one-line
errors; our DC-OPF equals pandapower's ``rundcopp`` on the same net; exact mode lands on it."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest

pp = pytest.importorskip("pandapower")
pn = pytest.importorskip("pandapower.networks")

from popdispatch.cases import builtin as cases  # noqa: E402
from popdispatch.errors import FeederError, FleetError  # noqa: E402
from popdispatch.feeder.generators import make_fleet  # noqa: E402
from popdispatch.feeder.profiles import single_minute_profiles  # noqa: E402
from popdispatch.feeder.reduction import reduce_feeder  # noqa: E402
from popdispatch.game.problem import build_problem  # noqa: E402
from popdispatch.online import RunSettings, run_snapshot  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402
from popdispatch.readers.pandapower import read_pandapower  # noqa: E402

SQRT3 = math.sqrt(3.0)


def one_gen(bus: int) -> pd.DataFrame:
    return make_fleet([(bus, 0.0, 10.0, 0.1, 0.0, 1000.0)])


def own_totals(net) -> tuple[int, float, float]:
    """In-service loads of pandapower's own tables: count, kW and kvar with scaling."""
    on = net.load[net.load.in_service & net.bus.in_service[net.load.bus].to_numpy()]
    return (
        len(on),
        float((on.p_mw * on.scaling).sum() * 1e3),
        float((on.q_mvar * on.scaling).sum() * 1e3),
    )


def dc_problem(feeder, injections: bool = True):
    """The one-step problem of the feeder's own loads (``injections=False``: its fixed
    injections at 0 kW, e.g. SimBench's PV at its installed capacity)."""
    kw = feeder.loads.p_kw
    if not injections:
        kw = kw.where(feeder.loads.kind == "load", 0.0)
    profiles = single_minute_profiles(1, kw, feeder.name)
    return build_problem(reduce_feeder(feeder), profiles)


def small_fleet(feeder, rows=None) -> pd.DataFrame:
    """A priced source and one DG at the bus farthest from it; costs scaled with the demand
    (of the load ``rows``, default all) so the optimum is interior (DG share 0.35 without
    limits) on any feeder size."""
    tree = feeder.bus_tree()
    depth = np.zeros(tree.n_nodes)
    for node in tree.preorder[1:]:
        depth[node] = depth[tree.parent[node]] + 1
    far = int(feeder.buses.index[np.argmax(depth)])
    total = float(feeder.loads.p_kw[rows if rows is not None else slice(None)].sum())
    mw = total / 1000.0
    return make_fleet(
        [
            (feeder.source_bus, 0, 20.0, 10.0 / mw, 0, 2 * total),
            (far, 0, 5.0, 40.0 / mw, 0, 0.8 * total),
        ]
    )


# -- pandapower's own grids ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "factory, kwargs",
    [
        ("create_kerber_landnetz_freileitung_1", {}),
        ("create_kerber_dorfnetz", {}),
        ("create_dickert_lv_network", {}),
        (
            "create_dickert_lv_network",
            dict(feeders_range="long", linetype="C&OHL", customer="multiple", case="bad"),
        ),
    ],
    ids=["kerber-landnetz-freileitung-1", "kerber-dorfnetz", "dickert-lv", "dickert-lv-long"],
)
def test_lv_grids_read_with_pandapowers_totals(factory, kwargs):
    net = getattr(pn, factory)(**kwargs)
    lv = int(net.trafo.lv_bus.iloc[0])
    feeder = read_pandapower(net, fleet=one_gen(lv))
    n_loads, p_kw, q_kvar = own_totals(net)
    assert feeder.source_bus == lv  # the substation transformer's LV side
    assert len(feeder.buses) == len(net.bus) - 1  # the HV bus goes with the transformer
    assert len(feeder.lines) == int(net.line.in_service.sum())
    assert set(feeder.buses.index) == set(net.bus.index) - {int(net.ext_grid.bus.iloc[0])}
    assert len(feeder.loads) == n_loads
    assert feeder.loads.p_kw.sum() == pytest.approx(p_kw, rel=1e-12)
    assert feeder.loads.q_kvar.sum() == pytest.approx(q_kvar, rel=1e-12, abs=1e-9)
    # ratings: sqrt(3) * 0.4 kV * max_i_ka * 1000 at unity power factor
    line = net.line.loc[int(feeder.lines.index[0].removeprefix("line"))]
    expected = SQRT3 * net.bus.vn_kv[line.from_bus] * line.max_i_ka * line.parallel * 1e3
    assert feeder.lines.limit_kw.iloc[0] == pytest.approx(expected)
    assert (feeder.buses.vn_kv == net.bus.vn_kv[lv]).all()  # impedances on the LV side's base
    assert reduce_feeder(feeder).n_nodes >= 2


def test_kerber_without_a_fleet_is_described_and_a_dispatch_asks_for_one():
    described = read_pandapower(pn.create_kerber_landnetz_freileitung_1())
    assert described.generators.empty and len(described.buses) == 14
    with pytest.raises(FleetError, match=r"no generator to dispatch: give a fleet \(--fleet"):
        dc_problem(described)
    with pytest.raises(FleetError, match="give a fleet"):
        dc_problem(cases.load_case("kerber-landnetz-freileitung-1"))
    feeder = cases.load_case("kerber-landnetz-freileitung-1", fleet=one_gen(1))
    assert len(feeder.buses) == 14 and feeder.loads.p_kw.sum() == pytest.approx(104.0)


def test_case33bw_reads_with_its_totals_and_priced_source():
    net = pn.case33bw()
    feeder = read_pandapower(net)
    assert len(feeder.buses) == 33 and len(feeder.lines) == 32 and len(feeder.loads) == 32
    assert feeder.loads.p_kw.sum() == pytest.approx(3715.0, rel=1e-12)
    assert feeder.loads.q_kvar.sum() == pytest.approx(2300.0, rel=1e-12)
    n_loads, p_kw, q_kvar = own_totals(net)
    assert (n_loads, feeder.loads.p_kw.sum()) == (32, pytest.approx(p_kw))
    ties = {f"line{i}" for i in net.line.index[~net.line.in_service]}
    assert len(ties) == 5 and not ties & set(feeder.lines.index)  # tie lines excluded
    assert np.isinf(feeder.lines.limit_kw).all()  # max_i_ka 99999 kA: unlimited
    # the priced ext_grid is the source generator (poly_cost cp1 -> b, max_p_mw -> pmax)
    cost = net.poly_cost.iloc[0]
    assert feeder.generators.index.tolist() == ["ext_grid0"]
    g = feeder.generators.loc["ext_grid0"]
    assert (g.bus, g.b, g.c, g.pmax_kw) == (0, cost.cp1_eur_per_mw, cost.cp2_eur_per_mw2, 1e4)
    ohm = net.line.loc[0]
    assert feeder.lines.loc["line0", "r_ohm"] == pytest.approx(ohm.r_ohm_per_km * ohm.length_km)
    assert cases.load_case("case33bw").generators.index.tolist() == ["ext_grid0"]


def test_case33bw_with_ties_in_service_names_a_loop():
    net = pn.case33bw()
    net.line.in_service = True
    with pytest.raises(FeederError, match=r"^line 'line\d+' closes a loop through buses \[") as e:
        read_pandapower(net)
    assert "\n" not in str(e.value)


def test_ieee_elv_net_reads_like_the_ieee_elv_case():
    """pandapower's own ELV net (asymmetric loads, a transformer from SOURCEBUS) gives the
    ieee-elv feeder: same counts, total, impedances and the paper's 110-node reduction."""
    net = cases._elv_net()
    elv = cases.ieee_elv()
    index_of = pd.Series(net.bus.index, index=net.bus.name)
    paper = elv.generators.assign(bus=index_of[elv.generators.bus.astype(str)].to_numpy())
    feeder = read_pandapower(net, fleet=paper, ratings=False)
    assert (len(feeder.buses), len(feeder.lines), len(feeder.loads)) == (906, 905, 55)
    assert feeder.loads.p_kw.sum() == pytest.approx(cases.elv_snapshot_566_kw().sum(), rel=1e-9)
    assert feeder.lines.r_ohm.sum() == pytest.approx(elv.lines.r_ohm.sum(), rel=1e-12)
    reduced, expected = reduce_feeder(feeder), reduce_feeder(elv)
    assert (reduced.n_nodes, reduced.n_lines) == (expected.n_nodes, expected.n_lines) == (110, 109)


# -- switches, service, loads --------------------------------------------------------------------


def tiny_net():
    """ext_grid 20 kV -- trafo -- LV busbar 1 -- line0 -- 2 -- line1 -- 3, and 2 -- line2 -- 4."""
    net = pp.create_empty_network()
    hv = pp.create_bus(net, 20.0, index=0)
    for b in (1, 2, 3, 4):
        pp.create_bus(net, 0.4, index=b)
    pp.create_ext_grid(net, hv)
    pp.create_transformer(net, hv, 1, "0.4 MVA 20/0.4 kV")
    for a, b in ((1, 2), (2, 3), (2, 4)):
        pp.create_line_from_parameters(
            net, a, b, 0.1, r_ohm_per_km=0.2, x_ohm_per_km=0.1, c_nf_per_km=0, max_i_ka=0.1
        )
    pp.create_load(net, 3, p_mw=0.01, q_mvar=0.002)
    pp.create_load(net, 4, p_mw=0.02, scaling=0.5)
    return net


def test_tiny_net_rules():
    net = tiny_net()
    feeder = read_pandapower(net, fleet=one_gen(1))
    assert feeder.source_bus == 1 and feeder.buses.index.tolist() == [1, 2, 3, 4]
    assert feeder.lines.index.tolist() == ["line0", "line1", "line2"]
    assert feeder.loads.p_kw.tolist() == pytest.approx([10.0, 10.0])  # scaling 0.5 applied
    assert feeder.loads.q_kvar.tolist() == pytest.approx([2.0, 0.0])
    assert feeder.lines.limit_kw.iloc[0] == pytest.approx(SQRT3 * 0.4 * 0.1 * 1e3)
    assert np.isinf(read_pandapower(net, fleet=one_gen(1), ratings=False).lines.limit_kw).all()
    net.line["max_loading_percent"] = 80.0
    limited = read_pandapower(net, fleet=one_gen(1)).lines.limit_kw.iloc[0]
    assert limited == pytest.approx(0.8 * SQRT3 * 0.4 * 0.1 * 1e3)


def test_open_line_switch_and_out_of_service_line_remove_lines():
    net = tiny_net()
    pp.create_switch(net, 2, 2, et="l", closed=False)  # opens line2 (2-4)
    net.load.loc[1, "in_service"] = False  # bus 4 becomes a load-free island: dropped
    feeder = read_pandapower(net, fleet=one_gen(1))
    assert "line2" not in feeder.lines.index and 4 not in feeder.buses.index
    net = tiny_net()
    net.line.loc[2, "in_service"] = False
    with pytest.raises(FeederError, match=r"^buses \[4\] \(1 buses, 1 loads\) form an island"):
        read_pandapower(net, fleet=one_gen(1))
    net.load.loc[1, "in_service"] = False
    assert "line2" not in read_pandapower(net, fleet=one_gen(1)).lines.index


def test_bus_bus_switches_merge_or_separate():
    net = tiny_net()
    pp.create_bus(net, 0.4, index=5)
    pp.create_switch(net, 4, 5, et="b", closed=True)
    pp.create_load(net, 5, p_mw=0.005)
    pp.create_sgen(net, 5, p_mw=0.01, max_p_mw=0.01, min_p_mw=0.0, controllable=True)
    pp.create_poly_cost(net, 0, "sgen", cp1_eur_per_mw=3.0)
    feeder = read_pandapower(net, fleet=make_fleet([(5, 0, 1, 0, 0, 100)]))
    assert 5 not in feeder.buses.index  # merged into bus 4 (the smaller index)
    assert feeder.loads.bus.tolist() == [3, 4, 4]
    assert feeder.generators.bus.tolist() == [4]  # a fleet may name the merged-away bus
    own = read_pandapower(net).generators
    assert own.index.tolist() == ["sgen0"] and own.bus.tolist() == [4]
    assert (own.b.iloc[0], own.pmax_kw.iloc[0]) == (3.0, 10.0)
    net.switch.loc[0, "closed"] = False  # open: bus 5 is an island with a load
    with pytest.raises(FeederError, match=r"^buses \[5\] .* island not connected to source bus 1"):
        read_pandapower(net, fleet=one_gen(1))


def test_closed_switch_across_two_lines_makes_them_parallel_and_merged():
    net = tiny_net()
    pp.create_switch(net, 3, 4, et="b", closed=True)  # 3 and 4 both hang below 2
    feeder = read_pandapower(net, fleet=one_gen(1))
    merged = feeder.lines.loc["line1+line2"]
    z1 = complex(*net.line.loc[1, ["r_ohm_per_km", "x_ohm_per_km"]]) * net.line.length_km[1]
    z2 = complex(*net.line.loc[2, ["r_ohm_per_km", "x_ohm_per_km"]]) * net.line.length_km[2]
    z = z1 * z2 / (z1 + z2)  # parallel impedance, summed ratings
    assert (merged.r_ohm, merged.x_ohm) == pytest.approx((z.real, z.imag), rel=1e-12)
    assert merged.limit_kw == pytest.approx(
        SQRT3 * 0.4 * 1e3 * (net.line.max_i_ka[1] + net.line.max_i_ka[2]), rel=1e-12
    )
    assert len(feeder.lines) == len(feeder.buses) - 1
    net = tiny_net()
    pp.create_switch(net, 2, 3, et="b", closed=True)  # bridges line1's own ends
    with pytest.raises(FeederError, match=r"^'line1' joins buses merged by a closed bus-bus "):
        read_pandapower(net, fleet=one_gen(1))


def test_asymmetric_load_is_the_sum_of_its_phases():
    net = tiny_net()
    pp.create_asymmetric_load(
        net, 4, p_a_mw=0.001, p_b_mw=0.002, p_c_mw=0.004, q_a_mvar=0.001, scaling=2.0
    )
    pp.create_asymmetric_load(net, 3, p_a_mw=1.0, in_service=False)
    loads = read_pandapower(net, fleet=one_gen(1)).loads
    assert loads.index.tolist() == ["load0", "load1", "asymmetric_load0"]
    assert loads.loc["asymmetric_load0", ["bus", "p_kw", "q_kvar"]].tolist() == pytest.approx(
        [4, 14.0, 2.0]
    )


def test_root_keeps_the_substation_transformer_with_each_branch_on_its_own_base():
    net = tiny_net()
    feeder = read_pandapower(net, fleet=one_gen(0), root=0)
    assert feeder.source_bus == 0 and "trafo0" in feeder.lines.index
    t = net.trafo.loc[0]
    z = t.vk_percent / 100 * 0.4**2 / t.sn_mva  # on its LV side, 0.4 kV
    r = t.vkr_percent / 100 * 0.4**2 / t.sn_mva
    trafo = feeder.lines.loc["trafo0"]
    assert (trafo.r_ohm, math.hypot(trafo.r_ohm, trafo.x_ohm)) == pytest.approx((r, z))
    assert trafo.kv_base == 0.4 and trafo.limit_kw == pytest.approx(t.sn_mva * 1e3)
    # the LV line keeps its own ohms; referred to the 20 kV source they are x (20 / 0.4)^2
    assert feeder.lines.loc["line0", ["r_ohm", "kv_base"]].tolist() == pytest.approx([0.02, 0.4])
    on_source = feeder.lines_on_base()
    assert feeder.base_kv == 20.0
    assert on_source.loc["line0", "r_ohm"] == pytest.approx(0.02 * (20 / 0.4) ** 2)
    assert on_source.loc["trafo0", "r_ohm"] == pytest.approx(r * (20 / 0.4) ** 2)


def test_json_file_reads_like_the_net(tmp_path):
    net = tiny_net()
    path = tmp_path / "tiny.json"
    pp.to_json(net, str(path))
    a = read_pandapower(net, fleet=one_gen(1))
    b = read_pandapower(path, fleet=one_gen(1))
    assert b.name == "tiny"
    for table in ("buses", "lines", "loads"):
        pd.testing.assert_frame_equal(getattr(a, table), getattr(b, table))


# -- errors --------------------------------------------------------------------------------------


def test_mv_oberrhein_sources_and_loops():
    net = pn.mv_oberrhein()
    # as shipped its open ring switches make two radial trees, one per HV/MV substation: two
    # feeders, joined at a virtual bus by 0 kW balance lines
    joined = read_pandapower(net, fleet=make_fleet([(39, 0, 10, 0.1, 0, 1e5),
                                                    (319, 0, 12, 0.1, 0, 1e5)]))  # fmt: skip
    assert joined.lines.loc[["balance:39", "balance:319"], "limit_kw"].tolist() == [0.0, 0.0]
    assert joined.source_bus not in net.bus.index
    assert len(joined.lines) == len(joined.buses) - 1
    feeder = read_pandapower(net, root=39, fleet=one_gen(39))
    assert feeder.source_bus == 39 and len(feeder.lines) == len(feeder.buses) - 1
    net.switch.closed = True  # close the rings: one meshed network with both substations
    with pytest.raises(FeederError, match="several sources feed one connected network"):
        read_pandapower(net)
    with pytest.raises(FeederError, match=r"^several sources feed the tree of root bus 39: "):
        read_pandapower(net, root=39, fleet=one_gen(39))
    net.ext_grid.loc[1, "in_service"] = False
    with pytest.raises(FeederError, match=r"^line 'line\d+' closes a loop through buses \[") as e:
        read_pandapower(net, fleet=one_gen(39))
    assert "\n" not in str(e.value)


def test_two_ext_grids_in_one_tree():
    net = tiny_net()
    pp.create_ext_grid(net, 3)
    with pytest.raises(FeederError) as e:
        read_pandapower(net, fleet=one_gen(1))
    assert str(e.value) == (
        "several sources feed one connected network (ext_grid 0 via trafo0 at bus 1, ext_grid 1 "
        "at bus 3): popdispatch supports one source per radial feeder; take the others out of "
        "service"
    )
    net.ext_grid.loc[1, "in_service"] = False
    assert read_pandapower(net, fleet=one_gen(1)).source_bus == 1


def test_unsupported_elements_name_themselves():
    net = tiny_net()
    pp.create_bus(net, 10.0, index=6)
    pp.create_transformer3w(net, 0, 6, 1, "63/25/38 MVA 110/20/10 kV")
    with pytest.raises(FeederError, match=r"^unsupported element trafo3w 0 \(three-winding "):
        read_pandapower(net, fleet=one_gen(1))
    net.trafo3w.in_service = False
    read_pandapower(net, fleet=one_gen(1))
    pp.create_impedance(net, 3, 4, rft_pu=0.1, xft_pu=0.1, sn_mva=1.0)
    with pytest.raises(FeederError, match=r"^unsupported element impedance 0 \(impedance"):
        read_pandapower(net, fleet=one_gen(1))


def test_generators_without_costs_are_fixed_injections():
    net = tiny_net()
    pp.create_sgen(net, 3, p_mw=0.01, scaling=0.5)
    feeder = read_pandapower(net)
    assert feeder.generators.empty  # nothing priced: described, not dispatched
    injection = feeder.loads.loc["sgen0"]
    assert (injection.bus, injection.p_kw, injection.kind) == (3, pytest.approx(-5.0), "sgen")
    with_fleet = read_pandapower(net, fleet=one_gen(1))
    assert with_fleet.loads.loc["sgen0", "p_kw"] == pytest.approx(-5.0)
    problem = dc_problem(with_fleet)
    gross = float(feeder.loads.p_kw[feeder.loads.p_kw > 0].sum())
    assert problem.fixed_injection[0] * 1e3 == pytest.approx(5.0)
    assert problem.demand[0] * 1e3 == pytest.approx(gross - 5.0)
    pp.create_poly_cost(net, 0, "sgen", cp1_eur_per_mw=1.0, cp2_eur_per_mw2=0.5)
    fleet = read_pandapower(net).generators
    assert fleet.loc["sgen0"].tolist() == [3, 0.0, 1.0, 0.5, 0.0, 10.0]  # pmax from p_mw
    assert "sgen0" not in read_pandapower(net).loads.index  # priced: dispatched, not fixed


def test_storage_and_ext_grid_fleet_rules():
    net = tiny_net()
    pp.create_storage(net, 3, p_mw=0.0, max_e_mwh=0.1, max_p_mw=0.002, min_p_mw=-0.005)
    pp.create_poly_cost(net, 0, "storage", cp1_eur_per_mw=-4.0, cp2_eur_per_mw2=0.5)
    pp.create_poly_cost(net, 0, "ext_grid", cp1_eur_per_mw=30.0)
    fleet = read_pandapower(net).generators
    # storage in load convention: discharging up to 5 kW, b = -cp1
    assert fleet.loc["storage0"].tolist() == [3, 0.0, 4.0, 0.5, 0.0, 5.0]
    # the ext_grid behind the substation transformer is a generator at the source, its pmax
    # (no max_p_mw) the transformer's 0.4 MVA
    assert fleet.loc["ext_grid0"].tolist() == [1, 0.0, 30.0, 0.0, 0.0, 400.0]


# -- the DC-OPF and exact mode ------------------------------------------------------------------


def test_dc_opf_on_case33bw_equals_pandapower_rundcopp():
    net = pn.case33bw()  # its priced ext_grid (20 EUR/MWh, 0-10 MW) is our source generator
    for bus, b, c, pmax in [(17, 5.0, 2.0, 2.0), (32, 8.0, 1.0, 1.5), (24, 12.0, 3.0, 2.0)]:
        g = pp.create_gen(net, bus, p_mw=0.0, vm_pu=1.0, min_p_mw=0.0, max_p_mw=pmax,
                          controllable=True)  # fmt: skip
        pp.create_poly_cost(net, g, "gen", cp1_eur_per_mw=b, cp2_eur_per_mw2=c)
    line = net.line.index[(net.line.from_bus == 16) & (net.line.to_bus == 17)][0]
    net.line.loc[line, "max_i_ka"] = 0.5 / (SQRT3 * 12.66)  # 500 kW at 12.66 kV
    feeder = read_pandapower(net)
    assert feeder.lines.loc[f"line{line}", "limit_kw"] == pytest.approx(500.0)
    ours = solve_opf(dc_problem(feeder), 1)
    assert ours.status == "optimal"
    assert abs(ours.line_price).max() > 1.0  # the 500 kW limit binds
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    assert net.OPF_converged
    theirs = np.concatenate([net.res_gen.p_mw.to_numpy(), net.res_ext_grid.p_mw.to_numpy()]) * 1e3
    assert feeder.generators.index.tolist() == ["gen0", "gen1", "gen2", "ext_grid0"]
    np.testing.assert_allclose(ours.p_kw, theirs, rtol=1e-6)
    assert ours.cost == pytest.approx(net.res_cost, rel=1e-6)
    assert abs(net.res_line.p_from_mw[line]) * 1e3 == pytest.approx(500.0, rel=1e-6)


@pytest.mark.parametrize("limit_kw", [None, 30.0], ids=["free", "binding"])
def test_exact_mode_on_kerber_lands_on_the_dc_opf(limit_kw):
    fleet = make_fleet([(1, 0, 20.0, 0.5, 0, 200), (8, 0, 5.0, 20.0, 0, 60),
                        (14, 0, 8.0, 10.0, 0, 60)])  # fmt: skip
    feeder = cases.load_case("kerber-landnetz-freileitung-1", fleet=fleet)
    if limit_kw is not None:
        feeder = feeder.with_line_limits(pd.Series({"line12": limit_kw}))  # into bus 14
    problem = dc_problem(feeder)
    opf = solve_opf(problem, 1)
    assert (abs(opf.line_price).max() > 1e-6) == (limit_kw is not None)
    snap = run_snapshot(problem, 1, RunSettings(mode="exact"))
    np.testing.assert_allclose(snap.setpoints_kw, opf.p_kw, atol=1e-3)


def test_exact_mode_on_kerber_with_a_binding_limit_converges():
    fleet = make_fleet([(1, 0, 20.0, 0.5, 0, 200), (8, 0, 5.0, 20.0, 0, 60),
                        (14, 0, 8.0, 10.0, 0, 60)])  # fmt: skip
    feeder = cases.load_case("kerber-landnetz-freileitung-1", fleet=fleet)
    feeder = feeder.with_line_limits(pd.Series({"line12": 30.0}))
    snap = run_snapshot(dc_problem(feeder), 1, RunSettings(mode="exact"))
    assert snap.status == "converged"


@pytest.mark.parametrize("name", [n for n in cases.CASES if n != "ieee-elv"])
def test_every_pandapower_case_runs_an_exact_snapshot(name):
    feeder = cases.load_case(name, fleet=small_fleet(cases.CASES[name].loader(None)))
    problem = dc_problem(feeder)
    opf = solve_opf(problem, 1)
    snap = run_snapshot(problem, 1, RunSettings(mode="exact"))
    assert snap.status == "converged"
    tolerance = max(1e-6 * opf.demand_kw, 1e-3)
    np.testing.assert_allclose(snap.setpoints_kw, opf.p_kw, atol=tolerance)


def test_list_cases_counts_and_totals(monkeypatch):
    subset = {n: cases.CASES[n] for n in ("kerber-landnetz-freileitung-1", "case33bw")}
    monkeypatch.setattr(cases, "CASES", subset)
    monkeypatch.setattr(cases, "simbench_available", lambda: False)
    monkeypatch.setattr(cases, "available_big_cases", lambda: [])
    table = cases.list_cases()
    assert table.index.tolist() == ["kerber-landnetz-freileitung-1", "case33bw"]
    assert table.loc["case33bw", ["buses", "lines", "loads"]].tolist() == [33, 32, 32]
    assert table.loc["case33bw", "total_load_kw"] == pytest.approx(3715.0)
    assert table.loc["kerber-landnetz-freileitung-1", "total_load_kw"] == pytest.approx(104.0)
    assert table.source.str.startswith("pandapower.networks.").all()
    # the counts are cached: a second listing reads no network
    monkeypatch.setattr(cases, "_case_counts", lambda names: pytest.fail("read again"))
    pd.testing.assert_frame_equal(cases.list_cases(), table)


@pytest.mark.parametrize(
    "code, n_buses", [("1-LV-rural1--0-sw", 14), ("1-MV-rural--0-sw", 94)], ids=["LV", "MV"]
)
def test_simbench_grids_read_when_installed(code, n_buses):
    sb = pytest.importorskip("simbench", reason="the optional simbench extra is not installed")
    net = sb.get_simbench_net(code)
    described = cases.load_case(f"simbench:{code}")
    assert described.generators.empty  # its PV and wind have no cost data: fixed injections
    sgens = net.sgen[net.sgen.in_service]
    injected = described.loads[described.loads.kind == "sgen"]
    assert len(injected) == len(sgens)
    assert injected.p_kw.sum() == pytest.approx(-(sgens.p_mw * sgens.scaling).sum() * 1e3)
    lv = int(net.trafo.lv_bus.min())
    feeder = read_pandapower(net, fleet=one_gen(lv))
    n_loads, p_kw, _ = own_totals(net)
    assert (len(feeder.buses), len(feeder.lines)) == (n_buses, n_buses - 1)
    loads = feeder.loads[feeder.loads.kind == "load"]
    assert (len(loads), loads.p_kw.sum()) == (n_loads, pytest.approx(p_kw))
    loads_only = feeder.loads.kind == "load"
    feeder = cases.load_case(f"simbench:{code}", fleet=small_fleet(feeder, loads_only))
    problem = dc_problem(feeder, injections=False)
    opf = solve_opf(problem, 1)
    snap = run_snapshot(problem, 1, RunSettings(mode="exact"))
    assert snap.status == "converged"
    tolerance = max(1e-6 * opf.demand_kw, 1e-3)
    np.testing.assert_allclose(snap.setpoints_kw, opf.p_kw, atol=tolerance)
