"""Load time series (kW per load, one row per time step) and where they come from.

Steps are 1-based, as the IEEE feeder's documentation numbers its minutes: the official day has
1440 one-minute steps and its aggregate load peaks at 57.358 kW at minute 566. Any other
series (a SimBench year at 15 minutes, a user's table) has as many steps as rows; the engine
and its outputs call a step a "minute" where the key was documented so (``--minute``,
``first_minute``), and every output also carries the step's time (:class:`Timeline`).

A step's time is the *start* of its interval. The official day is undated: its times are times
of day (minute 1 starts at 00:00, minute 566 at 09:25); a longer undated series (an OpenDSS
year of load shapes) counts days too (``217 days 05:00:00``).

Values are net loads: a negative value is a fixed injection (a generator without cost data
following its own profile), which the dispatch does not move.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from popdispatch.constants import MINUTES_PER_DAY
from popdispatch.errors import OptionError, ProfileError

__all__ = [
    "MINUTES_PER_DAY",
    "LoadProfiles",
    "Timeline",
    "check_minute",
    "day_timeline",
    "single_minute_profiles",
    "validate_profiles",
]


@dataclass(frozen=True)
class Timeline:
    """When each step starts and how long it lasts.

    Attributes
    ----------
    times : start of each step: a ``DatetimeIndex`` (dated series, naive or with a time zone)
        or a ``TimedeltaIndex`` (times of day of an undated day, e.g. the official ELV day).
    hours : duration of each step, h (energies are ``kW x hours``); the last step lasts as
        long as the one before it.
    """

    times: pd.DatetimeIndex | pd.TimedeltaIndex
    hours: np.ndarray = field(repr=False)

    @classmethod
    def from_times(cls, times, one_step_hours: float = 1 / 60) -> Timeline:
        """A timeline from step start ``times`` (increasing); a single step lasts
        ``one_step_hours`` (h)."""
        index = pd.Index(times)
        seconds = np.diff(index.to_numpy()).astype("timedelta64[ns]").astype(float) / 1e9
        hours = np.append(seconds, seconds[-1] if len(seconds) else one_step_hours * 3600) / 3600
        return cls(index, hours)

    def __len__(self) -> int:
        return len(self.times)

    @property
    def step_minutes(self) -> float | None:
        """The common step length, min; ``None`` if the steps differ in length."""
        if len(self.hours) and np.allclose(self.hours, self.hours[0], rtol=0, atol=1e-9):
            return float(self.hours[0] * 60)
        return None

    def label(self, step: int) -> str:
        """ISO 8601 time of a 1-based step: ``2016-01-01T00:15:00`` (dated), ``09:25:00``
        (time of day of an undated day) or ``217 days 05:00:00`` (an undated series longer
        than a day)."""
        return self.labels([step])[0]

    def labels(self, steps) -> list[str]:
        """ISO 8601 times of 1-based ``steps`` (see :meth:`label`)."""
        chosen = self.times[np.asarray(steps, dtype=np.int64) - 1]
        if isinstance(chosen, pd.TimedeltaIndex):
            total = chosen.total_seconds().astype(np.int64)
            seconds = total % 86400
            clock = [f"{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}" for s in seconds]
            if self.times[-1] < pd.Timedelta(days=1):
                return clock
            return [f"{d} days {c}" for d, c in zip(total // 86400, clock, strict=True)]
        return [t.isoformat() for t in chosen]

    def step_at(self, text: str, option: str = "--start") -> int:
        """The 1-based step whose interval holds time ``text`` (ISO 8601; ``HH:MM`` for an
        undated day). :class:`OptionError` naming ``option`` if it is unreadable or outside."""
        when = self._parse(text, option)
        position = int(self.times.searchsorted(when, side="right")) - 1
        end = self.times[-1] + pd.Timedelta(hours=float(self.hours[-1]))
        if position < 0 or when >= end:
            first, last = self.labels([1])[0], self.labels([len(self)])[0]
            raise OptionError(
                f"time {text!r} is outside the series ({first} .. {last}, {len(self)} steps)",
                option,
            )
        return position + 1

    def _parse(self, text: str, option: str):
        dated = not isinstance(self.times, pd.TimedeltaIndex)
        if dated and re.fullmatch(r"\s*\d{1,2}:\d{2}(:\d{2})?\s*", str(text)):
            first = self.labels([1])[0][:10]
            raise OptionError(
                f"{text!r} has no date, and this series is dated (from {first}): give the day "
                f"too, e.g. {first}T{str(text).strip()}",
                option,
            )
        try:
            if not dated:
                clock = str(text).strip()
                return pd.Timedelta(clock + (":00" if clock.count(":") == 1 else ""))
            when = pd.Timestamp(text)
        except ValueError:
            kind = "HH:MM" if isinstance(self.times, pd.TimedeltaIndex) else "an ISO 8601 time"
            raise OptionError(f"{text!r} is not {kind}", option) from None
        zone = self.times.tz
        if zone is not None and when.tzinfo is None:
            try:
                return when.tz_localize(zone)
            except Exception:  # pytz's AmbiguousTimeError/NonExistentTimeError: a clock change
                raise OptionError(
                    f"{text!r} is ambiguous or does not exist in {zone} (a clock change): give "
                    "its UTC offset, e.g. 2016-10-30T02:30+02:00",
                    option,
                ) from None
        if zone is None and when.tzinfo is not None:
            return when.tz_convert(None)
        return when


def day_timeline(steps: int = MINUTES_PER_DAY) -> Timeline:
    """One-minute steps of an undated day starting at 00:00 (the official ELV day)."""
    times = pd.to_timedelta(np.arange(steps), unit="min")
    return Timeline(times, np.full(steps, 1 / 60))


@dataclass(frozen=True)
class LoadProfiles:
    """Per-load demand at every step of a time series.

    Attributes
    ----------
    kw : index ``minute`` (the 1-based step, 1..steps), one column per load name; kW.
    source : human-readable origin, stated in every output
        (e.g. ``"official profiles: /data/ieee-elv"``).
    timeline : when each step starts and how long it lasts; default one-minute steps of an
        undated day (:func:`day_timeline`).
    """

    kw: pd.DataFrame
    source: str
    timeline: Timeline | None = None

    def __post_init__(self) -> None:
        validate_profiles(self.kw, self.source)
        if self.timeline is None:
            object.__setattr__(self, "timeline", day_timeline(len(self.kw)))
        elif len(self.timeline) != len(self.kw):
            raise ProfileError(
                f"{self.source}: {len(self.timeline)} times for {len(self.kw)} steps"
            )

    @property
    def minutes(self) -> np.ndarray:
        return self.kw.index.to_numpy()

    @property
    def steps(self) -> int:
        """Number of time steps."""
        return len(self.kw)

    def at(self, minute: int) -> pd.Series:
        """Per-load demand (kW) at a 1-based step."""
        check_minute(minute, self.steps)
        return self.kw.iloc[int(minute) - 1]

    def total_kw(self) -> pd.Series:
        """Aggregate demand (kW) per step."""
        return self.kw.sum(axis=1).rename("demand_kw")

    def for_loads(self, load_names: pd.Index) -> LoadProfiles:
        """The profiles in the order of a feeder's loads; error if one is missing.

        Names match exactly, else ignoring case (OpenDSS lower-cases the names that the
        official ``Loads.txt`` spells ``LOAD1``)."""
        columns = self.kw.columns
        if columns.equals(load_names):
            return self
        if not load_names.difference(columns).empty:
            folded = pd.Index([str(c).lower() for c in columns])
            if folded.has_duplicates:
                raise ProfileError(f"{self.source}: load names differ only in case")
            position = folded.get_indexer([str(n).lower() for n in load_names])
            if (position < 0).any():
                missing = load_names[np.flatnonzero(position < 0)[0]]
                raise ProfileError(f"no profile for load {missing!r} in {self.source}")
            table = self.kw.iloc[:, position].set_axis(load_names, axis=1)
            return LoadProfiles(table, self.source, self.timeline)
        return LoadProfiles(self.kw.loc[:, load_names], self.source, self.timeline)

    def select(self, first: int, last: int) -> LoadProfiles:
        """Steps ``first``..``last`` (1-based, both included), renumbered from 1."""
        check_minute(first, self.steps)
        check_minute(last, self.steps)
        part = self.kw.iloc[first - 1 : last].reset_index(drop=True)
        part.index = pd.RangeIndex(1, len(part) + 1, name="minute")
        times = self.timeline.times[first - 1 : last]
        timeline = Timeline(times, self.timeline.hours[first - 1 : last])
        return LoadProfiles(part, self.source, timeline)


def check_minute(minute: int, steps: int = MINUTES_PER_DAY) -> None:
    """Raise :class:`ProfileError` unless the 1-based step ``minute`` is in 1..``steps``
    (default a day of minutes)."""
    if not 1 <= int(minute) <= steps:
        what = "minute" if steps == MINUTES_PER_DAY else "step"
        raise ProfileError(f"{what} {minute} is outside 1..{steps}")


def validate_profiles(kw: pd.DataFrame, source: str) -> None:
    """Raise :class:`ProfileError` naming the first bad load: no steps, NaN or infinite
    (a negative value is a fixed injection)."""
    if len(kw) == 0:
        raise ProfileError(f"{source}: profiles have no time step")
    values = kw.to_numpy(dtype=float)
    for bad, what in ((np.isnan(values), "NaN"), (np.isinf(values), "infinite value")):
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise ProfileError(
                f"{source}: load {kw.columns[col]!r} has a {what} at step {kw.index[row]}"
            )


def single_minute_profiles(minute: int, load_kw: pd.Series, source: str) -> LoadProfiles:
    """Profiles known at one minute only (other minutes of the day repeat it); for snapshot
    runs."""
    check_minute(minute)
    table = pd.DataFrame(
        np.tile(load_kw.to_numpy(float), (MINUTES_PER_DAY, 1)),
        index=pd.RangeIndex(1, MINUTES_PER_DAY + 1, name="minute"),
        columns=load_kw.index,
    )
    return LoadProfiles(table, source)
