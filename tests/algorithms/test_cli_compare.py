"""``popdispatch compare`` in a subprocess: bad input is one line and exit 2 before any work;
a run prints its table, writes compare.csv, summary.json and the figure, and its JSON
agrees with the library's run of the same algorithm."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cli"))
from popdispatch.algorithms import ALGORITHMS, Faults, RunOptions, run_algorithm  # noqa: E402
from popdispatch.cli.compare import ALGORITHM_NAMES  # noqa: E402
from popdispatch.scenarios import CONGESTION_PATH, elv_problem  # noqa: E402

from test_commands import assert_one_line_error, run  # noqa: E402


def test_the_command_knows_the_registry():
    assert set(ALGORITHM_NAMES) == set(ALGORITHMS)


@pytest.mark.parametrize(("args", "words"), [
    (["--algorithms", "smith,newton"], ["--algorithms", "newton"]),
    (["--algorithms", ","], ["--algorithms", "no algorithm"]),
    (["--crash", "G114"], ["--crash", "GEN@ROUND"]),
    (["--crash", "G999@5"], ["--crash", "G999"]),
    (["--loss", "1.5"], ["--loss"]),
    (["--seeds", "0"], ["--seeds"]),
    (["--graph", "tree"], ["--graph", "tree"]),
    (["--algorithms", "smith,admm", "--graph", "circulant"], ["--graph", "distributed-smith"]),
])  # fmt: skip
def test_bad_input_is_one_line_and_exit_2(args, words):
    result = run("compare", "--minute", "566", *args)
    assert_one_line_error(result, 2, *words)


def test_a_run_writes_its_files_and_agrees_with_the_library(tmp_path):
    out = tmp_path / "cmp"
    result = run("compare", "--minute", "566", "--limit", "505:666=28", "--algorithms",
                 "dual-decomposition,admm", "--loss", "0.1", "--seeds", "2", "--max-rounds",
                 "60", "--out", str(out), "--json", "--quiet")  # fmt: skip
    assert result.returncode == 0, result.stderr
    payload = json.loads(result.stdout)
    assert [row["algorithm"] for row in payload["algorithms"]] == ["dual-decomposition", "admm"]
    table = pd.read_csv(out / "compare.csv")
    assert len(table) == 4 and set(table.seed) == {0, 1}
    assert (out / "distance.png").is_file() and (out / "summary.json").is_file()
    problem = elv_problem(limits=[CONGESTION_PATH])
    lib = run_algorithm("admm", problem, 566, Faults(loss=0.1, seed=1),
                        options=RunOptions(max_rounds=60))  # fmt: skip
    row = table[(table.algorithm == "admm") & (table.seed == 1)].iloc[0]
    assert row.messages_total == lib.messages[-1]
    assert row.final_distance_kw == pytest.approx(lib.distance_kw[-1], rel=1e-9)
    assert row.status == "not_converged"  # 60 rounds: far from the DC-OPF, and it says so


def test_the_table_stays_aligned_with_the_longest_algorithm_name():
    result = run("compare", "--minute", "566", "--limit", "505:666=28", "--algorithms",
                 "fast-dual-decomposition,admm", "--max-rounds", "20", "--quiet")  # fmt: skip
    assert result.returncode == 0, result.stderr
    header, *rows = result.stdout.splitlines()[1:4]
    assert rows[0].split()[0] == "fast-dual-decomposition"
    assert len({len(header), *(len(row) for row in rows)}) == 1
    assert header.index("converged") + len("converged") == rows[0].index("0/1") + len("0/1")


def test_dual_decomposition_refuses_a_linear_cost_in_one_line(tmp_path):
    """A DG with c = 0 has no unique best response: dual decomposition cannot run on the fleet
    and says which DG, before any work (the others still run without it)."""
    fleet = tmp_path / "fleet.csv"
    fleet.write_text("bus,name,a,b,c,pmin_kw,pmax_kw\n1,G1,0,60,0.5,0,100\n"
                     "114,G114,0,20,0,0,30\n578,G578,0,25,2,0,30\n")  # fmt: skip
    result = run("compare", "--minute", "566", "--fleet", str(fleet), "--algorithms",
                 "smith,dual-decomposition")  # fmt: skip
    assert_one_line_error(result, 2, "--algorithms", "'G114'", "linear cost")
    alone = run("compare", "--minute", "566", "--fleet", str(fleet), "--algorithms", "smith",
                "--json", "-q")  # fmt: skip
    assert alone.returncode == 0, alone.stderr


def test_distributed_smith_runs_on_the_graph_given():
    """``--graph circulant``: distributed Smith's agents talk to four partners each (plus the
    controllers), and the run equals the library's on that graph."""
    result = run("compare", "--minute", "566", "--limit", "505:666=28", "--algorithms",
                 "distributed-smith", "--graph", "circulant", "--max-rounds", "40", "--json",
                 "--quiet")  # fmt: skip
    assert result.returncode == 0, result.stderr
    payload = json.loads(result.stdout)
    assert payload["graph"] == "circulant"
    params = replace(ALGORITHMS["distributed-smith"].params(), graph="circulant")
    lib = run_algorithm("distributed-smith", elv_problem(limits=[CONGESTION_PATH]), 566,
                        Faults(), params, RunOptions(max_rounds=40))  # fmt: skip
    row = payload["runs"][0]
    assert row["messages_total"] == lib.messages[-1]
    assert row["final_distance_kw"] == pytest.approx(lib.distance_kw[-1], rel=1e-9)
    ring = run_algorithm("distributed-smith", elv_problem(limits=[CONGESTION_PATH]), 566,
                         Faults(), options=RunOptions(max_rounds=40))  # fmt: skip
    assert row["partners_max"] == ring.summary()["partners_max"] + 2  # 4 DG partners, not 2
