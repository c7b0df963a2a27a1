"""Profile assignment: the IEEE ELV's official profiles (100 in its folder) assigned to its
55 loads by seed.

Assignment ``(seed, draw)`` gives every load a distinct profile drawn without replacement from
the folder's profiles (``numpy.random.default_rng([seed, draw])``): the same numbers on every
machine and worker. A profile file's values are kW (the official loads have ``kW=1``, so their
multipliers are their demand; see the folder's README).
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.errors import ProfileError
from popdispatch.feeder.profiles import LoadProfiles

#: The OpenDSS form's and the IEEE CSV form's profile files (case-insensitive).
POOL_PATTERNS = (
    ("daily_1min_100profiles", re.compile(r"load_profile_(\d+)\.txt$", re.IGNORECASE)),
    ("load profiles", re.compile(r"load_profile_(\d+)\.csv$", re.IGNORECASE)),
)


def _pool_files(folder: Path) -> dict[int, Path]:
    """Profile number -> file, from whichever form's folder ``folder`` holds."""
    for sub, pattern in POOL_PATTERNS:
        dirs = [d for d in folder.iterdir() if d.is_dir() and d.name.lower() == sub]
        files = {}
        for d in dirs:
            for f in d.iterdir():
                match = pattern.match(f.name)
                if match:
                    files[int(match[1])] = f
        if files:
            return dict(sorted(files.items()))
    raise ProfileError(f"{folder}: no profile files (Daily_1min_100profiles/ or Load Profiles/)")


@functools.lru_cache(maxsize=4)
def profile_pool(folder: str) -> pd.DataFrame:
    """Every official profile of ``folder``: index ``minute`` 1..1440, one column per profile
    number (kW). Read once per process (cached)."""
    from popdispatch.readers.profiles import read_profile_file

    columns = {}
    for number, path in _pool_files(Path(folder)).items():
        columns[number] = read_profile_file(path, f"profile {number}")
    table = pd.DataFrame(columns, index=pd.RangeIndex(1, 1441, name="minute"))
    table.columns.name = "profile"
    return table


@functools.lru_cache(maxsize=4)
def official_profiles(folder: str) -> LoadProfiles:
    """The folder's profiles as its loads follow them (read once per process)."""
    from popdispatch.readers import read_profiles

    return read_profiles(folder)


def assignment_numbers(seed: int, draw: int, n_loads: int, n_profiles: int) -> np.ndarray:
    """Profile numbers (1-based) of ``n_loads`` loads: distinct, drawn from ``n_profiles``."""
    if n_loads > n_profiles:
        raise ProfileError(f"{n_loads} loads but only {n_profiles} profiles to assign")
    rng = np.random.default_rng([seed, draw])
    return rng.choice(n_profiles, size=n_loads, replace=False) + 1


def assigned_profiles(folder: str, seed: int, draw: int) -> tuple[LoadProfiles, list[int]]:
    """The loads of ``folder`` following randomly assigned profiles, and the profile number
    of each load (in load order)."""
    loads = official_profiles(folder).kw.columns
    pool = profile_pool(folder)
    picks = assignment_numbers(seed, draw, len(loads), pool.shape[1])
    numbers = pool.columns.to_numpy()[picks - 1]
    table = pd.DataFrame(pool[numbers].to_numpy(), index=pool.index, columns=loads)
    source = f"official profiles: {folder}, random assignment seed {seed} draw {draw}"
    return LoadProfiles(table, source), [int(n) for n in numbers]
