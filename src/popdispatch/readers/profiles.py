"""Load profiles: the official IEEE European LV Test Feeder files and the shipped offline default.

Two official forms are read by :func:`read_profiles`:

(a) OpenDSS form: ``Loads.txt`` (``New Load.NAME ... kW=k Yearly=SHAPE`` or ``Daily=SHAPE``),
    optionally ``LoadShapes.txt`` (``New Loadshape.SHAPE npts=1440 minterval=1
    mult=(file=Daily_1min_100profiles\\Load_profile_n.txt)``) and the multiplier files, one value
    per line. Without ``LoadShapes.txt`` shape ``Shape_n`` uses
    ``Daily_1min_100profiles/load_profile_n.txt``.
(b) IEEE CSV form: ``Loads.csv`` (any title lines, then a header row starting with ``Name`` and
    holding ``kW`` and ``Yearly``) and ``Load Profiles/Load_profile_n.csv`` (a header row with a
    ``mult`` column, e.g. ``time,mult``, then 1440 rows); shape ``Shape_n`` uses profile ``n``.

In both forms a load's demand in kW is ``kW x multiplier`` (the IEEE files have ``kW=1`` and
multipliers in kW; ``Master.dss`` sets ``useactual=no`` on every load shape, so ``kW`` scales).
File names are matched case-insensitively and backslashes are accepted as separators. Every
problem raises a one-line :class:`~popdispatch.errors.ProfileError` naming the file and load.
"""

from __future__ import annotations

import csv
import gzip
import os
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch import cache
from popdispatch.errors import ProfileError
from popdispatch.feeder.profiles import MINUTES_PER_DAY, LoadProfiles
from popdispatch.readers.manifest import Inputs, code_hash, split_current
from popdispatch.readers.opendss import _LOAD_KEYS, Statement, find_file, parse_statements

#: Environment variable naming a profile folder (used by :func:`resolve_profiles`).
PROFILES_ENV = "POPDISPATCH_PROFILES"
#: The shipped default profiles, in ``popdispatch/data``.
DEFAULT_PROFILES_FILE = "default_profiles.csv.gz"

#: Cache entry of a profile folder's table (:mod:`popdispatch.cache`) and its layout version.
PROFILES_CACHE, PROFILES_FORMAT = "profiles", 1

_LOADSHAPE_KEYS = {"npts", "minterval", "sinterval", "interval", "mult", "useactual"}
_SHAPE_NUMBER = re.compile(r"(\d+)$")


def read_profiles(folder: str | Path, use_cache: bool = True) -> LoadProfiles:
    """Read the official per-load profiles from ``folder`` (OpenDSS form or IEEE CSV form).

    Returns :class:`~popdispatch.feeder.profiles.LoadProfiles` with index ``minute`` 1..1440,
    one column per load (in file order, names as spelled there, e.g. ``LOAD1``), values in kW,
    and ``source = "official profiles: <absolute folder>"``.

    ``use_cache``: take the table from the on-disk cache (:mod:`popdispatch.cache`) when an
    entry for this folder exists and every file and folder the read looked at still has the
    size and modification time it had then (:mod:`popdispatch.readers.manifest`); otherwise
    read the files and store the table for the next process (a warm read is much quicker
    than parsing the folder).
    """
    root = Path(folder).expanduser()
    if not root.is_dir():
        raise ProfileError(f"profile folder {root} does not exist or is not a folder")
    root = root.resolve()
    try:
        next(root.iterdir(), None)
    except OSError as exc:
        raise ProfileError(f"profile folder {root} is unreadable: {exc}") from None
    source = f"official profiles: {root}"
    key = profiles_cache_key(root)
    if use_cache:
        cached = _from_cache(key)
        if cached is not None:
            return LoadProfiles(cached[0], source)
    inputs = Inputs()
    profiles = LoadProfiles(_read_folder(root, inputs), source)
    if use_cache:
        _save(key, profiles, inputs)
    return profiles


def profiles_cache_key(root: Path) -> dict:
    """The cache key of the profile folder (or shipped file) ``root`` (absolute): it, the layout and
    package versions and the code of the readers (the inputs' sizes and times are checked
    apart, :func:`popdispatch.readers.manifest.split_current`)."""
    from popdispatch import __version__

    code = code_hash("readers/profiles.py", "readers/opendss.py", "readers/manifest.py")
    return {
        "what": "load profiles",
        "path": str(root),
        "format": PROFILES_FORMAT,
        "popdispatch": __version__,
        "code": code,
    }


def _from_cache(key: dict, with_source: bool = False) -> tuple[pd.DataFrame, str] | None:
    """``(table, source)`` cached under ``key`` if its inputs are unchanged and it is sound,
    else None (``source`` is the stored one with ``with_source``, else empty)."""
    arrays = split_current(cache.load_arrays(PROFILES_CACHE, key))
    names = {"kw", "loads", "source"} if with_source else {"kw", "loads"}
    if arrays is None or set(arrays) != names:
        return None
    kw, loads = arrays["kw"], arrays["loads"]
    if kw.dtype.kind != "f" or kw.shape != (MINUTES_PER_DAY, len(loads)) or not len(loads):
        return None
    if loads.dtype.kind != "U" or len(set(loads.tolist())) != len(loads):
        return None
    if not (np.isfinite(kw).all() and (kw >= 0).all()):
        return None
    table = pd.DataFrame(
        kw,
        index=pd.RangeIndex(1, MINUTES_PER_DAY + 1, name="minute"),
        columns=pd.Index(loads.tolist(), dtype=object, name="load"),
    )
    return table, str(arrays["source"]) if with_source else ""


def _save(key: dict, profiles: LoadProfiles, inputs: Inputs) -> None:
    """Store ``profiles`` under ``key`` with the manifest of ``inputs`` (the source too when
    the key is not a folder's, whose source is derived from the folder); nothing while an
    input was modified too recently to be vouched for (:meth:`Inputs.settled`)."""
    if not inputs.settled():
        return
    kw = profiles.kw
    arrays = {"kw": kw.to_numpy(float), "loads": np.array([str(c) for c in kw.columns])}
    if not profiles.source.startswith("official profiles: "):
        arrays["source"] = np.array(profiles.source)
    cache.save_arrays(PROFILES_CACHE, key, {**arrays, **inputs.arrays()})


def _read_folder(root: Path, inputs: Inputs) -> pd.DataFrame:
    """The kW table of a profile folder, every file and folder looked at added to ``inputs``."""
    inputs.add(root)
    loads_txt = inputs.add(find_file(root, "Loads.txt", ProfileError), root)
    if loads_txt is not None:
        return _read_opendss_form(root, loads_txt, inputs)
    loads_csv = inputs.add(find_file(root, "Loads.csv", ProfileError), root)
    if loads_csv is None:
        raise ProfileError(
            f"{root}: neither Loads.txt (OpenDSS form) nor Loads.csv (IEEE CSV form)"
        )
    return _read_csv_form(root, loads_csv, inputs)


def _table(columns: dict[str, np.ndarray]) -> pd.DataFrame:
    if not columns:
        raise ProfileError("no loads")
    table = pd.DataFrame(columns, index=pd.RangeIndex(1, MINUTES_PER_DAY + 1, name="minute"))
    table.columns.name = "load"
    return table


def _fast_values(values: list[str]) -> np.ndarray | None:
    """The numbers if every token is a finite number >= 0 (surrounding blanks allowed), else
    None (then :func:`_check_values` finds and names the bad token)."""
    try:
        out = np.fromiter(map(float, values), dtype=float, count=len(values))
    except ValueError:
        return None
    return out if np.isfinite(out).all() and (out >= 0).all() else None


def _check_values(values: list[str], path: Path, load: str, first_line: int) -> np.ndarray:
    """Parse ``MINUTES_PER_DAY`` non-negative finite numbers (line numbers for messages)."""
    fast = _fast_values(values)  # the loop below only runs to name a bad value
    if fast is not None:
        if len(values) != MINUTES_PER_DAY:
            raise ProfileError(
                f"{path}: profile of load {load!r} has {len(values)} values, "
                f"expected {MINUTES_PER_DAY}"
            )
        return fast
    out = np.empty(len(values))
    for i, token in enumerate(values):
        try:
            value = float(token)
        except ValueError:
            value = float("nan")
        line = first_line + i
        if not np.isfinite(value):
            raise ProfileError(f"{path}:{line}: load {load!r}: not a finite number: {token!r}")
        if value < 0:
            raise ProfileError(f"{path}:{line}: load {load!r}: negative value {token!r}")
        out[i] = value
    if len(values) != MINUTES_PER_DAY:
        raise ProfileError(
            f"{path}: profile of load {load!r} has {len(values)} values, expected {MINUTES_PER_DAY}"
        )
    return out


# -- OpenDSS form -------------------------------------------------------------------------------


def _read_opendss_form(root: Path, loads_txt: Path, inputs: Inputs) -> pd.DataFrame:
    loads = parse_statements(loads_txt, "Load", _LOAD_KEYS, ProfileError)
    if not loads:
        raise ProfileError(f"{loads_txt}: no Load statements")
    shapes_txt = inputs.add(find_file(root, "LoadShapes.txt", ProfileError), root)
    shapes: dict[str, Statement] | None = None
    if shapes_txt is not None:
        shapes = {
            s.name.lower(): s
            for s in parse_statements(shapes_txt, "Loadshape", _LOADSHAPE_KEYS, ProfileError)
        }
    columns: dict[str, np.ndarray] = {}
    cache: dict[Path, np.ndarray] = {}
    for load in loads:
        shape = load.params.get("yearly", load.params.get("daily"))
        if shape is None:
            raise load.fail(
                f"load {load.name!r} has no Yearly= or Daily= shape", load.name, ProfileError
            )
        scale = load.number("kw", ProfileError)
        if scale < 0:
            raise load.fail(f"load {load.name!r} has negative kW", f"kW={scale}", ProfileError)
        if shapes is not None:
            if shape.lower() not in shapes:
                raise load.fail(
                    f"load {load.name!r}: shape not defined in {shapes_txt}", shape, ProfileError
                )
            relative = _shape_file(shapes[shape.lower()])
        else:
            relative = f"Daily_1min_100profiles/load_profile_{_shape_number(load, shape)}.txt"
        path = find_file(root, relative, ProfileError)
        if path is None or not path.is_file():
            raise ProfileError(f"{root}: missing profile file {relative} for load {load.name!r}")
        inputs.add(path, root)
        if path not in cache:
            cache[path] = _read_mult_file(path, load.name)
        columns[load.name] = cache[path] * scale
    return _table(columns)


def _shape_number(statement: Statement, shape: str) -> int:
    match = _SHAPE_NUMBER.search(shape)
    if match is None:
        raise statement.fail("shape name does not end in a profile number", shape, ProfileError)
    return int(match.group(1))


def _shape_file(shape: Statement) -> str:
    """The multiplier file of a 1-minute, 1440-point ``Loadshape`` statement."""
    npts = shape.get("npts", ProfileError)
    if npts != str(MINUTES_PER_DAY):
        raise shape.fail(f"only npts={MINUTES_PER_DAY} is supported", f"npts={npts}", ProfileError)
    minutes = shape.params.get("minterval")
    if minutes is None or float(minutes) != 1.0 or {"sinterval", "interval"} & shape.params.keys():
        raise shape.fail("only minterval=1 is supported", shape.name, ProfileError)
    mult = shape.get("mult", ProfileError)
    match = re.fullmatch(r"\(\s*file\s*=\s*([^)]+?)\s*\)", mult, flags=re.IGNORECASE)
    if match is None:
        raise shape.fail("only mult=(file=NAME) is supported", f"mult={mult}", ProfileError)
    return match.group(1).strip("\"'")


def _read_mult_file(path: Path, load: str) -> np.ndarray:
    """One value per line; blank lines only at the end."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"cannot read profile file {path} of load {load!r}: {exc}") from None
    rows = text.rstrip().splitlines()  # blank lines at the end dropped
    fast = _fast_values(rows)
    if fast is not None and len(fast) == MINUTES_PER_DAY:
        return fast
    return _check_values([r.strip() for r in rows], path, load, 1)


# -- IEEE CSV form ------------------------------------------------------------------------------


def _csv_rows(path: Path, what: str) -> list[list[str]]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            return [[cell.strip() for cell in row] for row in csv.reader(handle)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ProfileError(f"cannot read {what} {path}: {exc}") from None


def _read_csv_form(root: Path, loads_csv: Path, inputs: Inputs) -> pd.DataFrame:
    rows = _csv_rows(loads_csv, "load table")
    header_at = next((i for i, row in enumerate(rows) if row and row[0].lower() == "name"), None)
    if header_at is None:
        raise ProfileError(f"{loads_csv}: no header row starting with 'Name'")
    header = [c.lower() for c in rows[header_at]]
    for needed in ("kw", "yearly"):
        if needed not in header:
            raise ProfileError(f"{loads_csv}:{header_at + 1}: header lacks column {needed!r}")
    i_kw, i_shape = header.index("kw"), header.index("yearly")
    profiles_dir = find_file(root, "Load Profiles", ProfileError)
    if profiles_dir is None or not profiles_dir.is_dir():
        raise ProfileError(f"{root}: missing folder 'Load Profiles' of the IEEE CSV form")
    columns: dict[str, np.ndarray] = {}
    for number, row in enumerate(rows[header_at + 1 :], start=header_at + 2):
        if not any(row):
            continue
        where = f"{loads_csv}:{number}"
        if len(row) != len(header):
            raise ProfileError(f"{where}: {len(row)} fields, header has {len(header)}: {row[0]!r}")
        name = row[0]
        if not name:
            raise ProfileError(f"{where}: empty load name")
        if name in columns:
            raise ProfileError(f"{where}: load {name!r} listed twice")
        try:
            scale = float(row[i_kw])
        except ValueError:
            scale = float("nan")
        if not np.isfinite(scale) or scale < 0:
            raise ProfileError(f"{where}: load {name!r} has invalid kW {row[i_kw]!r}")
        match = _SHAPE_NUMBER.search(row[i_shape])
        if match is None:
            raise ProfileError(f"{where}: load {name!r} has no profile number in {row[i_shape]!r}")
        relative = f"Load_profile_{int(match.group(1))}.csv"
        path = find_file(profiles_dir, relative, ProfileError)
        if path is None or not path.is_file():
            raise ProfileError(f"{profiles_dir}: missing profile file {relative} for load {name!r}")
        inputs.add(path, root)
        columns[name] = _read_profile_csv(path, name) * scale
    if not columns:
        raise ProfileError(f"{loads_csv}: no loads below the header")
    return _table(columns)


def _read_profile_csv(path: Path, load: str) -> np.ndarray:
    """A ``time,mult`` CSV: the header row holds a ``mult`` column; 1440 data rows follow."""
    rows = _csv_rows(path, "profile file")
    header_at = next((i for i, row in enumerate(rows) if "mult" in (c.lower() for c in row)), None)
    if header_at is None:
        raise ProfileError(f"{path}: no header row with a 'mult' column (load {load!r})")
    header = [c.lower() for c in rows[header_at]]
    column = header.index("mult")
    data = rows[header_at + 1 :]
    while data and not any(data[-1]):
        data.pop()
    for offset, row in enumerate(data):
        if len(row) != len(header):
            line = header_at + 2 + offset
            raise ProfileError(
                f"{path}:{line}: load {load!r}: {len(row)} fields, header has {len(header)}"
            )
    return _check_values([row[column] for row in data], path, load, header_at + 2)


# -- default and resolution ---------------------------------------------------------------------


def default_profiles() -> LoadProfiles:
    """The shipped offline default: synthetic 1-minute profiles (kW) of ``LOAD1``..``LOAD55``.

    Generated once by ``scripts/make_default_profiles.py`` with the CREST model (richardsonpy,
    a fixed seed), then all loads scaled by one common factor so the aggregate daily peak is
    57.358 kW (the official feeder's peak, below the paper fleet's 65 kW); stored rounded to 1 W.
    ``source`` is the file's first comment line, e.g.
    ``"synthetic default (richardsonpy CREST, seed 20240566, scaled to a 57.358 kW peak)"``.
    Kept in the on-disk cache like a profile folder (:func:`read_profiles`).
    """
    resource = resources.files("popdispatch") / "data" / DEFAULT_PROFILES_FILE
    try:
        with resources.as_file(resource) as path:
            # cached only where the file is installed as itself (not extracted from a zip)
            installed = Path(str(resource)).is_file()
            key = profiles_cache_key(Path(path).resolve()) if installed else None
            cached = _from_cache(key, with_source=True) if key is not None else None
            if cached is not None:
                return LoadProfiles(*cached)
            inputs = Inputs()
            inputs.add(Path(path).resolve())
            table = pd.read_csv(path, comment="#", index_col="minute")
            with gzip.open(path, "rt", encoding="ascii") as handle:
                source = handle.readline().lstrip("#").strip()
    except (OSError, ValueError) as exc:
        raise ProfileError(f"cannot read the shipped default profiles {resource}: {exc}") from None
    table.index = pd.RangeIndex(1, len(table) + 1, name="minute")
    table.columns.name = "load"
    profiles = LoadProfiles(table.astype(float), source)
    if key is not None:
        _save(key, profiles, inputs)
    return profiles


def resolve_profiles(folder: str | Path | None = None) -> LoadProfiles:
    """The profiles to use: ``folder`` if given, else ``$POPDISPATCH_PROFILES``, else the default.

    ``folder`` and the environment variable name a folder in a form :func:`read_profiles` reads;
    an empty environment variable counts as unset.
    """
    if folder is not None:
        return read_profiles(folder)
    env = os.environ.get(PROFILES_ENV, "").strip()
    if env:
        return read_profiles(env)
    return default_profiles()


def read_profile_file(path: Path, label: str) -> np.ndarray:
    """One official profile file (kW per minute, 1440 values): the OpenDSS form (one value per
    line) or the IEEE CSV form (a ``mult`` column), by suffix; ``label`` names it in errors."""
    read = _read_profile_csv if Path(path).suffix.lower() == ".csv" else _read_mult_file
    return read(Path(path), label)
