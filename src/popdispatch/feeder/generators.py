"""Generator fleets: the paper's Table I and user tables.

A fleet is a DataFrame indexed by generator name with columns

- ``bus``: original bus id,
- ``a`` (EUR/h), ``b`` (EUR/MWh), ``c`` (EUR/(MW^2 h)): cost rate ``C(p) = a + b p + c p^2``
  in EUR/h with p in MW (eq. 2; the paper's Table I units, so the marginal cost ``b + 2 c p``
  is in EUR/MWh),
- ``pmin_kw``, ``pmax_kw``: output limits in kW.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.errors import FleetError

FLEET_COLUMNS = ["bus", "a", "b", "c", "pmin_kw", "pmax_kw"]

#: The paper's Table I (bus, a EUR/h, b EUR/MWh, c EUR/(MW^2 h), Pmin kW, Pmax kW).
TABLE_I = [
    (1, 0.0, 5.0, 0.02, 0.0, 10.0),
    (114, 0.0, 1.0, 0.01, 0.0, 10.0),
    (578, 0.0, 3.0, 0.025, 0.0, 5.0),
    (739, 0.0, 4.0, 0.01, 0.0, 10.0),
    (817, 0.0, 2.5, 0.015, 0.0, 20.0),
    (835, 0.0, 2.0, 0.02, 0.0, 10.0),
]


def make_fleet(rows: Iterable[tuple], names: Iterable[str] | None = None) -> pd.DataFrame:
    """A fleet table from ``(bus, a, b, c, pmin_kw, pmax_kw)`` rows.

    Parameters
    ----------
    rows : one tuple per generator: ``bus`` (bus id of the feeder), ``a`` (EUR/h), ``b``
        (EUR/MWh), ``c`` (EUR/(MW^2 h)) of the cost rate ``a + b p + c p^2`` with p in MW
        (paper eq. 2), ``pmin_kw`` and ``pmax_kw`` (output limits, kW).
    names : generator names; default ``G<bus>``.
    """
    table = pd.DataFrame(list(rows), columns=FLEET_COLUMNS)
    table["bus"] = table["bus"].astype(int)
    table.index = pd.Index(
        list(names) if names is not None else [f"G{b}" for b in table.bus], name="generator"
    )
    return table


def paper_fleet() -> pd.DataFrame:
    """The six distributed generators of the paper's Table I."""
    return make_fleet(TABLE_I)


#: Unit-named fleet file columns -> fleet table columns (``a_eur_per_h`` optional, default 0).
FILE_COLUMNS = {
    "a_eur_per_h": "a",
    "b_eur_per_mwh": "b",
    "c_eur_per_mw2h": "c",
}


def read_fleet(path: str | Path) -> pd.DataFrame:
    """Read a fleet from a CSV or TOML file.

    Columns ``bus, name, b_eur_per_mwh, c_eur_per_mw2h, pmin_kw, pmax_kw`` and optionally
    ``a_eur_per_h`` (default 0): ``b`` EUR/MWh, ``c`` EUR/(MW^2 h) and ``a`` EUR/h of the cost
    rate ``a + b p + c p^2`` with p in MW (paper eq. 2), limits in kW. The short names ``a``,
    ``b``, ``c`` of :data:`FLEET_COLUMNS` are read too; ``name`` is optional (default
    ``G<bus>``). ``bus`` is the source format's bus id: a MATPOWER bus number, a pandapower
    bus index, an OpenDSS bus name (kept as text when it is not an integer).

    CSV: one row per generator. TOML: an array of tables ``[[generator]]`` with those keys.
    """
    path = Path(path)
    try:
        if path.suffix.lower() == ".toml":
            rows = tomllib.loads(path.read_text()).get("generator")
            if not rows:
                raise FleetError(f"{path}: no [[generator]] tables")
            table = pd.DataFrame(rows)
        else:
            table = pd.read_csv(path, skipinitialspace=True, dtype={"bus": str, "name": str})
    except (
        OSError,
        UnicodeDecodeError,
        tomllib.TOMLDecodeError,
        pd.errors.ParserError,
        pd.errors.EmptyDataError,
    ) as exc:
        raise FleetError(f"cannot read fleet file {path}: {exc}") from None
    table.columns = [str(c).strip().lower() for c in table.columns]
    table = table.rename(columns=FILE_COLUMNS)
    if "a" not in table.columns:
        table["a"] = 0.0
    missing = [c for c in FLEET_COLUMNS if c not in table.columns]
    if missing:
        unit_named = {v: k for k, v in FILE_COLUMNS.items()}
        wanted = unit_named.get(missing[0], missing[0])
        raise FleetError(
            f"{path}: fleet table lacks column {wanted!r} (needs bus, name, b_eur_per_mwh, "
            "c_eur_per_mw2h, pmin_kw, pmax_kw; optional a_eur_per_h)"
        )
    return _fleet_table(table, path)


def as_fleet(fleet: pd.DataFrame | str | Path | None) -> pd.DataFrame | None:
    """A fleet table given as a table, as the path of a CSV or TOML fleet file
    (:func:`read_fleet`) or as ``None`` (none given); anything else is a :class:`FleetError`
    saying what is wanted."""
    if fleet is None or isinstance(fleet, pd.DataFrame):
        return fleet
    if isinstance(fleet, str | Path):
        return read_fleet(fleet)
    raise FleetError(
        f"a fleet is a table (pandas DataFrame with columns {', '.join(FLEET_COLUMNS)}) or the "
        f"path of a CSV or TOML fleet file, not {type(fleet).__name__}"
    )


def _fleet_table(table: pd.DataFrame, path: Path) -> pd.DataFrame:
    """Numbers checked (the first bad cell named by row), buses as integers where they are."""
    for column in FLEET_COLUMNS[1:]:
        numeric = pd.to_numeric(table[column], errors="coerce")
        if numeric.isna().any():
            row = int(numeric.isna().to_numpy().argmax())
            raise FleetError(
                f"{path}: row {row + 1} has non-numeric {column} = {table[column][row]!r}"
            )
        table[column] = numeric.astype(float)
    buses = [_bus_id(bus, path, row) for row, bus in enumerate(table["bus"])]
    names = (
        table["name"].astype(str).str.strip().tolist()
        if "name" in table.columns
        else [f"G{b}" for b in buses]
    )
    fleet = table[FLEET_COLUMNS].copy()
    named = any(isinstance(b, str) for b in buses)
    fleet["bus"] = np.array(buses, dtype=object if named else np.int64)
    fleet.index = pd.Index(names, name="generator")
    return fleet


def _bus_id(bus, path: Path, row: int) -> int | str:
    """A fleet file's bus: an integer where it spells one, else the name (OpenDSS)."""
    text = str(bus).strip() if bus is not None else ""
    if text in ("", "nan", "None"):
        raise FleetError(f"{path}: row {row + 1} has no bus")
    try:
        return int(text)
    except ValueError:
        number = pd.to_numeric(text, errors="coerce")
        return int(number) if pd.notna(number) and float(number).is_integer() else text


def validate_fleet(fleet: pd.DataFrame, buses: pd.Index) -> None:
    """Raise :class:`FleetError` naming the first invalid generator (an empty fleet is valid:
    a network described without one; a dispatch needs one, see
    :func:`popdispatch.game.problem.build_problem`)."""
    missing = [c for c in FLEET_COLUMNS if c not in fleet.columns]
    if missing:
        raise FleetError(f"fleet table lacks column {missing[0]!r}")
    if fleet.index.has_duplicates:
        raise FleetError(f"generator {fleet.index[fleet.index.duplicated()][0]!r} is defined twice")
    for name, row in fleet.iterrows():
        if row.bus not in buses:
            raise FleetError(f"generator {name!r} is on unknown bus {row.bus}")
        for column in ("a", "b", "c", "pmin_kw", "pmax_kw"):
            value = float(row[column])
            if not np.isfinite(value):
                raise FleetError(f"generator {name!r} has non-finite {column} = {value}")
        for column in ("a", "b", "c", "pmin_kw", "pmax_kw"):
            if row[column] < 0:
                raise FleetError(f"generator {name!r} has negative {column} = {row[column]}")
        if row.pmin_kw > row.pmax_kw:
            raise FleetError(
                f"generator {name!r} has pmin_kw = {row.pmin_kw} > pmax_kw = {row.pmax_kw}"
            )
