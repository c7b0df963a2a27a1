"""A run compiles only the kernels it uses (issue 13, first run): the mode, field, graph and
stepper reach the kernels as record classes and numba compiles, per class, the one kernel it
names; the warm start is a plain value, so every policy shares one compiled day loop.
Checked on a cold numba cache in a child process, with numba's own compile events and cache
index as the yardstick; and the compile notice's check agrees with what the engine builds."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from popdispatch.compile_notice import run_classes
from popdispatch.online import Engine, RunSettings
from popdispatch.scenarios import CONGESTION_PATH, elv_problem

CONFIGURATIONS = [
    {"mode": "paper"},
    {"mode": "exact"},
    {"mode": "exact", "dynamics": "distributed-smith", "graph": "ring"},
    {"mode": "paper", "dynamics": "local-replicator", "graph": "path"},
    {"mode": "exact", "warm_start": "setpoints"},
    {"mode": "paper", "dynamics": "bnn"},
    {"mode": "exact", "dynamics": "logit", "eta": 0.1},
]


@pytest.mark.parametrize("options", CONFIGURATIONS, ids=lambda o: "-".join(map(str, o.values())))
def test_the_notice_checks_the_classes_the_engine_passes(options):
    settings = RunSettings(**options)
    engine = Engine(elv_problem(limits=[CONGESTION_PATH]), settings)
    passed = {
        type(engine.term.field), type(engine.term.mode), type(engine.term.graph),
        type(settings.stepping.stepper().method),
    }  # fmt: skip
    assert run_classes(settings) == passed


CHILD = textwrap.dedent(
    """
    import json
    import numpy as np
    from numba.core import event
    from popdispatch.compile_notice import kernels_cached
    from popdispatch.online import RunSettings, run_day, run_snapshot
    from popdispatch.online.day import integrate_day
    from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

    compiled = []

    class Names(event.Listener):
        def on_start(self, ev):
            compiled.append(ev.data["dispatcher"].py_func.__qualname__)

        def on_end(self, ev):
            pass

    event.register("numba:compile", Names())
    problem = elv_problem(limits=[CONGESTION_PATH])
    exact, paper = RunSettings(mode="exact"), RunSettings(mode="paper")
    before = kernels_cached(exact)
    minute = run_snapshot(problem, PEAK_MINUTE, exact)
    minutes = np.array([PEAK_MINUTE, PEAK_MINUTE + 1])
    day = run_day(problem, exact, minutes=minutes)
    for policy in ("setpoints", "shares"):
        run_day(problem, RunSettings(mode="exact", warm_start=policy), minutes=minutes)
    print(json.dumps({
        "before": before, "exact": kernels_cached(exact), "paper": kernels_cached(paper),
        "compiled": compiled, "status": [minute.status, day.status],
        "day_loops": sum(integrate_day.stats.cache_misses.values()),
    }))
    """
)


@pytest.mark.slow
def test_an_exact_run_compiles_its_own_kernels_only(tmp_path):
    """Cold cache: an exact minute, a two-minute exact day and the same day with the
    ``setpoints`` and ``shares`` warm starts compile the day loop once (a minute is a day of
    one row; the policy is a plain value), Heun but not Euler, the complete graph's sums but
    not the sparse ones; afterwards the notice's check says exact is cached and paper is
    not."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    done = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True,
                          text=True, timeout=900, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["before"] is False
    assert report["exact"] is True
    assert report["paper"] is False
    assert report["day_loops"] == 1
    compiled = set(report["compiled"])
    assert {"advance_heun", "_order_for.<locals>.complete"} <= compiled
    assert "continue_setpoints" in compiled
    unused = {"advance_euler", "_order_for.<locals>.unsorted", "_law_flows.<locals>.sparse",
              "_law_flows.<locals>.target"}  # fmt: skip
    assert not compiled & unused, compiled & unused
    assert report["status"] == ["converged", "converged"]
