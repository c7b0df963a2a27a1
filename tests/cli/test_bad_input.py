"""Absurd numbers, unwritable places and files that are not networks: one line on stderr in
one style (``popdispatch: error: ...``), naming the file, row and column or the option, exit 2
for bad usage and 1 for a problem, never a traceback and never a temporary file's name. Run
for real in subprocesses on the built-in ieee-elv case (no data folder needed)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from test_commands import assert_one_line_error, clean_env, run

#: The paper's fleet (Table I) as a file, with one number to spoil.
FLEET = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,G1,5,0.02,0,10
114,G114,1,0.01,0,10
578,G578,3,0.025,0,5
739,G739,4,0.01,0,10
817,G817,2.5,0.015,0,20
835,G835,2,0.02,0,10
"""


@pytest.mark.parametrize(
    ("row", "before", "after", "column"),
    [
        (1, "1,G1,5,0.02,0,10", "1,G1,5,0.02,0,1e30", "pmax_kw = 1e+30"),
        (2, "114,G114,1,0.01", "114,G114,1e20,0.01", "b_eur_per_mwh = 1e+20"),
        (3, "578,G578,3,0.025", "578,G578,3,1e300", "c_eur_per_mw2h = 1e+300"),
        (5, "817,G817,2.5,0.015,0", "817,G817,2.5,0.015,-4", "pmin_kw = -4"),
    ],
)
def test_absurd_fleet_numbers_name_file_row_and_column(tmp_path, row, before, after, column):
    fleet = tmp_path / "fleet.csv"
    fleet.write_text(FLEET.replace(before, after))
    result = run("opf", "--minute", "566", "--fleet", str(fleet))
    assert_one_line_error(result, 1, f"{fleet}: row {row}", column, "is outside 0..")
    assert result.stdout == ""


def test_an_absurd_limit_is_a_usage_error():
    result = run("opf", "--minute", "566", "--limit", "505:666=1e308")
    assert_one_line_error(result, 2, "--limit", "1e+308 kW is above 1e+07 kW")


def test_a_solver_that_gives_up_is_one_line(tmp_path):
    """Whatever a solver raises (here Clarabel's status, forced) ends as one line, exit 1."""
    code = (
        "import sys\n"
        "from popdispatch import opf\n"
        "def give_up(self, minute):\n"
        "    raise RuntimeError(f'DC-OPF at minute {minute}: Clarabel returned "
        "InsufficientProgress')\n"
        "opf.OpfSolver.solve = give_up\n"
        "from popdispatch.cli import main\n"
        "sys.exit(main(['opf', '--minute', '566']))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env=clean_env(), cwd=tmp_path, timeout=600)  # fmt: skip
    assert_one_line_error(result, 1, "Clarabel returned InsufficientProgress", "a solver failed")


def test_out_on_a_file_system_that_takes_no_files_names_no_temporary_file(tmp_path):
    result = run("snapshot", "--minute", "566", "--out", "/proc/pd_out", "-q")
    assert_one_line_error(result, 1, "cannot write to /proc/pd_out",
                          "/proc does not take new files")  # fmt: skip
    assert ".tmp" not in result.stderr


def test_out_below_a_file_names_the_file(tmp_path):
    (tmp_path / "notanet.txt").write_text("keep me")
    target = tmp_path / "notanet.txt" / "sub" / "deeper"
    result = run("snapshot", "--minute", "566", "--out", str(target), "-q")
    assert_one_line_error(result, 2, "--out", f"{tmp_path / 'notanet.txt'} is a file, not a folder")
    assert (tmp_path / "notanet.txt").read_text() == "keep me"


@pytest.mark.parametrize("text", ["{}", "[]", '{"a": 1}'])
def test_json_that_is_no_pandapower_network_is_one_line(tmp_path, text):
    net = tmp_path / "net.json"
    net.write_text(text)
    result = run("feeder", "--net", str(net))
    assert_one_line_error(result, 1, f"cannot read pandapower JSON {net}",
                          "holds no pandapower network")  # fmt: skip
    assert "attribute" not in result.stderr


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["opf", "--minute", "x"], ["invalid value for --minute / --step", "'x'"]),
        (["opf"], ["missing option '--minute'"]),
        (["opf", "--minute", "1", "--nope"], ["no such option '--nope'"]),
        (["snapshot", "--minute", "1", "--mode", "exact", "--dynamics", "replicator"],
         ["invalid value for --mode"]),
        (["nope"], ["no such command 'nope'"]),
    ],
)  # fmt: skip
def test_every_error_has_one_prefix(args, words, tmp_path: Path):
    """Click's own errors and popdispatch's read alike: ``popdispatch: error: ...``."""
    result = run(*args, cwd=tmp_path)
    assert_one_line_error(result, 2, *words)
