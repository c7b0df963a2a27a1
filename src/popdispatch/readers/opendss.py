"""A small, strict reader of the IEEE European LV Test Feeder's OpenDSS files.

It reads exactly the statements that feeder uses and nothing else:

- ``LineCode.txt``: ``New LineCode.NAME nphases= R1= X1= R0= X0= C1= C0= Units=km``,
- ``Lines.txt``: ``New Line.NAME Bus1= Bus2= phases= Linecode= Length= Units=m``,
- ``Loads.txt``: ``New Load.NAME Phases= Bus1=34.1 kV= kW= PF= Yearly=``/``Daily=``,
- ``Buscoords.txt``: ``bus x y`` separated by tabs, spaces or commas,
- ``Transformers.txt`` (optional): ``New Transformer.NAME Buses=[HV LV] kVs=[..] ...``; the
  source of the radial feeder is the transformer's lowest-voltage bus (bus 1 without the file).

Keys are case-insensitive, file names are matched case-insensitively, CRLF line ends and ``!`` or
``//`` comments are accepted. Anything else raises :class:`~popdispatch.errors.FeederError` with a
one-line message naming the file, the line number and the offending token.

Why not OpenDSSDirect.py: its engine cannot open the load shapes of the distribution on a
case-sensitive file system (``LoadShapes.txt`` names ``Daily_1min_100profiles\\Load_profile_n.txt``
while the files are ``load_profile_n.txt``), so ``Loads.txt`` then fails on the missing shapes;
it also lower-cases every element name (``load1``). See the tests for a cross-check against it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.errors import FeederError, PopdispatchError
from popdispatch.feeder.generators import paper_fleet
from popdispatch.feeder.model import Feeder

#: Length units accepted in ``Units=``, as km per unit.
KM_PER_UNIT = {"km": 1.0, "m": 1e-3, "cm": 1e-5, "ft": 0.3048e-3, "kft": 0.3048, "mi": 1.609344}

_LINECODE_KEYS = {"nphases", "r1", "x1", "r0", "x0", "c1", "c0", "units", "basefreq", "normamps"}
_LINE_KEYS = {"bus1", "bus2", "phases", "linecode", "length", "units"}
_LOAD_KEYS = {
    "phases", "bus1", "kv", "kw", "pf", "kvar", "yearly", "daily", "duty", "model", "conn",
    "status", "vminpu", "vmaxpu",
}  # fmt: skip
_TRANSFORMER_KEYS = {
    "phases", "windings", "buses", "conns", "kvs", "kvas", "xhl", "xht", "xlt", "%r", "%rs",
    "%loadloss", "%noloadloss", "sub", "tap", "taps",
}  # fmt: skip

_TOKEN = re.compile(r"""\s*([^\s=]+)=(\[[^\]]*\]|\([^)]*\)|"[^"]*"|'[^']*'|[^\s\[\]()"']+)""")


@dataclass(frozen=True)
class Statement:
    """One ``New Class.Name key=value ...`` statement of an OpenDSS file.

    ``params`` maps lower-case keys to raw values (brackets/quotes kept); ``path`` and ``line``
    locate it (1-based line number) for error messages.
    """

    cls: str
    name: str
    params: dict[str, str]
    path: Path
    line: int

    def fail(
        self, message: str, token: str, error: type[PopdispatchError] = FeederError
    ) -> PopdispatchError:
        """An error naming this statement's file, line and the offending token."""
        return error(f"{self.path}:{self.line}: {message}: {token!r}")

    def get(self, key: str, error: type[PopdispatchError] = FeederError) -> str:
        """The value of a required key."""
        if key not in self.params:
            raise self.fail(
                f"{self.cls}.{self.name} lacks {key}=", f"New {self.cls}.{self.name}", error
            )
        return self.params[key]

    def number(self, key: str, error: type[PopdispatchError] = FeederError) -> float:
        """A required finite numeric value."""
        raw = self.get(key, error)
        try:
            value = float(raw)
        except ValueError:
            value = float("nan")
        if not np.isfinite(value):
            raise self.fail(f"{key}= is not a finite number", f"{key}={raw}", error)
        return value


def find_file(folder: Path, name: str, error: type[PopdispatchError] = FeederError) -> Path | None:
    """The file ``name`` (may contain ``/`` or ``\\``) below ``folder``, matched case-insensitively.

    Returns ``None`` when absent; raises ``error`` when several files match ambiguously.
    """
    current = folder
    for part in re.split(r"[\\/]", name):
        if part in ("", "."):
            continue
        exact = current / part
        if exact.exists():
            current = exact
            continue
        if not current.is_dir():
            return None
        matches = [p for p in current.iterdir() if p.name.lower() == part.lower()]
        if not matches:
            return None
        if len(matches) > 1:
            raise error(
                f"{current}: {part!r} matches several files: {sorted(p.name for p in matches)}"
            )
        current = matches[0]
    return current


def _lines(path: Path, error: type[PopdispatchError]) -> Iterator[tuple[int, str]]:
    """Non-blank, comment-free lines of a text file with their 1-based numbers."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"cannot read {path}: {exc}") from None
    for number, raw in enumerate(text.splitlines(), start=1):
        line = re.split(r"!|//", raw, maxsplit=1)[0].strip()
        if line:
            yield number, line


def parse_statements(
    path: Path,
    cls: str,
    keys: set[str],
    error: type[PopdispatchError] = FeederError,
) -> list[Statement]:
    """Parse a file of ``New <cls>.NAME key=value ...`` statements with keys from ``keys``.

    Raises ``error`` (file, line, token) on any other statement, class, key or syntax, and on
    a name defined twice (names compare case-insensitively, as in OpenDSS).
    """
    statements: list[Statement] = []
    seen: dict[str, int] = {}
    for number, line in _lines(path, error):
        where = f"{path}:{number}"
        parts = line.split(maxsplit=2) + ["", ""]
        head, target, rest = parts[0], parts[1], parts[2]
        if head.lower() != "new":
            raise error(f"{where}: expected a 'New {cls}.NAME' statement: {head!r}")
        kind, dot, name = target.partition(".")
        if not dot or kind.lower() != cls.lower() or not name or "=" in target:
            raise error(f"{where}: expected '{cls}.NAME' after New: {target!r}")
        params: dict[str, str] = {}
        position = 0
        while position < len(rest):
            match = _TOKEN.match(rest, position)
            if match is None:
                token = rest[position:].split()[0]
                raise error(f"{where}: not a key=value token: {token!r}")
            key, value = match.group(1).lower(), match.group(2)
            if key not in keys:
                raise error(f"{where}: unsupported {cls} property: {match.group(0).strip()!r}")
            if key in params:
                raise error(f"{where}: property given twice: {match.group(0).strip()!r}")
            params[key] = value
            position = match.end()
            if position < len(rest) and not rest[position].isspace():
                raise error(f"{where}: not a key=value token: {rest[match.start() :].split()[0]!r}")
        if name.lower() in seen:
            raise error(
                f"{where}: {cls}.{name} already defined on line {seen[name.lower()]}: {name!r}"
            )
        seen[name.lower()] = number
        statements.append(Statement(cls, name, params, path, number))
    return statements


def _bus_id(statement: Statement, key: str, known: set[int] | None) -> int:
    """Integer bus id of ``Bus1=34.1`` style values (phase suffixes dropped)."""
    raw = statement.get(key)
    head = raw.split(".")[0]
    if not re.fullmatch(r"\d+", head) or not re.fullmatch(r"\d+(\.\d+)*", raw):
        raise statement.fail(
            "bus is not an integer id with optional .phase suffixes", f"{key}={raw}"
        )
    bus = int(head)
    if known is not None and bus not in known:
        raise statement.fail("bus has no coordinates in Buscoords.txt", f"{key}={raw}")
    return bus


def _units(statement: Statement) -> float:
    raw = statement.get("units")
    factor = KM_PER_UNIT.get(raw.lower())
    if factor is None:
        raise statement.fail(f"unsupported Units (known: {', '.join(KM_PER_UNIT)})", f"units={raw}")
    return factor


def _required(folder: Path, name: str) -> Path:
    path = find_file(folder, name)
    if path is None or not path.is_file():
        raise FeederError(f"{folder}: missing OpenDSS file {name}")
    return path


def read_bus_coords(path: Path) -> pd.DataFrame:
    """Read ``bus x y`` rows; index ``bus`` (int), columns ``x``, ``y`` (m)."""
    ids: list[int] = []
    xy: list[tuple[float, float]] = []
    seen: dict[int, int] = {}
    for number, line in _lines(path, FeederError):
        fields = [f for f in re.split(r"[\s,]+", line) if f]
        where = f"{path}:{number}"
        if len(fields) != 3:
            raise FeederError(f"{where}: expected 'bus x y', got {len(fields)} fields: {line!r}")
        if not re.fullmatch(r"\d+", fields[0]):
            raise FeederError(f"{where}: bus is not an integer id: {fields[0]!r}")
        bus = int(fields[0])
        if bus in seen:
            raise FeederError(f"{where}: bus {bus} already on line {seen[bus]}: {fields[0]!r}")
        seen[bus] = number
        coords = []
        for token in fields[1:]:
            try:
                value = float(token)
            except ValueError:
                value = float("nan")
            if not np.isfinite(value):
                raise FeederError(f"{where}: coordinate is not a finite number: {token!r}")
            coords.append(value)
        ids.append(bus)
        xy.append((coords[0], coords[1]))
    if not ids:
        raise FeederError(f"{path}: no bus coordinates")
    table = np.array(xy, dtype=float)
    return pd.DataFrame({"x": table[:, 0], "y": table[:, 1]}, index=pd.Index(ids, name="bus"))


def _source_bus(folder: Path, buses: set[int]) -> int:
    path = find_file(folder, "Transformers.txt")
    if path is None:
        return 1
    transformers = parse_statements(path, "Transformer", _TRANSFORMER_KEYS)
    if len(transformers) != 1:
        raise FeederError(f"{path}: expected exactly one transformer, found {len(transformers)}")
    tr = transformers[0]
    raw = tr.get("buses")
    names = raw.strip("[]()\"'").replace(",", " ").split()
    kvs_raw = tr.params.get("kvs")
    if kvs_raw is not None:
        try:
            kvs = [float(v) for v in kvs_raw.strip("[]()\"'").replace(",", " ").split()]
        except ValueError:
            raise tr.fail("kVs= is not a list of numbers", f"kVs={kvs_raw}") from None
        if len(kvs) != len(names):
            raise tr.fail("kVs= and Buses= differ in length", f"kVs={kvs_raw}")
        lv = names[int(np.argmin(kvs))]
    else:
        lv = names[-1]
    head = lv.split(".")[0]
    if not re.fullmatch(r"\d+", head) or int(head) not in buses:
        raise tr.fail("low-voltage bus is not a bus of Buscoords.txt", f"Buses={raw}")
    return int(head)


def read_opendss_feeder(
    folder: str | Path,
    name: str = "ieee-elv",
    generators: pd.DataFrame | None = None,
) -> Feeder:
    """Read the IEEE European LV Test Feeder from its OpenDSS files in ``folder``.

    Parameters
    ----------
    folder : the folder holding ``Lines.txt``, ``LineCode.txt``, ``Loads.txt``, ``Buscoords.txt``
        and optionally ``Transformers.txt`` (names matched case-insensitively).
    name : the feeder's case name.
    generators : the fleet; the paper's Table I (:func:`~popdispatch.feeder.paper_fleet`) if None.

    Returns
    -------
    The same :class:`~popdispatch.feeder.Feeder` as :func:`popdispatch.feeder.ieee_elv`: buses by
    their integer ids with ``x``, ``y`` (m) from ``Buscoords.txt``; lines by name with lengths in
    km (``Length`` x ``Units``) and ``r_ohm``/``x_ohm`` = positive-sequence ``R1``/``X1`` (ohm per
    line-code unit) x length (ohm, whole line), ``limit_kw = inf``; loads by name (as spelled in
    ``Loads.txt``, e.g. ``LOAD1``) with their bus; source bus = transformer LV bus (else 1).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FeederError(f"OpenDSS feeder folder {folder} does not exist or is not a folder")
    buses = read_bus_coords(_required(folder, "Buscoords.txt"))
    known = set(buses.index)

    codes: dict[str, tuple[float, float]] = {}
    for code in parse_statements(_required(folder, "LineCode.txt"), "LineCode", _LINECODE_KEYS):
        per_km = 1.0 / _units(code)
        codes[code.name.lower()] = (code.number("r1") * per_km, code.number("x1") * per_km)

    rows = []
    lines_path = _required(folder, "Lines.txt")
    for line in parse_statements(lines_path, "Line", _LINE_KEYS):
        code = line.get("linecode")
        if code.lower() not in codes:
            raise line.fail("unknown line code (not in LineCode.txt)", f"Linecode={code}")
        length_km = line.number("length") * _units(line)
        if length_km < 0:
            raise line.fail("negative length", f"Length={line.get('length')}")
        r_km, x_km = codes[code.lower()]
        rows.append(
            (line.name, _bus_id(line, "bus1", known), _bus_id(line, "bus2", known), length_km,
             r_km * length_km, x_km * length_km)
        )  # fmt: skip
    if not rows:
        raise FeederError(f"{lines_path}: no Line statements")
    names, from_bus, to_bus, length, r, x = zip(*rows, strict=True)
    lines = pd.DataFrame(
        {
            "from_bus": np.array(from_bus, dtype=np.int64),
            "to_bus": np.array(to_bus, dtype=np.int64),
            "length_km": np.array(length, dtype=float),
            "r_ohm": np.array(r, dtype=float),
            "x_ohm": np.array(x, dtype=float),
            "limit_kw": np.inf,
        },
        index=pd.Index(list(names), name="line"),
    )

    loads_path = _required(folder, "Loads.txt")
    load_rows = [
        (load.name, _bus_id(load, "bus1", known))
        for load in parse_statements(loads_path, "Load", _LOAD_KEYS)
    ]
    loads = pd.DataFrame(
        {"bus": np.array([b for _, b in load_rows], dtype=np.int64)},
        index=pd.Index([n for n, _ in load_rows], name="load"),
    )
    source = _source_bus(folder, known)
    fleet = paper_fleet() if generators is None else generators
    return Feeder(name, buses, lines, loads, source, fleet)
