"""The AC check's API: the objects the CLI holds, summaries, model rules and bad input.

Numbers are checked against the tables they summarise (a summary's extremes against the per-bus
and per-line results, energies against sums of the per-step columns) or against a second,
simpler network (a zero-impedance line against the same feeder with its two buses merged).
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("power_grid_model", reason='the AC check needs pip install "popdispatch[ac]"')

from popdispatch.ac import build_network, check_day, check_setpoints, check_snapshot  # noqa: E402
from popdispatch.ac.network import load_q_per_kw, nominal_kv  # noqa: E402
from popdispatch.errors import FeederError, InfeasibleError, OptionError  # noqa: E402
from popdispatch.feeder.generators import make_fleet  # noqa: E402
from popdispatch.feeder.model import Feeder  # noqa: E402
from popdispatch.online import DayResult, RunSettings, SnapshotResult  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402
from popdispatch.scenarios import (  # noqa: E402
    CONGESTION_PATH,
    DayComparison,
    SnapshotComparison,
    elv_problem,
    peak_profiles,
)

ISSUE_KEYS = {
    "losses_kw", "v_min_pu", "v_min_bus", "v_max_pu", "v_max_bus", "max_loading_percent",
    "max_loading_line",
}  # fmt: skip


def small_feeder(r_ohm=(0.05, 0.04, 0.03), name="small", **load_columns) -> Feeder:
    """Source 1 - 2 - 3, and 2 - 4; loads at 3 and 4, a generator at 4."""
    buses = pd.DataFrame({"x": [0.0, 1, 2, 2], "y": [0.0, 0, 0, 1]}, index=[1, 2, 3, 4])
    buses.index.name = "bus"
    lines = pd.DataFrame(
        {
            "from_bus": [1, 2, 2],
            "to_bus": [2, 3, 4],
            "length_km": 0.1,
            "r_ohm": list(r_ohm),
            "x_ohm": [0.01, 0.01, 0.01],
            "limit_kw": [40.0, np.inf, 10.0],
        },
        index=["L12", "L23", "L24"],
    )
    loads = pd.DataFrame({"bus": [3, 4], **load_columns}, index=["D3", "D4"])
    fleet = make_fleet([(1, 0, 5.0, 0.02, 0, 100), (4, 0, 1.0, 0.01, 0, 100)])
    return Feeder(name, buses, lines, loads, 1, fleet)


# -- the objects the commands hold -------------------------------------------------------------


@pytest.fixture(scope="module")
def congestion_problem():
    return elv_problem(limits=[CONGESTION_PATH])


def test_snapshot_of_a_comparison_gives_the_issue_json_keys(congestion_problem):
    problem = congestion_problem
    opf = solve_opf(problem, 566)
    run = SnapshotResult(
        minute=566, demand_kw=opf.demand_kw, settings=RunSettings(), generators=problem.generators,
        trajectory_kw=opf.p_kw[None, :], converged_at=0, first_congestion=None,
        overflow_kw=np.zeros(len(problem.lines)), flows_kw=np.zeros(len(problem.lines)),
        wall_seconds=0.0, profile_source="test",
    )  # fmt: skip
    ac = check_snapshot(problem, peak_profiles(), SnapshotComparison(run, opf))
    summary = ac.summary()
    assert summary.keys() >= ISSUE_KEYS
    json.dumps(summary)  # JSON-ready: no numpy scalars, no NaN
    assert summary["minute"] == 566
    assert summary["losses_kw"] == pytest.approx(ac.lines.loss_kw.sum(), abs=1e-12)
    assert summary["v_min_pu"] == ac.buses.v_pu.min()
    assert summary["v_min_bus"] == ac.buses.v_pu.idxmin()
    assert summary["v_max_bus"] == ac.buses.v_pu.idxmax()  # G817 exports: above the source
    assert summary["max_loading_percent"] == ac.lines.loading_percent.max()
    assert summary["max_loading_line"] == ac.lines.loading_percent.idxmax()
    # the DC-OPF balances the demand: the source supplies the losses, no more
    assert summary["dc_mismatch_kw"] == pytest.approx(0.0, abs=1e-6)
    assert summary["source_extra_kw"] == pytest.approx(summary["losses_kw"], abs=1e-4)
    assert summary["load_kw"] == pytest.approx(57.358, abs=1e-6)
    assert summary["model"]["vn_kv"] == 0.416 and summary["model"]["source_pu"] == 1.0
    assert "0.95" in summary["model"]["load_q_rule"]
    assert len(ac.buses) == 906 and len(ac.lines) == 905  # the full network


def test_day_of_a_comparison_summarises_its_steps(congestion_problem):
    problem = congestion_problem
    minutes = np.array([565, 566, 567])
    scale = np.array([0.5, 1.0, 0.8])  # the minute-566 loads (every minute of the problem)
    opf = solve_opf(problem, 566)
    setpoints = opf.p_kw[None, :] * scale[:, None]
    n_lines = len(problem.lines)
    run = DayResult(
        minutes=minutes, settings=RunSettings(), generators=problem.generators,
        demand_kw=np.full(3, opf.demand_kw), setpoints_kw=setpoints,
        iterations=np.zeros(3, int), converged=np.ones(3, bool),
        overflow_kw=np.zeros((3, n_lines)), cost=np.zeros(3), online=np.ones((3, 6), bool),
        wall_seconds=0.0, profile_source="test",
    )  # fmt: skip
    day = check_day(problem, peak_profiles(), DayComparison(run, [opf] * 3))
    steps = day.steps
    assert list(steps.index) == list(minutes)
    # set points short of the demand at 565 and 567: the source makes up the rest
    np.testing.assert_allclose(
        steps.source_extra_kw,
        steps.losses_kw + steps.load_kw - steps.generation_kw,
        atol=1e-4,
        rtol=0,
    )
    summary = day.summary()
    json.dumps(summary)
    assert set(summary) == {
        "steps", "losses_kwh", "source_extra_kwh", "max_losses_kw", "max_losses_minute",
        "v_min_pu", "v_min_bus", "v_min_minute", "v_max_pu", "v_max_bus", "v_max_minute",
        "max_loading_percent", "max_loading_line", "max_loading_minute", "max_source_extra_kw",
        "max_source_extra_minute", "model",
    }  # fmt: skip
    assert summary["max_losses_kw"] == steps.losses_kw.max()
    assert summary["max_losses_minute"] == steps.losses_kw.idxmax()
    assert summary["losses_kwh"] == pytest.approx(steps.losses_kw.sum() / 60)
    assert summary["v_min_pu"] == steps.v_min_pu.min()
    assert summary["v_min_minute"] == steps.v_min_pu.idxmin() == 565  # least generation
    assert summary["v_min_bus"] == steps.v_min_bus[565]
    assert summary["max_loading_percent"] == steps.max_loading_percent.max()
    assert summary["max_loading_line"] == steps.max_loading_line[summary["max_loading_minute"]]
    assert day.v_pu().shape == (3, 906)
    assert day.loading_percent().columns.equals(
        problem.feeder.original.lines.index[np.isfinite(problem.feeder.original.lines.limit_kw)]
    )


# -- model rules -------------------------------------------------------------------------------


def test_nominal_voltage_rules():
    feeder = small_feeder()
    with pytest.raises(FeederError, match="feeder 'small' has no nominal voltage"):
        nominal_kv(feeder)
    assert nominal_kv(feeder, 0.4) == 0.4
    buses = feeder.buses.assign(kv_ln_base=0.23)
    assert nominal_kv(Feeder("small", buses, feeder.lines, feeder.loads, 1, feeder.generators)) == (
        pytest.approx(0.23 * math.sqrt(3))
    )
    buses = buses.assign(vn_kv=11.0)
    assert (
        nominal_kv(Feeder("small", buses, feeder.lines, feeder.loads, 1, feeder.generators)) == 11
    )
    assert nominal_kv(Feeder("ieee-elv", *_tables(feeder))) == 0.416
    with pytest.raises(OptionError, match="vn_kv = -1"):
        nominal_kv(feeder, -1)


def _tables(feeder: Feeder) -> tuple:
    return feeder.buses, feeder.lines, feeder.loads, feeder.source_bus, feeder.generators


def test_load_reactive_power_rules():
    q, rule = load_q_per_kw(small_feeder(p_kw=[10.0, 0.0], q_kvar=[3.0, 1.0]))
    np.testing.assert_allclose(q, [0.3, 0.0])
    assert "q_kvar" in rule
    q, rule = load_q_per_kw(small_feeder(pf=[0.8, 1.0]))
    np.testing.assert_allclose(q, [0.75, 0.0])
    q, rule = load_q_per_kw(small_feeder())
    assert not q.any() and rule.startswith("unity")
    q, rule = load_q_per_kw(small_feeder(), load_pf=0.8)
    np.testing.assert_allclose(q, 0.75)
    with pytest.raises(OptionError, match=r"load 'D4' pf = 1.2"):
        load_q_per_kw(small_feeder(pf=[0.9, 1.2]))


def test_zero_impedance_line_is_a_link_equal_to_merged_buses():
    """L24 with no impedance: bus 4 is bus 2, as on a feeder whose load and generator at 4 sit
    at 2 (and L24 is dropped)."""
    linked = small_feeder(r_ohm=(0.05, 0.04, 0.0))
    lines = linked.lines.copy()
    lines.loc["L24", "x_ohm"] = 0.0
    linked = Feeder("linked", linked.buses, lines, linked.loads, 1, linked.generators)
    merged_loads = pd.DataFrame({"bus": [3, 2]}, index=["D3", "D4"])
    merged_fleet = make_fleet([(1, 0, 5.0, 0.02, 0, 100), (2, 0, 1.0, 0.01, 0, 100)])
    merged = Feeder(
        "merged", linked.buses.loc[[1, 2, 3]], linked.lines.loc[["L12", "L23"]], merged_loads,
        1, merged_fleet,
    )  # fmt: skip
    load_kw, setpoints = [[20.0, 15.0]], [[30.0, 5.0]]
    tight = {"vn_kv": 0.4, "tolerance_pu": 1e-12}
    a = check_setpoints(linked, load_kw, setpoints, **tight)
    b = check_setpoints(merged, load_kw, setpoints, **tight)
    # power-grid-model's link is a very large admittance, not an exact short: 2e-9 p.u. here
    np.testing.assert_allclose(a.flows.v_pu[0, :3], b.flows.v_pu[0], atol=1e-8, rtol=0)
    assert a.flows.v_pu[0, 3] == pytest.approx(b.flows.v_pu[0, 1], abs=1e-8)
    assert a.steps.losses_kw.iloc[0] == pytest.approx(b.steps.losses_kw.iloc[0], abs=1e-6)
    # the link's current is its apparent power over sqrt(3) times its (bus 2) voltage
    i_24 = a.flows.current_a[0, 2]
    s_24 = math.hypot(a.flows.p_from_kw[0, 2], a.flows.q_from_kvar[0, 2])
    assert i_24 == pytest.approx(s_24 / (math.sqrt(3) * 0.4 * a.flows.v_pu[0, 1]), rel=1e-6)


# -- bad input ---------------------------------------------------------------------------------


def test_bad_input_is_refused_naming_the_element():
    feeder = small_feeder()
    ok = {"vn_kv": 0.4}
    with pytest.raises(OptionError, match=r"generator 'G4' has nan kW at minute 8"):
        check_setpoints(feeder, [[1, 1], [1, 1]], [[0, 1], [0, np.nan]], [7, 8], **ok)
    with pytest.raises(OptionError, match=r"load 'D3' has inf kW at minute 2"):
        check_setpoints(feeder, [[1, 1], [np.inf, 1]], [[0, 1], [0, 1]], **ok)
    with pytest.raises(OptionError, match="3 minutes for 2 steps"):
        check_setpoints(feeder, [[1, 1], [1, 1]], [[0, 1], [0, 1]], [1, 2, 3], **ok)
    with pytest.raises(OptionError, match="1 generator values per step for 2 generators"):
        check_setpoints(feeder, [[1, 1]], [[1]], **ok)
    with pytest.raises(OptionError, match="2 steps of loads but 1 of set points"):
        check_setpoints(feeder, [[1, 1], [1, 1]], [[1, 1]], **ok)
    with pytest.raises(OptionError, match="source voltage 2.5 p.u."):
        build_network(feeder, source_pu=2.5, **ok)
    with pytest.raises(OptionError, match="generator power factor 0"):
        build_network(feeder, generator_pf=0.0, **ok)
    with pytest.raises(FeederError, match="no nominal voltage"):
        check_setpoints(feeder, [[1, 1]], [[1, 1]])


def test_a_power_flow_without_solution_names_its_minute():
    """20 MW through 0.05 ohm at 0.4 kV: no voltage can carry it."""
    feeder = small_feeder()
    with pytest.raises(InfeasibleError, match=r"AC power flow did not converge at minute 8"):
        check_setpoints(feeder, [[1, 1], [20000, 1]], [[0, 0], [0, 0]], [7, 8], vn_kv=0.4)


def test_missing_power_grid_model_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "power_grid_model", None)  # import fails
    with pytest.raises(ImportError, match=r'pip install "popdispatch\[ac\]"'):
        build_network(small_feeder(), vn_kv=0.4)
