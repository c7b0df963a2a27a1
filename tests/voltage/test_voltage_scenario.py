"""The ``voltage`` scenario (issue 14 part 3) in AC: the DC exact dispatch violates 0.95 p.u.,
the voltage-aware one keeps every AC voltage at 0.95 p.u. minus the linearization error (target
under 0.002 p.u.), and pandapower's AC OPF (``runopp``, the anchor) is checked against our own AC
power flow (power-grid-model) of its dispatch."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("power_grid_model", reason='the AC check needs pip install "popdispatch[ac]"')
pytest.importorskip("pandapower", reason="case33bw and runopp come from pandapower")

from popdispatch.ac import check_setpoints  # noqa: E402
from popdispatch.ac.check import TOLERANCE_PU  # noqa: E402
from popdispatch.reproduce import DISPATCHES, voltage_summary  # noqa: E402
from popdispatch.scenarios import VOLTAGE_LIMITS, voltage  # noqa: E402

VMIN = VOLTAGE_LIMITS[0]
#: The issue's target for the linearization error, p.u.
LINEARIZATION_TARGET_PU = 0.002


@pytest.fixture(scope="module")
def result():
    return voltage()


def test_dc_exact_dispatch_violates_the_limit_in_ac(result):
    assert result.dc.run.status == "converged"
    v = result.ac_dc.buses["v_pu"]
    # published: 0.913 p.u. at MATPOWER bus 18 (our bus 17) without DGs; the cheapest dispatch
    # buys everything at the source, so it is the no-DG case
    assert v.min() < VMIN
    assert v.idxmin() == 17
    assert v.min() == pytest.approx(0.913, abs=5e-4)


def test_voltage_aware_dispatch_keeps_the_limit_up_to_the_linearization_error(result):
    run, opf = result.voltage.run, result.voltage.opf
    assert run.status == "converged"
    lindistflow_min = float(np.min(opf.v_pu))
    assert lindistflow_min == pytest.approx(VMIN, abs=1e-9)  # the limit binds
    ac_min = float(result.ac_voltage.buses["v_pu"].min())
    error = lindistflow_min - ac_min
    assert 0.0 < error < LINEARIZATION_TARGET_PU  # LinDistFlow drops the losses: AC is lower
    assert ac_min >= VMIN - LINEARIZATION_TARGET_PU
    summary = voltage_summary(result)
    assert summary["linearization_error_pu"] == pytest.approx(error, abs=1e-12)


def test_anchor_is_consistent_with_our_ac_power_flow(result):
    if result.anchor is None:
        pytest.skip(f"pandapower runopp failed: {result.anchor_error}")
    anchor = result.anchor
    feeder = result.problem.feeder.original
    assert anchor.v_pu.min() >= VMIN - 1e-6  # runopp keeps the limit (its own tolerance)
    # our AC power flow of the anchor's set points gives the anchor's voltages (to the power
    # flow's tolerance; measured 2.4e-9 p.u.), and its source then supplies nothing beyond
    # the anchor's (which includes the losses; measured 2.5e-5 kW)
    day = check_setpoints(feeder, result.load_kw, [anchor.p_kw.loc[feeder.generators.index]])
    assert np.max(np.abs(day.flows.v_pu[0] - anchor.v_pu.to_numpy())) < 10 * TOLERANCE_PU
    assert abs(day.steps.iloc[0].source_extra_kw) < 1e-3
    # the AC optimum costs more than the voltage-aware LinDistFlow dispatch whose AC voltages
    # fall below the limit, and within a few percent of it
    costs = {name: d["cost_eur_per_h"] for name, d in voltage_summary(result)["dispatches"].items()}
    assert costs[DISPATCHES[0]] < costs[DISPATCHES[1]] < costs[DISPATCHES[2]]
    assert costs[DISPATCHES[2]] < 1.03 * costs[DISPATCHES[1]]


#: The issue's targets with --ac-correct: AC voltages within 5e-4 p.u. of the limit, cost within
#: 0.5 % of pandapower's AC OPF.
CORRECTED_TARGET_PU, CORRECTED_COST_REL = 5e-4, 5e-3


def test_ac_correction_reaches_the_ac_opf(result):
    corrected = result.corrected
    assert corrected.result.run.status == "converged"
    assert corrected.offset_change_pu <= 1e-5  # the loop's own stopping tolerance
    ac_min = float(corrected.ac.buses["v_pu"].min())
    assert ac_min >= VMIN - CORRECTED_TARGET_PU
    # the voltage limit binds in AC now (the uncorrected dispatch was 1.5e-3 p.u. below)
    assert ac_min == pytest.approx(VMIN, abs=CORRECTED_TARGET_PU)
    if result.anchor is None:
        pytest.skip(f"pandapower runopp failed: {result.anchor_error}")
    anchor = result.anchor
    assert abs(corrected.cost_eur_per_h - anchor.cost) <= CORRECTED_COST_REL * anchor.cost
    # measured: the two dispatches agree to 0.02 kW (runopp's own tolerance)
    p_kw = corrected.summary()["setpoints_kw"]
    dgs = [g for g in anchor.p_kw.index if g != "source"]
    assert max(abs(p_kw[g] - anchor.p_kw[g]) for g in dgs) < 0.1


def test_the_scenario_run_in_a_second_process_is_the_same(result):
    """``reproduce`` runs the scenario in a spawned process beside the others (issue 13): what
    comes back through the pipe summarises exactly as the scenario run here."""
    from popdispatch.online import RunSettings
    from popdispatch.report.output import json_text
    from popdispatch.reproduce import voltage_in_background

    with voltage_in_background(RunSettings(), parallel=True) as pending:
        remote = pending.get(timeout=600)
    assert json_text(voltage_summary(remote)) == json_text(voltage_summary(result))
