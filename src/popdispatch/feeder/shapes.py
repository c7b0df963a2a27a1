"""A network's own time series: its load shapes run as the loads of every step.

An OpenDSS circuit names, for each load (and each generator or PV system the run does not
dispatch, a fixed injection), a load shape per kind of simulation: ``daily``, ``yearly`` and
``duty`` (the loads table's columns of those names; OpenDSS's own defaults included: a
``daily`` shape is also the ``yearly`` one where none is given, and the ``duty`` one).
:func:`shape_series` turns the shapes of one kind into
:class:`~popdispatch.feeder.profiles.LoadProfiles`, OpenDSS's way:

- a row's kW at a step is its ``p_kw`` times the shape's multiplier, or the multiplier itself
  (kW, with the row's sign) for a shape with ``UseActual=yes``; a row without a shape of that
  kind keeps its ``p_kw`` at every step;
- the steps are as long as the shortest interval of the shapes used and run over the longest of
  them (``npts x interval``); step ``k`` (1-based) takes the point OpenDSS takes at hour ``k x
  step``: ``round(k x step / interval)``, wrapped around the shape's points (a shorter shape
  repeats);
- the steps are undated: their times are offsets from the start (``00:00`` on the first day,
  then ``1 days 00:00:00`` and so on), as OpenDSS counts hours.

The default kind (:func:`default_series`) is the one the loads use: ``yearly`` where a load
names a yearly shape other than its daily one, else ``daily`` where a load has a daily shape;
none (one step of the network's own loads) otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from popdispatch.errors import OptionError, ProfileError
from popdispatch.feeder.profiles import LoadProfiles, Timeline

#: The kinds of series a network's shapes can describe, as OpenDSS names them.
SERIES = ("daily", "yearly", "duty")


@dataclass(frozen=True)
class LoadShape:
    """A load shape: ``mult`` (multiplier per point; kW per point with ``use_actual``) and
    ``hours`` (length of each point's interval, h)."""

    mult: np.ndarray
    hours: float
    use_actual: bool = False

    @property
    def duration_hours(self) -> float:
        return len(self.mult) * self.hours


def default_series(loads: pd.DataFrame) -> str | None:
    """The kind of series the loads use (see the module docstring), ``None`` for none."""
    if not set(SERIES) <= set(loads.columns):
        return None
    daily, yearly = loads["daily"].fillna("").astype(str), loads["yearly"].fillna("").astype(str)
    if ((yearly != "") & (yearly != daily)).any():
        return "yearly"
    if (daily != "").any():
        return "daily"
    return None


def shape_series(feeder, series: str | None = None) -> LoadProfiles | None:
    """Per-row kW of ``feeder``'s loads table at every step of its ``series`` (``daily``,
    ``yearly`` or ``duty``; default :func:`default_series`), or ``None`` when the loads name
    no shape of that kind (the network's own loads are then its one step).

    :class:`OptionError` (``--series``) for an unknown kind or one the network cannot run.
    """
    loads = feeder.loads
    if series is not None and series not in SERIES:
        raise OptionError(f"unknown series {series!r} (known: {', '.join(SERIES)})", "--series")
    if series is not None and not set(SERIES) <= set(loads.columns):
        raise OptionError(
            f"feeder {feeder.name!r} has no load shapes (only OpenDSS circuits name them)",
            "--series",
        )
    series = series or default_series(loads)
    if series is None:
        return None
    names = loads[series].fillna("").astype(str).str.lower().to_numpy()
    if series == "duty":  # OpenDSS runs a duty cycle on the daily shape where none is given
        daily = loads["daily"].fillna("").astype(str).str.lower().to_numpy()
        names = np.where(names == "", daily, names)
    used = sorted(set(names) - {""})
    if not used:
        return None
    missing = [name for name in used if name not in feeder.shapes]
    if missing:
        raise ProfileError(f"feeder {feeder.name!r}: load shape {missing[0]!r} is not defined")
    shapes = {name: feeder.shapes[name] for name in used}
    step = min(s.hours for s in shapes.values())
    steps = int(round(max(s.duration_hours for s in shapes.values()) / step))
    base = loads["p_kw"].to_numpy(float)
    k = np.arange(1, steps + 1)
    # one column per shape (the multiplier at each step), a last one of ones for no shape
    columns = np.ones((steps, len(used) + 1))
    for j, shape in enumerate(shapes.values()):
        point = (np.rint(k * step / shape.hours).astype(np.int64) - 1) % len(shape.mult)
        columns[:, j] = shape.mult[point]
    which = pd.Index(used).get_indexer(names)
    which[which < 0] = len(used)
    actual = np.array([shapes[n].use_actual for n in used] + [False])[which]
    # an actual shape gives kW itself (an injection's kW produced, hence its sign)
    scale = np.where(actual, np.where(base < 0, -1.0, 1.0), base)
    kw = np.take(columns, which, axis=1)
    kw *= scale
    table = pd.DataFrame(kw, index=pd.RangeIndex(1, steps + 1, name="minute"), columns=loads.index)
    times = pd.to_timedelta(np.arange(steps) * step, unit="h")
    timeline = Timeline(times, np.full(steps, step))
    source = f"{feeder.name} {series} load shapes ({len(used)} shapes, {steps} steps of {step:g} h)"
    return LoadProfiles(table, source, timeline)


__all__ = ["SERIES", "LoadShape", "default_series", "shape_series"]
