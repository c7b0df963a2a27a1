"""Any radial OpenDSS circuit, read through OpenDSSDirect.py (the optional ``opendss`` extra).

:func:`read_opendss_master` compiles a master file with OpenDSS itself and turns the circuit into
the plain-table :class:`~popdispatch.feeder.Feeder`: a positive-sequence single-line model.

Conversion rules
----------------
- **Buses**: one per OpenDSS bus (``Circuit.AllBusNames`` after ``MakeBusList``). A bus whose
  name is a canonical non-negative integer (``"1"``, ``"650"``; not ``"007"``) keeps that number
  as its id; the others (``sourcebus``, ``rg60``, ``814r``) get the next ids above the largest
  such number, in OpenDSS's bus order. The ``name`` column keeps the OpenDSS name,
  ``kv_ln_base`` its base voltage (kV line-to-neutral, 0 if the master sets none). A bus cut
  off from the source by an open switch is dropped (with a :class:`UserWarning` naming it) if
  nothing is connected to it; with a load or generator it is an error.
- **Lines** (``Line`` elements, enabled): ``length_km`` = ``Length`` x its ``Units`` in km
  (``none`` taken as km); ``r_ohm + j x_ohm`` = positive-sequence impedance per unit length x
  ``Length`` (ohm, whole line, then referred to the source: see *Impedance base*). The
  per-length value comes from OpenDSS's own phase matrices
  (``Lines.RMatrix``/``XMatrix``, ohm per line unit, whatever defined them: sequence values,
  line code matrices or a line geometry): Kron-reduced to the phase conductors, then
  ``Z1 = mean(diagonal) - mean(off-diagonal)`` (exactly ``R1 + j X1`` for sequence-defined
  lines); a line with fewer than three phases whose matrix is the one its ``R1/X1/R0/X0`` give
  uses ``R1 + j X1``, a one-phase matrix line its self impedance. (``Lines.R1`` alone is not
  used: OpenDSS leaves it at its default for matrix-defined lines.)
- **Switches** (``Switch=yes`` lines) are lines with ``kind = "switch"``. A line or switch with a
  terminal open on every phase (``open Line.X 1``) is removed; a partly open one is kept.
- **Transformers and regulators** are branches with ``length_km = 0`` and the series impedance
  ``z = (%R1 + %R2 kVA1/kVA2)/100 + j XHL/100`` per unit on the unit's own winding-1 rating,
  in ohm on the source's base: ``z V_LL^2 / MVA1`` for a three-phase unit and ``z V_LN^2 /
  MVA1`` (per phase) for a one-phase unit, with ``V`` the source bus's base voltage. One-phase
  units between the same two buses (a regulator bank such as ``reg1a/b/c``) are one branch named
  ``Transformer.reg1a+reg1b+reg1c`` with the mean of their impedances (a bank of equal units:
  the unit's). ``kind`` is ``"regulator"`` when a ``RegControl`` acts on a unit, else
  ``"transformer"``. Taps and off-nominal ratios are ignored. Three-winding transformers are
  refused.
- **Impedance base**: as in the pandapower reader, every ``r_ohm``/``x_ohm`` is in ohm referred
  to the base voltage of the source bus (its ``kv_ln_base``): a line whose from-bus base is
  ``V`` has its own ohmic impedance times ``(V_source / V)^2``; on a single-voltage feeder
  (the ELV rooted at bus 1) they are the lines' own ohms. Nominal ratios only; the engine's
  lossless DC flows use the topology and the limits, the impedances are for AC work.
- Any other series element (a two-terminal ``Reactor``, ``Capacitor``, ``AutoTrans``, ...)
  is refused with an error naming it; shunt capacitors and reactors are ignored (no active power).
- **Loads** (``Load`` elements, enabled): one row per OpenDSS load, index its name (OpenDSS
  lower-cases names), ``bus`` (int id), ``p_kw`` = ``Loads.kW`` (the load's total over its
  phases) and ``q_kvar`` = ``Loads.kvar``; load shapes and ``LoadMult`` are not applied.
- **Ratings** (``ratings=True``): a line's ``limit_kw`` = ``phases x V_LN x NormAmps`` with
  ``V_LN`` the from-bus base voltage (kV), i.e. ``sqrt(3) x V_LL x I`` for a three-phase line,
  at unity power factor. OpenDSS gives every line ``NormAmps = 400`` unless told otherwise and
  this reader cannot tell that default from a stated rating: pass ``ratings=False`` (all limits
  ``inf``) when the master states none. A transformer branch's limit is its winding-1 kVA
  (summed over a bank's units) in kW.
- **Base voltages**: OpenDSS's own (``Bus.kVBase``); when a bus has none, ``CalcVoltageBases``
  is run once (OpenDSS's default ``VoltageBases`` list applies if the master sets none).
- **Coordinates**: the circuit's bus coordinates (``BusCoords`` in the master) where present; a
  bus without any takes its nearest placed neighbour's towards the source. A circuit with none
  gets a schematic layout: ``y = -100 x depth`` from the source and ``x = 100 x`` leaf order.
- **Source**: the ``Vsource``'s bus (``sourcebus`` in most masters) unless ``root`` names
  another bus; the tree is then rooted there (the part between the two stays, as a branch).
- **Fleet**: OpenDSS ``Generator``, ``PVSystem`` and ``Storage`` elements have no cost data, so
  ``fleet`` is required: a DataFrame with the columns of
  :data:`~popdispatch.feeder.generators.FLEET_COLUMNS` whose ``bus`` holds OpenDSS bus names
  (an integer is read as the name it spells). A row whose ``bus`` is missing (NaN/None) and whose
  name is an OpenDSS generator (``g1`` or ``Generator.g1``) takes that element's bus; missing
  ``pmax_kw`` takes its rating (``kW``, PV ``Pmpp``, storage ``kWrated``) and ``pmin_kw`` 0.

Compiling
---------
The master is compiled as it is, in a private OpenDSS context (the process's working directory
and any circuit of the default OpenDSSDirect.py engine are untouched). It is compiled from a
temporary copy of the master and the files it redirects to only (a) when it contains commands
that write files into OpenDSS's data folder, i.e. the master's own folder (``Show``, ``Export``,
``Plot``, ``CloseDI``, ``Set Demand=true``, ...: they then write into the temporary folder,
which is deleted), or (b) when compiling it as it is fails. In the copy, file references are
made portable: ``\\`` separators and a file name differing only in case from an
existing file (``Daily_1min_100profiles\\Load_profile_1.txt`` for ``load_profile_1.txt``) are
replaced by the file's absolute path, and a ``Redirect``/``Compile`` of a file that does not exist
(the ELV's ``Monitors.txt``) is commented out. Every such change is listed in a
:class:`UserWarning`. The copy's own outputs (e.g. the ELV master's demand-interval files) go to the
temporary folder.
"""

from __future__ import annotations

import math
import os
import re
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.errors import FeederError, FleetError
from popdispatch.feeder.generators import FLEET_COLUMNS
from popdispatch.feeder.model import Feeder
from popdispatch.readers.opendss import find_file

#: OpenDSS length unit codes (``Lines.Units``) as km per unit; 0 (``none``) is taken as km.
KM_PER_DSS_UNIT = {
    0: 1.0, 1: 1.609344, 2: 0.3048, 3: 1.0, 4: 1e-3, 5: 0.3048e-3, 6: 0.0254e-3, 7: 1e-5, 8: 1e-6,
}  # fmt: skip

#: The rows of :func:`fleet_candidates`.
CANDIDATE_COLUMNS = ["element", "bus_name", "rating_kw"]

_EXTRA = "pip install popdispatch[opendss]"
_CANONICAL_INT = re.compile(r"0|[1-9][0-9]*")


def _opendss():
    """The ``opendssdirect`` module, or a clear error naming the extra."""
    try:
        import opendssdirect
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"reading OpenDSS master files needs OpenDSSDirect.py: {_EXTRA} ({exc})"
        ) from exc
    return opendssdirect


# --------------------------------------------------------------------------------------------
# Compiling


def compile_master(master_path: str | Path):
    """Compile ``master_path`` in a new OpenDSS context; returns ``(context, notes)``.

    ``notes`` lists the file references a temporary copy had to change (see the module
    docstring; empty when none). Raises :class:`FeederError` when OpenDSS cannot compile it.
    """
    path = Path(master_path)
    if not path.is_file():
        raise FeederError(f"OpenDSS master file {path} does not exist")
    dss = _opendss()
    with tempfile.TemporaryDirectory(prefix="popdispatch-dss-") as tmp:
        notes: list[str] = []
        writes: list[str] = []
        copy = _portable_copy(path.resolve(), Path(tmp), notes, {}, writes)
        first = None
        if not writes:
            ctx = _new_context(dss)
            try:
                ctx.Text.Command(f'compile "{path.resolve()}"')
                return ctx, []
            except Exception as exc:  # DSSException; its class lives in dss-python
                first = _one_line(exc)
            if not notes:
                raise FeederError(f"OpenDSS cannot compile {path}: {first}")
        ctx = _new_context(dss)
        cwd = os.getcwd()
        try:
            ctx.Text.Command(f'compile "{copy}"')
        except Exception as exc:
            before = f"{first}; nor its portable copy ({_summary(notes)})" if first else "its copy"
            raise FeederError(
                f"OpenDSS cannot compile {path}: {before}: {_one_line(exc)}"
            ) from None
        finally:
            os.chdir(cwd)
    return ctx, notes


def _summary(notes: list[str]) -> str:
    """The notes of a portable copy in one line: each kind of change once, with its count."""
    kinds: dict[str, list[str]] = {}
    for note in notes:
        kind = "commented out" if note.endswith("(no such file)") else note.split(":")[0]
        kinds.setdefault(kind, []).append(note)
    parts = []
    for group in kinds.values():
        more = f" (and {len(group) - 1} more like it)" if len(group) > 1 else ""
        parts.append(group[0] + more)
    return "; ".join(parts)


def _new_context(dss):
    ctx = dss.NewContext()
    ctx.Basic.AllowChangeDir(False)  # keep the process's working directory
    ctx.Basic.AllowForms(False)
    ctx.Basic.AllowEditor(False)
    return ctx


def _one_line(exc: Exception) -> str:
    return " ".join(str(exc).split())


_FILE_COMMAND = re.compile(
    r"^(\s*)(redirect|compile|buscoords|latlongcoords)(\s+)(\S.*?)\s*$", re.I
)
_FILE_KEY = re.compile(
    r"""((?:file|csvfile|sngfile|dblfile)\s*=\s*)("[^"]*"|'[^']*'|[^\s)\]]+)""", re.I
)
_COMMENT = re.compile(r"!|//")
#: Commands that write report or result files into OpenDSS's data folder.
_WRITES = re.compile(
    r"\s*(show|export|plot|closedi|save|dump|visualize|fileedit|sample)\b"
    r"|\s*set\b.*\b(demand|overloadreport|voltexcept|diverbose|keeplist)\s*=\s*[yt]",
    re.I,
)


def _resolve(folder: Path, raw: str) -> Path | None:
    name = raw.strip().strip("\"'")
    try:
        found = find_file(folder, name)
    except FeederError:
        return None
    return found if found is not None and found.is_file() else None


def _portable_copy(
    source: Path, tmp: Path, notes: list[str], done: dict[Path, Path], writes: list[str]
) -> Path:
    """Copy ``source`` (and the files it redirects to) into ``tmp`` with portable references;
    ``notes`` gets the changes, ``writes`` the commands that write output files."""
    if source in done:
        return done[source]
    target = tmp / f"{len(done)}_{source.name}"
    done[source] = target
    folder = source.parent
    out: list[str] = []
    in_block = False
    text = source.read_text(encoding="utf-8-sig", errors="replace")
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if in_block or stripped.startswith("/*"):
            in_block = "*/" not in stripped
            out.append(line)
            continue
        code = _COMMENT.split(line, maxsplit=1)[0]
        where = f"{source.name}:{number}"
        if _WRITES.match(code):
            writes.append(f"{where}: {stripped!r}")
        match = _FILE_COMMAND.match(code)
        if match:
            indent, command, _, raw = match.groups()
            found = _resolve(folder, raw)
            if found is None:
                if command.lower() in ("redirect", "compile"):
                    out.append(f"! popdispatch: file not found, neutralised: {line}")
                    notes.append(f"{where}: {stripped!r} commented out (no such file)")
                    continue
                out.append(line)
                continue
            if command.lower() in ("redirect", "compile"):
                new = _portable_copy(found, tmp, notes, done, writes)
                # Redirect, not compile: a nested compile would clear the circuit the same way.
                out.append(f'{indent}{command} "{new}"')
                if found != folder / raw.strip().strip("\"'"):
                    notes.append(f"{where}: {raw.strip()!r} read as {found}")
            else:
                out.append(f'{indent}{command} "{found}"')
                if found != folder / raw.strip().strip("\"'"):
                    notes.append(f"{where}: {raw.strip()!r} read as {found}")
            continue

        def portable(m: re.Match, where: str = where) -> str:
            raw = m.group(2)
            plain = raw.strip("\"'")
            if (folder / plain).is_file():
                return m.group(0)
            found = _resolve(folder, plain)
            if found is None:
                return m.group(0)
            notes.append(f"{where}: {plain!r} read as {found}")
            return f'{m.group(1)}"{found}"'

        if _FILE_KEY.search(code):
            line = _FILE_KEY.sub(portable, code) + line[len(code) :]
        out.append(line)
    target.write_text("\n".join(out) + "\n")
    return target


# --------------------------------------------------------------------------------------------
# Reading the circuit


def _bus(name: str) -> str:
    return name.split(".")[0].lower()


def bus_ids(names: list[str]) -> dict[str, int]:
    """Integer ids of OpenDSS bus names: canonical integers keep their number, the others get
    the next ids above the largest of them, in the given order (see the module docstring)."""
    ints = [int(n) for n in names if _CANONICAL_INT.fullmatch(n)]
    nxt = max(ints, default=0) + 1
    ids: dict[str, int] = {}
    for name in names:
        if _CANONICAL_INT.fullmatch(name):
            ids[name] = int(name)
        else:
            ids[name] = nxt
            nxt += 1
    return ids


def _kron(z: np.ndarray, n: int) -> np.ndarray:
    """Eliminate conductors beyond the first ``n`` (neutrals) from a series impedance matrix."""
    if z.shape[0] <= n:
        return z
    a, b, c, d = z[:n, :n], z[:n, n:], z[n:, :n], z[n:, n:]
    return a - b @ np.linalg.solve(d, c)


def _positive_sequence(ctx) -> complex:
    """Positive-sequence series impedance of the active line, ohm per line unit length."""
    lines = ctx.Lines
    n = lines.Phases()
    r, x = np.asarray(lines.RMatrix(), float), np.asarray(lines.XMatrix(), float)
    m = int(round(math.sqrt(len(r))))
    z = _kron((r + 1j * x).reshape(m, m), n)
    z1 = complex(lines.R1(), lines.X1())
    z0 = complex(lines.R0(), lines.X0())
    zs, zm = (2 * z1 + z0) / 3, (z0 - z1) / 3
    if n < 3:
        from_sequence = np.full((n, n), zm) + np.eye(n) * (zs - zm)
        if np.allclose(z, from_sequence, rtol=1e-6, atol=1e-12):
            return z1
    if n == 1:
        return complex(z[0, 0])
    diagonal = np.trace(z) / n
    off = (z.sum() - np.trace(z)) / (n * (n - 1))
    return complex(diagonal - off)


def _elements(ctx, cls) -> list[str]:
    names = cls.AllNames()
    return [] if names in ([], ["NONE"], ["none"]) else list(names)


def _open_terminal(ctx) -> bool:
    """True when a terminal of the active element is open on every phase."""
    element = ctx.CktElement
    phases = element.NumPhases()
    return any(
        all(element.IsOpen(term, phase) for phase in range(1, phases + 1))
        for term in range(1, element.NumTerminals() + 1)
    )


def _read_lines(ctx, ids: dict[str, int], kv: dict[str, float], ratings: bool) -> list[dict]:
    rows = []
    for name in _elements(ctx, ctx.Lines):
        ctx.Lines.Name(name)
        if not ctx.CktElement.Enabled() or _open_terminal(ctx):
            continue
        bus1, bus2 = _bus(ctx.Lines.Bus1()), _bus(ctx.Lines.Bus2())
        units = ctx.Lines.Units()
        if units not in KM_PER_DSS_UNIT:
            raise FeederError(f"Line.{name}: unsupported length unit code {units}")
        length = ctx.Lines.Length()
        z1 = _positive_sequence(ctx) * length
        phases = ctx.Lines.Phases()
        limit = phases * kv.get(bus1, 0.0) * ctx.Lines.NormAmps() if ratings else math.inf
        if ratings and not limit > 0:
            raise FeederError(
                f"Line.{name}: cannot convert NormAmps = {ctx.Lines.NormAmps()} A to kW: bus "
                f"{bus1!r} has no base voltage (set voltagebases, or ratings=False)"
            )
        rows.append({
            "line": name, "from_bus": ids[bus1], "to_bus": ids[bus2],
            "length_km": length * KM_PER_DSS_UNIT[units], "r_ohm": abs(z1.real),
            "x_ohm": abs(z1.imag), "limit_kw": limit,
            "kind": "switch" if ctx.Lines.IsSwitch() else "line",
            "_kv": kv.get(bus1, 0.0),  # ohm at this voltage: referred to the source's later
        })  # fmt: skip
    return rows


def _read_transformers(ctx, ids: dict[str, int], ratings: bool) -> list[dict]:
    regulated = set()
    for name in _elements(ctx, ctx.RegControls):
        ctx.RegControls.Name(name)
        regulated.add(ctx.RegControls.Transformer().lower())
    units: dict[tuple, list[dict]] = {}
    for name in _elements(ctx, ctx.Transformers):
        ctx.Transformers.Name(name)
        if not ctx.CktElement.Enabled() or _open_terminal(ctx):
            continue
        if ctx.Transformers.NumWindings() != 2:
            raise FeederError(
                f"Transformer.{name}: unsupported {ctx.Transformers.NumWindings()}-winding "
                "transformer (popdispatch reads two-winding transformers)"
            )
        buses = [_bus(b) for b in ctx.CktElement.BusNames()]
        xhl = ctx.Transformers.Xhl()
        ctx.Transformers.Wdg(1)
        kva1, r1 = ctx.Transformers.kVA(), ctx.Transformers.R()
        ctx.Transformers.Wdg(2)
        kva2, r2 = ctx.Transformers.kVA(), ctx.Transformers.R()
        one_phase = ctx.CktElement.NumPhases() == 1
        # ohm per (kV line-to-neutral)^2 of the voltage they are referred to: z_pu V_LL^2 / MVA
        # for a three-phase unit, z_pu V_LN^2 / MVA for a one-phase one (per phase)
        per_kv2 = (1.0 if one_phase else 3.0) * 1e3 / kva1
        unit = {
            "name": name, "buses": buses, "r": (r1 + r2 * kva1 / kva2) / 100 * per_kv2,
            "x": xhl / 100 * per_kv2, "kva": kva1, "reg": name.lower() in regulated,
        }  # fmt: skip
        key = (frozenset(buses),) if one_phase else (name,)
        units.setdefault(key, []).append(unit)
    rows = []
    for group in units.values():
        first = group[0]
        rows.append({
            "line": "Transformer." + "+".join(u["name"] for u in group),
            "from_bus": ids[first["buses"][0]], "to_bus": ids[first["buses"][1]],
            "length_km": 0.0, "r_ohm": float(np.mean([u["r"] for u in group])),
            "x_ohm": float(np.mean([u["x"] for u in group])),
            "limit_kw": float(sum(u["kva"] for u in group)) if ratings else math.inf,
            "kind": "regulator" if any(u["reg"] for u in group) else "transformer",
            "_kv": math.nan,  # r_ohm, x_ohm: ohm / kV^2 of the source's base, see the caller
        })  # fmt: skip
    return rows


def _check_other_series(ctx) -> None:
    """Refuse two-terminal power-delivery elements other than lines and transformers."""
    if not ctx.PDElements.First():
        return
    while True:
        element = ctx.CktElement.Name()
        cls = element.split(".")[0].lower()
        if cls not in ("line", "transformer") and ctx.CktElement.Enabled():
            buses = {_bus(b) for b in ctx.CktElement.BusNames()}
            if ctx.CktElement.NumTerminals() > 1 and len(buses) > 1:
                raise FeederError(
                    f"{element}: unsupported series element between buses {sorted(buses)} "
                    "(popdispatch reads lines, switches, transformers and regulators)"
                )
        if not ctx.PDElements.Next():
            return


def fleet_candidates(ctx) -> pd.DataFrame:
    """The compiled circuit's generators, PV systems and storage (no cost data): index element
    name (``Generator.g1``), columns ``bus_name`` and ``rating_kw``."""
    rows = []
    for cls, prefix, rating in (
        (ctx.Generators, "Generator", lambda: ctx.Generators.kW()),
        (ctx.PVsystems, "PVSystem", lambda: ctx.PVsystems.Pmpp()),
        (ctx.Storages, "Storage", lambda: _storage_rating(ctx)),
    ):  # fmt: skip
        for name in _elements(ctx, cls):
            cls.Name(name)
            if ctx.CktElement.Enabled():
                rows.append((f"{prefix}.{name}", _bus(ctx.CktElement.BusNames()[0]), rating()))
    table = pd.DataFrame(rows, columns=CANDIDATE_COLUMNS).set_index("element")
    return table


def _storage_rating(ctx) -> float:
    """The active storage element's ``kWrated`` (no dedicated getter in OpenDSSDirect.py)."""
    ctx.Text.Command(f"? {ctx.CktElement.Name()}.kWrated")
    try:
        return float(ctx.Text.Result())
    except (AttributeError, ValueError):  # pragma: no cover - old engines
        return math.nan


def _map_fleet(fleet: pd.DataFrame, ids: dict[str, int], candidates: pd.DataFrame) -> pd.DataFrame:
    missing = [c for c in FLEET_COLUMNS if c not in fleet.columns]
    if missing:
        raise FleetError(f"fleet table lacks column {missing[0]!r} (needs {FLEET_COLUMNS})")
    table = fleet.copy()
    by_name = {e.lower(): e for e in candidates.index}
    by_name.update({e.split(".", 1)[1].lower(): e for e in candidates.index})
    buses = []
    for generator, row in table.iterrows():
        element = by_name.get(str(generator).lower())
        bus = row["bus"]
        if bus is None or (np.ndim(bus) == 0 and pd.isna(bus)):
            if element is None:
                raise FleetError(
                    f"generator {generator!r} has no bus and is no OpenDSS generator "
                    f"(known: {sorted(candidates.index) or 'none'})"
                )
            bus = candidates.loc[element, "bus_name"]
        if isinstance(bus, float) and bus.is_integer():
            bus = int(bus)
        key = str(bus).strip().lower()
        if key not in ids:
            raise FleetError(f"generator {generator!r} is on unknown OpenDSS bus {bus!r}")
        buses.append(ids[key])
        if element is not None:
            if pd.isna(row["pmax_kw"]):
                table.loc[generator, "pmax_kw"] = candidates.loc[element, "rating_kw"]
            if pd.isna(row["pmin_kw"]):
                table.loc[generator, "pmin_kw"] = 0.0
    table["bus"] = np.array(buses, dtype=np.int64)
    for column in ("a", "b", "c", "pmin_kw", "pmax_kw"):
        table[column] = pd.to_numeric(table[column], errors="raise").astype(float)
    table.index.name = "generator"
    return table


def _layout(
    names: list[str], parent: dict[str, str | None], order: list[str], coords: dict
) -> dict[str, tuple[float, float]]:
    """Coordinates per bus (see the module docstring); ``order`` is a pre-order from the root."""
    if coords:
        placed = dict(coords)
        root = order[0]
        if root not in placed:
            placed[root] = next(coords[b] for b in order if b in coords)
        for bus in order:
            if bus not in placed:
                placed[bus] = placed[parent[bus]]
        return placed
    children: dict[str, list[str]] = {b: [] for b in names}
    for bus in order[1:]:
        children[parent[bus]].append(bus)
    depth = {order[0]: 0}
    for bus in order[1:]:
        depth[bus] = depth[parent[bus]] + 1
    x: dict[str, float] = {}
    leaf = 0
    for bus in reversed(order):  # children before parents
        if children[bus]:
            x[bus] = min(x[c] for c in children[bus])
        else:
            x[bus] = float(leaf)
            leaf += 1
    return {b: (100.0 * x[b], -100.0 * depth[b] + 0.0) for b in order}


def read_opendss_master(
    master_path: str | Path,
    *,
    fleet: pd.DataFrame | None = None,
    root: str | int | None = None,
    ratings: bool = True,
    name: str | None = None,
) -> Feeder:
    """Read the radial circuit of an OpenDSS master file as a :class:`Feeder`.

    Parameters
    ----------
    master_path : the master ``.dss`` file (compiled by OpenDSS; see the module docstring).
    fleet : the generator table (columns ``bus, a, b, c, pmin_kw, pmax_kw``, ``bus`` = OpenDSS
        bus name; required: OpenDSS has no cost data).
    root : the source bus (OpenDSS bus name, or an int spelling it); default the Vsource's bus.
    ratings : line limits from ``NormAmps`` and transformer limits from kVA (else ``inf``).
    name : the feeder's case name; default the OpenDSS circuit's name.

    Conversion rules: see :mod:`popdispatch.readers.opendss_direct`.
    """
    ctx, notes = compile_master(master_path)
    if notes:
        warnings.warn(
            f"{master_path}: compiled from a portable copy: {_summary(notes)}",
            UserWarning,
            stacklevel=2,
        )
    circuit = ctx.Circuit.Name()
    ctx.Text.Command("makebuslist")  # buses of elements defined after the master's last solve
    names = [b.lower() for b in ctx.Circuit.AllBusNames()]
    if not names:
        raise FeederError(f"{master_path}: the OpenDSS circuit {circuit!r} has no bus")
    ids = bus_ids(names)
    kv = _base_voltages(ctx, names)
    _check_other_series(ctx)
    branches = _read_lines(ctx, ids, kv, ratings) + _read_transformers(ctx, ids, ratings)
    if not branches:
        raise FeederError(f"{master_path}: the OpenDSS circuit {circuit!r} has no line")

    loads = []
    for load in _elements(ctx, ctx.Loads):
        ctx.Loads.Name(load)
        if ctx.CktElement.Enabled():
            bus = _bus(ctx.CktElement.BusNames()[0])
            loads.append((load, ids[bus], ctx.Loads.kW(), ctx.Loads.kvar()))
    candidates = fleet_candidates(ctx)

    source = _source(ctx, root, ids, master_path)
    name_of = {v: k for k, v in ids.items()}
    lines = pd.DataFrame(branches).set_index("line")
    parent, order = _tree_order(lines, name_of, source)
    occupied = {name_of[b] for _, b, _, _ in loads} | set(candidates.bus_name)
    island = [b for b in names if b not in parent]
    for bus in island:
        if bus in occupied:
            raise FeederError(
                f"{master_path}: bus {bus!r} is not connected to source bus {name_of[source]!r} "
                "but has a load or generator: feeder is disconnected"
            )
    if island:
        warnings.warn(
            f"{master_path}: dropped {len(island)} bus(es) cut off from the source, with nothing "
            f"connected: {island[:10]}",
            UserWarning,
            stacklevel=2,
        )
        keep_ids = {ids[b] for b in names if b in parent}
        lines = lines[lines.from_bus.isin(keep_ids) & lines.to_bus.isin(keep_ids)]
    kept = [b for b in names if b in parent]
    lines = _refer_to_source(lines, kv[name_of[source]], name_of, master_path)

    coords = {}
    for bus in kept:
        ctx.Circuit.SetActiveBus(bus)
        if ctx.Bus.Coorddefined():
            coords[bus] = (ctx.Bus.X(), ctx.Bus.Y())
    xy = _layout(kept, parent, order, coords)
    buses = pd.DataFrame(
        {
            "x": [xy[b][0] for b in kept],
            "y": [xy[b][1] for b in kept],
            "name": kept,
            "kv_ln_base": [kv.get(b, 0.0) for b in kept],
        },
        index=pd.Index([ids[b] for b in kept], name="bus", dtype=np.int64),
    )
    load_table = pd.DataFrame(
        {
            "bus": np.array([b for _, b, _, _ in loads], dtype=np.int64),
            "p_kw": np.array([p for _, _, p, _ in loads], dtype=float),
            "q_kvar": np.array([q for _, _, _, q in loads], dtype=float),
        },
        index=pd.Index([n for n, _, _, _ in loads], name="load", dtype=object),
    )
    if fleet is None:
        if len(candidates):
            listed = ", ".join(f"{e} (bus {b})" for e, b in candidates.bus_name.items())
            raise FleetError(
                f"{master_path}: OpenDSS generators have no cost data: give fleet= (columns "
                f"{', '.join(FLEET_COLUMNS)}; bus = OpenDSS bus name); candidates: {listed}"
            )
        raise FleetError(
            f"{master_path}: the circuit has no generator: give fleet= (columns "
            f"{', '.join(FLEET_COLUMNS)}; bus = OpenDSS bus name)"
        )
    generators = _map_fleet(fleet, ids, candidates)
    lines.index.name = "line"
    lines = lines.astype({"from_bus": np.int64, "to_bus": np.int64})
    return Feeder(name or circuit, buses, lines, load_table, source, generators)


def _refer_to_source(
    lines: pd.DataFrame, kv_source: float, name_of: dict[int, str], master_path
) -> pd.DataFrame:
    """Impedances in ohm referred to the source bus's base voltage (see the module docstring)."""
    if not kv_source > 0:
        raise FeederError(f"{master_path}: the source bus has no base voltage (set voltagebases)")
    line_kv = lines["_kv"].to_numpy(float)
    transformer = np.isnan(line_kv)
    bad = ~transformer & ~(line_kv > 0)
    if bad.any():
        name = lines.index[bad][0]
        raise FeederError(
            f"{master_path}: line {name!r}: bus {name_of[lines.loc[name, 'from_bus']]!r} has no "
            "base voltage to refer its impedance to the source's (set voltagebases)"
        )
    scale = np.where(transformer, kv_source**2, (kv_source / np.where(bad, 1.0, line_kv)) ** 2)
    lines = lines.drop(columns="_kv")
    lines["r_ohm"] = lines["r_ohm"].to_numpy(float) * scale
    lines["x_ohm"] = lines["x_ohm"].to_numpy(float) * scale
    return lines


def _kv(ctx, bus: str) -> float:
    ctx.Circuit.SetActiveBus(bus)
    return float(ctx.Bus.kVBase())


def _base_voltages(ctx, names: list[str]) -> dict[str, float]:
    kv = {b: _kv(ctx, b) for b in names}
    if any(v <= 0 for v in kv.values()):
        ctx.Text.Command("calcvoltagebases")
        kv = {b: _kv(ctx, b) for b in names}
    return kv


def _source(ctx, root, ids: dict[str, int], master_path) -> int:
    if root is not None:
        key = str(root).strip().lower()
        if key not in ids:
            raise FeederError(f"{master_path}: root bus {root!r} is not an OpenDSS bus")
        return ids[key]
    sources = []
    for vsource in _elements(ctx, ctx.Vsources):
        ctx.Vsources.Name(vsource)
        if ctx.CktElement.Enabled():
            sources.append((vsource, _bus(ctx.CktElement.BusNames()[0])))
    buses = sorted({b for _, b in sources})
    if len(buses) != 1:
        raise FeederError(
            f"{master_path}: {len(buses)} source buses ({', '.join(buses) or 'no Vsource'}): "
            "give root= to pick the radial feeder's source bus"
        )
    return ids[buses[0]]


def _tree_order(
    lines: pd.DataFrame, name_of: dict[int, str], source: int
) -> tuple[dict[str, str | None], list[str]]:
    """Parent bus name per bus reached from the source, and a pre-order (loops are left to
    the Feeder's own check, which names them)."""
    adjacent: dict[int, list[int]] = {}
    for a, b in zip(lines.from_bus.tolist(), lines.to_bus.tolist(), strict=True):
        adjacent.setdefault(a, []).append(b)
        adjacent.setdefault(b, []).append(a)
    parent: dict[str, str | None] = {name_of[source]: None}
    order = []
    stack = [source]
    while stack:
        bus = stack.pop()
        order.append(name_of[bus])
        for other in adjacent.get(bus, []):
            if name_of[other] not in parent:
                parent[name_of[other]] = name_of[bus]
                stack.append(other)
    return parent, order


__all__ = ["compile_master", "fleet_candidates", "read_opendss_master"]
