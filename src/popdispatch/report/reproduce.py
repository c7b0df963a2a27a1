"""``popdispatch reproduce``: the paper's three experiments end to end, as figures and a table.

1. minute 566 without limits and the whole base day (Smith, no line limits) against the DC-OPF,
2. the congestion scenario (minute 566, the 505-666 path limited to 28 kW),
3. the extinction comparison (replicator and Smith, generator G114 starting at zero share).

Minute 566 always uses the official loads (pandapower's snapshot); the day uses the profiles it
is given. Outputs: ``figures/*.png|pdf``, ``base_day.csv``, ``congestion.csv``,
``extinction.csv``, ``summary.json`` and ``report.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.online import RunSettings
from popdispatch.report.output import StagedFolder
from popdispatch.report.progress import Progress
from popdispatch.report.summaries import (
    day_summary,
    day_table,
    generator_buses,
    snapshot_summary,
    trajectory_table,
)
from popdispatch.scenarios import (
    CONGESTION_PATH,
    PEAK_MINUTE,
    DayComparison,
    ExtinctionResult,
    SnapshotComparison,
    congestion,
    day_vs_opf,
    elv_problem,
    extinction,
    peak_profiles,
    snapshot_vs_opf,
)

FITNESS_GENERATOR = "G739"  # the generator the paper's congestion scenario penalises


@dataclass(frozen=True)
class Reproduction:
    """Everything the figures and the report need (powers in kW)."""

    settings: RunSettings
    peak_problem: DispatchProblem
    peak: SnapshotComparison
    congestion_problem: DispatchProblem
    congestion: SnapshotComparison
    extinction: ExtinctionResult
    day_problem: DispatchProblem
    day: DayComparison


def run_reproduction(
    profiles: LoadProfiles, settings: RunSettings, minutes, progress: Progress
) -> Reproduction:
    """Run the three experiments (``minutes``: the base day's minutes, None = whole day)."""
    with progress.step("loading the ieee-elv feeder"):
        peak_problem = elv_problem(peak_profiles())
        congestion_problem = elv_problem(peak_profiles(), [CONGESTION_PATH])
        day_problem = elv_problem(profiles)
    with progress.step("minute 566, congestion and extinction"):
        peak = snapshot_vs_opf(peak_problem, PEAK_MINUTE, settings)
        congested = congestion(settings=settings)
        extinct = extinction(settings=settings)  # sets its own x0
    day = day_vs_opf(day_problem, settings, minutes, progress)
    return Reproduction(
        settings, peak_problem, peak, congestion_problem, congested, extinct, day_problem, day
    )


def peak_load_kw(problem: DispatchProblem) -> np.ndarray:
    """Per-load demand (kW) of minute 566 in the order of the feeder's loads."""
    loads = peak_profiles().for_loads(problem.feeder.original.loads.index)
    return loads.at(PEAK_MINUTE).to_numpy(float)


def congestion_shift(rep: Reproduction) -> float:
    """Signal magnitude (EUR/MW) of the overflow the unconstrained DC-OPF would cause.

    That is the overflow the paper's congestion scenario starts from ("4 kW to 6 kW").
    """
    free = rep.congestion.opf_unconstrained
    if free is None or free.status != "optimal":
        return 0.0
    problem = rep.congestion_problem
    flows = problem.flows(free.p_kw / KW_PER_MW, PEAK_MINUTE)
    overflow = np.max(np.abs(flows) - problem.limit)
    return float(max(overflow, 0.0) * rep.settings.fitness.C)


def make_figures(rep: Reproduction, folder: StagedFolder, progress: Progress) -> list[str]:
    """Draw and save every figure; returns the file stems written (under ``figures/``)."""
    from popdispatch.report import figures  # matplotlib: only imported when drawing

    loads = peak_load_kw(rep.peak_problem)
    free = rep.congestion.opf_unconstrained
    drawings = {
        "fig1_fitness": lambda: figures.fitness_figure(
            rep.peak_problem, FITNESS_GENERATOR, congestion_shift(rep), rep.settings.fitness
        ),
        "fig2_congestion_detection": lambda: figures.congestion_detection_figure(
            rep.congestion_problem,
            free.p_kw,
            PEAK_MINUTE,
            loads,
            rep.settings.fitness.C,
            "the unconstrained DC-OPF at minute 566",
        ),
        "fig3_feeder_flows_566": lambda: figures.feeder_flow_figure(
            rep.peak_problem, rep.peak.run.setpoints_kw, PEAK_MINUTE, loads
        ),
        "fig4_base_day": lambda: figures.base_day_figure(rep.day, generator_buses(rep.day_problem)),
        "fig5_congestion_iterations": lambda: figures.congestion_figure(
            rep.congestion,
            "Congestion scenario: 505-666 limited to 28 kW\nset points (solid), DC-OPF (dashed)",
        ),
        "fig6_extinction": lambda: figures.extinction_figure(rep.extinction),
    }
    for stem, draw in progress.iterate(drawings.items(), "figures", len(drawings)):
        figures.save_figure(draw(), folder.file(f"figures/{stem}"))
    return list(drawings)


def extinction_summary(rep: Reproduction) -> dict:
    """Both runs of the extinction comparison, summarised against the DC-OPF."""
    problem, result = rep.peak_problem, rep.extinction
    return {
        "generator": result.generator,
        "replicator": snapshot_summary(problem, SnapshotComparison(result.replicator, result.opf)),
        "smith": snapshot_summary(problem, SnapshotComparison(result.smith, result.opf)),
    }


def reproduction_summary(rep: Reproduction) -> dict:
    """The ``summary.json`` object of a reproduction."""
    limits = [CONGESTION_PATH]
    return {
        "mode": rep.settings.mode,
        "dynamics": rep.settings.dynamics,
        "profile_source": rep.day.run.profile_source,
        "minute_566": snapshot_summary(rep.peak_problem, rep.peak),
        "congestion": snapshot_summary(rep.congestion_problem, rep.congestion, limits),
        "extinction": extinction_summary(rep),
        "base_day": day_summary(rep.day_problem, rep.day),
    }


def extinction_table(rep: Reproduction) -> pd.DataFrame:
    """Set points per iteration (kW) of both extinction runs, side by side."""
    result = rep.extinction
    length = max(result.replicator.iterations, result.smith.iterations) + 1
    table = pd.DataFrame({"iteration": np.arange(length)})
    for label, run in (("replicator", result.replicator), ("smith", result.smith)):
        padded = np.full((length, len(run.generators)), np.nan)
        padded[: run.iterations + 1] = run.trajectory_kw
        for k, name in enumerate(run.generators):
            table[f"{label}_{name}_setpoint_kw"] = padded[:, k]
    return table


def write_reproduction(
    rep: Reproduction, folder: StagedFolder, progress: Progress,
    html_profiles: LoadProfiles | None = None,
) -> dict:  # fmt: skip
    """Write figures, time series, ``summary.json`` and ``report.md``; returns the summary.
    With ``html_profiles`` (the base day's profiles) also the interactive reports."""
    from popdispatch.report.markdown import reproduction_report

    stems = make_figures(rep, folder, progress)
    summary = reproduction_summary(rep)
    folder.write_csv("base_day.csv", day_table(rep.day, rep.day_problem))
    folder.write_csv("congestion.csv", trajectory_table(rep.congestion))
    folder.write_csv("extinction.csv", extinction_table(rep))
    folder.write_json("summary.json", summary)
    folder.write_text("report.md", reproduction_report(summary, stems, rep))
    if html_profiles is not None:
        write_reproduction_html(rep, folder, html_profiles, summary, progress)
    return summary


def write_reproduction_html(
    rep: Reproduction, folder: StagedFolder, profiles: LoadProfiles, summary: dict,
    progress: Progress,
) -> list[str]:  # fmt: skip
    """The interactive reports of the base day and the congestion minute (``--html``):
    ``base_day.html`` and ``congestion.html``; returns their names."""
    from popdispatch.report.interactive import day_report_html, snapshot_report_html
    from popdispatch.scenarios import peak_profiles

    with progress.step("writing the interactive reports"):
        day = day_report_html(rep.day, rep.day_problem, profiles, run_info=summary["base_day"])
        folder.write_text("base_day.html", day)
        congestion = snapshot_report_html(
            rep.congestion, rep.congestion_problem, peak_profiles(), run_info=summary["congestion"]
        )
        folder.write_text("congestion.html", congestion)  # fmt: skip
    return ["base_day.html", "congestion.html"]
