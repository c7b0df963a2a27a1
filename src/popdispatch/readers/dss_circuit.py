"""A compiled OpenDSS circuit as plain rows: buses, branches, loads, fixed injections, sources
and load shapes (read by :mod:`popdispatch.readers.opendss_direct`, whose docstring states the
conversion rules).

Everything is read while the OpenDSS context is alive and returned as Python and numpy values
in a :class:`Circuit`; nothing here builds the :class:`~popdispatch.feeder.model.Feeder`.
Branch impedances are each branch's own ohms, on the voltage base ``kv_base`` (line-to-line kV)
of its first bus.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from popdispatch.errors import FeederError

SQRT3 = math.sqrt(3.0)

#: OpenDSS length unit codes (``Lines.Units``) as km per unit; 0 (``none``) is taken as km.
KM_PER_DSS_UNIT = {
    0: 1.0, 1: 1.609344, 2: 0.3048, 3: 1.0, 4: 1e-3, 5: 0.3048e-3, 6: 0.0254e-3, 7: 1e-5, 8: 1e-6,
}  # fmt: skip
#: Power-delivery classes read as branches; every other two-bus one is refused by name.
BRANCH_CLASSES = frozenset({"line", "transformer", "reactor", "capacitor"})
#: Classes whose elements sit on one bus (or none): loads, sources, generators, meters and
#: controls; any other class with two buses is a series element to read or refuse.
ONE_BUS_CLASSES = frozenset({
    "load", "generator", "pvsystem", "storage", "vsource", "isource", "windgen",
    "energymeter", "monitor", "sensor", "capcontrol", "regcontrol", "invcontrol",
    "expcontrol", "storagecontroller", "fuse", "recloser", "relay", "swtcontrol",
    "gencontroller", "upfccontrol", "esppvcontrol", "gicsource", "fmonitor", "vccs",
})  # fmt: skip


@dataclass
class Branch:
    """One series element: buses by OpenDSS name, own ohms on ``kv_base`` (line-to-line kV)."""

    name: str
    bus_a: str
    bus_b: str
    length_km: float
    r_ohm: float
    x_ohm: float
    kv_base: float
    limit_kw: float
    kind: str
    elements: tuple[str, ...] = ()


@dataclass
class Shape:
    """A load shape: ``mult`` per point, ``hours`` per point, ``use_actual`` (values in kW)."""

    mult: np.ndarray
    hours: float
    use_actual: bool


@dataclass
class Circuit:
    """What the reader needs of a compiled circuit (see the module docstring).

    ``loads`` and ``injections`` are rows ``(name, bus, kW, kvar, kind, daily, yearly, duty)``
    (``injections``: OpenDSS generators and PV systems, kW produced); ``sources`` the
    ``Vsource`` buses; ``kv`` every bus's base voltage, line-to-neutral kV.
    """

    name: str
    buses: list[str]
    kv: dict[str, float]
    coords: dict[str, tuple[float, float]]
    branches: list[Branch]
    loads: list[tuple]
    injections: list[tuple]
    storage: list[tuple]
    sources: list[str]
    shapes: dict[str, Shape] = field(default_factory=dict)
    merged: dict[str, list[str]] = field(default_factory=dict)  # parallel branches, by the reader


def bus_of(name: str) -> str:
    """The bus of an OpenDSS terminal spec, lower case (``650.1.2`` -> ``650``)."""
    return name.split(".")[0].lower()


def elements(cls) -> list[str]:
    """Names of an OpenDSSDirect.py class's elements ([] for none)."""
    names = cls.AllNames()
    return [] if names in ([], ["NONE"], ["none"]) else list(names)


def each(cls):
    """Iterate over a class's elements, each the active one in turn (faster than by name)."""
    more = cls.First()
    while more:
        yield cls.Name()
        more = cls.Next()


def read_circuit(ctx, ratings: bool) -> Circuit:
    """The compiled circuit of ``ctx`` as a :class:`Circuit` (``ratings``: limits from
    ``NormAmps`` and kVA, else ``inf``)."""
    ctx.Text.Command("makebuslist")  # buses of elements defined after the last solve
    names = [b.lower() for b in ctx.Circuit.AllBusNames()]
    if not names:
        raise FeederError(f"the OpenDSS circuit {ctx.Circuit.Name()!r} has no bus")
    kv = _base_voltages(ctx, names)
    _check_other_series(ctx)
    branches = (
        _lines(ctx, kv, ratings)
        + _transformers(ctx, kv, ratings)
        + _series_shunts(ctx, kv, ratings)
    )
    for branch in branches:  # three-winding transformers' star points: buses of their own
        if branch.bus_b.endswith(".star") and branch.bus_b not in kv:
            names.append(branch.bus_b)
            kv[branch.bus_b] = branch.kv_base / SQRT3
    coords = {}
    for bus in names:
        if bus.endswith(".star"):
            continue
        ctx.Circuit.SetActiveBus(bus)
        if ctx.Bus.Coorddefined():
            coords[bus] = (float(ctx.Bus.X()), float(ctx.Bus.Y()))
    loads, injections, storage = _loads(ctx), _injections(ctx), _storage(ctx)
    used = {shape for row in loads + injections for shape in row[5:] if shape}
    return Circuit(
        name=ctx.Circuit.Name(), buses=names, kv=kv, coords=coords, branches=branches,
        loads=loads, injections=injections, storage=storage, sources=_sources(ctx),
        shapes=_shapes(ctx, used),
    )  # fmt: skip


# -- buses ------------------------------------------------------------------------------------


def _kv(ctx, bus: str) -> float:
    ctx.Circuit.SetActiveBus(bus)
    return float(ctx.Bus.kVBase())


def _base_voltages(ctx, names: list[str]) -> dict[str, float]:
    """Line-to-neutral base voltage per bus (kV): OpenDSS's own, ``CalcVoltageBases`` once
    where some bus has none."""
    kv = {b: _kv(ctx, b) for b in names}
    if any(v <= 0 for v in kv.values()):
        ctx.Text.Command("calcvoltagebases")
        kv = {b: _kv(ctx, b) for b in names}
    return kv


def _sources(ctx) -> list[str]:
    buses = []
    for name in elements(ctx.Vsources):
        ctx.Vsources.Name(name)
        if ctx.CktElement.Enabled():
            buses.append(bus_of(ctx.CktElement.BusNames()[0]))
    return sorted(set(buses), key=buses.index)


# -- branches ---------------------------------------------------------------------------------


def _open_terminal(ctx) -> bool:
    """True when a terminal of the active element is open on every phase."""
    element = ctx.CktElement
    phases = element.NumPhases()
    return any(
        all(element.IsOpen(term, phase) for phase in range(1, phases + 1))
        for term in range(1, element.NumTerminals() + 1)
    )


def _skipped(ctx) -> bool:
    """Whether the active element is not part of the network: disabled, or open on a whole
    terminal (``Open``, or a fuse, recloser, relay or switch control holding it open: OpenDSS
    opens the terminals of the element they switch)."""
    return not ctx.CktElement.Enabled() or _open_terminal(ctx)


def _kron(z: np.ndarray, n: int) -> np.ndarray:
    """Eliminate conductors beyond the first ``n`` (neutrals) from a series impedance matrix."""
    if z.shape[0] <= n:
        return z
    a, b, c, d = z[:n, :n], z[:n, n:], z[n:, :n], z[n:, n:]
    return a - b @ np.linalg.solve(d, c)


def _sequence_of(z: np.ndarray) -> complex:
    """Positive-sequence impedance of a phase impedance matrix: mean of the diagonal minus
    mean of the off-diagonal (the self impedance of a one-phase matrix)."""
    n = z.shape[0]
    if n == 1:
        return complex(z[0, 0])
    diagonal = np.trace(z) / n
    return complex(diagonal - (z.sum() - np.trace(z)) / (n * (n - 1)))


def _line_z1(ctx, cache: dict) -> complex:
    """Positive-sequence series impedance of the active line, ohm per line unit length
    (``cache``: by phase matrices, shared by the lines of one line code)."""
    lines = ctx.Lines
    n = lines.Phases()
    r_list, x_list = lines.RMatrix(), lines.XMatrix()
    key = (n, tuple(r_list), tuple(x_list))
    if key not in cache:
        cache[key] = _line_z1_of(ctx, n, np.asarray(r_list, float), np.asarray(x_list, float))
    return cache[key]


def _line_z1_of(ctx, n: int, r: np.ndarray, x: np.ndarray) -> complex:
    lines = ctx.Lines
    m = int(round(math.sqrt(len(r))))
    z = _kron((r + 1j * x).reshape(m, m), n)
    z1 = complex(lines.R1(), lines.X1())
    z0 = complex(lines.R0(), lines.X0())
    zs, zm = (2 * z1 + z0) / 3, (z0 - z1) / 3
    if n < 3:
        from_sequence = np.full((n, n), zm) + np.eye(n) * (zs - zm)
        if (np.abs(z - from_sequence) <= 1e-12 + 1e-6 * np.abs(from_sequence)).all():
            return z1
    return _sequence_of(z)


def _lines(ctx, kv: dict[str, float], ratings: bool) -> list[Branch]:
    rows: list[Branch] = []
    cache: dict = {}
    for name in each(ctx.Lines):
        if _skipped(ctx):
            continue
        bus1, bus2 = bus_of(ctx.Lines.Bus1()), bus_of(ctx.Lines.Bus2())
        units = ctx.Lines.Units()
        if units not in KM_PER_DSS_UNIT:
            raise FeederError(f"Line.{name}: unsupported length unit code {units}")
        length = ctx.Lines.Length()
        z1 = _line_z1(ctx, cache) * length
        limit = _rated_kw(ctx, f"Line.{name}", kv[bus1], ratings)
        kind = "switch" if ctx.Lines.IsSwitch() else "line"
        rows.append(Branch(name, bus1, bus2, length * KM_PER_DSS_UNIT[units], abs(z1.real),
                           abs(z1.imag), kv[bus1] * SQRT3, limit, kind,
                           (f"Line.{name}",)))  # fmt: skip
    return rows


def _rated_kw(ctx, element: str, kv_ln: float, ratings: bool) -> float:
    """``phases x V_LN x NormAmps`` (kW at unity power factor), ``inf`` without ratings."""
    if not ratings:
        return math.inf
    amps = ctx.CktElement.NormalAmps()
    limit = ctx.CktElement.NumPhases() * kv_ln * amps
    if not limit > 0:
        raise FeederError(
            f"{element}: cannot convert NormAmps = {amps} A to kW: its bus has no base voltage "
            "(set voltagebases) or the rating is 0 (--no-ratings ignores ratings)"
        )
    return limit


def _series_z(ctx) -> complex:
    """Positive-sequence series impedance (ohm) of the active two-terminal element from its
    primitive admittance: ``Z = -Y12^-1`` between its terminals (shunt parts excluded)."""
    y = np.asarray(ctx.CktElement.YPrim(), float)
    y = (y[0::2] + 1j * y[1::2]).reshape(int(round(math.sqrt(len(y) / 2))), -1)
    n = ctx.CktElement.NumConductors()
    y12 = y[:n, n : 2 * n]
    try:
        z = np.linalg.inv(-y12)
    except np.linalg.LinAlgError:
        return 0j
    return _sequence_of(z[: ctx.CktElement.NumPhases(), : ctx.CktElement.NumPhases()])


def _series_shunts(ctx, kv: dict[str, float], ratings: bool) -> list[Branch]:
    """Reactors and capacitors between two different buses (series elements); those on one
    bus (shunts) carry no active power and are left out."""
    rows = []
    for cls, prefix in ((ctx.Reactors, "Reactor"), (ctx.Capacitors, "Capacitor")):
        for name in elements(cls):
            cls.Name(name)
            buses = [bus_of(b) for b in ctx.CktElement.BusNames()]
            if len(set(buses)) < 2 or _skipped(ctx):
                continue
            z = _series_z(ctx)
            limit = _rated_kw(ctx, f"{prefix}.{name}", kv[buses[0]], ratings)
            rows.append(Branch(f"{prefix}.{name}", buses[0], buses[1], 0.0, abs(z.real),
                               abs(z.imag), kv[buses[0]] * SQRT3, limit, prefix.lower(),
                               (f"{prefix}.{name}",)))  # fmt: skip
    return rows


def _winding_z(ctx) -> tuple[list[str], np.ndarray, np.ndarray, complex]:
    """The active transformer's buses per winding, kVA per winding, and its star impedances
    per winding (p.u. on winding 1's kVA, on which OpenDSS states ``%R`` of every winding
    and ``XHL``, ``XHT``, ``XLT``; two windings: all in winding 1's) with XHL."""
    t = ctx.Transformers
    n = t.NumWindings()
    buses = [bus_of(b) for b in ctx.CktElement.BusNames()]
    kva, r = np.zeros(n), np.zeros(n)
    for w in range(1, n + 1):
        t.Wdg(w)
        kva[w - 1], r[w - 1] = t.kVA(), t.R() / 100
    r_pu = r  # OpenDSS states every winding's %R on winding 1's kVA (its own power flow shows)
    xhl = t.Xhl() / 100
    if n == 2:
        return buses, kva, np.array([complex(r_pu[0] + r_pu[1], xhl), 0j]), xhl
    xht, xlt = t.Xht() / 100, t.Xlt() / 100
    x = np.array([xhl + xht - xlt, xhl + xlt - xht, xht + xlt - xhl]) / 2
    return buses, kva, r_pu + 1j * x, xhl


def _transformers(ctx, kv: dict[str, float], ratings: bool) -> list[Branch]:
    """Transformers as branches (rules in :mod:`popdispatch.readers.opendss_direct`)."""
    regulated = set()
    for name in elements(ctx.RegControls):
        ctx.RegControls.Name(name)
        regulated.add(ctx.RegControls.Transformer().lower())
    banks: dict[tuple, list[tuple]] = {}
    for name in elements(ctx.Transformers):
        ctx.Transformers.Name(name)
        if _skipped(ctx):
            continue
        windings = ctx.Transformers.NumWindings()
        if windings not in (2, 3):
            raise FeederError(
                f"Transformer.{name}: unsupported {windings}-winding transformer (popdispatch "
                "reads two- and three-winding transformers)"
            )
        buses, kva, z, _ = _winding_z(ctx)
        phases = ctx.CktElement.NumPhases()
        kv_ll = kv[buses[0]] * SQRT3
        if not kv_ll > 0:
            raise FeederError(f"Transformer.{name}: bus {buses[0]!r} has no base voltage")
        # ohm on winding 1's base: z V_LL^2 / MVA (three-phase), z V_LN^2 / MVA (one-phase)
        ohm_per_pu = (kv_ll**2 if phases >= 3 else (kv_ll / SQRT3) ** 2) * 1e3 / kva[0]
        kind = "regulator" if name.lower() in regulated else "transformer"
        parts = _winding_branches(name, buses, kva, z)
        for part, (a, b, z_ab, kva_ab) in enumerate(parts):
            limit = kva_ab if ratings else math.inf
            unit_name = name if len(parts) == 1 else f"{name}:w{part + 1}"
            unit = (unit_name, a, b, z_ab * ohm_per_pu, kv_ll, limit, kind)
            key = (frozenset((a, b)), part) if phases == 1 else (name, part)
            banks.setdefault(key, []).append(unit)
    rows = []
    for units in banks.values():
        name, a, b, _, kv_ll, _, _ = units[0]
        z = complex(np.mean([u[3] for u in units]))
        rows.append(Branch(
            "Transformer." + "+".join(u[0] for u in units), a, b, 0.0, abs(z.real), abs(z.imag),
            kv_ll, float(sum(u[5] for u in units)),
            "regulator" if any(u[6] == "regulator" for u in units) else "transformer",
            tuple(f"Transformer.{u[0].split(':')[0]}" for u in units),
        ))  # fmt: skip
    return rows


def _winding_branches(
    name: str, buses: list[str], kva: np.ndarray, z: np.ndarray
) -> list[tuple[str, str, complex, float]]:
    """``(bus_a, bus_b, z p.u., kVA)`` branches of a transformer: one for two windings; for
    three, windings 2 and 3 on one bus (split-phase service) are in parallel behind winding
    1's impedance: ``z1 + z2 z3 / (z2 + z3)``; on three buses, the star equivalent: a star
    bus ``NAME.star`` (:func:`star_bus`) joined to each winding's bus by its impedance."""
    if len(buses) == 2:
        return [(buses[0], buses[1], complex(z[0]), float(kva[0]))]
    if buses[1] == buses[2] != buses[0]:
        z23 = z[1] * z[2] / (z[1] + z[2]) if abs(z[1] + z[2]) > 0 else 0j
        return [(buses[0], buses[1], complex(z[0] + z23), float(kva[0]))]
    if len(set(buses)) < 3:
        raise FeederError(
            f"Transformer.{name}: three-winding transformer with winding 1 and another on one "
            f"bus {buses} is not supported"
        )
    star = star_bus(name)
    return [(buses[0], star, complex(z[0]), float(kva[0]))] + [
        (star, buses[w], complex(z[w]), float(kva[w])) for w in (1, 2)
    ]


def star_bus(transformer: str) -> str:
    """The star point of a three-winding transformer between three buses, as a bus name (a
    dot cannot be part of an OpenDSS bus name, so it is no other bus's)."""
    return f"transformer.{transformer.lower()}.star"


def _check_other_series(ctx) -> None:
    """Refuse two-bus elements other than lines, transformers, reactors and capacitors (an
    autotransformer, a fault between two buses, ...), naming the first."""
    for element in ctx.Circuit.AllElementNames():
        cls = element.split(".")[0].lower()
        if cls in BRANCH_CLASSES or cls in ONE_BUS_CLASSES:
            continue
        ctx.Circuit.SetActiveElement(element)
        if not ctx.CktElement.Enabled() or ctx.CktElement.NumTerminals() < 2:
            continue
        buses = {bus_of(b) for b in ctx.CktElement.BusNames()}
        if len(buses) > 1:
            raise FeederError(
                f"{element}: unsupported series element between buses {sorted(buses)} "
                "(popdispatch reads lines, switches, transformers, regulators, reactors "
                "and series capacitors)"
            )


# -- loads, injections, shapes ----------------------------------------------------------------


def _loads(ctx) -> list[tuple]:
    rows = []
    for name in each(ctx.Loads):
        if not ctx.CktElement.Enabled():
            continue
        fixed = ctx.Loads.Status() == 1  # status=fixed: load shapes do not apply
        shapes = (
            ("", "", "") if fixed else (ctx.Loads.Daily(), ctx.Loads.Yearly(), ctx.Loads.Duty())
        )
        rows.append((name, bus_of(ctx.CktElement.BusNames()[0]), ctx.Loads.kW(),
                     ctx.Loads.kvar(), "load", *(s.lower() for s in shapes)))  # fmt: skip
    return rows


def _injections(ctx) -> list[tuple]:
    """Generators (``kW``) and PV systems (``Pmpp x Irradiance``) with their shapes."""
    rows = []
    for name in elements(ctx.Generators):
        ctx.Generators.Name(name)
        if ctx.CktElement.Enabled():
            shapes = (ctx.Generators.daily(), ctx.Generators.Yearly(), ctx.Generators.duty())
            rows.append((f"Generator.{name}", bus_of(ctx.CktElement.BusNames()[0]),
                         ctx.Generators.kW(), ctx.Generators.kvar(), "generator",
                         *(s.lower() for s in shapes)))  # fmt: skip
    for name in elements(ctx.PVsystems):
        ctx.PVsystems.Name(name)
        if ctx.CktElement.Enabled():
            shapes = (ctx.PVsystems.daily(), ctx.PVsystems.yearly(), ctx.PVsystems.duty())
            kw = ctx.PVsystems.Pmpp() * ctx.PVsystems.Irradiance()
            rows.append((f"PVSystem.{name}", bus_of(ctx.CktElement.BusNames()[0]), kw, 0.0,
                         "pvsystem", *(s.lower() for s in shapes)))  # fmt: skip
    return rows


def _storage(ctx) -> list[tuple]:
    """Storage elements ``(name, bus, kWrated)``: dispatchable only through a fleet."""
    rows = []
    for name in elements(ctx.Storages):
        ctx.Storages.Name(name)
        if ctx.CktElement.Enabled():
            ctx.Text.Command(f"? {ctx.CktElement.Name()}.kWrated")
            try:
                rating = float(ctx.Text.Result())
            except (AttributeError, ValueError):  # pragma: no cover - old engines
                rating = math.nan
            rows.append((f"Storage.{name}", bus_of(ctx.CktElement.BusNames()[0]), rating))
    return rows


def _shapes(ctx, names: set[str]) -> dict[str, Shape]:
    """The load shapes named by loads and injections (fixed-interval shapes only)."""
    shapes = {}
    for name in sorted(names):
        ctx.LoadShape.Name(name)
        if ctx.LoadShape.Name().lower() != name:
            raise FeederError(f"LoadShape.{name} is used but not defined")
        hours = float(ctx.LoadShape.HrInterval())
        if not hours > 0:
            raise FeederError(
                f"LoadShape.{name}: a shape without a fixed interval (hour= points) is not "
                "supported; give it interval=, minterval= or sinterval="
            )
        mult = np.asarray(ctx.LoadShape.PMult(), float)[: ctx.LoadShape.Npts()]
        shapes[name] = Shape(mult.copy(), hours, bool(ctx.LoadShape.UseActual()))
    return shapes


__all__ = ["Branch", "Circuit", "Shape", "bus_of", "read_circuit"]
