"""The ELV in mosaik with an AC plant (``popdispatch cosim``), against independent yardsticks:
power-grid-model's AC power flow of the co-simulation's set points (the limited line's AC flow
at its limit, never above) and Clarabel's DC-OPF (the set points are the DC-OPF's where the
line does not bind, and where it binds the generation below it is the DC-OPF's plus the offset
the measured AC flow adds)."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
import pytest

from helpers import official_folder

pytest.importorskip("mosaik", reason="the cosim extra is not installed (mosaik)")

LIMIT_KW = 28.0
MINUTES = np.arange(560, 570)
TOL_KW = 2e-3  # the dispatcher's offset tolerance (1e-3 kW) plus the certificate's accuracy


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = official_folder()
    out = tmp_path_factory.mktemp("cosim") / "out"
    done = subprocess.run(
        [sys.executable, "-m", "popdispatch.cli", "cosim", "ieee-elv", "--profiles", str(folder),
         "--limit", "505:666=28", "--minutes", "560-569", "--out", str(out), "--json", "-q"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    steps = pd.read_csv(out / "steps.csv", index_col="minute")
    return folder, json.loads(done.stdout), steps, out


@pytest.fixture(scope="module")
def problem(run):
    from popdispatch.runs import FeederSource, load_run

    return load_run(FeederSource(), run[0], limits=[(505, 666, LIMIT_KW)])


def test_outputs_and_status(run):
    _, summary, steps, out = run
    assert summary["status"] == "converged" and summary["minutes"] == 10
    assert list(steps.index) == list(MINUTES)
    record = pd.read_csv(out / "cosim.csv")
    assert {"Grid-0.Branch-505-578.p_kw", "Grid-0.DG-G817.p_kw",
            "Dispatcher-0.Controller-505-578.offset_kw"} <= set(record.columns)  # fmt: skip
    assert json.loads((out / "summary.json").read_text())["rounds"] == summary["rounds"]


def _chain_end_flows_kw(feeder, ac, top: int, bottom: int) -> np.ndarray:
    """(minutes, 2): the active power flowing away from the source at both ends of the chain
    of lines between ``top`` and ``bottom`` (power-grid-model's results)."""
    graph = nx.Graph()
    for name, line in feeder.lines.iterrows():
        graph.add_edge(int(line.from_bus), int(line.to_bus), name=name)
    path = nx.shortest_path(graph, top, bottom)
    rows = {name: i for i, name in enumerate(feeder.lines.index)}
    ends = []
    for near, far in ((path[0], path[1]), (path[-1], path[-2])):
        name = graph.edges[near, far]["name"]
        at_from = int(feeder.lines.at[name, "from_bus"]) == near
        p = (ac.flows.p_from_kw if at_from else ac.flows.p_to_kw)[:, rows[name]]
        ends.append(p if near == top else -p)  # entering at the top, leaving at the bottom
    return np.column_stack(ends)


def _top_flow_kw(problem, p_kw, minute) -> float:
    """The DC flow (kW) of the top limited line 505-578 at set points ``p_kw``."""
    return float(problem.flows(np.asarray(p_kw) / 1e3, int(minute))[0] * 1e3)


def test_ac_flow_of_the_limited_line_stays_at_its_limit(run, problem):
    from popdispatch.ac import check_setpoints
    from popdispatch.opf import solve_opf_day

    _, summary, steps, _ = run
    dc, series = problem
    feeder = dc.feeder.original
    points = steps[[f"{g}_setpoint_kw" for g in dc.generators]].to_numpy()
    loads = series.for_loads(feeder.loads.index).kw.to_numpy()[MINUTES - 1]
    ac = check_setpoints(feeder, loads, points, MINUTES)  # power-grid-model, not pandapower
    flows = _chain_end_flows_kw(feeder, ac, 505, 578)
    largest = np.abs(flows).max(axis=1)
    assert largest.max() <= LIMIT_KW + TOL_KW
    opf = solve_opf_day(dc, MINUTES)
    binding = np.array([abs(abs(_top_flow_kw(dc, o.p_kw, m)) - LIMIT_KW) < 1e-6
                        for o, m in zip(opf, MINUTES, strict=True)])  # fmt: skip
    assert binding.sum() >= 2  # the DC-OPF binds the line at some of these minutes
    np.testing.assert_allclose(largest[binding], LIMIT_KW, atol=TOL_KW)
    # the same flow as the plant measured (pandapower) to the power flows' tolerance
    np.testing.assert_allclose(np.where(np.abs(flows[:, 0]) >= np.abs(flows[:, 1]), flows[:, 0],
                                        flows[:, 1]),
                               steps["505-578_ac_flow_kw"], atol=1e-6)  # fmt: skip


def test_setpoints_against_the_dc_opf(run, problem):
    from popdispatch.opf import solve_opf

    _, summary, steps, _ = run
    dc, _ = problem
    points = steps[[f"{g}_setpoint_kw" for g in dc.generators]].to_numpy()
    below = dc.down[0] > 0  # the generators below the top line 505-578
    offsets = steps[[c for c in steps if c.endswith("_offset_kw")]].to_numpy() / 1e3
    for row, minute in enumerate(MINUTES):
        plain = solve_opf(dc, int(minute))
        flow = _top_flow_kw(dc, plain.p_kw, minute)
        if abs(abs(flow) - LIMIT_KW) > 1e-6:  # the line is free: the DC day's set points
            np.testing.assert_allclose(points[row], plain.p_kw, atol=TOL_KW)
            continue
        # binding: the generation below moves by the offset of the measured AC flow
        assert points[row][below].sum() - plain.p_kw[below].sum() == pytest.approx(
            steps.at[minute, "505-578_offset_kw"], abs=TOL_KW
        )
        load_flow = dc.load_flow.copy()
        load_flow[minute - 1, : len(dc.limit)] += offsets[row]
        corrected = solve_opf(replace(dc, load_flow=load_flow), int(minute))
        np.testing.assert_allclose(points[row], corrected.p_kw, atol=TOL_KW)
    assert points.sum(axis=1) == pytest.approx(dc.demand[MINUTES - 1] * 1e3, abs=TOL_KW)
    assert summary["vs_dc_day"]["free_minutes_equal"]


def test_example_scenario_runs(tmp_path):
    """examples/cosim_scenario.py as docs/cosim.md gives it (two minutes): mosaik's record
    holds a row per minute with the limited line's measured flow and the dispatcher's status."""
    folder = official_folder()
    example = Path(__file__).resolve().parents[2] / "examples" / "cosim_scenario.py"
    done = subprocess.run([sys.executable, str(example), str(folder), str(tmp_path), "2"],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    record = pd.read_csv(tmp_path / "cosim.csv")
    assert list(record.time_s) == [0, 60]
    assert (record["Dispatcher-0.Dispatcher.status"] == "converged").all()
    assert (record["Grid-0.Branch-505-578.p_kw"].abs() <= LIMIT_KW).all()
