"""Text rendering of summaries (issue 10, items 3, 5 and 6): compact minute lists, limits and
events echoed, nothing printed as ``nan`` when values are unknown."""

from __future__ import annotations

from popdispatch.cli import infeasible_day_message
from popdispatch.report.text import day_text, events_text, limits_text, minute_ranges, opf_text


def test_minute_ranges_are_compact():
    assert minute_ranges([]) == ""
    assert minute_ranges([566]) == "566"
    assert minute_ranges([602, 600, 601, 566, 700, 701]) == "566, 600-602, 700-701"


def test_limits_and_events_are_echoed():
    rows = [{"from_bus": 505, "to_bus": 666, "limit_kw": 28.0, "lines_on_path": 21},
            {"from_bus": 1, "to_bus": 34, "limit_kw": 40.5, "lines_on_path": 1}]  # fmt: skip
    assert limits_text(rows) == "limits: 505:666=28 kW (21 lines), 1:34=40.5 kW (1 line)"
    assert limits_text([]) == "limits: none"
    assert events_text(["739:off@600", "739:on@720"]) == "events: 739:off@600, 739:on@720"
    assert events_text([]) == "events: none"


def day_summary(**changes) -> dict:
    summary = {
        "status": "infeasible", "minutes": 4, "first_minute": 1, "last_minute": 4,
        "case": "ieee-elv", "profile_source": "test", "mode": "exact", "dynamics": "smith",
        "limits": [], "events": ["1:off@2"], "infeasible_minutes": [1, 2, 3, 4],
        "stalled_minutes": [], "converged_minutes": 4, "compared_minutes": 0,
        "minutes_within_0_1_kw": 0, "max_abs_error_kw": None, "mean_abs_error_kw": None,
        "energy_kwh": {"1": 0.0}, "opf_energy_kwh": {"1": None}, "cost": 0.0, "opf_cost": None,
        "cost_all_minutes": 0.01, "minutes_outside_limits": 0, "max_outside_limits_kw": 0.0,
        "minutes_outside_limits_by_generator": {}, "max_overflow_kw": 2.0,
        "wall_seconds": 0.01, "command_seconds": 1.0,
    }  # fmt: skip
    return {**summary, **changes}


def test_day_without_any_dc_opf_says_so():
    text = day_text(day_summary())
    assert "nan" not in text.lower()
    assert "DC-OPF infeasible at 4 minutes: 1-4" in text
    assert "no minute has a DC-OPF: nothing to compare with" in text
    assert "events: 1:off@2" in text


def test_infeasible_day_message_lists_the_first_ranges():
    bad = [5, 7, 9, 11, 13, 15, 16, 17]
    message = infeasible_day_message({"infeasible_minutes": bad, "minutes": 20})
    assert message.startswith("the DC-OPF is infeasible at 8 of 20 minutes (5, 7, 9, 11, 13, ...)")
    assert "\n" not in message


def test_infeasible_opf_text_has_no_table_of_unknowns():
    summary = {
        "status": "infeasible", "minute": 566, "demand_kw": 57.358, "capacity_kw": 65.0,
        "case": "ieee-elv", "profile_source": "test", "cost": None,
        "limits": [{"from_bus": 505, "to_bus": 666, "limit_kw": 0.0, "lines_on_path": 21}],
        "generators": [{"name": "G1", "bus": 1, "p_kw": None}],
    }  # fmt: skip
    text = opf_text(summary)
    assert "p_kw" not in text and "nan" not in text.lower()
    assert "infeasible: no dispatch meets" in text and "limits: 505:666=0 kW" in text
