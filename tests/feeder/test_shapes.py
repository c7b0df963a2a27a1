"""A network's own load shapes as the run's loads (popdispatch.feeder.shapes): the kW of every
load and fixed injection at every step equal OpenDSS's own daily simulation of the same circuit
(each step solved by OpenDSS, each element's power read back), with shapes of different
intervals and lengths, an actual-kW shape, a load without a shape and a generator without cost
data (a fixed injection)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from popdispatch.errors import OptionError
from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.shapes import LoadShape, default_series, shape_series

opendssdirect = pytest.importorskip("opendssdirect", reason="needs popdispatch[opendss]")

from popdispatch.readers.opendss_direct import read_opendss_master  # noqa: E402

HOURLY = [0.5, 0.4, 0.45, 0.6, 0.8, 1.0, 0.9, 0.7, 0.6, 0.65, 0.7, 0.75,
          0.8, 0.85, 0.9, 0.95, 1.0, 0.9, 0.8, 0.7, 0.6, 0.55, 0.5, 0.45]  # fmt: skip
QUARTER = [0.2 + 0.8 * abs(np.sin(k / 7)) for k in range(96)]
ACTUAL = [3.0, 5.0, 4.0, 2.0]  # kW, 6-hour points

CIRCUIT = """Clear
New Circuit.shapes basekV=12.47 pu=1.0 bus1=src MVAsc3=1e9 MVAsc1=1e9
New Linecode.lc nphases=3 r1=0.01 x1=0.02 r0=0.03 x0=0.06 units=km
New Line.l1 bus1=src bus2=a linecode=lc length=0.1
New Line.l2 bus1=a bus2=b linecode=lc length=0.1
New Loadshape.hourly npts=24 interval=1 mult=({hourly})
New Loadshape.quarter npts=96 minterval=15 mult=({quarter})
New Loadshape.actual npts=4 interval=6 mult=({actual}) useactual=yes
New Load.h bus1=a kV=12.47 kW=100 pf=1 model=1 vminpu=0.5 daily=hourly
New Load.q bus1=b kV=12.47 kW=40 pf=1 model=1 vminpu=0.5 daily=quarter
New Load.u bus1=b kV=12.47 kW=1 pf=1 model=1 vminpu=0.5 daily=actual
New Load.flat bus1=a kV=12.47 kW=7 pf=1 model=1 vminpu=0.5
New Generator.g bus1=b kV=12.47 kW=30 pf=1 model=1 vminpu=0.5 daily=hourly
Set voltagebases=[12.47]
Calcvoltagebases
"""


def write_circuit(folder):
    text = CIRCUIT.format(
        hourly=" ".join(map(str, HOURLY)),
        quarter=" ".join(f"{v:.6f}" for v in QUARTER),
        actual=" ".join(map(str, ACTUAL)),
    )
    path = folder / "shapes.dss"
    path.write_text(text)
    return path


def opendss_daily(path, steps: int, minutes: int) -> pd.DataFrame:
    """Each element's power (kW, loads positive, the generator negative) at each step of
    OpenDSS's own daily simulation with ``minutes``-minute steps."""
    ctx = opendssdirect.NewContext()
    ctx.Basic.AllowChangeDir(False)
    ctx.Text.Command(f'compile "{path}"')
    ctx.Text.Command(f"set mode=daily stepsize={minutes}m number=1")
    rows = []
    for _ in range(steps):
        ctx.Text.Command("solve")
        row = {}
        for element in ("Load.h", "Load.q", "Load.u", "Load.flat", "Generator.g"):
            ctx.Circuit.SetActiveElement(element)
            powers = ctx.CktElement.Powers()
            conductors = ctx.CktElement.NumConductors()
            row[element.split(".")[1] if element.startswith("Load") else element] = sum(
                powers[0 : 2 * conductors : 2]
            )
        rows.append(row)
    return pd.DataFrame(rows)


def test_daily_shapes_equal_opendss_own_daily_simulation(tmp_path):
    path = write_circuit(tmp_path)
    feeder = read_opendss_master(path)
    assert default_series(feeder.loads) == "daily"
    profiles = shape_series(feeder)
    # the finest interval (15 min) over the longest shape (24 h): 96 steps
    assert profiles.steps == 96 and profiles.timeline.step_minutes == 15.0
    assert profiles.timeline.label(1) == "00:00:00" and profiles.timeline.label(96) == "23:45:00"
    theirs = opendss_daily(path, 96, 15)
    ours = profiles.kw[theirs.columns]
    np.testing.assert_allclose(ours.to_numpy(), theirs.to_numpy(), rtol=1e-6, atol=1e-6)
    assert (ours["Generator.g"] < 0).all()  # a fixed injection: negative load


def test_one_step_without_shapes_and_unknown_series(tmp_path):
    path = write_circuit(tmp_path)
    feeder = read_opendss_master(path)
    assert shape_series(feeder, "duty") is not None  # duty defaults to the daily shape
    flat = feeder.loads.assign(daily="", yearly="", duty="")
    assert shape_series(Feeder(feeder.name, feeder.buses, feeder.lines, flat, feeder.source_bus,
                               feeder.generators, feeder.shapes)) is None  # fmt: skip
    with pytest.raises(OptionError, match="unknown series 'weekly'"):
        shape_series(feeder, "weekly")


def test_networks_without_shapes_refuse_a_series():
    buses = pd.DataFrame({"x": [0.0, 1.0], "y": 0.0}, index=pd.Index([1, 2], name="bus"))
    lines = pd.DataFrame(
        {"from_bus": [1], "to_bus": [2], "length_km": 1.0, "r_ohm": 0.1, "x_ohm": 0.1,
         "limit_kw": np.inf},
        index=["l"],
    )  # fmt: skip
    loads = pd.DataFrame({"bus": [2], "p_kw": [5.0]}, index=["a"])
    feeder = Feeder("two", buses, lines, loads, 1, make_fleet([(1, 0, 1, 0, 0, 10)]))
    assert shape_series(feeder) is None
    with pytest.raises(OptionError, match="has no load shapes"):
        shape_series(feeder, "yearly")


def test_wrapping_and_actual_kw_rules():
    """A 3-point shape under a 6-point one repeats; an actual-kW shape of an injection is
    produced kW (negative load)."""
    buses = pd.DataFrame({"x": [0.0, 1.0], "y": 0.0}, index=pd.Index([1, 2], name="bus"))
    lines = pd.DataFrame(
        {"from_bus": [1], "to_bus": [2], "length_km": 1.0, "r_ohm": 0.1, "x_ohm": 0.1,
         "limit_kw": np.inf},
        index=["l"],
    )  # fmt: skip
    loads = pd.DataFrame(
        {"bus": [2, 2], "p_kw": [10.0, -4.0], "kind": ["load", "generator"],
         "daily": ["short", "pv"], "yearly": ["short", "pv"], "duty": ["", ""]},
        index=["a", "Generator.pv"],
    )  # fmt: skip
    shapes = {
        "short": LoadShape(np.array([1.0, 0.5, 0.25]), 1.0),
        "pv": LoadShape(np.array([0.0, 1.0, 2.0, 3.0, 2.0, 1.0]), 1.0, use_actual=True),
    }
    feeder = Feeder("w", buses, lines, loads, 1, make_fleet([(1, 0, 1, 0, 0, 10)]), shapes)
    kw = shape_series(feeder, "daily").kw
    assert kw["a"].tolist() == [10.0, 5.0, 2.5, 10.0, 5.0, 2.5]
    assert kw["Generator.pv"].tolist() == [-0.0, -1.0, -2.0, -3.0, -2.0, -1.0]
