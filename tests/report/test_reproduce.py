"""Summaries, figures, the reproduction report and atomic output (issue 4)."""

from __future__ import annotations

import json
import stat

import numpy as np
import pytest

from popdispatch import reproduce as rp
from popdispatch.online import RunSettings
from popdispatch.progress import Progress
from popdispatch.readers import default_profiles
from popdispatch.report.output import atomic_write_text, json_text, staged_folder
from popdispatch.reproduce.markdown import reproduction_report


@pytest.fixture(scope="module")
def reproduction():
    """The three experiments with a short base day (minutes 560-565 of the default profiles)."""
    return rp.run_reproduction(
        default_profiles(), RunSettings(), np.arange(560, 566), Progress(quiet=True)
    )


# -- atomic output ------------------------------------------------------------------------------


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_staged_folder_leaves_nothing_on_error(tmp_path, error):
    with pytest.raises(error), staged_folder(tmp_path / "out") as folder:
        folder.write_text("a.txt", "complete")
        folder.write_text("b/c.txt", "complete")
        raise error
    assert list(tmp_path.iterdir()) == []


def test_staged_folder_merges_into_an_existing_folder(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("old")
    (out / "a.txt").write_text("old")
    with staged_folder(out) as folder:
        folder.write_text("a.txt", "new")
        folder.write_json("s/summary.json", {"x": np.float64(1.5), "nan": float("nan")})
    assert (out / "keep.txt").read_text() == "old"
    assert (out / "a.txt").read_text() == "new"
    assert json.loads((out / "s/summary.json").read_text()) == {"x": 1.5, "nan": None}
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_new_output_folder_and_files_get_ordinary_permissions(tmp_path):
    with staged_folder(tmp_path / "out") as folder:
        folder.write_text("a.txt", "x")
    assert stat.S_IMODE((tmp_path / "out").stat().st_mode) & 0o055 == 0o055 & ~_umask()
    path = atomic_write_text(tmp_path / "f.txt", "hello")
    assert path.read_text() == "hello"
    assert stat.S_IMODE(path.stat().st_mode) & 0o044 == 0o044 & ~_umask()


def _umask() -> int:
    import os

    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_atomic_write_keeps_the_old_file_on_error(tmp_path):
    from popdispatch.report.output import atomic_write

    target = tmp_path / "f.txt"
    target.write_text("old")

    def fail(tmp):
        tmp.write_text("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(target, fail)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.txt"]


def test_json_text_is_strict_json():
    text = json_text({"a": np.array([1.0, np.inf]), "b": np.int64(3), "c": np.bool_(True)})
    assert json.loads(text) == {"a": [1.0, None], "b": 3, "c": True}


# -- reproduction ---------------------------------------------------------------------------------


def test_reproduction_summary_numbers(reproduction):
    summary = rp.reproduction_summary(reproduction)
    peak = summary["minute_566"]
    assert peak["status"] == "converged"
    assert peak["max_abs_error_kw"] < 0.1
    opf = {g["name"]: g["opf_kw"] for g in peak["generators"]}
    assert opf["G1"] == pytest.approx(2.358, abs=1e-3)
    cong = summary["congestion"]
    assert {g["name"]: g["opf_kw"] for g in cong["generators"]}["G739"] == pytest.approx(
        3.138, abs=1e-3
    )
    day = summary["base_day"]
    assert (day["first_minute"], day["last_minute"], day["minutes"]) == (560, 565, 6)
    table = rp.day_table(reproduction.day)
    assert day["cost"] == pytest.approx(table.cost_eur_per_h.sum() / 60)
    assert day["max_abs_error_kw"] == pytest.approx(table.max_abs_error_kw.max())
    assert sum(day["energy_kwh"].values()) == pytest.approx(table.demand_kw.sum() / 60)
    json.loads(json_text(summary))  # serialisable, no NaN


def test_congestion_shift_is_the_unconstrained_overflow(reproduction):
    # The unconstrained DC-OPF overloads the 505-666 path by several kW (paper: "4 to 6 kW").
    shift = rp.congestion_shift(reproduction)
    assert 4.0 < shift < 10.0  # EUR/MW = overflow (MW) x C (1000)


def test_report_table_carries_paper_ours_and_dc_opf(reproduction):
    summary = rp.reproduction_summary(reproduction)
    report = reproduction_report(summary, ["fig1_fitness"])
    rows = [line for line in report.splitlines() if line.startswith("| ")]
    assert len(rows) == 6  # header, separator and four experiments
    cong = summary["congestion"]
    congestion_row = next(r for r in rows if r.startswith("| congestion"))
    assert "iteration 53" in congestion_row and "iteration 201" in congestion_row
    assert f"detected at iteration {cong['first_congestion_iteration']}," in congestion_row
    assert "G739 3.138" in congestion_row  # the DC-OPF column
    day_row = next(r for r in rows if r.startswith("| base day"))
    assert f"{summary['base_day']['minutes_within_0_1_kw']} of 6 minutes" in day_row
    assert "docs/paper-mode.md" in report  # paper mode: say why it misses the DC-OPF
    assert all(r.count(" | ") == 3 for r in rows)  # no stray column separators


def test_every_figure_entry_of_the_report_has_a_title_and_no_issue_number(reproduction):
    from popdispatch.reproduce.markdown import FIGURES

    summary = rp.reproduction_summary(reproduction)
    assert rp.VOLTAGE_FIGURE in FIGURES
    report = reproduction_report(summary, list(FIGURES))
    entries = [line for line in report.splitlines() if "`figures/" in line]
    assert len(entries) == 7
    for line in entries:
        assert not line.startswith("- fig"), line  # a title, not the file's stem
    if summary["voltage"] is not None:
        report += rp.voltage_markdown(summary["voltage"])
    assert "issue" not in report.lower()


def test_every_figure_is_written_as_png_and_pdf(reproduction, tmp_path):
    with staged_folder(tmp_path / "out") as folder:
        stems = rp.make_figures(reproduction, folder, Progress(quiet=True))
    assert len(stems) == 6
    for stem in stems:
        png = (tmp_path / "out" / "figures" / f"{stem}.png").read_bytes()
        pdf = (tmp_path / "out" / "figures" / f"{stem}.pdf").read_bytes()
        assert png.startswith(b"\x89PNG") and pdf.startswith(b"%PDF")


# -- differences from the paper (issue 10) ------------------------------------------------------


def test_report_explains_every_difference_with_this_runs_numbers(reproduction):
    from popdispatch.game.problem import KW_PER_MW
    from popdispatch.scenarios import PEAK_MINUTE

    summary = rp.reproduction_summary(reproduction)
    report = reproduction_report(summary, ["fig1_fitness"], reproduction)
    section = report.split("## Differences from the paper")[1].split("## Figures")[0]
    cong = summary["congestion"]
    run = reproduction.congestion.run
    first = run.trajectory_kw[0]
    problem = reproduction.congestion_problem
    start_overflow = (np.abs(problem.flows(first / KW_PER_MW, PEAK_MINUTE)) - problem.limit).max()
    g1 = next(g for g in cong["generators"] if g["name"] == "G1")
    # detection at iteration 1, not 53, because of the initial state
    assert f"Congestion detected at iteration {cong['first_congestion_iteration']}" in section
    assert "not at iteration 53" in section and "initial state" in section
    assert f"every generator at {first[0]:.2f} kW" in section
    assert f"overloads the 505-666 path by {start_overflow * KW_PER_MW:.2f} kW" in section
    # G1 ends below its DC-OPF where the paper's rises
    assert f"G1 ends at {g1['setpoint_kw']:.2f} kW** (DC-OPF {g1['opf_kw']:.2f} kW)" in section
    assert "G1 *rises*" in section
    assert f"G1 starts at {first[0]:.2f} kW" in section
    # the proportional signal's residual overflow
    overflow = cong["max_overflow_kw"]
    assert f"Residual overflow of {overflow:.2f} kW" in section
    assert f"gives {overflow * reproduction.settings.fitness.C / 1000:.2f} EUR/MW" in section
    day = summary["base_day"]
    if day["minutes_within_0_1_kw"] < day["minutes"]:
        assert f"{day['minutes_within_0_1_kw']} of {day['minutes']} minutes" in section


def test_differences_follow_the_numbers_not_the_paper_mode_story(reproduction):
    """A run that detects at 53, ends on the DC-OPF without overflow gets no such notes."""
    import copy

    from popdispatch.reproduce.markdown import differences

    summary = copy.deepcopy(rp.reproduction_summary(reproduction))
    cong = summary["congestion"]
    cong["first_congestion_iteration"], cong["converged_iteration"] = 53, 201
    cong["max_overflow_kw"] = 0.0
    for g in cong["generators"]:
        g["setpoint_kw"] = g["opf_kw"]
    day = summary["base_day"]
    day["minutes_within_0_1_kw"] = day["minutes"]
    text = differences(summary)
    assert "Congestion detected" not in text
    assert "Residual overflow" not in text and "stays" not in text
    assert "Base day" not in text
    assert "Agreeing with the paper" in text


def test_report_without_the_run_still_addresses_each_difference(reproduction):
    """``reproduction_report(summary, stems)`` (no run object): the same three points, with
    what the summary holds."""
    summary = rp.reproduction_summary(reproduction)
    section = reproduction_report(summary, []).split("## Differences from the paper")[1]
    cong = summary["congestion"]
    assert f"Congestion detected at iteration {cong['first_congestion_iteration']}" in section
    assert f"`{cong['x0']}` shares" in section and "initial state" in section
    assert "G1 *rises*" in section
    assert f"Residual overflow of {cong['max_overflow_kw']:.2f} kW" in section
