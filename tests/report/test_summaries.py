"""Unit-named cost keys of the JSON summaries (popdispatch.report.summaries).

``cost``/``opf_cost``/``cost_all_minutes`` are EUR/h in a snapshot or DC-OPF summary and EUR in
a day summary; their unit-named twins (``cost_eur_per_h``, ``opf_cost_eur_per_h``, ``cost_eur``,
``opf_cost_eur``, ``cost_all_minutes_eur``) carry the same values. The old keys are deprecated
for one release. Costs are recomputed here from the fleet's Table I coefficients (EUR/h with
p in MW).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from popdispatch.feeder.synthetic import synthetic_feeder, synthetic_profiles
from popdispatch.online import RunSettings
from popdispatch.opf import solve_opf
from popdispatch.report.output import json_text
from popdispatch.report.summaries import day_summary, opf_summary, snapshot_summary
from popdispatch.scenarios import PEAK_MINUTE, day_vs_opf, elv_problem, snapshot_vs_opf


def _cost_eur_per_h(problem, p_kw, online=None) -> float:
    """sum a + b p + c p^2 over the (online) fleet, p in MW: EUR/h."""
    fleet = problem.feeder.generators
    p = np.asarray(p_kw, dtype=float) / 1000.0
    terms = fleet.a.to_numpy() + fleet.b.to_numpy() * p + fleet.c.to_numpy() * p**2
    return float(np.sum(terms if online is None else np.where(online, terms, 0.0)))


@pytest.fixture(scope="module")
def peak():
    problem = elv_problem()
    return problem, snapshot_vs_opf(problem, PEAK_MINUTE, RunSettings())


def test_snapshot_cost_keys_are_eur_per_hour(peak):
    problem, result = peak
    s = snapshot_summary(problem, result)
    assert s["cost_eur_per_h"] == s["cost"] and s["opf_cost_eur_per_h"] == s["opf_cost"]
    assert s["cost_unit"] == "EUR/h"  # deprecated with cost, still there for one release
    setpoints = [g["setpoint_kw"] for g in s["generators"]]
    opf = [g["opf_kw"] for g in s["generators"]]
    assert s["cost_eur_per_h"] == pytest.approx(_cost_eur_per_h(problem, setpoints), rel=1e-12)
    assert s["opf_cost_eur_per_h"] == pytest.approx(_cost_eur_per_h(problem, opf), rel=1e-9)
    assert json.loads(json_text(s))["cost_eur_per_h"] == s["cost_eur_per_h"]


def test_opf_cost_key_is_eur_per_hour(peak):
    problem, _ = peak
    opf = solve_opf(problem, PEAK_MINUTE)
    s = opf_summary(problem, opf)
    assert s["cost_eur_per_h"] == s["cost"] and s["cost_unit"] == "EUR/h"
    p_kw = [g["p_kw"] for g in s["generators"]]
    assert s["cost_eur_per_h"] == pytest.approx(_cost_eur_per_h(problem, p_kw), rel=1e-9)


def test_day_cost_keys_are_eur():
    feeder = synthetic_feeder(120, 4, seed=2)
    problem = elv_problem(synthetic_profiles(feeder, seed=3), feeder=feeder)
    minutes = np.arange(600, 606)
    result = day_vs_opf(problem, RunSettings(), minutes)
    s = day_summary(problem, result)
    assert s["cost_eur"] == s["cost"] and s["opf_cost_eur"] == s["opf_cost"]
    assert s["cost_all_minutes_eur"] == s["cost_all_minutes"]
    assert s["cost_unit"] == "EUR"
    online = problem.online[minutes - 1]
    per_hour = [
        _cost_eur_per_h(problem, p, on)
        for p, on in zip(result.run.setpoints_kw, online, strict=True)
    ]
    # EUR: each minute's EUR/h over 1/60 h, summed (every minute here has a DC-OPF)
    assert result.feasible.all()
    assert s["cost_eur"] == pytest.approx(sum(per_hour) / 60.0, rel=1e-12)
    assert s["cost_all_minutes_eur"] == pytest.approx(sum(per_hour) / 60.0, rel=1e-12)
    opf = [_cost_eur_per_h(problem, p, on) for p, on in zip(result.opf_kw, online, strict=True)]
    assert s["opf_cost_eur"] == pytest.approx(sum(opf) / 60.0, rel=1e-9)


def test_day_energies_weigh_each_step_by_its_length():
    """Irregular steps (15, 15, 30, 60, 60, 60 min): energies and costs are sum(kW x h) from the
    per-step values recomputed here; the span keys carry the steps' ISO 8601 start times."""
    from popdispatch.feeder.profiles import Timeline

    feeder = synthetic_feeder(120, 4, seed=2)
    problem = elv_problem(synthetic_profiles(feeder, seed=3), feeder=feeder)
    minutes = np.arange(600, 606)
    result = day_vs_opf(problem, RunSettings(mode="exact"), minutes)
    starts = pd.DatetimeIndex([f"2024-05-01T{t}" for t in ("10:00", "10:15", "10:30", "11:00",
                                                            "12:00", "13:00")])  # fmt: skip
    hours = np.full(1440, 0.25)
    hours[minutes - 1] = [0.25, 0.25, 0.5, 1.0, 1.0, 1.0]
    before = pd.date_range("2024-04-25", periods=minutes[0] - 1, freq="15min")
    after = pd.date_range("2024-05-02", periods=1440 - minutes[-1], freq="15min")
    timeline = Timeline(before.append(starts).append(after), hours)
    s = day_summary(problem, result, timeline=timeline)
    weight = hours[minutes - 1]
    online = problem.online[minutes - 1]
    energy = (result.run.setpoints_kw * weight[:, None]).sum(axis=0)
    for (bus, kwh), expected in zip(s["energy_kwh"].items(), energy, strict=True):
        assert kwh == pytest.approx(expected, rel=1e-12), bus
    per_hour = [
        _cost_eur_per_h(problem, p, on)
        for p, on in zip(result.run.setpoints_kw, online, strict=True)
    ]
    assert s["cost_eur"] == pytest.approx(float(np.dot(per_hour, weight)), rel=1e-12)
    assert (s["first_time"], s["last_time"]) == ("2024-05-01T10:00:00", "2024-05-01T13:00:00")
    assert s["step_minutes"] is None and (s["first_step"], s["last_step"]) == (600, 605)
