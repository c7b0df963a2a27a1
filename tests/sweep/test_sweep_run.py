"""Sweeps on a Dask LocalCluster: failures recorded, resume, workers loading the cached
kernels (no official data needed: the ELV runs on the profiles the environment gives)."""

from __future__ import annotations

import pandas as pd
import pytest

from popdispatch.sweep import parse_spec, run
from popdispatch.sweep.execute import warm_up
from popdispatch.sweep.store import STEPS, read_summary

#: Every generator of the paper's fleet (Table I) off from minute 600: the run raises.
ALL_OFF = [f"{bus}:off@600" for bus in (1, 114, 578, 739, 817, 835)]
#: Bus 34 (LOAD1) cut off: no dispatch serves it, the DC-OPF is infeasible at every step.
CUT_OFF = ["1:34=0"]

SPEC = {"steps": "600-605", "mode": "exact", "limits": [[], CUT_OFF], "events": [[], ALL_OFF]}


@pytest.fixture(scope="module")
def failing_sweep(tmp_path_factory):
    """Four scenarios on one worker process: one fine, one infeasible, two raising."""
    warm_up()  # the kernels are in numba's disk cache before the worker starts
    out = tmp_path_factory.mktemp("sweep")
    spec = parse_spec(SPEC)
    return spec, out, run(spec, out, workers=1, quiet=True)


def test_raising_scenarios_are_recorded_and_the_rest_complete(failing_sweep):
    spec, out, result = failing_sweep
    assert result.ran == 4 and len(result.failed) == 2
    summary = read_summary(out).set_index(["limits", "events"])
    fine = summary.loc[("none", "none")]
    assert fine.status == "converged" and fine.max_abs_error_kw < 1e-3 and pd.isna(fine.error)
    assert fine.compared_minutes == 6
    infeasible = summary.loc[("1:34=0", "none")]
    assert infeasible.status == "infeasible" and list(infeasible.infeasible_minutes) == list(
        range(600, 606)
    )
    assert infeasible.error.startswith("the DC-OPF is infeasible at 6 of 6 minutes")
    for limits in ("none", "1:34=0"):
        failed = summary.loc[(limits, ";".join(ALL_OFF))]
        assert failed.status == "failed" and failed.error.startswith("InfeasibleError: ")
        assert "online" in failed.error
    steps = pd.read_parquet(out / STEPS)
    by_scenario = steps.groupby(steps.scenario_id.astype(str), observed=True).size()
    ids = set(summary.scenario_id[summary.status != "failed"])
    assert set(by_scenario.index) == ids and (by_scenario == 6 * 6).all()


def test_workers_load_the_kernels_from_the_disk_cache(failing_sweep):
    _, _, result = failing_sweep
    (info,) = result.warm_up.values()
    # the engine's entry points a day calls from Python (compile_notice.ENTRY_POINTS): the day
    # loop, loaded from the disk cache, nothing compiled (the game and field are linked into
    # the day loop's cached code)
    assert info["cache_misses"] == 0 and info["cache_hits"] >= 1


def test_resume_runs_only_the_missing_scenarios(tmp_path):
    spec = parse_spec({"steps": "600-603", "modes": ["exact"], "limits": [[], ["505:666=28"]],
                       "events": [[], ["114:off@601"]]})  # fmt: skip
    first = run(spec.scenarios[:2], tmp_path, workers=1, quiet=True, processes=False)
    assert (first.ran, first.skipped) == (2, 0)
    before = read_summary(tmp_path).set_index("scenario_id").finished_at
    rest = run(spec, tmp_path, workers=1, quiet=True, processes=False)
    assert (rest.total, rest.ran, rest.skipped) == (4, 2, 2)
    after = read_summary(tmp_path).set_index("scenario_id").finished_at
    assert len(after) == 4 and (after[before.index] == before).all()
    again = run(spec, tmp_path, workers=1, quiet=True, processes=False)
    assert (again.ran, again.skipped) == (0, 4)


def test_failed_scenarios_run_again_on_resume(tmp_path):
    spec = parse_spec({"steps": "600-601", "events": [[], ALL_OFF]})
    first = run(spec, tmp_path, workers=1, quiet=True, processes=False)
    assert (first.ran, len(first.failed)) == (2, 1)
    rerun = run(spec, tmp_path, workers=1, quiet=True, processes=False)
    assert (rerun.ran, rerun.skipped, list(rerun.failed)) == (1, 1, list(first.failed))


KILLED_SWEEP = """
import sys
from popdispatch.sweep import parse_spec, run
if __name__ == "__main__":
    spec = parse_spec({"steps": "1-240", "modes": ["exact"], "x0": ["uniform", "capacity"],
                       "limits": [[], ["505:666=28"], ["505:666=30"]]})
    run(spec, sys.argv[1], workers=1, quiet=True)
"""


def test_a_killed_sweep_resumes_without_recomputing(tmp_path):
    """Kill a sweep (driver and its worker, SIGKILL) once some scenarios are written, rerun:
    only the others run, the finished ones keep their rows."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from popdispatch.sweep.store import SUMMARY

    out = tmp_path / "out"
    script = tmp_path / "sweep.py"
    script.write_text(KILLED_SWEEP)
    child = subprocess.Popen([sys.executable, str(script), str(out)], start_new_session=True)
    try:
        deadline = time.monotonic() + 300
        while len(list((out / SUMMARY).glob("*/part-0.parquet"))) < 2:
            assert child.poll() is None and time.monotonic() < deadline, "sweep ended early"
            time.sleep(0.1)
    finally:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()
    before = read_summary(out).set_index("scenario_id").finished_at
    assert 2 <= len(before) < 6  # killed halfway
    spec = parse_spec({"steps": "1-240", "modes": ["exact"], "x0": ["uniform", "capacity"],
                       "limits": [[], ["505:666=28"], ["505:666=30"]]})  # fmt: skip
    rest = run(spec, out, workers=1, quiet=True, processes=False)
    assert (rest.ran, rest.skipped) == (6 - len(before), len(before))
    after = read_summary(out).set_index("scenario_id").finished_at
    assert len(after) == 6 and (after[before.index] == before).all()


def test_report_counts_failed_and_infeasible(failing_sweep, tmp_path):
    from popdispatch.sweep.report import write_report

    _, out, _ = failing_sweep
    text, folder = write_report(out, tmp_path / "report")
    assert text.startswith("4 scenarios: ") and "2 failed" in text and "1 infeasible" in text
    groups = pd.read_csv(folder / "groups.csv").set_index("limits")
    assert groups.loc["none", ["scenarios", "failed", "converged"]].tolist() == [2, 1, 1]
    assert groups.loc["1:34=0", ["scenarios", "failed", "infeasible"]].tolist() == [2, 1, 1]
    assert text.count("InfeasibleError: ") == 2 and (folder / "sweep.png").is_file()


def test_a_lost_task_is_recorded_failed_unless_its_results_were_written(tmp_path):
    from popdispatch.sweep.execute import _lost
    from popdispatch.sweep.scenario import Context
    from popdispatch.sweep.store import status_of, write_scenario

    first, second = parse_spec({"steps": "1-2", "modes": ["exact", "paper"]}).scenarios
    context = Context(str(tmp_path))
    write_scenario(tmp_path, second.id, {"status": "converged"})
    lost = _lost(first, context, RuntimeError("worker tcp://x died\n3 times"))
    assert (
        lost["status"] == "failed" and lost["error"] == "RuntimeError: worker tcp://x died 3 times"
    )
    assert status_of(tmp_path, first.id) == "failed"
    assert _lost(second, context, RuntimeError("late"))["status"] == "converged"
    assert status_of(tmp_path, second.id) == "converged"
