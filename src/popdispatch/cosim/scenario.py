"""The co-simulation scenario: load profiles, the pandapower plant (AC power flow) and the
dispatcher in one mosaik world, one step per minute (:func:`run_cosim`).

Data flow (mosaik connections; ``[weak]`` closes the same-time loop)::

    Profiles.Load p_kw ──► Grid.Load p_kw
    Profiles.Load p_kw ──► Dispatcher.Dispatcher load_kw
    Dispatcher.DG p_kw ──► Grid.DG p_kw
    Grid.Branch p_kw ──[weak]──► Dispatcher.Controller flow_kw

The dispatcher and the grid form a mosaik group: at each minute the dispatcher runs on the
new demand, the grid solves the AC power flow at its set points, the measured flows of the
limited lines return at the same time and the dispatcher reruns until they no longer move
(:mod:`popdispatch.cosim.dispatcher`). Every simulator's outputs go to ``cosim.csv`` (one
row per minute, the values the loop settled on) through
:class:`~popdispatch.cosim.recorder.RecorderSim`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.constants import KW_PER_MW
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import DispatchProblem
from popdispatch.online import RunSettings

SIM_CONFIG = {
    "Profiles": {"python": "popdispatch.cosim.profiles:ProfileSim"},
    "Grid": {"python": "popdispatch.cosim.grid:GridSim"},
    "Dispatcher": {"python": "popdispatch.cosim.dispatcher_sim:DispatcherSim"},
    "Recorder": {"python": "popdispatch.cosim.recorder:RecorderSim"},
}
STEP_SECONDS = 60
#: mosaik's bound on same-time rounds of one time (the dispatcher stops far earlier).
MAX_LOOP_ITERATIONS = 100
CSV_NAME = "cosim.csv"


@dataclass(frozen=True)
class CosimResult:
    """A co-simulation's outcome.

    Attributes
    ----------
    minutes : the 1-based minutes run.
    generators : names, the order of ``setpoints_kw``'s columns.
    setpoints_kw : (minutes, generators) each minute's final set points, kW.
    steps : index ``minute``: ``status``, ``rounds`` (runs of the dynamics), ``iterations``
        (over the rounds), per limited line ``<from>-<to>_ac_flow_kw`` (measured at the final
        set points), ``<from>-<to>_offset_kw`` (in force at the final run), ``losses_kw``,
        ``source_kw`` (what the slack at the source supplied), ``v_min_pu``, ``v_max_pu``.
    limits_kw : per limited line ``<from>-<to>``, its limit, kW.
    csv : the recorder's file.
    """

    minutes: np.ndarray
    generators: list[str]
    setpoints_kw: np.ndarray
    steps: pd.DataFrame
    limits_kw: dict[str, float]
    csv: Path


def run_cosim(
    problem: DispatchProblem,
    profiles: LoadProfiles,
    minutes: np.ndarray,
    settings: RunSettings,
    out: Path,
) -> CosimResult:
    """Run ``minutes`` (consecutive, 1-based steps of ``profiles``) of the feeder of
    ``problem`` (its full network the plant, its fleet and limits the dispatcher's) in mosaik;
    the recorder's CSV goes to ``out``."""
    import mosaik

    minutes = np.asarray(minutes, dtype=np.int64)
    out.mkdir(parents=True, exist_ok=True)
    feeder = problem.feeder.original
    kw = profiles.for_loads(feeder.loads.index).kw
    log: list[dict] = []
    world = mosaik.World(SIM_CONFIG, skip_greetings=True, configure_logging=False,
                         max_loop_iterations=MAX_LOOP_ITERATIONS)  # fmt: skip
    loads = world.start("Profiles", kw=kw, first=int(minutes[0]), step_seconds=STEP_SECONDS)
    with world.group():
        dispatcher_sim = world.start("Dispatcher", problem=problem, settings=settings, log=log)
        grid_sim = world.start("Grid", feeder=feeder)
    recorder = world.start("Recorder", path=out / CSV_NAME).Recorder()
    network = grid_sim.Network()
    dispatcher = dispatcher_sim.Dispatcher()
    for name in feeder.loads.index:
        source, sink = loads.Load(name=name), grid_sim.Load(name=name)
        world.connect(source, sink, "p_kw")
        world.connect(source, dispatcher, ("p_kw", "load_kw"))
        world.connect(sink, recorder, "p_kw")
    for name in problem.generators:
        dg, plant = dispatcher_sim.DG(name=name), grid_sim.DG(name=name)
        world.connect(dg, plant, "p_kw")
        world.connect(plant, recorder, "p_kw", "setpoint_kw")
    names = []
    for a, b in problem.feeder.lines.loc[problem.lines, ["from_bus", "to_bus"]].itertuples(
        index=False
    ):
        controller = dispatcher_sim.Controller(from_bus=int(a), to_bus=int(b))
        branch = grid_sim.Branch(top_bus=int(a), bottom_bus=int(b))
        world.connect(branch, controller, ("p_kw", "flow_kw"), weak=True)
        world.connect(branch, recorder, "p_kw", "p_top_kw", "p_bottom_kw", "loss_kw")
        world.connect(controller, recorder, "offset_kw", "limit_kw")
        names.append(f"{a}-{b}")
    world.connect(dispatcher, recorder, "status", "iterations", "rounds")
    world.connect(network, recorder, "losses_kw", "v_min_pu", "v_max_pu", "source_kw")
    world.run(until=len(minutes) * STEP_SECONDS, print_progress=False)
    return _result(problem, minutes, log, names, out / CSV_NAME)


def _result(problem, minutes, log, names, csv: Path) -> CosimResult:
    """The final run of every minute (from the dispatcher's log) and the plant's measurements
    at its set points (from the recorder's file)."""
    runs = pd.DataFrame(log)
    runs["minute"] = minutes[0] + runs.time_s // STEP_SECONDS
    final = runs.groupby("minute").last()
    iterations = runs.groupby("minute").iterations.sum()
    recorded = pd.read_csv(csv).groupby("time_s").last()
    recorded.index = minutes[0] + recorded.index // STEP_SECONDS
    steps = pd.DataFrame({"status": final.status, "rounds": final.rounds,
                          "iterations": iterations})  # fmt: skip
    for k, name in enumerate(names):
        steps[f"{name}_ac_flow_kw"] = recorded[f"Grid-0.Branch-{name}.p_kw"]
        steps[f"{name}_offset_kw"] = [o[k] for o in final.offset_kw]
    for column in ("losses_kw", "source_kw", "v_min_pu", "v_max_pu"):
        steps[column] = recorded[f"Grid-0.Network.{column}"]
    steps.index.name = "minute"
    limits = dict(zip(names, (problem.limit * KW_PER_MW).tolist(), strict=True))
    return CosimResult(minutes, [str(g) for g in problem.generators],
                       np.array(final.setpoints_kw.tolist()), steps, limits, csv)  # fmt: skip
