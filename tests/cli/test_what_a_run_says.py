"""What a command says besides its result, run for real in subprocesses: where reproduce put
its results (stdout), a loop's progress in a log (one line with its count and time, no bar
frozen at its first draw), a clock time without a date on a dated series, a sweep of one
minute."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.cases import ieee_elv

from test_commands import assert_one_line_error, run


def test_reproduce_says_where_its_results_are(tmp_path):
    out = tmp_path / "results"
    result = run("reproduce", "--mode", "exact", "--minutes", "565-567", "--out", str(out), "-q")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == f"results in {out}:"
    for name in ("report.md", "figures/", "summary.json"):
        assert any(line.strip().startswith(f"{name}:") for line in lines), name
        assert (out / name.rstrip("/")).exists(), name


def test_a_long_loop_in_a_log_is_one_line_with_its_count(tmp_path):
    """stderr is a file here, not a terminal: the paper-mode day (several seconds) reports its
    1440 minutes once, when done, with the time it took."""
    result = run("day", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "\r" not in result.stderr and "?it/s" not in result.stderr
    done = [line for line in result.stderr.splitlines() if line.startswith("online day")]
    assert len(done) == 1 and done[0].split(": ")[1].startswith("1440/1440 in "), result.stderr


def dated_table(tmp_path: Path) -> Path:
    """Four quarter hours of 2024-01-01 for the 55 ELV loads."""
    names = list(ieee_elv().loads.index)
    frame = pd.DataFrame(np.full((4, len(names)), 0.5), columns=names)
    frame.insert(0, "time", [f"2024-01-01T00:{m:02d}:00" for m in (0, 15, 30, 45)])
    path = tmp_path / "loads.csv"
    frame.to_csv(path, index=False)
    return path


def test_a_clock_time_on_a_dated_series_asks_for_the_date(tmp_path):
    result = run("day", "--loads", str(dated_table(tmp_path)), "--start", "00:20", "-q")
    assert_one_line_error(result, 2, "--start", "'00:20' has no date", "2024-01-01T00:20")
    assert "outside the series" not in result.stderr


def test_a_sweep_of_one_minute(tmp_path):
    spec = tmp_path / "spec.toml"
    spec.write_text('case = "ieee-elv"\nsteps = "566"\nmodes = ["exact"]\n')
    result = run("sweep", str(spec), "--out", str(tmp_path / "out"), "--dry-run", "-q")
    assert result.returncode == 0, result.stderr
    assert "\t566-566\t" in result.stdout
