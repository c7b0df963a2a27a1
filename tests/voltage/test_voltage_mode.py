"""Voltage limits in exact mode (issue 14 part 2): the voltage mode against the LinDistFlow OPF,
and the LinDistFlow OPF against an independent formulation of the same problem.

The independent formulation writes LinDistFlow from the bus voltages: line flows are the sums of
the net injections below each line (a walk over the feeder's line table), and ``v_to^2 =
v_from^2 - 2 (r P + x Q) / Z_base`` down every line from the source, at *every* bus (not only
the key nodes the engine monitors), without the sensitivity matrix. The OPF's solution is
checked as a KKT point of that problem with its own duals, and its cost against scipy's SLSQP.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pandapower", reason="case33bw comes from pandapower's networks")

from scipy.optimize import minimize  # noqa: E402

from popdispatch.ac.lindistflow import check_voltage_limits, with_voltage_limits  # noqa: E402
from popdispatch.ac.network import load_q_per_kw, nominal_kv  # noqa: E402
from popdispatch.errors import OptionError  # noqa: E402
from popdispatch.game.problem import KW_PER_MW  # noqa: E402
from popdispatch.integrate import Integrator  # noqa: E402
from popdispatch.modes import get_mode  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402
from popdispatch.online.kkt import KktTolerances, kkt_violations  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402
from popdispatch.runs import run_snapshot_vs_opf  # noqa: E402
from popdispatch.scenarios import VOLTAGE_LIMITS, voltage_problems  # noqa: E402

VMIN, VMAX = VOLTAGE_LIMITS
#: Clarabel runs with gap and feasibility tolerances 1e-10 (opf.py) on an objective scaled to
#: EUR/MW per kW: stationarity holds to that times the largest marginal cost, EUR/MW.
SOLVER_TOL = 1e-10


@pytest.fixture(scope="module")
def problems():
    return voltage_problems()


def independent_v_sq(feeder, load_kw: np.ndarray, gen_kw: np.ndarray) -> np.ndarray:
    """LinDistFlow squared voltages (p.u.^2) of every bus, from a walk down the line table."""
    kv = nominal_kv(feeder)
    z_base = kv**2 * 1e3  # ohm, on a 1 kVA base: powers in kW
    ratio, _ = load_q_per_kw(feeder)
    p_inj = {b: 0.0 for b in feeder.buses.index}
    q_inj = dict(p_inj)
    for (_, load), kw, q in zip(feeder.loads.iterrows(), load_kw, ratio, strict=True):
        p_inj[load.bus] -= kw
        q_inj[load.bus] -= kw * q
    for (_, g), kw in zip(feeder.generators.iterrows(), gen_kw, strict=True):
        p_inj[g.bus] += kw
    children: dict[int, list] = {b: [] for b in feeder.buses.index}
    for _, ln in feeder.lines.iterrows():
        children[ln.from_bus].append((ln.to_bus, ln))
        children[ln.to_bus].append((ln.from_bus, ln))
    order, parent_line, seen = [feeder.source_bus], {}, {feeder.source_bus}
    for bus in order:
        for other, ln in children[bus]:
            if other not in seen:
                seen.add(other)
                parent_line[other] = (bus, ln)
                order.append(other)
    below_p, below_q = dict(p_inj), dict(q_inj)
    for bus in reversed(order[1:]):
        up = parent_line[bus][0]
        below_p[up] += below_p[bus]
        below_q[up] += below_q[bus]
    v_sq = {feeder.source_bus: 1.0}
    for bus in order[1:]:
        up, ln = parent_line[bus]
        # flow down the line = -(net injection below it)
        v_sq[bus] = v_sq[up] + 2.0 * (ln.r_ohm * below_p[bus] + ln.x_ohm * below_q[bus]) / z_base
    return np.array([v_sq[b] for b in feeder.buses.index])


def test_lindistflow_opf_is_a_kkt_point_of_the_independent_formulation(problems):
    _, problem, load_kw = problems
    feeder = problem.feeder.original
    opf = solve_opf(problem, 1)
    assert opf.status == "optimal"
    p = opf.p_kw

    def v_sq(p_kw):
        return independent_v_sq(feeder, load_kw[0], p_kw)

    # primal feasibility at every bus
    assert v_sq(p).min() >= VMIN**2 - 1e-9
    assert v_sq(p).max() <= VMAX**2 + 1e-9
    # the rows' gradient by differences of the independent (linear) model, p.u.^2 per MW
    grad = np.array([(v_sq(p + e) - v_sq(p)) for e in np.eye(len(p))]).T * KW_PER_MW
    bus_pos = feeder.buses.index.get_indexer(problem.voltage_buses)
    # the OPF's prices are the duals of the rows scaled by s_j: dual = price / s_j
    dual = opf.voltage_price / problem.voltage_scale
    assert np.sum(np.abs(opf.voltage_price) > 1e-6) >= 1  # some voltage limit binds
    for j, d in enumerate(dual):
        # complementary slackness: a priced bus sits at its bound (an interior point leaves
        # the others a price of the order of its tolerance)
        if abs(opf.voltage_price[j]) > 1e-6:
            bound = VMIN**2 if d > 0 else VMAX**2
            assert abs(v_sq(p)[bus_pos[j]] - bound) < 1e-9
    lmc = problem.b + 2 * problem.c * p / KW_PER_MW - dual @ grad[bus_pos]
    inside = (p > problem.pmin * KW_PER_MW + 1e-6) & (p < problem.pmax * KW_PER_MW - 1e-6)
    scale = float(np.max(problem.b + 2 * problem.c * problem.pmax))
    assert np.ptp(lmc[inside]) < 1e3 * SOLVER_TOL * scale * len(p)
    lam = float(np.mean(lmc[inside]))
    at_min = p <= problem.pmin * KW_PER_MW + 1e-6
    assert np.all(lmc[at_min] >= lam - 1e-6)  # nobody at Pmin would rather produce
    assert abs(lam - opf.marginal_price) < 1e-6 * scale


def test_lindistflow_opf_cost_matches_scipy_on_the_independent_formulation(problems):
    _, problem, load_kw = problems
    feeder = problem.feeder.original
    opf = solve_opf(problem, 1)
    demand = float(load_kw[0].sum())

    def cost(p_kw):
        p = p_kw / KW_PER_MW
        return float(np.sum(problem.b * p + problem.c * p**2))

    constraints = [
        {"type": "eq", "fun": lambda p: p.sum() - demand},
        {"type": "ineq", "fun": lambda p: independent_v_sq(feeder, load_kw[0], p) - VMIN**2},
        {"type": "ineq", "fun": lambda p: VMAX**2 - independent_v_sq(feeder, load_kw[0], p)},
    ]
    bounds = list(zip(problem.pmin * KW_PER_MW, problem.pmax * KW_PER_MW, strict=True))
    start = np.array([demand, 0, 0, 0, 0], dtype=float)
    found = minimize(cost, start, method="SLSQP", bounds=bounds, constraints=constraints,
                     options={"ftol": 1e-14, "maxiter": 500})  # fmt: skip
    assert found.success, found.message
    assert abs(cost(found.x) - opf.cost) <= 1e-7 * opf.cost
    assert np.max(np.abs(found.x - opf.p_kw)) < 0.05  # SLSQP's own accuracy, kW


def test_voltage_mode_equals_the_lindistflow_opf(problems):
    _, problem, _ = problems
    settings = RunSettings(mode="exact", vmin_pu=VMIN, vmax_pu=VMAX)
    assert settings.mode == "voltage"
    result = run_snapshot_vs_opf(problem, 1, settings)
    assert result.run.status == "converged", result.run.stall_reason
    demand_kw = float(problem.demand[0] * KW_PER_MW)
    error = np.max(np.abs(result.run.setpoints_kw - result.opf.p_kw))
    mode_tolerance = Integrator(**get_mode("voltage").integrator_options).tol_rel
    assert error <= mode_tolerance * demand_kw  # the mode's tolerance
    assert error <= max(1e-6 * demand_kw, 1e-3)  # ... within the target
    # the voltage limits bind: the DC-OPF's dispatch (all from the source) is far from it
    assert np.min(result.opf.v_pu) == pytest.approx(VMIN, abs=1e-9)


def test_kkt_check_sees_the_voltage_rows(problems):
    plain, problem, _ = problems
    tol = KktTolerances(1e-6 * float(problem.demand[0]), 1e-3, 1e-3)
    n_states = 2 * len(problem.limit) + 2 * problem.n_voltage
    dc = solve_opf(plain, 1).p_kw / KW_PER_MW
    reason = kkt_violations(problem, [1], dc, np.zeros(n_states), tol)[0]
    assert reason is not None and "beyond vmin" in reason
    opf = solve_opf(problem, 1)
    # the OPF's prices as controller states (the interior point's ~1e-14 on slack rows: 0, as
    # the controllers' projection leaves them)
    price = np.where(np.abs(opf.voltage_price) > 1e-6, opf.voltage_price, 0.0)
    z = np.concatenate([np.zeros(2 * len(problem.limit)), np.maximum(price, 0),
                        np.maximum(-price, 0)])  # fmt: skip
    assert kkt_violations(problem, [1], opf.p_kw / KW_PER_MW, z, tol)[0] is None
    # the OPF's point with no voltage price: the generators' marginal costs differ
    bare = kkt_violations(problem, [1], opf.p_kw / KW_PER_MW, np.zeros(n_states), tol)[0]
    assert bare is not None and "not a KKT point" in bare


def test_infeasible_voltage_limits_are_reported_infeasible(problems):
    plain, _, load_kw = problems
    tight = with_voltage_limits(plain, load_kw, 0.99, None)
    assert solve_opf(tight, 1).status == "infeasible"
    result = run_snapshot_vs_opf(tight, 1, RunSettings(mode="exact", vmin_pu=0.99))
    assert result.run.status == "infeasible"
    assert result.run.converged_at is None


def test_exact_mode_ignores_nothing_silently(problems):
    plain, problem, _ = problems
    with pytest.raises(OptionError, match="voltage limits"):
        run_snapshot_vs_opf(problem, 1, RunSettings(mode="exact"))
    with pytest.raises(OptionError, match="voltage limits"):
        run_snapshot_vs_opf(plain, 1, RunSettings(mode="exact", vmin_pu=VMIN))


@pytest.mark.parametrize(
    ("vmin", "vmax", "words"),
    [(0.0, None, r"outside \(0, 2\)"), (None, 2.0, r"outside \(0, 2\)"),
     (math.nan, None, "outside"), (0.95, 0.95, "not below"), (1.0, 0.9, "not below")],
)  # fmt: skip
def test_bad_limits_are_refused(vmin, vmax, words):
    with pytest.raises(OptionError, match=words):
        check_voltage_limits(vmin, vmax)
    with pytest.raises(OptionError, match=words):
        RunSettings(mode="exact", vmin_pu=vmin, vmax_pu=vmax)


def test_limits_need_exact_mode_and_voltage_mode_needs_limits():
    with pytest.raises(OptionError, match="need exact mode"):
        RunSettings(mode="paper", vmin_pu=0.95)
    with pytest.raises(OptionError, match="needs --vmin"):
        RunSettings(mode="voltage")


@pytest.mark.parametrize(
    ("mode", "limits"),
    [("exact", ("--vmin", "0.95", "--vmax", "0.9")), ("exact", ("--vmin", "2")),
     ("paper", ("--vmin", "0.95"))],
)  # fmt: skip
def test_cli_refuses_bad_limits_before_any_work(mode, limits):
    """RunSettings' check (the only one), before the feeder is read."""
    result = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", "snapshot", "--case", "case33bw", "--minute",
         "1", "--mode", mode, *limits],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "--vmin" in lines[0], result.stderr


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "popdispatch.cli", *args], capture_output=True,
                          text=True, timeout=600)  # fmt: skip


def test_cli_snapshot_reports_the_voltage_object(problems, tmp_path):
    pytest.importorskip("power_grid_model", reason='--ac needs pip install "popdispatch[ac]"')
    import json

    from popdispatch.scenarios import VOLTAGE_FLEET, VOLTAGE_NAMES

    fleet = tmp_path / "fleet.csv"
    rows = [f"{bus},{name},{b},{c},{lo},{hi}" for (bus, _, b, c, lo, hi), name
            in zip(VOLTAGE_FLEET, VOLTAGE_NAMES, strict=True)]  # fmt: skip
    fleet.write_text("bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw\n" + "\n".join(rows))
    result = cli("snapshot", "--case", "case33bw", "--fleet", str(fleet), "--minute", "1",
                 "--mode", "exact", "--vmin", str(VMIN), "--vmax", str(VMAX), "--ac", "--json",
                 "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["mode"] == "voltage" and summary["status"] == "converged"
    v = summary["voltage"]
    _, problem, _ = problems
    opf = solve_opf(problem, 1)
    assert v["opf_v_min_pu"] == pytest.approx(float(np.min(opf.v_pu)), abs=1e-12)
    assert {b["bus"] for b in v["binding"]} == set(
        problem.voltage_buses[np.abs(opf.voltage_price) > 1e-6].tolist()
    )
    assert v["linearization_error_pu"] == pytest.approx(
        v["v_min_pu"] - summary["ac"]["v_min_pu"], abs=1e-12
    )
    # the AC check says whether its voltages keep the limits: the LinDistFlow dispatch misses
    # vmin by the linearization error (0.0015 p.u. on this scenario) and keeps vmax
    limits = summary["ac"]["voltage_limits"]
    assert limits["vmin_pu"] == VMIN and limits["vmax_pu"] == VMAX
    assert limits["below_vmin_pu"] == pytest.approx(VMIN - summary["ac"]["v_min_pu"], abs=1e-15)
    assert limits["below_vmin_bus"] == summary["ac"]["v_min_bus"]
    assert limits["above_vmax_pu"] == 0.0 and limits["above_vmax_bus"] is None
    assert limits["kept"] is False and limits["steps_outside"] == 1


def test_voltage_payoff_equals_a_dense_reference(problems):
    """The compiled payoff (line prices, voltage prices, fitness) against plain numpy with the
    voltage rows written from the problem's unscaled LinDistFlow model."""
    from popdispatch.game.parameters import GameParameters, GameWork, MinuteInputs
    from popdispatch.modes.voltage import payoff
    from popdispatch.reference import fitness

    _, problem, _ = problems
    mode = get_mode("voltage")
    fp = RunSettings(mode="exact", vmin_pu=VMIN).game_constants(problem)
    rng = np.random.default_rng(7)
    p = problem.pmax * rng.uniform(0.0, 1.0, problem.n_generators)
    n_states = mode.controller_states(problem)
    z = rng.uniform(0.0, 5.0, n_states) * (rng.random(n_states) < 0.5)  # half of them priced
    got_f, got_rate = np.empty(len(p)), np.empty(len(z))
    work = GameWork.empty(len(problem.limit), n_generators=problem.n_generators)
    congestion, residual = payoff(p, z, GameParameters.of(problem, fp), MinuteInputs.of(problem, 1),
                                  work, got_f, got_rate)  # fmt: skip
    # dense: v^2 from the unscaled model, rows divided by the scales
    scale = problem.voltage_scale
    v_sq = problem.voltage_sq(p, 1)
    excess = np.concatenate([(VMIN**2 - v_sq) / scale, (v_sq - VMAX**2) / scale])
    n_v = problem.n_voltage
    mu = np.maximum(0.0, z + fp.C * excess)  # no limited lines in this problem
    net = mu[:n_v] - mu[n_v:]
    signal = net @ problem.voltage_sens
    np.testing.assert_allclose(got_f, fitness(problem, p, signal, fp, fp.gain, False), rtol=1e-9)
    np.testing.assert_allclose(got_rate, fp.price_rate * excess, rtol=1e-9, atol=1e-9)
    assert congestion == pytest.approx(np.abs(net).max(), rel=1e-12)
    slack = np.where(z > 0.0, np.abs(excess), np.maximum(excess, 0.0))
    assert residual == pytest.approx(slack.max(), rel=1e-12)


FEEDERS = Path(
    os.environ.get("POPDISPATCH_FEEDERS")
    or Path(__file__).resolve().parents[3] / "shared" / "feeders"
)
CASE33 = FEEDERS / "matpower" / "case33bw.m"


@pytest.mark.skipif(
    not CASE33.is_file(),
    reason=f"MATPOWER case33bw.m not found at {CASE33} (set POPDISPATCH_FEEDERS)",
)
def test_the_matpower_file_gives_the_same_lindistflow_opf(problems):
    """The scenario on pandapower's case33bw (buses from 0) and on the MATPOWER file (buses
    from 1, read by our own reader): the same monitored voltages and LinDistFlow optimum."""
    from popdispatch.feeder.generators import make_fleet
    from popdispatch.readers import read_matpower
    from popdispatch.runs import network_profiles
    from popdispatch.scenarios import VOLTAGE_FLEET, VOLTAGE_NAMES, elv_problem

    _, problem, _ = problems
    fleet = make_fleet([(bus + 1, *rest) for bus, *rest in VOLTAGE_FLEET], VOLTAGE_NAMES)
    feeder = read_matpower(CASE33, fleet=fleet)
    profiles = network_profiles(feeder)
    other = with_voltage_limits(elv_problem(profiles, (), feeder, check=False),
                                profiles.kw.to_numpy(float), VMIN, VMAX)  # fmt: skip
    np.testing.assert_array_equal(other.voltage_buses, problem.voltage_buses + 1)
    np.testing.assert_allclose(other.voltage_base, problem.voltage_base, atol=1e-12)
    ours, theirs = solve_opf(problem, 1), solve_opf(other, 1)
    np.testing.assert_allclose(theirs.p_kw, ours.p_kw, atol=1e-6)
