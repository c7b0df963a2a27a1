"""Your own mosaik scenario with popdispatch's dispatcher (docs/cosim.md).

Run from a checkout with the ELV data beside it (``pip install "popdispatch[cosim]"``)::

    python examples/cosim_scenario.py ../shared/ieee-elv /tmp/cosim-example [MINUTES]

(MINUTES: how many minutes from minute 560, default 10).

What it builds, simulator by simulator (swap any of them for your own):

- ``Profiles``: the ELV load profiles, one ``Load`` entity per load, ``p_kw`` each minute.
- ``Grid``: the plant, a pandapower net of the full feeder solved by AC power flow whenever
  a load or a set point changes. Its ``Branch`` entities measure the active flow of a chain
  of lines (``p_kw``, positive away from the source).
- ``Dispatcher``: popdispatch's DG agents and node controllers. Reads ``load_kw`` (every
  load's demand) and, per limited line, ``flow_kw`` (the measured flow); writes ``p_kw`` of
  each ``DG`` (its set point, kW).
- ``Recorder``: every output to ``cosim.csv``.

The dispatcher and the grid sit in one mosaik group and the measured flows come back over a
*weak* connection: mosaik runs the dispatcher and the grid again at the same time until the
dispatcher sends nothing new (the measured flows moved its offsets by less than 1e-3 kW).
"""

import sys
from pathlib import Path

import mosaik

from popdispatch.online import RunSettings
from popdispatch.runs import FeederSource, load_run

profiles_folder, out = Path(sys.argv[1]), Path(sys.argv[2])
out.mkdir(parents=True, exist_ok=True)
first_minute, minutes = 560, int(sys.argv[3]) if len(sys.argv) > 3 else 10

# the feeder, the paper's fleet and a 28 kW limit on the path 505-666 (the dispatcher's problem)
problem, profiles = load_run(FeederSource(), profiles_folder, limits=[(505, 666, 28.0)])
feeder = problem.feeder.original  # the full network: the plant's

world = mosaik.World(
    {
        "Profiles": {"python": "popdispatch.cosim.profiles:ProfileSim"},
        "Grid": {"python": "popdispatch.cosim.grid:GridSim"},
        "Dispatcher": {"python": "popdispatch.cosim.dispatcher_sim:DispatcherSim"},
        "Recorder": {"python": "popdispatch.cosim.recorder:RecorderSim"},
    },
    skip_greetings=True,
)
loads = world.start("Profiles", kw=profiles.for_loads(feeder.loads.index).kw,
                    first=first_minute, step_seconds=60)  # fmt: skip
with world.group():  # the same-time loop: dispatcher and grid
    dispatcher_sim = world.start("Dispatcher", problem=problem,
                                 settings=RunSettings(mode="exact"))  # fmt: skip
    grid = world.start("Grid", feeder=feeder)
recorder = world.start("Recorder", path=out / "cosim.csv").Recorder()

dispatcher = dispatcher_sim.Dispatcher()
for name in feeder.loads.index:
    profile = loads.Load(name=name)
    world.connect(profile, grid.Load(name=name), "p_kw")
    world.connect(profile, dispatcher, ("p_kw", "load_kw"))
for name in problem.generators:
    plant_dg = grid.DG(name=name)
    world.connect(dispatcher_sim.DG(name=name), plant_dg, "p_kw")
    world.connect(plant_dg, recorder, "p_kw", "setpoint_kw")
for a, b in problem.feeder.lines.loc[problem.lines, ["from_bus", "to_bus"]].to_numpy():
    branch = grid.Branch(top_bus=int(a), bottom_bus=int(b))
    world.connect(branch, dispatcher_sim.Controller(from_bus=int(a), to_bus=int(b)),
                  ("p_kw", "flow_kw"), weak=True)  # fmt: skip
    world.connect(branch, recorder, "p_kw")
world.connect(dispatcher, recorder, "status", "rounds")
world.connect(grid.Network(), recorder, "losses_kw", "source_kw")

world.run(until=minutes * 60, print_progress=False)
rows = (out / "cosim.csv").read_text().count("\n") - 1
print(f"wrote {out / 'cosim.csv'}: {rows} rows (one per minute; columns <entity>.<attribute>)")
