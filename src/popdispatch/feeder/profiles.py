"""One day of 1-minute load profiles (kW per load), and where they come from.

Minutes are 1-based (1..1440), as in the IEEE feeder's documentation: the aggregate load peaks
at 57.358 kW at minute 566.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from popdispatch.constants import MINUTES_PER_DAY
from popdispatch.errors import ProfileError


@dataclass(frozen=True)
class LoadProfiles:
    """Per-load demand for every minute of a day.

    Attributes
    ----------
    kw : index ``minute`` (1..1440), one column per load name; demand in kW.
    source : human-readable origin, stated in every output
        (e.g. ``"official profiles: /data/ieee-elv"``).
    """

    kw: pd.DataFrame
    source: str

    def __post_init__(self) -> None:
        validate_profiles(self.kw, self.source)

    @property
    def minutes(self) -> np.ndarray:
        return self.kw.index.to_numpy()

    def at(self, minute: int) -> pd.Series:
        """Per-load demand (kW) at a 1-based minute."""
        check_minute(minute)
        return self.kw.loc[minute]

    def total_kw(self) -> pd.Series:
        """Aggregate demand (kW) per minute."""
        return self.kw.sum(axis=1).rename("demand_kw")

    def for_loads(self, load_names: pd.Index) -> LoadProfiles:
        """The profiles in the order of a feeder's loads; error if one is missing."""
        missing = load_names.difference(self.kw.columns)
        if len(missing):
            raise ProfileError(f"no profile for load {missing[0]!r} in {self.source}")
        return LoadProfiles(self.kw.loc[:, load_names], self.source)


def check_minute(minute: int) -> None:
    """Raise :class:`ProfileError` unless ``minute`` is in 1..1440."""
    if not 1 <= int(minute) <= MINUTES_PER_DAY:
        raise ProfileError(f"minute {minute} is outside 1..{MINUTES_PER_DAY}")


def validate_profiles(kw: pd.DataFrame, source: str) -> None:
    """Raise :class:`ProfileError` naming the first bad load: wrong length, NaN or negative."""
    if len(kw) != MINUTES_PER_DAY:
        raise ProfileError(f"{source}: profiles have {len(kw)} minutes, expected {MINUTES_PER_DAY}")
    values = kw.to_numpy(dtype=float)
    for bad, what in ((np.isnan(values), "NaN"), (values < 0, "negative value")):
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise ProfileError(
                f"{source}: load {kw.columns[col]!r} has a {what} at minute {kw.index[row]}"
            )


def single_minute_profiles(minute: int, load_kw: pd.Series, source: str) -> LoadProfiles:
    """Profiles known at one minute only (other minutes repeat it); for snapshot runs."""
    check_minute(minute)
    table = pd.DataFrame(
        np.tile(load_kw.to_numpy(float), (MINUTES_PER_DAY, 1)),
        index=pd.RangeIndex(1, MINUTES_PER_DAY + 1, name="minute"),
        columns=load_kw.index,
    )
    return LoadProfiles(table, source)
