"""The ``popdispatch`` command line, run for real in subprocesses (issue 4).

Engine runs cost a JIT compilation per process (~10 s), so each command that integrates the
dynamics is run once and its outputs are checked together.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from popdispatch.modes import MODES

from helpers import find_official_folder, official_folder

SCRIPT = Path(sys.executable).with_name("popdispatch")
COMMANDS = [
    "agents", "cases", "compare", "cosim", "day", "export", "feeder", "opf", "reproduce",
    "snapshot", "sweep",
    "sweep-report",
]  # fmt: skip


def command(*args: str) -> list[str]:
    base = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "popdispatch.cli"]
    return base + list(args)


def clean_env() -> dict[str, str]:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("POPDISPATCH_PROFILES", "POPDISPATCH_DEBUG")
    }
    env["MPLBACKEND"] = "Agg"
    return env


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        command(*args), capture_output=True, text=True, env=clean_env(), cwd=cwd, timeout=900
    )


def assert_one_line_error(result: subprocess.CompletedProcess, code: int, *words: str) -> None:
    assert result.returncode == code, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("popdispatch: error: "), lines[0]  # one style for every error
    for word in words:
        assert word in lines[0], lines[0]


def gens(summary: dict) -> dict[str, dict]:
    return {g["name"]: g for g in summary["generators"]}


# -- help and choices ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_has_help(name):
    result = run(name, "--help")
    assert result.returncode == 0
    assert result.stdout.startswith(f"Usage: popdispatch {name}")


def test_mode_choices_come_from_the_engine():
    text = run("snapshot", "--help").stdout
    for mode in MODES:
        assert mode in text


def test_minutes_per_day_is_the_profiles_constant():
    from popdispatch.cli import MINUTES_PER_DAY
    from popdispatch.feeder.profiles import MINUTES_PER_DAY as PROFILE_MINUTES

    assert MINUTES_PER_DAY == PROFILE_MINUTES


def test_top_level_help_lists_every_command_in_full():
    text = run("--help").stdout
    lines = {line.split()[0]: line for line in text.splitlines()[-len(COMMANDS) :]}
    assert sorted(lines) == sorted(COMMANDS)
    assert all("..." not in line for line in lines.values()), text
    assert "paper eq. 1" in lines["opf"]


HEAVY = ("numpy", "pandas", "numba", "scipy", "networkx", "pandapower", "matplotlib", "tqdm")


def loaded_after(code: str) -> tuple[subprocess.CompletedProcess, list[str]]:
    """Run ``code`` in a fresh interpreter; which of :data:`HEAVY` it imported."""
    report = f"import json, sys; print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    result = subprocess.run(
        [sys.executable, "-c", f"{code}\n{report}"], capture_output=True, text=True,
        env=clean_env(), timeout=900,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    return result, json.loads(result.stdout.strip().splitlines()[-1])


def test_importing_the_cli_imports_no_heavy_library():
    result, loaded = loaded_after("import popdispatch.cli")
    assert result.returncode == 0
    assert loaded == []


# -- feeder and opf -----------------------------------------------------------------------------


def test_feeder_json():
    result = run("feeder", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert (summary["buses"], summary["nodes"], summary["lines"], summary["loads"]) == (
        906, 110, 109, 55,
    )  # fmt: skip
    assert summary["capacity_kw"] == 65.0
    assert [g["bus"] for g in summary["generators"]] == [1, 114, 578, 739, 817, 835]


def test_feeder_from_opendss_matches_the_built_in_case():
    folder = official_folder()
    summary = json.loads(run("feeder", "--opendss", str(folder), "--json", "-q").stdout)
    assert (summary["buses"], summary["nodes"], summary["lines"], summary["loads"]) == (
        906, 110, 109, 55,
    )  # fmt: skip


def test_opf_json_with_the_paper_limit():
    result = run("opf", "--minute", "566", "--limit", "505:666=28", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["status"] == "optimal"
    assert summary["minute"] == 566
    assert summary["demand_kw"] == pytest.approx(57.358, abs=1e-3)
    p = {name: g["p_kw"] for name, g in gens(summary).items()}
    assert p["G739"] == pytest.approx(3.138, abs=1e-3)
    assert p["G1"] == pytest.approx(9.220, abs=1e-3)
    assert sum(p.values()) == pytest.approx(57.358, abs=1e-3)
    assert summary["cost"] == pytest.approx(0.1536634, rel=1e-5)


def test_opf_infeasible_limits_exit_1_and_still_report():
    result = run("opf", "--minute", "566", "--limit", "505:666=0", "--json")
    assert_one_line_error(result, 1, "infeasible")
    assert json.loads(result.stdout)["status"] == "infeasible"


def test_opf_text_echoes_the_limits():
    result = run("opf", "--minute", "566", "--limit", "505:666=28", "-q")
    assert result.returncode == 0, result.stderr
    assert "limits: 505:666=28 kW (21 lines)" in result.stdout
    assert "feeder: ieee-elv" in result.stdout


def test_opf_on_the_opendss_feeder_equals_the_built_in_case():
    folder = official_folder()
    runs = [
        json.loads(run("opf", "--minute", "566", "--limit", "505:666=28", "--json", "-q",
                       *extra).stdout)
        for extra in ([], ["--opendss", str(folder)])
    ]  # fmt: skip
    for a, b in zip(runs[0]["generators"], runs[1]["generators"], strict=True):
        assert a["p_kw"] == pytest.approx(b["p_kw"], abs=1e-6)


# -- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["opf", "--minute", "0"], ["--minute", "0"]),
        (["opf", "--minute", "1441"], ["--minute", "1441"]),
        (["opf", "--minute", "566", "--limit", "505-666=28"], ["--limit", "505-666=28"]),
        (["opf", "--minute", "566", "--limit", "505:666=-3"], ["--limit", "-3"]),
        (["opf", "--minute", "566", "--limit", "505:9999=28"], ["--limit", "unknown bus 9999"]),
        (["opf", "--minute", "566", "--profiles", "/no/such/folder"], ["--profiles"]),
        (["snapshot", "--minute", "566", "--x0", "G999=1"], ["--x0", "G999"]),
        (["snapshot", "--minute", "566", "--x0", "G114=abc"], ["--x0", "G114=abc"]),
        (["snapshot", "--minute", "566", "--dynamics", "nope"], ["--dynamics", "nope"]),
        (["day", "--event", "739:offline@10"], ["--event", "739:offline@10"]),
        (["day", "--event", "115:off@10", "-q"], ["--event", "no generator at bus 115"]),
        (["day", "--event", "739:on@10", "-q"], ["--event", "G739 is not off"]),
        (["day", "--minutes", "10-5"], ["--minutes", "10-5"]),
        (["export", "--minute", "566", "--format", "csv", "--out", "x.m"], ["--format"]),
        (["feeder", "--case", "ieee-elv", "--opendss", "."], ["--case", "--opendss"]),
        (["reproduce", "--out", "no/such/results"], ["--out", "does not exist"]),
        (["reproduce", "--out", "r", "--opendss", "."], ["--opendss", "feeder, opf, snapshot"]),
        (
            ["snapshot", "--minute", "566", "--mode", "exact", "--dynamics", "replicator"],
            ["--mode", "replicator"],
        ),
        (["day", "--dynamics", "smith", "--graph", "ring"], ["--graph", "ring"]),
        (["snapshot", "--minute", "566", "--x0", "=1"], ["--x0", "=1"]),
    ],
)
def test_usage_errors_exit_2_with_one_line(args, words, tmp_path):
    result = run(*args, cwd=tmp_path)
    assert_one_line_error(result, 2, *words)
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--mode", "exact", "--dynamics", "replicator"], ["--mode", "replicator"]),
        (["--graph", "ring"], ["--graph", "ring"]),
        (["--x0", "G999=1"], ["--x0", "G999"]),
    ],
)
def test_options_are_checked_before_any_data_is_read(args, words, tmp_path):
    # profiles that would fail to load (exit 1) if they were read before the options
    (tmp_path / "Loads.txt").write_text("New Load.LOAD1 Phases=1 Bus1=34.1 kW=1 Yearly=Shape_x\n")
    result = run("snapshot", "--minute", "100", "--profiles", str(tmp_path), *args)
    assert_one_line_error(result, 2, *words)


def test_x0_naming_some_generators_says_which_start_at_zero():
    result = run("snapshot", "--minute", "566", "--x0", "G1=1", "--json")
    assert result.returncode == 0, result.stderr
    assert "--x0 gives no share to G114, G578, G739, G817, G835" in result.stderr
    assert json.loads(result.stdout)["x0"] == "G1=1"


def test_unreadable_profile_folder_is_a_problem(tmp_path):
    (tmp_path / "Loads.txt").write_text("New Load.LOAD1 Phases=1 Bus1=34.1 kW=1 Yearly=Shape_x\n")
    result = run("opf", "--minute", "100", "--profiles", str(tmp_path))
    assert_one_line_error(result, 1, "Loads.txt", "Shape_x")


def test_out_that_is_a_file_is_a_usage_error(tmp_path):
    target = tmp_path / "taken"
    target.write_text("keep me")
    result = run("snapshot", "--minute", "566", "--out", str(target))
    assert_one_line_error(result, 2, "--out")
    assert target.read_text() == "keep me"


# -- snapshot -----------------------------------------------------------------------------------

SNAPSHOT_KEYS = {
    "status", "minute", "demand_kw", "mode", "dynamics", "x0", "profile_source", "generators",
    "iterations", "first_congestion_iteration", "max_overflow_kw", "max_abs_error_kw",
    "wall_seconds", "command_seconds",
}  # fmt: skip


def test_snapshot_congestion_json_and_out(tmp_path):
    out = tmp_path / "snap"
    result = run("snapshot", "--minute", "566", "--limit", "505:666=28", "--out", str(out),
                 "--json")  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary.keys() >= SNAPSHOT_KEYS
    assert 0 <= summary["wall_seconds"] <= summary["command_seconds"]
    assert summary["status"] == "converged"
    assert (summary["mode"], summary["dynamics"], summary["x0"]) == ("paper", "smith", "uniform")
    assert "official minute 566" in summary["profile_source"]
    g = gens(summary)
    assert set(g["G739"]) >= {"bus", "setpoint_kw", "opf_kw"}
    assert g["G739"]["opf_kw"] == pytest.approx(3.138, abs=1e-3)
    assert g["G739"]["setpoint_kw"] < 5.0  # penalised well below its free optimum of 10 kW
    assert g["G1"]["setpoint_kw"] > 5.0  # raised to compensate (free optimum 2.358 kW)
    assert summary["first_congestion_iteration"] is not None
    assert summary["first_congestion_iteration"] <= summary["iterations"]
    assert 0.1 < summary["max_overflow_kw"] < 1.0  # the paper's signal leaves a residual
    error = max(abs(x["setpoint_kw"] - x["opf_kw"]) for x in summary["generators"])
    assert summary["max_abs_error_kw"] == pytest.approx(error)
    assert sorted(p.name for p in out.iterdir()) == [
        "setpoints.pdf", "setpoints.png", "summary.json", "trajectory.csv",
    ]  # fmt: skip
    assert json.loads((out / "summary.json").read_text()) == summary
    table = pd.read_csv(out / "trajectory.csv")
    assert len(table) == summary["iterations"] + 1
    assert {"iteration", "time_s", "G739_setpoint_kw", "G739_opf_kw"} <= set(table.columns)
    assert table.G739_setpoint_kw.iloc[-1] == pytest.approx(g["G739"]["setpoint_kw"], abs=1e-5)


def test_snapshot_replicator_keeps_a_zero_start_generator_extinct():
    result = run("snapshot", "--minute", "566", "--dynamics", "replicator", "--x0",
                 "G114=0,G1=1,G578=1,G739=1,G817=1,G835=1", "--json", "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["dynamics"] == "replicator"
    assert summary["x0"].startswith("G114=0")
    assert gens(summary)["G114"]["setpoint_kw"] == 0.0
    assert summary["max_abs_error_kw"] > 9.9  # the DC-OPF puts G114 at 10 kW


def test_snapshot_infeasible_limits_write_the_complete_run_and_exit_1(tmp_path):
    out = tmp_path / "snap"
    result = run("snapshot", "--minute", "566", "--limit", "505:666=0", "--out", str(out),
                 "--json", "-q")  # fmt: skip
    assert_one_line_error(result, 1, "infeasible")
    assert json.loads(result.stdout)["status"] == "infeasible"
    assert json.loads((out / "summary.json").read_text()) == json.loads(result.stdout)
    assert not [p for p in tmp_path.rglob("*") if p.name.startswith(".")]  # no staging left


# -- day ----------------------------------------------------------------------------------------

DAY_KEYS = {
    "status", "minutes", "profile_source", "mode", "dynamics", "max_abs_error_kw",
    "mean_abs_error_kw", "energy_kwh", "opf_energy_kwh", "cost", "opf_cost", "max_overflow_kw",
    "wall_seconds", "command_seconds",
}  # fmt: skip


def test_day_with_an_outage_json_and_out(tmp_path):
    out = tmp_path / "day"
    result = run("day", "--minutes", "600-620", "--event", "817:off@605", "--event",
                 "817:on@612", "--out", str(out), "--json")  # fmt: skip
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary.keys() >= DAY_KEYS
    # the engine's own time, and the whole command's (from the process start), which holds it
    assert 0 <= summary["wall_seconds"] <= summary["command_seconds"]
    assert summary["minutes"] == 21
    assert summary["events"] == ["817:off@605", "817:on@612"]
    assert summary["profile_source"].startswith("synthetic default")
    assert "offline default" in result.stderr  # says so
    table = pd.read_csv(out / "day.csv")
    assert list(table.minute) == list(range(600, 621))
    off = table.minute.between(605, 611)
    assert (table.G817_setpoint_kw[off] == 0).all()
    assert (table.G817_opf_kw[off] == 0).all()
    assert table.G817_setpoint_kw[~off].gt(0).all()
    assert summary["energy_kwh"]["817"] == pytest.approx(table.G817_setpoint_kw.sum() / 60)
    assert summary["opf_cost"] == pytest.approx(table.opf_cost_eur_per_h.sum() / 60)
    assert summary["cost"] >= summary["opf_cost"] - 1e-9  # the DC-OPF is the cheapest
    demand = table.demand_kw
    setpoints = table[[c for c in table.columns if c.endswith("_setpoint_kw")]].sum(axis=1)
    assert (setpoints - demand).abs().max() < 1e-6
    assert json.loads((out / "summary.json").read_text()) == summary
    assert (out / "setpoints.png").stat().st_size > 0


def test_day_imports_neither_pandapower_nor_matplotlib_once_cached():
    code = "from popdispatch.cli import main; main(['day', '--minutes', '600-602', '-q'])"
    loaded_after(code)  # fills the feeder cache if this is the first run
    result, loaded = loaded_after(code)
    assert result.returncode == 0, result.stderr
    assert "pandapower" not in loaded
    assert "matplotlib" not in loaded  # drawing is for --out only
    text = result.stdout
    assert "engine" in text and "whole command" in text  # both times, in words too


# -- export -------------------------------------------------------------------------------------


@pytest.mark.parametrize(("fmt", "name"), [("matpower", "elv566.m"), ("pandapower", "elv.json")])
def test_export_writes_the_file(tmp_path, fmt, name):
    out = tmp_path / name
    result = run("export", "--minute", "566", "--format", fmt, "--out", str(out), "--limit",
                 "505:666=28", "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    text = out.read_text()
    if fmt == "matpower":
        assert text.startswith("function mpc = elv566")
        assert "mpc.gencost" in text
    else:
        assert json.loads(text)["_module"].startswith("pandapower")
    assert [p.name for p in tmp_path.iterdir()] == [name]


# -- reproduce ----------------------------------------------------------------------------------

FIGURES = [
    "fig1_fitness", "fig2_congestion_detection", "fig3_feeder_flows_566", "fig4_base_day",
    "fig5_congestion_iterations", "fig6_extinction",
]  # fmt: skip


def test_reproduce_writes_every_file(tmp_path):
    out = tmp_path / "results"
    folder = find_official_folder()
    profiles = ["--profiles", str(folder)] if folder else []
    result = run("reproduce", *profiles, "--minutes", "560-575", "--out", str(out), "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    expected = {"base_day.csv", "congestion.csv", "extinction.csv", "summary.json", "report.md"}
    expected |= {f"figures/{f}.{ext}" for f in FIGURES for ext in ("png", "pdf")}
    if importlib.util.find_spec("power_grid_model") is not None:  # the voltage scenario
        expected |= {"voltage.csv"} | {f"figures/fig7_voltage_profile.{e}" for e in ("png", "pdf")}
    written = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()}
    assert written == expected
    assert all((out / name).stat().st_size > 0 for name in expected)
    assert json.loads((out / "summary.json").read_text()) == summary
    assert {"minute_566", "congestion", "extinction", "base_day"} <= summary.keys()
    assert summary["base_day"]["minutes"] == 16
    extinct = gens(summary["extinction"]["replicator"])["G114"]["setpoint_kw"]
    assert extinct == 0.0
    report = (out / "report.md").read_text()
    assert "iteration 53" in report and "iteration 201" in report  # the paper's figures
    first = summary["congestion"]["first_congestion_iteration"]
    assert f"detected at iteration {first}," in report  # ours
    assert list(tmp_path.iterdir()) == [out]  # no staging folder left behind


def test_reproduce_in_exact_mode_lands_on_the_dc_opf(tmp_path):
    out = tmp_path / "results"
    result = run(
        "reproduce", "--mode", "exact", "--minutes", "565-567", "--out", str(out), "--json"
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["mode"] == "exact"
    assert summary["congestion"]["max_abs_error_kw"] < 1e-3
    assert summary["congestion"]["max_overflow_kw"] < 1e-3
    assert summary["base_day"]["max_abs_error_kw"] < 0.01
    # the extinction row still shows the paper's replicator keeping G114 at zero
    assert gens(summary["extinction"]["replicator"])["G114"]["setpoint_kw"] == 0.0
    assert gens(summary["extinction"]["smith"])["G114"]["setpoint_kw"] > 9.999


def test_ctrl_c_leaves_no_partial_output(tmp_path):
    out = tmp_path / "results"
    # Without the feeder cache, loading the feeder imports pandapower (seconds), so its step
    # is logged (steps over a second are) and tells us the experiments are next.
    process = subprocess.Popen(
        command("reproduce", "--out", str(out)),
        env={**clean_env(), "POPDISPATCH_CACHE_DIR": "off"},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # a process group of its own, as a terminal's job
    )
    seen = []
    for line in process.stderr:  # steps are logged as they finish (stderr is not a terminal)
        seen.append(line)
        if line.startswith("loading the ieee-elv feeder"):
            break  # the experiments (about 25 s, most of it the online day) are next
    time.sleep(3)
    # Ctrl-C in a terminal interrupts every process of the job: the command and the worker
    # process that runs the voltage scenario beside it
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, "".join(seen) + stderr
    for stray in ("Traceback", "KeyboardInterrupt", "Process "):
        assert stray not in stderr, stderr
    assert stderr.strip().splitlines()[-1] == "popdispatch: error: interrupted; no output written"
    assert list(tmp_path.iterdir()) == []


def test_day_warm_start_choice_is_reported_and_each_reaches_the_dc_opf():
    runs = {}
    for choice in (None, "shares", "setpoints"):
        extra = ["--warm-start", choice] if choice else []
        result = run("day", "--mode", "exact", "--minutes", "600-610", "--json", *extra)
        assert result.returncode == 0, result.stderr
        runs[choice] = json.loads(result.stdout)
    assert runs[None]["warm_start"] == "merit"  # exact mode's default
    assert runs["shares"]["warm_start"] == "shares"
    assert runs["setpoints"]["warm_start"] == "setpoints"
    for summary in runs.values():
        assert summary["status"] == "converged"
        assert summary["max_abs_error_kw"] < 1e-3
    bad = run("day", "--warm-start", "sideways", "--minutes", "600-601")
    assert bad.returncode == 2
    assert "sideways" in bad.stderr
