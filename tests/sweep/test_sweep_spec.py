"""The sweep spec: expansion count, stable ids, one-line errors naming the key (no data)."""

from __future__ import annotations

import pytest

from popdispatch.errors import OptionError
from popdispatch.sweep.spec import StepRange, load_spec, parse_spec

ISSUE_SPEC = """
case = "ieee-elv"
steps = "600-660"                    # minutes 600..660
modes = ["exact", "paper"]
limits = [[], ["505:666=28"]]
profile_assignments = { count = 5, seed = 1 }
"""


def test_issue_spec_expands_to_twenty_scenarios(tmp_path):
    path = tmp_path / "spec.toml"
    path.write_text(ISSUE_SPEC)
    spec = load_spec(path)
    scenarios = spec.scenarios
    assert len(scenarios) == spec.product_size == 2 * 2 * 5
    assert {s.mode for s in scenarios} == {"exact", "paper"}
    assert {s.limits for s in scenarios} == {(), ((505, 666, 28.0),)}
    assert {s.assignment.label for s in scenarios} == {f"random:1:{d}" for d in range(5)}
    assert all(s.steps == StepRange(600, 660) and s.steps.count == 61 for s in scenarios)
    assert len({s.id for s in scenarios}) == 20
    assert [s.index for s in scenarios] == list(range(20))


def test_ids_depend_on_parameters_not_position():
    one = parse_spec({"steps": "1-5", "modes": ["exact", "paper"]}).scenarios
    two = parse_spec({"steps": "1-5", "modes": ["paper", "exact"]}).scenarios
    assert {s.mode: s.id for s in one} == {s.mode: s.id for s in two}
    assert one[0].index == two[1].index - 1  # positions differ, ids do not


def test_singular_keys_and_defaults():
    (s,) = parse_spec({"mode": "paper", "steps": 566}).scenarios
    assert (s.case, s.mode, s.dynamics, s.graph, s.x0) == (
        "ieee-elv", "paper", "smith", "complete", "uniform",
    )  # fmt: skip
    assert s.steps == StepRange(566, 566)
    (day,) = parse_spec({}).scenarios
    assert day.steps == StepRange(1, 1440) and day.mode == "exact"


def test_sample_is_seeded_subset_of_product():
    table = {"steps": ["1-2", "3-4", "5-6"], "modes": ["exact", "paper"]}
    full = parse_spec(table).scenarios
    sample = parse_spec(table | {"sample": {"count": 4, "seed": 7}})
    assert sample.product_size == 6 and len(sample.scenarios) == 4
    assert {s.id for s in sample.scenarios} <= {s.id for s in full}
    again = parse_spec(table | {"sample": {"count": 4, "seed": 7}}).scenarios
    assert [s.id for s in again] == [s.id for s in sample.scenarios]


@pytest.mark.parametrize(
    "table, named",
    [
        ({"limits": [["505:666"]]}, "limits[0][0]"),
        ({"limits": [[], ["505:666=-1"]]}, "limits[1][0]"),
        ({"events": [["114:down@600"]]}, "events[0][0]"),
        ({"steps": "900-600"}, "steps[0]"),
        ({"modes": ["fast"]}, "mode"),
        ({"mode": "exact", "dynamics": "replicator"}, "mode"),
        ({"cases": ["nowhere"]}, "cases[0]"),
        ({"modez": ["exact"]}, "modez"),
        ({"mode": "exact", "modes": ["paper"]}, "modes"),
        ({"profile_assignments": {"count": 0}}, "profile_assignments.count"),
        ({"profile_assignments": {"count": 2}, "case": "case33bw"}, "profile_assignments"),
        ({"sample": {"count": 3}}, "sample.count"),
    ],
)
def test_bad_spec_is_one_line_naming_the_key(table, named):
    with pytest.raises(OptionError) as caught:
        parse_spec(table, "my.toml")
    message = str(caught.value)
    assert message.startswith(f"my.toml: {named}: ") and "\n" not in message


def test_unreadable_or_invalid_toml(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("modes = [exact]\n")
    with pytest.raises(OptionError, match="bad.toml: not valid TOML"):
        load_spec(bad)
    with pytest.raises(OptionError, match="cannot read spec"):
        load_spec(tmp_path / "missing.toml")
