"""The MATPOWER case reader (popdispatch.readers.matpower).

The radial cases come from ``../shared/feeders/matpower`` (or ``$POPDISPATCH_FEEDERS/matpower``).
Expected totals are recomputed here from the raw numbers of the files (kW and ohm as written,
before the files' own conversion statements), with a regular expression independent of the
reader; the DC-OPF is compared with pandapower's ``rundcopp`` on a net built here from those
raw numbers.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch.errors import FeederError, FleetError
from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem, build_problem_from_loads
from popdispatch.opf import solve_opf
from popdispatch.readers import read_matpower
from popdispatch.readers.matpower import IDX_FUNCTIONS, parse_matpower

FEEDERS_ENV = "POPDISPATCH_FEEDERS"
_DEFAULT = Path(__file__).resolve().parents[3] / "shared" / "feeders"
FEEDERS = Path(os.environ.get(FEEDERS_ENV) or _DEFAULT)
MATPOWER = FEEDERS / "matpower"
CASES = ["case22", "case33bw", "case69", "case85"]
needs_cases = pytest.mark.skipif(
    not all((MATPOWER / f"{case}.m").is_file() for case in CASES),
    reason=f"MATPOWER test cases not found in {MATPOWER} (set {FEEDERS_ENV} to the folder holding "
    "matpower/case22.m, case33bw.m, case69.m, case85.m)",
)


def raw_matrix(path: Path, name: str) -> np.ndarray:
    """The numbers of ``mpc.<name> = [...]`` exactly as written in the file (no conversion)."""
    text = path.read_text()
    body = re.search(rf"mpc\.{name}\s*=\s*\[(.*?)\];", text, re.S).group(1)
    rows = []
    for line in body.splitlines():
        line = line.split("%")[0].strip().rstrip(";")
        if line:
            rows.append([float(v) for v in line.split()])
    return np.array(rows)


def case_path(case: str) -> Path:
    return MATPOWER / f"{case}.m"


# -- totals ----------------------------------------------------------------------------------


@needs_cases
def test_case33bw_reads_with_published_totals():
    feeder = read_matpower(case_path("case33bw"))
    assert feeder.name == "case33bw" and feeder.source_bus == 1
    assert len(feeder.buses) == 33 and len(feeder.lines) == 32 and len(feeder.loads) == 32
    assert feeder.loads.p_kw.sum() == pytest.approx(3715.0, rel=1e-12)
    assert feeder.loads.q_kvar.sum() == pytest.approx(2300.0, rel=1e-12)
    # the five tie lines (out of service) are not part of the feeder
    for tie in ("L21-8", "L9-15", "L12-22", "L18-33", "L25-29"):
        assert tie not in feeder.lines.index
    assert feeder.lines.loc["L1-2", ["r_ohm", "x_ohm"]].tolist() == pytest.approx([0.0922, 0.047])
    assert (feeder.lines.length_km == 0).all() and np.isinf(feeder.lines.limit_kw).all()
    assert feeder.loads.loc["load18", ["bus", "p_kw", "q_kvar"]].tolist() == pytest.approx(
        [18, 90.0, 40.0]
    )
    assert (feeder.loads.kind == "load").all()
    assert (feeder.buses.vn_kv == 12.66).all()  # the file's BASE_KV (the AC check's base)
    g = feeder.generators.loc["G1"]
    assert (g.bus, g.a, g.b, g.c, g.pmin_kw, g.pmax_kw) == (1, 0.0, 20.0, 0.0, 0.0, 10000.0)


@needs_cases
@pytest.mark.parametrize("case", CASES)
def test_totals_equal_the_raw_file_numbers(case):
    path = case_path(case)
    bus, branch = raw_matrix(path, "bus"), raw_matrix(path, "branch")
    in_service = branch[branch[:, 10] != 0]
    feeder = read_matpower(path)
    # loads are written in kW/kvar in these files
    assert feeder.loads.p_kw.sum() == pytest.approx(bus[:, 2].sum(), rel=1e-12)
    assert feeder.loads.q_kvar.sum() == pytest.approx(bus[bus[:, 2] > 0, 3].sum(), rel=1e-12)
    assert len(feeder.loads) == int((bus[:, 2] > 0).sum())
    assert len(feeder.buses) == len(bus) and len(feeder.lines) == len(in_service)
    assert len(feeder.lines) == len(feeder.buses) - 1
    # impedances are written in ohm: the reader's p.u. (after the file's statements) x Z_base
    np.testing.assert_allclose(feeder.lines.r_ohm, in_service[:, 2], rtol=1e-12)
    np.testing.assert_allclose(feeder.lines.x_ohm, in_service[:, 3], rtol=1e-12)
    # ... and the matrices after the file's statements are in MW and p.u., as MATPOWER has them
    base_mva, mpc = parse_matpower(path)
    assert base_mva == raw_scalar(path, "baseMVA")
    z_base = bus[0, 9] ** 2 / base_mva
    np.testing.assert_allclose(mpc["branch"][:, 2:4], branch[:, 2:4] / z_base, rtol=1e-12)
    np.testing.assert_allclose(mpc["bus"][:, 2:4], bus[:, 2:4] / 1000, rtol=1e-12)
    assert feeder.source_bus == int(bus[bus[:, 1] == 3, 0][0])


def raw_scalar(path: Path, name: str) -> float:
    return float(re.search(rf"mpc\.{name}\s*=\s*([\d.eE+-]+);", path.read_text()).group(1))


# -- DC-OPF against pandapower ----------------------------------------------------------------


def dispatch_fleet(feeder) -> pd.DataFrame:
    """The source and three DGs with distinct costs and capacities scaled to the demand."""
    demand_mw = feeder.loads.p_kw.sum() / 1000
    buses = feeder.buses.index.sort_values()
    n = len(buses)
    rows = [
        (feeder.source_bus, 1.0, 20.0, 2.0 / demand_mw, 0.0, 10_000.0),
        (int(buses[n // 3]), 0.5, 30.0, 10.0 / demand_mw, 0.0, 250.0 * demand_mw),
        (int(buses[2 * n // 3]), 0.0, 32.0, 20.0 / demand_mw, 0.0, 150.0 * demand_mw),
        (int(buses[-1]), 0.2, 25.0, 40.0 / demand_mw, 0.0, 50.0 * demand_mw),
    ]
    return make_fleet(rows)


def pandapower_dcopp(path: Path, fleet: pd.DataFrame, limit_kw: float):
    """``rundcopp`` on a net built from the raw file numbers (kW, ohm as written); line 1-2
    limited to ``limit_kw`` through ``max_i_ka`` at 100 % loading (DC: |P| <= sqrt(3) V I)."""
    import pandapower as pp

    bus, branch = raw_matrix(path, "bus"), raw_matrix(path, "branch")
    net = pp.create_empty_network(sn_mva=1.0)
    for row in bus:
        pp.create_bus(net, vn_kv=row[9], index=int(row[0]))
    for row in branch[branch[:, 10] != 0]:
        a, b = int(row[0]), int(row[1])
        kv = bus[bus[:, 0] == a, 9][0]
        max_i_ka = limit_kw / 1000 / (math.sqrt(3) * kv) if (a, b) == (1, 2) else 1000.0
        pp.create_line_from_parameters(
            net, a, b, length_km=1.0, r_ohm_per_km=row[2], x_ohm_per_km=max(row[3], 1e-6),
            c_nf_per_km=0.0, max_i_ka=max_i_ka, max_loading_percent=100.0,
        )  # fmt: skip
    for row in bus[bus[:, 2] > 0]:
        pp.create_load(net, int(row[0]), p_mw=row[2] / 1000, q_mvar=row[3] / 1000)
    elements = []
    for name, g in fleet.iterrows():
        limits = dict(min_p_mw=g.pmin_kw / 1000, max_p_mw=g.pmax_kw / 1000, controllable=True)
        if name == fleet.index[0]:
            index, kind = pp.create_ext_grid(net, int(g.bus), **limits), "ext_grid"
        else:
            index, kind = pp.create_gen(net, int(g.bus), p_mw=0.0, **limits), "gen"
        pp.create_poly_cost(net, index, kind, cp0_eur=g.a, cp1_eur_per_mw=g.b, cp2_eur_per_mw2=g.c)
        elements.append((kind, index))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    assert net.OPF_converged
    p_mw = [
        net.res_ext_grid.p_mw[i] if kind == "ext_grid" else net.res_gen.p_mw[i]
        for kind, i in elements
    ]
    flow_12 = net.res_line.p_from_mw[(net.line.from_bus == 1) & (net.line.to_bus == 2)].iloc[0]
    return np.array(p_mw) * 1000, net.res_cost, flow_12 * 1000


@needs_cases
@pytest.mark.parametrize("case", CASES)
def test_dc_opf_equals_pandapower_rundcopp(case):
    path = case_path(case)
    feeder = read_matpower(path)
    fleet = dispatch_fleet(feeder)
    demand_kw = feeder.loads.p_kw.sum()
    limit_kw = 0.7 * demand_kw
    feeder = feeder.with_generators(fleet).with_line_limits(pd.Series({"L1-2": limit_kw}))
    profiles = single_minute_profiles(1, feeder.loads.p_kw, f"{case} loads")
    problem = build_problem(reduce_feeder(feeder), profiles)
    ours = solve_opf(problem, 1)
    assert ours.status == "optimal"
    assert ours.demand_kw == pytest.approx(demand_kw, rel=1e-12)
    assert np.abs(ours.line_price).max() > 0  # the limit binds
    theirs_kw, theirs_cost, flow_kw = pandapower_dcopp(path, fleet, limit_kw)
    assert flow_kw == pytest.approx(limit_kw, rel=1e-6)  # binding in pandapower too
    np.testing.assert_allclose(ours.p_kw, theirs_kw, rtol=1e-6, atol=1e-6 * demand_kw)
    assert ours.cost == pytest.approx(theirs_cost, rel=1e-6)
    assert ours.p_kw[0] == pytest.approx(limit_kw, rel=1e-6)  # the source supplies the limit


# -- errors ----------------------------------------------------------------------------------


def with_lines(tmp_path: Path, case: str, extra: str, name: str = "edited") -> Path:
    """A copy of ``case`` with ``extra`` appended; returns its path."""
    text = case_path(case).read_text()
    path = tmp_path / f"{name}.m"
    path.write_text(text + extra)
    return path


@needs_cases
def test_unknown_statement_is_refused_with_its_line(tmp_path):
    lines = case_path("case33bw").read_text().splitlines()
    path = with_lines(
        tmp_path, "case33bw", "\n% a comment\nmpc.bus(:, QD) = mpc.bus(:, PD) * pf;\n"
    )
    line = len(lines) + 3
    with pytest.raises(
        FeederError, match=rf"edited\.m:{line}: unknown name 'pf'.*mpc\.bus\(:, QD\)"
    ):
        read_matpower(path)
    path = with_lines(tmp_path, "case33bw", "\nfor k = 1:3\n")
    with pytest.raises(FeederError, match=rf"edited\.m:{len(lines) + 2}: .*'for k = 1:3'"):
        read_matpower(path)
    path = with_lines(tmp_path, "case33bw", "\nmpc.dcline = [1 2 3];\n")
    with pytest.raises(FeederError, match=r"unsupported MATPOWER field mpc\.dcline"):
        read_matpower(path)


@needs_cases
def test_tie_line_switched_in_gives_the_loop_error(tmp_path):
    # row 33 of mpc.branch is the tie line 21-8
    path = with_lines(tmp_path, "case33bw", "\nmpc.branch(33, BR_STATUS) = 1;\n")
    with pytest.raises(FeederError, match=r"line 'L21-8' closes a loop through buses \[21, "):
        read_matpower(path)


@needs_cases
def test_two_reference_buses_in_one_tree_are_named(tmp_path):
    path = with_lines(tmp_path, "case33bw", "\nmpc.bus(5, BUS_TYPE) = REF;\n")
    with pytest.raises(FeederError, match=r"reference buses \[1, 5\] feed one connected network"
                       r".*pick one \(--root BUS\)$"):  # fmt: skip
        read_matpower(path)
    assert read_matpower(path, root=5).source_bus == 5


@needs_cases
def test_generator_without_cost_is_left_out_and_a_dispatch_asks_for_a_fleet(tmp_path):
    text = case_path("case33bw").read_text()
    path = tmp_path / "nocost.m"
    path.write_text(re.sub(r"mpc\.gencost\s*=\s*\[.*?\];", "", text, flags=re.S))
    with pytest.warns(UserWarning, match=r"left out of the fleet: generator 1 at bus 1 has no "
                      r"cost data .*--fleet FILE"):  # fmt: skip
        described = read_matpower(path)
    assert described.generators.empty and len(described.buses) == 33
    with pytest.raises(FleetError, match=r"no generator to dispatch: give a fleet"):
        build_problem_from_loads(reduce_feeder(described), [described.loads.p_kw], "own")
    fleet = make_fleet([(1, 0.0, 10.0, 0.0, 0.0, 5000.0), (18, 0.0, 5.0, 1.0, 0.0, 100.0)])
    feeder = read_matpower(path, fleet=fleet)
    assert feeder.generators.index.tolist() == ["G1", "G18"]


# -- the little MATLAB interpreter, on hand-written files -------------------------------------

SMALL = """function mpc = small
%SMALL  three buses, hand-written
%{
block comment: mpc.bus = [ is ignored
%}
mpc.version = '2';
mpc.baseMVA = 100;
mpc.bus = [
\t1\t3\t0\t0\t0\t0\t1\t1\t0\t20\t1\t1.1\t0.9;
\t2\t1\t1500\t500\t0\t0\t1\t1\t0\t20\t1\t1.1\t0.9
\t3, 1, 2500, 0, 0, 0, 1, 1, 0, 20, 1, 1.1, 0.9;   % commas work too
];
mpc.gen = [
\t1\t0\t0\t0\t0\t1\t100\t1\t50\t0;
\t3\t0\t0\t0\t0\t1\t100\t1\t3\t1;
\t2\t0\t0\t0\t0\t1\t100\t0\t3\t1;
];
mpc.branch = [
\t1\t2\t2\t4\t0\t4\t0\t0\t0\t0\t1\t-360\t360;
\t2\t3\t1\t1\t0\t0\t0\t0\t0\t0\t1\t-360\t360;
\t1\t3\t1\t1\t0\t9\t0\t0\t0\t0\t0\t-360\t360;
];
mpc.gencost = [
\t2\t0\t0\t3\t0.01\t20\t5;
\t2\t0\t0\t2\t30\t0\t0;
\t2\t0\t0\t1\t0\t0\t0;
];
define_constants;
Zb = (mpc.bus(1, BASE_KV) ...  a continued line
      * 1e3)^2 / (mpc.baseMVA * 1e6);
mpc.branch(:, [BR_R, BR_X]) = mpc.branch(:, [BR_R BR_X]) / Zb;
mpc.bus(:, [PD QD]) = mpc.bus(:, [PD QD]) ./ 1e3; mpc.bus(2, QD) = -(-2^2) / 1e3;
"""


def test_small_case_is_interpreted(tmp_path):
    path = tmp_path / "small.m"
    path.write_text(SMALL)
    base_mva, mpc = parse_matpower(path)
    assert base_mva == 100
    np.testing.assert_allclose(mpc["bus"][:, 2], [0.0, 1.5, 2.5])
    np.testing.assert_allclose(mpc["bus"][:, 3], [0.0, 0.004, 0.0])  # -(-2^2) = 4 (kvar)
    np.testing.assert_allclose(mpc["branch"][:2, 2:4], [[2 / 4, 4 / 4], [1 / 4, 1 / 4]])
    feeder = read_matpower(path)
    assert feeder.lines.index.tolist() == ["L1-2", "L2-3"]
    np.testing.assert_allclose(feeder.lines.r_ohm, [2.0, 1.0])  # back in ohm (Z_base 4 ohm)
    assert feeder.lines.limit_kw.tolist() == [4000.0, math.inf]  # RATE_A 4 MVA; 0 = unlimited
    assert np.isinf(read_matpower(path, ratings=False).lines.limit_kw).all()
    assert feeder.loads.p_kw.tolist() == pytest.approx([1500.0, 2500.0])
    fleet = feeder.generators  # the third generator is out of service
    assert fleet.index.tolist() == ["G1", "G3"]
    assert fleet.loc["G1", ["a", "b", "c", "pmax_kw"]].tolist() == [5.0, 20.0, 0.01, 50_000.0]
    assert fleet.loc["G3", ["a", "b", "c", "pmin_kw"]].tolist() == [0.0, 30.0, 0.0, 1000.0]
    assert feeder.buses.loc[3, ["x", "y"]].tolist() == [2.0, 0.0]  # two hops from the source


@pytest.mark.parametrize(
    ("statement", "message"),
    [
        ("mpc.bus(:, PD) = mpc.bus(:, PD) * mpc.bus(:, QD);", "matrix '\\*'"),
        ("mpc.bus(4, PD) = 1;", "row index 4 is not an integer in 1..3"),
        ("x = mpc.bus(:, PD);", "x is not a scalar"),
        ("mpc.bus(:, PD) = eval('1');", "unknown name 'eval'"),
        ("mpc.version = '1';", "version '1'"),
        ("mpc.gencost(3, :) = [1 0 0 2 1 1];", r"cannot assign a \(1, 6\) block"),
    ],
)
def test_statements_outside_the_subset_are_refused(tmp_path, statement, message):
    path = tmp_path / "small.m"
    path.write_text(SMALL + statement + "\n")
    line = SMALL.count("\n") + 1
    with pytest.raises(FeederError, match=rf"small\.m:{line}: .*{message}"):
        parse_matpower(path)


def test_idx_names_match_pandapowers_pypower():
    from pandapower.pypower import idx_brch, idx_bus, idx_cost, idx_gen

    modules = {"idx_bus": idx_bus, "idx_brch": idx_brch, "idx_gen": idx_gen, "idx_cost": idx_cost}
    for function, outputs in IDX_FUNCTIONS.items():
        for name, value in outputs:
            expected = getattr(modules[function], name)
            if name not in ("PQ", "PV", "REF", "NONE", "PW_LINEAR", "POLYNOMIAL"):
                expected += 1  # pypower's column indices are 0-based
            assert value == expected, (function, name)


@needs_cases
def test_root_picks_one_tree_and_load_free_islands_are_dropped(tmp_path):
    # branch 1 (1-2) opened and bus 2 made a reference bus: two separate feeders
    split = "\nmpc.branch(1, BR_STATUS) = 0;\nmpc.bus(2, BUS_TYPE) = REF;\n"
    path = with_lines(tmp_path, "case33bw", split)
    joined = read_matpower(path, fleet=make_fleet([(1, 0, 10, 0, 0, 1), (2, 0, 10, 0, 0, 5000)]))
    assert joined.lines.loc[["balance:1", "balance:2"], "limit_kw"].tolist() == [0.0, 0.0]
    fleet = make_fleet([(2, 0.0, 10.0, 0.0, 0.0, 5000.0)])
    feeder = read_matpower(path, root=2, fleet=fleet)
    assert feeder.source_bus == 2 and len(feeder.buses) == 32 and len(feeder.lines) == 31
    assert feeder.loads.p_kw.sum() == pytest.approx(3715.0)
    # an island without load (bus 1 alone, once no longer a reference bus) is dropped
    path = with_lines(tmp_path, "case33bw", split + "mpc.bus(1, BUS_TYPE) = PQ;\n")
    assert len(read_matpower(path, fleet=fleet).buses) == 32
    # ... but an island with load is reported
    path = with_lines(tmp_path, "case33bw", split + "mpc.bus(1, [BUS_TYPE PD]) = [PQ 5];\n")
    with pytest.raises(FeederError, match=r"bus 1 is not connected to source bus 2"):
        read_matpower(path, fleet=fleet)
