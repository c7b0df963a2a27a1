"""A small, strict reader of MATPOWER case files (``.m``) into a :class:`Feeder` (in progress)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from popdispatch.feeder.model import Feeder


def read_matpower(
    path: str | Path,
    *,
    fleet: pd.DataFrame | None = None,
    root: int | None = None,
    ratings: bool = True,
) -> Feeder:
    """Read a MATPOWER case file into a radial :class:`Feeder` (not implemented yet)."""
    raise NotImplementedError("read_matpower is being written (issue 12)")
