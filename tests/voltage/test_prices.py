"""The engine's own controller prices, in the results and the JSON/CSV output, against the
OPF's duals (Clarabel's, the independent yardstick).

At a converged minute of a mode with price controllers (exact, voltage) the broadcast prices
are the duals of the DC-OPF (LinDistFlow OPF) rows. Tolerance, from the run's own tolerances
(:class:`~popdispatch.online.kkt.KktTolerances`): a net price is two controller states, each
resolved to the Heun error control's ``price_atol`` (``tol.price = 2 price_atol`` in EUR/MW),
and its proportional part ``C e`` moves by at most ``C tol.power_mw`` while the excess is
within the stopping tolerance. Clarabel's duals are accurate to its 1e-10 gap, far below.
"""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.modes.exact import ExactConstants
from popdispatch.online import RunSettings
from popdispatch.online.engine import Engine
from popdispatch.report.summaries import day_summary, day_table, snapshot_summary
from popdispatch.runs import run_day_vs_opf, run_snapshot_vs_opf
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

EXACT = RunSettings(mode="exact")


def price_tolerance(problem, settings: RunSettings, minute: int) -> float:
    """EUR/MWh: ``2 price_atol * price_scale + C * tol_mw`` of the run at ``minute``."""
    engine = Engine(problem, settings)
    tol = engine.kkt_tolerances(float(problem.demand[minute - 1]))
    return tol.price + float(np.max(engine.constants.C)) * tol.power_mw


@pytest.fixture(scope="module")
def congested():
    problem = elv_problem(None, [CONGESTION_PATH])
    return problem, run_snapshot_vs_opf(problem, PEAK_MINUTE, EXACT)


def test_exact_line_prices_are_the_dc_opf_duals(congested):
    problem, result = congested
    run, opf = result.run, result.opf
    assert run.status == "converged", run.stall_reason
    tol = price_tolerance(problem, EXACT, PEAK_MINUTE)
    assert np.max(np.abs(opf.line_price)) > 100 * tol  # a line binds: the test can fail
    np.testing.assert_allclose(run.line_price_eur_per_mwh, opf.line_price, rtol=0, atol=tol)
    assert run.voltage_price_eur_per_mwh.shape == (0,)


@pytest.mark.parametrize("law", ["tree", "scaled"])
def test_every_price_law_reports_the_dc_opf_duals(law):
    """The tree and scaled laws broadcast the same prices at rest; the scaled law reads them
    with its per-line weight ``sqrt(N/N_k) C`` (``Engine.price_weight``), which also bounds
    how far the proportional part may move them within the stopping tolerance."""
    problem = elv_problem(None, [CONGESTION_PATH])
    settings = RunSettings(mode="exact", exact=ExactConstants(price_law=law))
    result = run_snapshot_vs_opf(problem, PEAK_MINUTE, settings)
    run, opf = result.run, result.opf
    assert run.status == "converged", run.stall_reason
    engine = Engine(problem, settings)
    tol = engine.kkt_tolerances(float(problem.demand[PEAK_MINUTE - 1]))
    weight = float(np.max(engine.price_weight(np.array([PEAK_MINUTE]))))
    atol = tol.price + weight * tol.power_mw
    assert np.max(np.abs(opf.line_price)) > 100 * atol
    np.testing.assert_allclose(run.line_price_eur_per_mwh, opf.line_price, rtol=0, atol=atol)


def test_snapshot_json_carries_the_engine_prices(congested):
    problem, result = congested
    summary = snapshot_summary(problem, result)
    tol = price_tolerance(problem, EXACT, PEAK_MINUTE)
    rows = summary["line_prices"]
    assert len(rows) == len(problem.limit) and summary["voltage_prices"] == []
    for row, dual in zip(rows, result.opf.line_price, strict=True):
        assert row["price_eur_per_mwh"] == pytest.approx(dual, abs=tol)
        assert row["opf_price_eur_per_mwh"] == pytest.approx(dual, abs=1e-12)
    # the priced line is the limited path's first line, named by its buses
    first = rows[int(np.argmax(np.abs(result.opf.line_price)))]
    assert first["from_bus"] == CONGESTION_PATH[0]


def test_paper_mode_has_no_price_controllers(congested):
    problem, _ = congested
    result = run_snapshot_vs_opf(problem, PEAK_MINUTE, RunSettings(mode="paper"))
    assert result.run.line_price_eur_per_mwh is None
    summary = snapshot_summary(problem, result)
    assert summary["line_prices"] is None and summary["voltage_prices"] is None


def test_day_csv_carries_the_engine_prices(congested):
    problem, _ = congested
    minutes = np.arange(PEAK_MINUTE - 3, PEAK_MINUTE + 2)
    result = run_day_vs_opf(problem, EXACT, minutes)
    run = result.run
    assert run.line_price_eur_per_mwh.shape == (len(minutes), len(problem.limit))
    table = day_table(result, problem)
    a, b, _ = CONGESTION_PATH
    duals = np.array([o.line_price for o in result.opf])
    k = int(np.argmax(np.abs(duals).max(axis=0)))
    column = [c for c in table.columns if c.endswith("_price_eur_per_mwh") and "opf" not in c][k]
    assert column.startswith(f"line_{a}_")
    checked = 0
    for r, minute in enumerate(minutes):
        if not run.converged[r]:
            continue
        tol = price_tolerance(problem, EXACT, int(minute))
        np.testing.assert_allclose(run.line_price_eur_per_mwh[r], duals[r], rtol=0, atol=tol)
        assert table[column].iloc[r] == pytest.approx(duals[r, k], abs=tol)
        checked += 1
    assert checked >= len(minutes) - 1, run.converged
    summary = day_summary(problem, result)
    gap = summary["max_abs_price_gap_eur_per_mwh"]
    assert gap <= max(price_tolerance(problem, EXACT, int(m)) for m in minutes)
    assert gap == pytest.approx(
        max(np.abs(run.line_price_eur_per_mwh[r] - duals[r]).max()
            for r in range(len(minutes)) if run.converged[r]), rel=1e-12)  # fmt: skip


def test_voltage_prices_are_the_lindistflow_opf_duals():
    pytest.importorskip("pandapower", reason="case33bw comes from pandapower's networks")
    from popdispatch.scenarios import VOLTAGE_LIMITS, voltage_problems

    _, problem, _ = voltage_problems()
    settings = RunSettings(mode="exact", vmin_pu=VOLTAGE_LIMITS[0], vmax_pu=VOLTAGE_LIMITS[1])
    result = run_snapshot_vs_opf(problem, 1, settings)
    run, opf = result.run, result.opf
    assert run.status == "converged", run.stall_reason
    tol = price_tolerance(problem, settings, 1)
    assert np.max(np.abs(opf.voltage_price)) > 100 * tol  # a voltage row binds
    np.testing.assert_allclose(run.voltage_price_eur_per_mwh, opf.voltage_price, rtol=0,
                               atol=tol)  # fmt: skip
    summary = snapshot_summary(problem, result)
    buses = [row["bus"] for row in summary["voltage_prices"]]
    assert buses == [int(b) for b in problem.voltage_buses]
    # the voltage object's binding rows: the engine's price beside the OPF's
    from popdispatch.ac.report import voltage_summary

    voltage = voltage_summary(problem, [1], run.setpoints_kw, [opf],
                              run.voltage_price_eur_per_mwh)  # fmt: skip
    assert voltage["binding"]
    for row in voltage["binding"]:
        assert row["engine_price_eur_per_mwh"] == pytest.approx(
            row["opf_price_eur_per_mwh"], abs=tol
        )
