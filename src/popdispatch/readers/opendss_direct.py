"""Any radial OpenDSS circuit, read through OpenDSSDirect.py (the optional ``opendss`` extra).

:func:`read_opendss_master` compiles a master file or a run script with OpenDSS itself, in
place (:mod:`popdispatch.readers.dss_script`: Windows file names, the script's edits after
the compile honoured, commands that solve, show, plot or export skipped) and turns the circuit
into the plain-table :class:`~popdispatch.feeder.Feeder`: a positive-sequence single-line
model.

Conversion rules
----------------
- **Buses**: one per OpenDSS bus (``Circuit.AllBusNames``). The ``name`` column keeps the
  OpenDSS name (lower case), which is how every output and option names the bus; the int id
  behind it is the name's number where it is a canonical non-negative integer (``"650"``; not
  ``"007"``), else the next id above the largest such number, in OpenDSS's bus order.
  ``vn_kv``: the bus's base voltage, line-to-line kV (OpenDSS's ``kVBase`` x sqrt(3);
  ``CalcVoltageBases`` is run once when a bus has none). A bus cut off from every source by an
  open element is dropped (a :class:`UserWarning` names it) if nothing is connected to it;
  with a load or generator it is an error.
- **Impedances** are each branch's own ohms, stated on the line-to-line voltage ``kv_base``
  of its first bus (a 4.16 kV line's ohms are 4.16 kV ohms, a transformer's are on its
  winding 1's side); :meth:`~popdispatch.feeder.Feeder.lines_on_base` refers them to one
  base for the AC check and the reduction.
- **Lines** (enabled, not open on a whole terminal, not held open by a fuse, recloser, relay
  or switch control): ``length_km`` = ``Length`` x its ``Units``; ``r_ohm + j x_ohm`` = the
  positive-sequence impedance of OpenDSS's own phase matrices (``Lines.RMatrix``/
  ``XMatrix``, whatever defined them) Kron-reduced to the phase conductors, ``Z1 =
  mean(diagonal) - mean(off-diagonal)`` (exactly ``R1 + j X1`` for sequence-defined lines; a
  one-phase matrix line its self impedance), times ``Length``. Switches (``Switch=yes``) are
  lines with ``kind = "switch"``.
- **Transformers and regulators**: branches with ``length_km = 0`` and the series impedance
  ``z = (%R1 + %R2)/100 + j XHL/100`` per unit on winding 1's kVA (OpenDSS states every
  winding's ``%R`` on it: its own power flow does not change with winding 2's kVA), in ohm on
  winding 1's side: ``z V_LL^2 / MVA1`` for a three-phase unit, ``z V_LN^2 / MVA1`` (per
  phase) for a one-phase unit. One-phase units between the same two buses (a regulator bank
  ``reg1a/b/c``) are one branch ``Transformer.reg1a+reg1b+reg1c`` with the mean of their
  impedances.
  ``kind`` is ``"regulator"`` when a ``RegControl`` acts on a unit. Taps are ignored.
- **Three-winding transformers**: the split-phase (centre-tap) service transformer, windings
  2 and 3 on one bus, is one branch from winding 1's bus to the secondary bus. Its star
  impedances come from ``XHL``, ``XHT``, ``XLT`` and each winding's ``%R`` (all on winding 1's
  kVA); the secondary's loads draw on both halves alike, so the halves are in parallel behind
  the primary: ``z = z1 + z2 z3 / (z2 + z3)``; the loads stay on the secondary bus. Three
  windings on three buses are the star equivalent: a bus ``transformer.NAME.star`` of its
  own and one branch ``Transformer.NAME:wK`` per winding (limit the winding's kVA).
- **Reactors and capacitors** between two different buses (the 8500-node feeder's source
  reactor, series capacitors) are branches with the impedance of their primitive admittance
  (``Z = -Y12^-1`` between the terminals, positive sequence); shunt ones (one bus) carry no
  active power and are left out, as capacitors and regulators' controls are: topology only.
- **Parallel branches** (parallel conductors, lines of different phases between the same
  buses) are merged (:mod:`popdispatch.feeder.radial`: parallel impedance, summed ratings).
- Any other series element (``AutoTrans``, ``GICTransformer``, ``UPFC``, a fault between two
  buses, ...) is refused with one line naming it and the file and line defining it.
- **Loads** (enabled): one row per OpenDSS load, index its name (OpenDSS lower-cases names),
  ``bus``, ``p_kw`` = ``Loads.kW`` (the total over its phases), ``q_kvar`` = ``Loads.kvar``,
  ``kind = "load"`` and the names of its ``daily``, ``yearly`` and ``duty`` shapes
  (:mod:`popdispatch.feeder.shapes` runs them: ``--series``); a ``status=fixed`` load none.
- **Fixed injections**: OpenDSS ``Generator`` and ``PVSystem`` elements have no cost data.
  Those the ``fleet`` does not dispatch are fixed injections following their own shapes:
  rows of the loads table named ``Generator.g1``/``PVSystem.pv1`` with ``p_kw`` = minus their
  output (``kW``; PV ``Pmpp x Irradiance``, temperature and efficiency curves not applied) and
  ``kind`` ``generator``/``pvsystem``. ``Storage`` elements outside the fleet are left idle.
- **Ratings** (``ratings=True``): a branch's ``limit_kw`` = ``phases x V_LN x NormAmps`` at its
  first bus's base voltage, i.e. ``sqrt(3) x V_LL x I`` for a three-phase line, at unity power
  factor; a transformer's its winding-1 kVA (summed over a bank). OpenDSS gives every line
  ``NormAmps = 400`` unless told otherwise and this reader cannot tell that default from a
  stated rating: ``ratings=False`` (``--no-ratings``) leaves every limit ``inf``.
- **Coordinates**: the circuit's bus coordinates (``BusCoords``) where present; a bus without
  any takes its nearest placed neighbour's towards the source. A circuit with none gets a
  schematic layout: ``y = -100 x depth`` from the source and ``x = 100 x`` leaf order.
- **Source**: the ``Vsource``'s bus (``sourcebus`` in most masters) unless ``root`` names
  another bus (the tree is then rooted there). Several Vsources feeding separate trees are
  several feeders, joined for one run at a virtual bus by balance lines of 0 kW
  (:mod:`popdispatch.feeder.radial`: each balanced by its own generators), unless ``root``
  picks one; several Vsources in one tree are refused.
- **Fleet**: a table with the columns of :data:`~popdispatch.feeder.generators.FLEET_COLUMNS`
  (or the path of a CSV/TOML fleet file) whose ``bus`` holds OpenDSS bus names (an integer is
  read as the name it spells). A row whose ``bus`` is missing (NaN/None) and whose name is an
  OpenDSS generator, PV system or storage element (``g1`` or ``Generator.g1``) takes that
  element's bus, and a missing ``pmax_kw`` its rating (``kW``, PV ``Pmpp``, storage
  ``kWrated``), ``pmin_kw`` 0. Without a fleet the feeder has none: it can be described
  (``popdispatch feeder``), a dispatch asks for one.
"""

from __future__ import annotations

import contextlib
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FeederError, FleetError, MeshedError, OptionError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.generators import FLEET_COLUMNS, as_fleet, make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.radial import join_feeders, merge_parallel
from popdispatch.feeder.shapes import LoadShape
from popdispatch.readers.dss_circuit import SQRT3, Circuit, read_circuit
from popdispatch.readers.dss_script import compiled_script, opendss

#: The rows of :func:`fleet_candidates`.
CANDIDATE_COLUMNS = ["element", "bus_name", "rating_kw"]
#: Shape columns of the loads table, one per OpenDSS series.
SERIES = ("daily", "yearly", "duty")

_CANONICAL_INT = re.compile(r"0|[1-9][0-9]*")
_ELEMENT = re.compile(r"^([A-Za-z]\w*\.[^\s:]+): ")


def _opendss():
    """The ``opendssdirect`` module, or a clear error naming the extra."""
    return opendss()


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


def read_opendss_master(
    master_path: str | Path,
    *,
    fleet: pd.DataFrame | str | Path | None = None,
    root: str | int | None = None,
    ratings: bool = True,
    name: str | None = None,
) -> Feeder:
    """Read the radial circuit of an OpenDSS master file or run script as a :class:`Feeder`.

    Conversion rules: see :mod:`popdispatch.readers.opendss_direct`.

    Parameters
    ----------
    master_path : the ``.dss`` file (compiled in place: see the module docstring).
    fleet : the generators to dispatch (a table with ``bus, a, b, c, pmin_kw, pmax_kw``, ``bus``
        = OpenDSS bus name, or the path of a CSV/TOML fleet file); ``None``: none (the feeder
        can be described; a dispatch needs a fleet, OpenDSS has no cost data).
    root : the source bus (OpenDSS bus name, or an int spelling it); default the Vsource's bus.
    ratings : line limits from ``NormAmps`` and transformer limits from kVA (else ``inf``).
    name : the feeder's case name; default the OpenDSS circuit's name.
    """
    fleet = as_fleet(fleet)
    path = Path(master_path)
    with _compiled_circuit(path, ratings) as (ctx, circuit):
        try:
            feeder = _feeder(circuit, path, fleet, root, name)
        except MeshedError as exc:
            raise MeshedError(f"{path}: {exc}{_open_point(ctx, circuit, exc)}",
                              exc.loop_lines) from None  # fmt: skip
    return feeder


@contextlib.contextmanager
def _compiled_circuit(path: Path, ratings: bool):
    """``(OpenDSS context, circuit)`` of the script ``path`` compiled in place (the context
    answers questions while the block runs); a problem names the script's file and line, and
    the script's notes (what was skipped or applied) are warned once the block ends."""
    with compiled_script(path) as script:
        try:
            circuit = read_circuit(script.ctx, ratings)
        except FeederError as exc:
            raise _located(exc, script) from None
        yield script.ctx, circuit
    summary = script.summary()
    if summary:
        warnings.warn(f"{path}: {summary}", UserWarning, stacklevel=4)


def _open_point(ctx, circuit: Circuit, exc: MeshedError) -> str:
    """Where to open a loop: the element of the loop that OpenDSS's own solution loads least
    (one sentence), or a plain hint when the circuit does not solve."""
    members = {b.name: b.elements for b in circuit.branches}
    elements = [e for line in exc.loop_lines for part in circuit.merged.get(line, [line])
                for e in members.get(part, ())]  # fmt: skip
    hint = (
        "; open one element of the loop in a run script after the Compile (e.g. "
        "`Open Line.NAME 1`), as OpenDSS would read it"
    )
    try:
        ctx.Text.Command("solve")
        if not ctx.Solution.Converged():
            return hint
        flows = []
        for element in elements:
            ctx.Circuit.SetActiveElement(element)
            powers = ctx.CktElement.Powers()
            conductors = ctx.CktElement.NumConductors()
            flows.append((abs(sum(powers[0 : 2 * conductors : 2])), element))
    except Exception:  # a circuit OpenDSS cannot solve: the plain hint
        return hint
    if not flows:
        return hint
    kw, element = min(flows)
    return (
        f"; OpenDSS's own solution carries the least power of the loop, {kw:.2f} kW, on "
        f"{element}: open it in a run script after the Compile (`Open {element} 1`)"
    )


def _located(exc: FeederError, script) -> FeederError:
    """``exc`` prefixed with the file and line that defined the element it names."""
    message = str(exc)
    match = _ELEMENT.match(message)
    where = script.where(match.group(1)) if match else str(script.path)
    return FeederError(f"{where}: {message}")


def fleet_candidates(circuit: Circuit) -> pd.DataFrame:
    """The circuit's generators, PV systems and storage (no cost data): index element name
    (``Generator.g1``), columns ``bus_name`` and ``rating_kw``."""
    rows = [(name, bus, kw) for name, bus, kw, *_ in circuit.injections]
    rows += [(name, bus, rating) for name, bus, rating in circuit.storage]
    return pd.DataFrame(rows, columns=CANDIDATE_COLUMNS).set_index("element")


def _feeder(circuit: Circuit, path: Path, fleet, root, name) -> Feeder:
    names = circuit.buses
    ids = bus_ids(names)
    lines, circuit.merged = merge_parallel(_branch_table(circuit, ids, path))
    generators, loads = _fleet_and_loads(circuit, ids, fleet, path)
    sources = _sources(circuit, root, ids, path)
    keep = _kept_buses(lines, loads, generators, sources, root, names, ids, path)
    lines = lines[lines.from_bus.isin(keep) & lines.to_bus.isin(keep)]
    loads = loads[loads.bus.isin(keep)]
    kept = [b for b in names if ids[b] in keep]
    buses = pd.DataFrame(
        {"name": kept, "vn_kv": [circuit.kv[b] * SQRT3 for b in kept]},
        index=pd.Index([ids[b] for b in kept], name="bus", dtype=np.int64),
    )
    source_ids = [ids[s] for s in sources]
    if len(source_ids) > 1:
        buses = buses.assign(x=0.0, y=0.0)
        buses, lines, source = join_feeders(buses, lines, source_ids)
    else:
        source = source_ids[0]
    xy = _layout(buses, lines, source, {ids[b]: xy for b, xy in circuit.coords.items()})
    buses["x"], buses["y"] = xy[:, 0], xy[:, 1]
    buses = buses[["x", "y", "name", "vn_kv"]]
    shapes = {k: LoadShape(s.mult, s.hours, s.use_actual) for k, s in circuit.shapes.items()}
    return Feeder(name or circuit.name, buses, lines, loads, source, generators, shapes)


def _branch_table(circuit: Circuit, ids: dict[str, int], path: Path) -> pd.DataFrame:
    """The circuit's series branches as a lines table (bus ids), self loops left out."""
    if not circuit.branches:
        raise FeederError(f"{path}: the OpenDSS circuit {circuit.name!r} has no line")
    lines = pd.DataFrame(
        {
            "from_bus": [ids[b.bus_a] for b in circuit.branches],
            "to_bus": [ids[b.bus_b] for b in circuit.branches],
            "length_km": [b.length_km for b in circuit.branches],
            "r_ohm": [b.r_ohm for b in circuit.branches],
            "x_ohm": [b.x_ohm for b in circuit.branches],
            "limit_kw": [b.limit_kw for b in circuit.branches],
            "kv_base": [b.kv_base for b in circuit.branches],
            "kind": [b.kind for b in circuit.branches],
        },
        index=pd.Index([b.name for b in circuit.branches], name="line"),
    ).astype({"from_bus": np.int64, "to_bus": np.int64})
    return lines[lines.from_bus != lines.to_bus]


def _fleet_and_loads(
    circuit: Circuit, ids: dict[str, int], fleet, path: Path
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``(generators, loads)``: the fleet mapped onto the circuit, and the loads with the
    injections the fleet does not dispatch (fixed injections, negative kW)."""
    candidates = fleet_candidates(circuit)
    generators = _map_fleet(fleet, ids, candidates, path) if fleet is not None else _no_fleet()
    dispatched = {str(e).lower() for e in _dispatched_elements(fleet, candidates)}
    injections = [row for row in circuit.injections if row[0].lower() not in dispatched]
    return generators, _load_table(circuit.loads, injections, ids)


def _kept_buses(lines, loads, generators, sources, root, names, ids, path) -> set[int]:
    """The bus ids of the sources' networks (:func:`_feeder_buses`), warning about the empty
    buses dropped."""
    name_of = {v: k for k, v in ids.items()}
    occupied = set(loads.bus) | set(generators.bus.tolist())
    components = _components(lines, names, ids)
    keep, dropped = _feeder_buses(components, sources, occupied, root, name_of, path)
    if dropped:
        warnings.warn(
            f"{path}: dropped {len(dropped)} bus(es) cut off from the source, with nothing "
            f"connected: {dropped[:10]}",
            UserWarning,
            stacklevel=4,
        )
    return keep


def read_opendss_network(
    master_path: str | Path,
    *,
    fleet: pd.DataFrame | str | Path | None = None,
    root: str | int | None = None,
    ratings: bool = True,
    name: str | None = None,
) -> DcNetwork:
    """An OpenDSS circuit of any shape (tie switches closed: loops) as a
    :class:`~popdispatch.feeder.dcnet.DcNetwork` for MATPOWER's lossless DC model.

    The circuit is compiled and read as :func:`read_opendss_master` reads it (buses, branches
    with their positive-sequence ohms and ratings, loads, fixed injections, the fleet), with
    these differences: parallel branches stay separate rows; each branch's reactance is in per
    unit on 1 MVA and its own line-to-line base, ``x_pu = x_ohm / kv_base^2`` (a transformer's
    ohms are on its winding 1's side, so its per-unit reactance is its own; taps ignored, as
    the radial reading ignores them); each bus's demand ``pd_mw`` is its loads' kW less its
    fixed injections' (one step: load shapes are not run on a mesh); the slack is the
    ``Vsource``'s bus or ``root``, and one source only. Buses keep their OpenDSS names (the
    ``name`` column), which every output and option uses.
    """
    fleet = as_fleet(fleet)
    path = Path(master_path)
    with _compiled_circuit(path, ratings) as (_, circuit):
        return _dc_network(circuit, path, fleet, root, name)


def _dc_network(circuit: Circuit, path: Path, fleet, root, name) -> DcNetwork:
    """:func:`read_opendss_network` of a circuit read."""
    names = circuit.buses
    ids = bus_ids(names)
    lines = _branch_table(circuit, ids, path)
    generators, loads = _fleet_and_loads(circuit, ids, fleet, path)
    sources = _sources(circuit, root, ids, path)
    if len(sources) > 1:
        raise FeederError(f"{path}: a meshed circuit runs with one source; it has "
                          f"{', '.join(sources)}: pick one (--root BUS)")  # fmt: skip
    keep = _kept_buses(lines, loads, generators, sources, root, names, ids, path)
    lines = lines[lines.from_bus.isin(keep) & lines.to_bus.isin(keep)]
    kept = [b for b in names if ids[b] in keep]
    index = pd.Index([ids[b] for b in kept], name="bus", dtype=np.int64)
    demand_kw = loads[loads.bus.isin(keep)].groupby("bus").p_kw.sum()
    buses = pd.DataFrame(
        {"pd_mw": demand_kw.reindex(index, fill_value=0.0).to_numpy() / KW_PER_MW,
         "gs_mw": 0.0, "name": kept},
        index=index,
    )  # fmt: skip
    table = pd.DataFrame(
        {"from_bus": lines.from_bus, "to_bus": lines.to_bus,
         "x_pu": lines.x_ohm / lines.kv_base**2, "tap": 0.0, "shift_deg": 0.0,
         "limit_kw": lines.limit_kw},
        index=lines.index,
    )  # fmt: skip
    return DcNetwork(name or circuit.name, 1.0, buses, table, generators, ids[sources[0]])


def _no_fleet() -> pd.DataFrame:
    return make_fleet([])


def _load_table(loads: list[tuple], injections: list[tuple], ids: dict[str, int]) -> pd.DataFrame:
    """Loads and fixed injections (``p_kw`` negative) with their kind and shape names."""
    rows = [(n, ids[b], kw, kvar, kind, *shapes) for n, b, kw, kvar, kind, *shapes in loads]
    rows += [(n, ids[b], -kw, -kvar, kind, *sh) for n, b, kw, kvar, kind, *sh in injections]
    columns = ["load", "bus", "p_kw", "q_kvar", "kind", *SERIES]
    table = pd.DataFrame(rows, columns=columns).set_index("load")
    return table.astype({"bus": np.int64, "p_kw": float, "q_kvar": float, "kind": object})


def _sources(circuit: Circuit, root, ids: dict[str, int], path: Path) -> list[str]:
    """The source buses: ``root``, else every Vsource's bus."""
    if root is not None:
        key = str(root).strip().lower()
        if key not in ids:
            raise OptionError(
                f"{path}: root bus {root!r} is not a bus of the OpenDSS circuit", "--root"
            )
        return [key]
    if not circuit.sources:
        raise FeederError(f"{path}: the circuit has no enabled Vsource: name the source bus "
                          "(--root BUS)")  # fmt: skip
    return list(circuit.sources)


def _components(lines: pd.DataFrame, names: list[str], ids: dict[str, int]) -> dict[int, int]:
    """Connected component of every bus id."""
    from scipy.sparse import csr_array
    from scipy.sparse.csgraph import connected_components

    index = pd.Index([ids[b] for b in names])
    a, b = index.get_indexer(lines.from_bus), index.get_indexer(lines.to_bus)
    graph = csr_array((np.ones(len(a)), (a, b)), shape=(len(index), len(index)))
    _, component = connected_components(graph, directed=False)
    return dict(zip(index.tolist(), component.tolist(), strict=True))


def _feeder_buses(
    components: dict[int, int], sources: list[str], occupied: set, root, name_of, path
) -> tuple[set[int], list[str]]:
    """``(bus ids kept, names of empty buses dropped)``: the sources' trees; another tree is an
    error if it has a load or generator (unless ``root`` picked a feeder and the tree has a
    Vsource of its own: another feeder, left out)."""
    ids_of = {v: k for k, v in name_of.items()}
    source_trees = [components[ids_of[s]] for s in sources]
    if len(set(source_trees)) < len(source_trees):
        shared = [s for s, t in zip(sources, source_trees, strict=True)
                  if source_trees.count(t) > 1]  # fmt: skip
        raise FeederError(
            f"{path}: several sources feed one connected network ({', '.join(shared)}): "
            "popdispatch supports one source per radial feeder; pick one (--root BUS) or "
            "disable the others"
        )
    keep = {bus for bus, tree in components.items() if tree in source_trees}
    outside = [bus for bus in components if bus not in keep]
    for bus in outside:
        if bus in occupied and root is None:
            raise FeederError(
                f"{path}: bus {name_of[bus]!r} is not connected to source bus "
                f"{', '.join(sources)} but has a load or generator: feeder is disconnected"
            )
    dropped = [name_of[bus] for bus in outside if bus not in occupied]
    return keep, dropped


def _dispatched_elements(fleet, candidates: pd.DataFrame) -> list[str]:
    """Candidate elements (``Generator.g1``) that fleet rows name: dispatched, not fixed."""
    if fleet is None:
        return []
    by_name = _candidate_names(candidates)
    return [by_name[str(g).lower()] for g in fleet.index if str(g).lower() in by_name]


def _candidate_names(candidates: pd.DataFrame) -> dict[str, str]:
    by_name = {e.lower(): e for e in candidates.index}
    by_name.update({e.split(".", 1)[1].lower(): e for e in candidates.index})
    return by_name


def _map_fleet(
    fleet: pd.DataFrame, ids: dict[str, int], candidates: pd.DataFrame, path: Path
) -> pd.DataFrame:
    missing = [c for c in FLEET_COLUMNS if c not in fleet.columns]
    if missing:
        raise FleetError(f"fleet table lacks column {missing[0]!r} (needs {FLEET_COLUMNS})")
    table = fleet.copy()
    by_name = _candidate_names(candidates)
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
            raise FleetError(
                f"generator {generator!r} is on unknown OpenDSS bus {bus!r} ({path.name})"
            )
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
    buses: pd.DataFrame, lines: pd.DataFrame, source: int, coords: dict[int, tuple]
) -> np.ndarray:
    """``(buses, 2)`` coordinates (see the module docstring), in the buses' order."""
    order, parent = _tree_order(buses.index, lines, source)
    placed: dict[int, tuple[float, float]] = {b: c for b, c in coords.items() if b in parent}
    if placed:
        if source not in placed:
            placed[source] = next(placed[b] for b in order if b in placed)
        for bus in order:
            if bus not in placed:
                placed[bus] = placed[parent[bus]]
        return np.array([placed.get(b, (0.0, 0.0)) for b in buses.index], dtype=float)
    children: dict[int, list[int]] = {b: [] for b in order}
    for bus in order[1:]:
        children[parent[bus]].append(bus)
    depth = {order[0]: 0}
    for bus in order[1:]:
        depth[bus] = depth[parent[bus]] + 1
    x: dict[int, float] = {}
    leaf = 0
    for bus in reversed(order):  # children before parents
        if children[bus]:
            x[bus] = min(x[c] for c in children[bus])
        else:
            x[bus] = float(leaf)
            leaf += 1
    return np.array(
        [(100.0 * x.get(b, 0.0), -100.0 * depth.get(b, 0)) for b in buses.index], dtype=float
    )


def _tree_order(
    index: pd.Index, lines: pd.DataFrame, source: int
) -> tuple[list[int], dict[int, int | None]]:
    """A pre-order of the buses reached from the source and each one's parent (loops are left
    to the Feeder's own check, which names them)."""
    adjacent: dict[int, list[int]] = {}
    for a, b in zip(lines.from_bus.tolist(), lines.to_bus.tolist(), strict=True):
        adjacent.setdefault(a, []).append(b)
        adjacent.setdefault(b, []).append(a)
    parent: dict[int, int | None] = {source: None}
    order = []
    stack = [source]
    while stack:
        bus = stack.pop()
        order.append(bus)
        for other in adjacent.get(bus, []):
            if other not in parent:
                parent[other] = bus
                stack.append(other)
    return order, parent


__all__ = ["bus_ids", "fleet_candidates", "read_opendss_master"]
