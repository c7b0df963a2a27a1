"""Load time series of any resolution and length: a user's table (CSV or Parquet) and SimBench's
own profiles, both attached to a feeder's loads.

**Table** (:func:`read_load_table`): one row per time step, a time column and one column per
load, values in kW.

- The time column is the one named ``time``, ``timestamp``, ``datetime`` or ``date`` (any case),
  else the first column. It holds ISO 8601 times (``2016-01-01T00:15:00``, a time zone allowed;
  other forms pandas reads unambiguously also work), strictly increasing. A step's time is the
  start of its interval; the last step lasts as long as the one before it.
- Every other column names a load (as the feeder names it: ``LOAD1``, ``load3``; case ignored
  when the exact name is absent) or a bus (the source format's id: MATPOWER bus number,
  pandapower bus index, OpenDSS bus name). A bus column's kW is shared by that bus's loads in
  proportion to their own ``p_kw`` (equally if those are all zero). Every load of the feeder
  needs exactly one column.

**SimBench** (:func:`simbench_profiles`): the grid's bundled one-year profiles at 15 minutes
(2016, 35,136 steps; German local time, ``+01:00``/``+02:00``) as absolute values
(``simbench.get_absolute_values``): the loads' active power, and the PV, wind and other
static generators' (``sgen``) as fixed injections (negative kW; they have no cost data).

Every problem raises a one-line :class:`~popdispatch.errors.ProfileError` naming the file, the
column and, for a bad value, the row.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.errors import ProfileError
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles, Timeline

#: Names of the time column (case-insensitive); else the first column is the time.
TIME_COLUMNS = ("time", "timestamp", "datetime", "date")
#: SimBench's profile times are German local time (CET/CEST).
SIMBENCH_ZONE = "Europe/Berlin"


def read_load_table(path: str | Path, feeder: Feeder) -> LoadProfiles:
    """The time series of ``path`` (``.csv``, ``.csv.gz``, ``.parquet``/``.pq``; see the
    module docstring) as profiles of ``feeder``'s loads, kW, in the feeder's load order."""
    path = Path(path)
    table = _read(path)
    if table.shape[1] < 2:
        raise ProfileError(f"{path}: needs a time column and at least one load column")
    time_column = next(
        (c for c in table.columns if str(c).strip().lower() in TIME_COLUMNS), table.columns[0]
    )
    times = _times(table[time_column], path, time_column)
    values = table.drop(columns=[time_column])
    values.columns = [str(c).strip() for c in values.columns]
    kw = _numbers(values, path)
    return attach_to_loads(kw, feeder, f"load table {path}", Timeline.from_times(times))


def _read(path: Path) -> pd.DataFrame:
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            try:
                return pd.read_parquet(path)
            except ImportError:
                raise ProfileError(
                    f'{path}: reading Parquet needs pyarrow: pip install "popdispatch[sweep]"'
                ) from None
        return pd.read_csv(path, skipinitialspace=True)
    except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise ProfileError(f"cannot read load table {path}: {exc}") from None
    except ValueError as exc:  # pyarrow's invalid-file errors
        raise ProfileError(f"cannot read load table {path}: {exc}") from None


def _times(column: pd.Series, path: Path, name) -> pd.DatetimeIndex:
    """The time column as a ``DatetimeIndex``, strictly increasing."""
    if pd.api.types.is_datetime64_any_dtype(column):
        times = pd.DatetimeIndex(column)
    else:
        text = column.astype(str).str.strip()
        try:
            times = pd.DatetimeIndex(pd.to_datetime(text, format="ISO8601"))
        except (ValueError, TypeError):
            with warnings.catch_warnings():  # "could not infer format": parsed one by one
                warnings.simplefilter("ignore", UserWarning)
                parsed = pd.to_datetime(text, errors="coerce")
            bad = np.flatnonzero(pd.isna(parsed))
            if len(bad) or not isinstance(parsed.dtype, (np.dtype, pd.DatetimeTZDtype)):
                row = int(bad[0]) if len(bad) else 0
                raise ProfileError(
                    f"{path}: time column {name!r}, row {row + 1}: {column.iloc[row]!r} is not "
                    "a time (use ISO 8601, e.g. 2016-01-01T00:15:00)"
                ) from None
            times = pd.DatetimeIndex(parsed)
    if times.isna().any():
        row = int(np.flatnonzero(times.isna())[0])
        raise ProfileError(f"{path}: time column {name!r}, row {row + 1}: missing time")
    step = np.diff(times.asi8)
    if (step <= 0).any():
        row = int(np.flatnonzero(step <= 0)[0]) + 2
        raise ProfileError(
            f"{path}: time column {name!r}, row {row}: {times[row - 1]} does not come after "
            f"{times[row - 2]} (times must increase)"
        )
    return times


def _numbers(values: pd.DataFrame, path: Path) -> pd.DataFrame:
    """The load columns as floats; the first non-numeric cell named."""
    numeric = values.apply(pd.to_numeric, errors="coerce")
    bad = ~np.isfinite(numeric.to_numpy(float))  # text, missing cells, inf
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ProfileError(
            f"{path}: column {values.columns[col]!r}, row {row + 1}: "
            f"{values.iat[row, col]!r} is not a finite number (kW)"
        )
    return numeric.astype(float)


def attach_to_loads(
    kw: pd.DataFrame, feeder: Feeder, source: str, timeline: Timeline | None = None
) -> LoadProfiles:
    """Columns of ``kw`` (one per load name or bus id, see the module docstring) as profiles of
    ``feeder``'s loads, in the feeder's load order."""
    weights = _column_weights(list(kw.columns), feeder, source)
    table = pd.DataFrame(
        kw.to_numpy(float) @ weights,
        index=pd.RangeIndex(1, len(kw) + 1, name="minute"),
        columns=feeder.loads.index,
    )
    return LoadProfiles(table, source, timeline)


def _column_weights(columns: list, feeder: Feeder, source: str) -> np.ndarray:
    """``(columns, loads)``: the share of each column's kW that each load takes."""
    loads = feeder.loads
    names = {str(n): k for k, n in enumerate(loads.index)}
    folded = {str(n).lower(): k for k, n in enumerate(loads.index)}
    at_bus = _loads_by_bus(feeder)
    weights = np.zeros((len(columns), len(loads)))
    assigned = np.zeros((len(columns), len(loads)), dtype=bool)
    for j, column in enumerate(columns):
        key = str(column)
        if key in names or key.lower() in folded:
            weights[j, names.get(key, folded.get(key.lower()))] = 1.0
            assigned[j, names.get(key, folded.get(key.lower()))] = True
        elif key.lower() in at_bus:
            members = at_bus[key.lower()]
            own = loads["p_kw"].to_numpy(float)[members] if "p_kw" in loads else np.zeros(1)
            share = own / own.sum() if own.sum() > 0 else np.full(len(members), 1 / len(members))
            weights[j, members] = share
            assigned[j, members] = True
        else:
            raise ProfileError(
                f"{source}: column {key!r} is neither a load nor a bus with loads of feeder "
                f"{feeder.name} (loads e.g. {', '.join(map(str, loads.index[:3]))})"
            )
    touched = assigned.sum(axis=0)
    twice = np.flatnonzero(touched > 1)
    if len(twice):
        raise ProfileError(f"{source}: load {loads.index[twice[0]]!r} is given by two columns")
    missing = np.flatnonzero(touched == 0)
    if len(missing):
        raise ProfileError(
            f"{source}: no column for load {loads.index[missing[0]]!r} (bus "
            f"{loads.bus.iloc[missing[0]]}; {len(missing)} of {len(loads)} loads have none)"
        )
    return weights


def _loads_by_bus(feeder: Feeder) -> dict[str, np.ndarray]:
    """Load positions by bus key: the bus id as text and, where buses have names (OpenDSS),
    the lower-cased name."""
    positions = pd.Series(np.arange(len(feeder.loads)), index=feeder.loads.bus.to_numpy())
    groups = {str(bus): group.to_numpy() for bus, group in positions.groupby(level=0)}
    if "name" in feeder.buses.columns:
        names = feeder.buses["name"].astype(str).str.lower()
        for bus, name in names.items():
            if str(bus) in groups:
                groups.setdefault(name, groups[str(bus)])
    return groups


