"""The sweep commands' usage errors and listing (click's test runner; no cluster, no data)."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from popdispatch.cli.sweep import sweep, sweep_report
from popdispatch.errors import OptionError


@pytest.fixture
def spec(tmp_path):
    path = tmp_path / "spec.toml"
    path.write_text('steps = ["600-610", "700-710"]\nmodes = ["exact", "paper"]\n')
    return path


def test_dry_run_lists_every_scenario_before_any_work(spec, tmp_path):
    result = CliRunner().invoke(sweep, [str(spec), "--out", str(tmp_path / "o"), "--dry-run"])
    assert result.exception is None
    lines = result.output.strip().splitlines()
    assert lines[0] == f"4 scenarios: 0 already in {tmp_path / 'o'}, 4 to run"
    assert lines[1].split("\t") == [
        "id", "case", "steps", "mode", "dynamics", "graph", "limits", "events", "assignment",
        "state",
    ]  # fmt: skip
    rows = [line.split("\t") for line in lines[2:]]
    assert [(r[2], r[3]) for r in rows] == [
        ("600-610", "exact"), ("600-610", "paper"), ("700-710", "exact"), ("700-710", "paper"),
    ]  # fmt: skip
    assert all(r[-1] == "to-run" for r in rows)
    assert not (tmp_path / "o").exists()


def test_sample_shows_the_product_size(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('steps = ["1-2", "3-4", "5-6"]\nsample = { count = 2, seed = 3 }\n')
    result = CliRunner().invoke(sweep, [str(path), "--out", str(tmp_path / "o"), "--dry-run"])
    assert result.output.startswith("2 scenarios (sampled from 3): ")


@pytest.mark.parametrize(
    "text, extra, option",
    [
        ('modes = ["fast"]\n', [], "SPEC"),
        ("profile_assignments = { count = 2, seed = 1 }\n", [], "--profiles"),
        ("", ["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers"),
    ],
)
def test_usage_errors_name_the_option(tmp_path, monkeypatch, text, extra, option):
    monkeypatch.delenv("POPDISPATCH_PROFILES", raising=False)
    path = tmp_path / "spec.toml"
    path.write_text('steps = "600-601"\n' + text)
    result = CliRunner().invoke(sweep, [str(path), "--out", str(tmp_path / "o"), *extra])
    assert isinstance(result.exception, OptionError)  # the CLI's main exits 2
    assert result.exception.option == option and "\n" not in str(result.exception)
    assert not (tmp_path / "o").exists()


def test_report_of_an_empty_folder_is_a_usage_error(tmp_path):
    result = CliRunner().invoke(sweep_report, [str(tmp_path)])
    assert isinstance(result.exception, OptionError) and "no sweep results" in str(result.exception)
