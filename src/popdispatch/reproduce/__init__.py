"""``popdispatch reproduce``: the paper's three experiments end to end, as figures and a table.

1. minute 566 without limits and the whole base day (Smith, no line limits) against the DC-OPF,
2. the congestion scenario (minute 566, the 505-666 path limited to 28 kW),
3. the extinction comparison (replicator and Smith, generator G114 starting at zero share),
4. beyond the paper, the ``voltage`` scenario on case33bw (with power-grid-model installed):
   the DC exact dispatch, the voltage-aware dispatch and pandapower's AC OPF, checked in AC.

Minute 566 always uses the official loads (pandapower's snapshot); the day uses the profiles it
is given. On a machine with more than one core the voltage scenario runs in a second process
while the others run (on the first run after installing, both processes compile their own
kernels at once; ``benchmarks/bench_first_run.py --commands reproduce``).
Outputs: ``figures/*.png|pdf``, ``base_day.csv``, ``congestion.csv``, ``extinction.csv``,
``voltage.csv`` (bus voltages of the voltage scenario), ``summary.json`` and ``report.md``.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from importlib.util import find_spec
from multiprocessing.pool import AsyncResult

import numpy as np
import pandas as pd

from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.online import RunSettings
from popdispatch.progress import Progress
from popdispatch.report.output import StagedFolder
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
    VoltageResult,
    congestion,
    day_vs_opf,
    elv_problem,
    extinction,
    peak_profiles,
    snapshot_vs_opf,
    voltage,
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
    voltage: VoltageResult | None = None  # None without power-grid-model


@contextmanager
def voltage_in_background(settings: RunSettings, parallel: bool) -> Iterator[AsyncResult | None]:
    """The voltage scenario started in a second process (spawned: a fresh interpreter, no
    inherited threads or compiler state) when ``parallel``, as a pending result; else None
    (run it in this process). The process ignores Ctrl-C (a terminal sends it to every
    process of the command; this one's would print its own traceback) and is terminated when
    the block ends, so an error or Ctrl-C here does not wait for it."""
    pool = None
    if parallel:
        try:
            pool = multiprocessing.get_context("spawn").Pool(1, initializer=_ignore_interrupts)
        except (OSError, ImportError):  # no process pool here (e.g. no POSIX semaphores)
            pool = None
    if pool is None:
        yield None
        return
    with pool:
        yield pool.apply_async(voltage, (settings,))


def _ignore_interrupts() -> None:
    """A worker's initializer: SIGINT ignored (the command's own process reports it)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_reproduction(
    profiles: LoadProfiles, settings: RunSettings, minutes, progress: Progress,
    parallel: bool | None = None,
) -> Reproduction:  # fmt: skip
    """Run the three experiments (``minutes``: the base day's minutes, None = whole day) and
    the voltage scenario (with power-grid-model installed), the latter in a second process
    when ``parallel`` (default: when the machine has more than one core)."""
    with_voltage = find_spec("power_grid_model") is not None
    if not with_voltage:
        progress.note('voltage scenario skipped: it needs pip install "popdispatch[ac]"')
    if parallel is None:
        parallel = (os.cpu_count() or 1) > 1
    voltage_settings = replace(settings, dynamics="smith", graph="complete")
    with voltage_in_background(voltage_settings, parallel and with_voltage) as pending:
        with progress.step("loading the ieee-elv feeder"):
            peak_problem = elv_problem(peak_profiles())
            congestion_problem = elv_problem(peak_profiles(), [CONGESTION_PATH])
            day_problem = elv_problem(profiles)
        with progress.step("minute 566, congestion and extinction"):
            peak = snapshot_vs_opf(peak_problem, PEAK_MINUTE, settings)
            congested = congestion(settings=settings)
            extinct = extinction(settings=settings)  # sets its own x0
        day = day_vs_opf(day_problem, settings, minutes, progress)
        limited = None
        if with_voltage:
            with progress.step("voltage scenario (case33bw, AC checks and pandapower's AC OPF)"):
                limited = voltage(voltage_settings) if pending is None else pending.get()
    return Reproduction(
        settings, peak_problem, peak, congestion_problem, congested, extinct, day_problem, day,
        limited,
    )  # fmt: skip


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
        "voltage": None if rep.voltage is None else voltage_summary(rep.voltage),
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
    from popdispatch.reproduce.markdown import reproduction_report

    stems = make_figures(rep, folder, progress)
    if rep.voltage is not None:
        from popdispatch.report import figures

        figures.save_figure(voltage_figure(rep.voltage), folder.file(f"figures/{VOLTAGE_FIGURE}"))
        stems.append(VOLTAGE_FIGURE)
    summary = reproduction_summary(rep)
    folder.write_csv("base_day.csv", day_table(rep.day, rep.day_problem))
    folder.write_csv("congestion.csv", trajectory_table(rep.congestion))
    folder.write_csv("extinction.csv", extinction_table(rep))
    if rep.voltage is not None:
        folder.write_csv("voltage.csv", voltage_tables(rep.voltage)[0].reset_index())
    folder.write_json("summary.json", summary)
    report = reproduction_report(summary, stems, rep)
    if summary.get("voltage") is not None:
        report = report.rstrip("\n") + "\n\n" + voltage_markdown(summary["voltage"])
    folder.write_text("report.md", report)
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


# -- the voltage scenario -------------------------------------------------------------------

DISPATCHES = ("DC exact", "voltage-aware", "AC OPF", "AC-corrected")
VOLTAGE_FIGURE = "fig7_voltage_profile"


def _ac_costs(result: VoltageResult) -> dict[str, float]:
    """Each dispatch's cost, EUR/h, with the losses the AC check finds bought at the source
    (the AC OPF's source already includes them)."""
    from popdispatch.opf import generation_cost

    costs = {}
    for name, run, ac in _checked(result):
        p_kw = np.array(run.run.setpoints_kw, dtype=float)
        p_kw[_source_row(result)] += float(ac.totals["source_extra_kw"])
        costs[name] = float(generation_cost(result.plain, p_kw / KW_PER_MW))
    if result.anchor is not None:
        costs[DISPATCHES[2]] = result.anchor.cost
    if result.corrected is not None:
        costs[DISPATCHES[3]] = result.corrected.cost_eur_per_h
    return costs


def _checked(result: VoltageResult):
    pairs = ((DISPATCHES[0], result.dc, result.ac_dc), (DISPATCHES[1], result.voltage,
             result.ac_voltage))  # fmt: skip
    return [(name, run, ac) for name, run, ac in pairs if ac is not None]


def _source_row(result: VoltageResult) -> int:
    buses = result.plain.feeder.original.generators.loc[result.plain.generators, "bus"]
    return int(np.flatnonzero(buses.to_numpy() == result.plain.feeder.original.source_bus)[0])


def voltage_tables(result: VoltageResult) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``(profile, setpoints)``: AC voltage per bus (index ``bus``, MATPOWER numbering) and
    set points per generator (kW; the AC OPF's source with the losses), one column per
    dispatch that ran."""
    feeder = result.plain.feeder.original
    profile = pd.DataFrame(index=pd.Index(feeder.buses.index + 1, name="bus"))
    points = pd.DataFrame(index=result.plain.generators)
    for name, run, ac in _checked(result):
        profile[name] = ac.buses["v_pu"].to_numpy()
        points[name] = run.run.setpoints_kw
    if result.anchor is not None:
        profile[DISPATCHES[2]] = result.anchor.v_pu.to_numpy()
        points[DISPATCHES[2]] = result.anchor.p_kw.loc[result.plain.generators].to_numpy()
    if result.corrected is not None:  # its source with what it supplied beyond its set point
        profile[DISPATCHES[3]] = result.corrected.ac.buses["v_pu"].to_numpy()
        summary = result.corrected.summary()
        p_kw = np.array(result.corrected.result.run.setpoints_kw, dtype=float)
        p_kw[_source_row(result)] += summary["source_extra_kw"]
        points[DISPATCHES[3]] = p_kw
    return profile, points


def voltage_figure(result: VoltageResult):
    """``fig7_voltage_profile``: :func:`popdispatch.report.figures.voltage_profile_figure`."""
    from popdispatch.report import figures

    profile, points = voltage_tables(result)
    tree = result.plain.feeder.original.bus_tree()
    buses = result.plain.feeder.original.buses.index.to_numpy()
    parent = {int(buses[c]) + 1: int(buses[p]) + 1 for c, p in enumerate(tree.parent) if p >= 0}
    starts = [b for b in profile.index if b in parent and parent[b] != b - 1]
    gaps = pd.DataFrame(np.nan, index=[b - 0.5 for b in starts], columns=profile.columns)
    label = branch_label(list(profile.index), starts, parent)
    title = "case33bw: AC voltage profile of each dispatch"
    return figures.voltage_profile_figure(pd.concat([profile, gaps]).sort_index(), points,
                                          _ac_costs(result), result.problem.vmin_pu, title,
                                          label)  # fmt: skip


def branch_label(buses: list[int], starts: list[int], parent: dict[int, int]) -> str:
    """The profile's x label: which bus numbers are the main feeder and which each lateral,
    e.g. ``bus (MATPOWER number): main feeder 1-18;`` over ``laterals 19-22 (from bus 2),
    ...``."""
    ends = [*(b - 1 for b in starts[1:]), max(buses)]
    main = f"main feeder {min(buses)}-{starts[0] - 1}" if starts else "the feeder"
    spans = zip(starts, ends, strict=True)
    laterals = ", ".join(f"{a}-{b} (from bus {parent[a]})" for a, b in spans)
    return f"bus (MATPOWER number): {main}" + (f";\nlaterals {laterals}" if starts else "")


def voltage_summary(result: VoltageResult) -> dict:
    """The ``voltage`` object of ``summary.json``: per dispatch its set points (kW), cost
    (EUR/h, with the AC losses), lowest AC voltage (p.u., bus in MATPOWER numbering); the
    voltage-aware dispatch against the LinDistFlow OPF; the linearization error."""
    profile, points = voltage_tables(result)
    costs = _ac_costs(result)
    run, opf = result.voltage.run, result.voltage.opf
    error_kw = float(np.max(np.abs(run.setpoints_kw - opf.p_kw)))
    dispatches = {
        name: {
            "setpoints_kw": {str(g): float(v) for g, v in points[name].items()},
            "cost_eur_per_h": costs[name],
            "ac_v_min_pu": float(profile[name].min()),
            "ac_v_min_bus": int(profile[name].idxmin()),
        }
        for name in profile.columns
    }
    lindist = float(np.min(opf.v_pu))
    out = {
        "case": "case33bw", "vmin_pu": result.problem.vmin_pu, "vmax_pu": result.problem.vmax_pu,
        "dispatches": dispatches,
        "voltage_aware_status": run.status,
        "voltage_aware_vs_lindistflow_opf_kw": error_kw,
        "voltage_aware_vs_lindistflow_opf_rel": error_kw / float(opf.p_kw.sum()),
        "lindistflow_v_min_pu": lindist,
        "anchor_error": result.anchor_error,
    }  # fmt: skip
    if DISPATCHES[1] in dispatches:
        out["linearization_error_pu"] = lindist - dispatches[DISPATCHES[1]]["ac_v_min_pu"]
    if result.corrected is not None:
        out["ac_correct"] = result.corrected.summary()
        if result.anchor is not None:
            anchor = result.anchor.cost
            out["ac_correct_cost_vs_ac_opf_rel"] = (
                result.corrected.cost_eur_per_h - anchor
            ) / anchor
    return out


def voltage_markdown(v: dict) -> str:
    """The voltage scenario's section of ``report.md`` (from its summary object)."""
    rows = [
        f"| {name} | {', '.join(f'{g} {_kw(kw)}' for g, kw in d['setpoints_kw'].items())} | "
        f"{d['ac_v_min_pu']:.5f} (bus {d['ac_v_min_bus']}) | {d['cost_eur_per_h']:.3f} |"
        for name, d in v["dispatches"].items()
    ]
    lines = [
        "## Voltage limits: case33bw (beyond the paper; docs/voltage.md)",
        "",
        f"Source and four DGs, limits {v['vmin_pu']:g}-{v['vmax_pu']:g} p.u.; buses in MATPOWER "
        "numbering; cost with the AC losses bought at the source.",
        "",
        "| dispatch | set points, kW | AC minimum, p.u. | cost, EUR/h |",
        "| --- | --- | --- | --- |",
        *rows,
        "",
        f"Voltage-aware dispatch ({v['voltage_aware_status']}) vs the LinDistFlow OPF: "
        f"{v['voltage_aware_vs_lindistflow_opf_kw']:.2e} kW; linearization error "
        f"{v.get('linearization_error_pu', float('nan')):.5f} p.u.",
        "",
        f"![voltage profile](figures/{VOLTAGE_FIGURE}.png)",
        "",
    ]
    if v.get("anchor_error"):
        lines.insert(-2, f"pandapower's AC OPF: {v['anchor_error']}")
    return "\n".join(lines)


def _kw(value: float) -> str:
    """A set point to 0.1 kW, without the sign of a rounding residue ("-0.0")."""
    return f"{value if abs(value) >= 0.05 else 0.0:.1f}"
