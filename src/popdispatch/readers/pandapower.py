"""Read a pandapower network (a ``pandapowerNet`` or a pandapower JSON file) as a :class:`Feeder`.

Conversion rules (all vectorised; a 10,000-bus net reads in a fraction of a second):

- **Buses** keep their pandapower index as the int id. Out-of-service buses are absent, and so
  is every element attached to one. Closed bus-bus switches merge buses: the group takes the
  smallest bus index of its members (a fleet's ``bus`` may name any member). Open bus-bus
  switches leave their buses apart. ``x``, ``y`` come from the ``geo`` column (GeoJSON points)
  or the older ``bus_geodata`` table when every feeder bus has one; otherwise a schematic
  layout: ``x`` = hops from the source, ``y`` = the bus's depth-first position.
- **Lines** (``line`` rows in service, not opened by an open line switch) are named
  ``line<index>``; ``length_km`` as given, ``r_ohm``/``x_ohm`` = per-km values x length /
  ``parallel``. **Two-winding transformers** (``trafo``) are branches named ``trafo<index>``
  with ``length_km`` 0. Impedances are each branch's own ohms on the nominal voltage stated
  in ``kv_base`` (line-to-line kV): a line's at its ``from_bus``'s ``vn_kv``, a transformer's
  ``z = vk% / 100`` (``r = vkr% / 100``) on its own rating at its LV side, ``z V_LV^2 / sn_mva
  / parallel``. Nominal ratios only: taps and phase shifts are ignored (the DC dispatch uses
  only the topology and the limits; the impedances are for AC work, which refers them to one
  base, :meth:`~popdispatch.feeder.Feeder.lines_on_base`). Parallel branches between the same
  buses are merged (parallel impedance, summed ratings; :mod:`popdispatch.feeder.radial`).
  ``vn_kv`` of every bus is kept.
- **Source.** Each in-service ``ext_grid`` (a net without one: each slack ``gen``) whose bus is
  the HV side of in-service transformers is replaced by those transformers' LV buses (the HV
  bus and the transformer are dropped), unless ``root`` names the ext_grid's own bus. Sources
  in separate trees are several feeders, joined for one run at a virtual bus by balance lines
  of 0 kW (each balanced by its own generators, :mod:`popdispatch.feeder.radial`); several
  sources in one tree are refused, naming them. With ``root`` the feeder is the tree containing
  it; other trees with a source are left out. Any other island is named in an error if it
  carries load (a ``load``/``asymmetric_load`` with nonzero p or q), else dropped.
- **Loads**: ``load`` (``p_mw * scaling``, ``q_mvar * scaling``) and ``asymmetric_load``
  (sum of the three phases, times ``scaling``), in service, named ``load<index>`` and
  ``asymmetric_load<index>``; columns ``bus``, ``p_kw``, ``q_kvar``, ``kind = "load"``.
- **Fixed injections**: in-service ``sgen`` and (non-slack) ``gen`` rows without a
  ``poly_cost`` (SimBench's PV and wind) are load rows ``sgen<index>``/``gen<index>`` with
  ``p_kw = -p_mw x scaling x 1000`` and ``kind`` their table: the dispatch does not move them
  (SimBench's years give their profiles, :mod:`popdispatch.readers.series`).
- **Ratings** (``ratings=True``): a line's ``limit_kw = sqrt(3) * vn_kv * max_i_ka * df *
  parallel * 1000 * max_loading_percent / 100`` (``vn_kv`` of its ``from_bus``; the last
  factor only when the column exists and is finite), the active power at unity power factor at
  nominal voltage. A transformer's ``limit_kw = sn_mva * df * parallel * 1000 *
  max_loading_percent / 100``. ``max_i_ka`` that is missing, not positive or at least 99999
  (pandapower's "unlimited", e.g. from ``from_mpc`` with ``RATE_A`` 0) means no limit.
  ``ratings=False``: no limits.
- **Fleet.** ``fleet`` (a fleet table or the path of a fleet file, see
  :mod:`popdispatch.feeder.generators`, its ``bus`` the pandapower bus index) replaces the
  network's priced generators. Otherwise every in-service ``gen``, ``sgen`` and ``storage`` of
  the feeder, and an ``ext_grid`` at a source, that has a ``poly_cost`` is a generator named
  ``<table><index>`` with ``a = cp0_eur``, ``b = cp1_eur_per_mw``, ``c = cp2_eur_per_mw2``
  and ``pmin_kw``/``pmax_kw`` = ``min_p_mw``/``max_p_mw`` x 1000 (``pmin`` clipped at 0; a
  missing ``max_p_mw`` falls back to ``sn_mva``, then ``p_mw``; for an ext_grid to the
  substation transformers' ``sn_mva``). ``storage`` is
  in load convention, so its generator takes ``pmax = -min_p_mw``, ``pmin = max(-max_p_mw, 0)``
  and ``b = -cp1``. A ``storage`` without a ``poly_cost`` (or with a ``pwl_cost``) stays idle,
  named in a :class:`UserWarning`; a ``gen``/``sgen`` with only a ``pwl_cost`` is a fixed
  injection. A network without
  any priced generator has an empty fleet: it can be described; a dispatch needs a fleet.
- **Unsupported** in-service elements (``trafo3w``, ``dcline``, ``impedance``, ``ward``,
  ``xward``, ``motor``, ``asymmetric_sgen``, FACTS, DC grids, shunts with nonzero p) raise a
  one-line :class:`FeederError` naming the element.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components

from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FeederError, FleetError, MeshedError, OptionError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.generators import FLEET_COLUMNS, as_fleet, make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.radial import join_feeders, merge_parallel

#: Tables popdispatch cannot represent, with a readable name for the error.
UNSUPPORTED = {
    "trafo3w": "three-winding transformer",
    "dcline": "DC line",
    "impedance": "impedance element",
    "ward": "ward equivalent",
    "xward": "extended ward equivalent",
    "motor": "motor",
    "asymmetric_sgen": "asymmetric static generator",
    "tcsc": "TCSC",
    "svc": "SVC",
    "ssc": "SSC",
    "vsc": "VSC converter",
    "line_dc": "DC line",
    "bus_dc": "DC bus",
    "b2b_vsc": "back-to-back VSC",
    "vsc_stacked": "stacked VSC",
    "vsc_bipolar": "bipolar VSC",
    "source_dc": "DC source",
    "load_dc": "DC load",
}
#: ``max_i_ka`` at or above this means "no limit" (pandapower's placeholder value).
UNLIMITED_KA = 99999.0
SQRT3 = math.sqrt(3.0)


def read_pandapower(
    net_or_path,
    *,
    fleet: pd.DataFrame | None = None,
    root: int | None = None,
    ratings: bool = True,
    name: str | None = None,
) -> Feeder:
    """The radial feeder of a pandapower network (see the module docstring for every rule).

    Parameters
    ----------
    net_or_path : a ``pandapowerNet`` or the path of a pandapower JSON file.
    fleet : a fleet table replacing the network's own generators (``bus``: pandapower index).
    root : the source bus (pandapower index); default the substation transformer's LV side
        (or the ext_grid's bus when it has no transformer).
    ratings : take line and transformer limits from the network's ratings (else none).
    name : the feeder's name; default the net's ``name``, else the file stem, else
        ``"pandapower"``.
    """
    return _read(net_or_path, fleet, root, ratings, name)


def _read(net_or_path, fleet, root, ratings, name) -> Feeder:
    """:func:`read_pandapower` (its ``fleet`` already a table or ``None``)."""
    fleet = as_fleet(fleet)
    net, default_name = _load(net_or_path)
    _check_unsupported(net)
    bus_table = net.bus
    bus_ids = bus_table.index.to_numpy(np.int64)
    n = len(bus_ids)
    if n == 0:
        raise FeederError("pandapower net has no bus")
    position = pd.Index(bus_ids)
    bus_ok = bus_table.in_service.to_numpy(bool)
    rep = _merge_buses(net, position, bus_ok)  # per bus position, its representative position

    branches = _branches(net, position, bus_ok)
    branches["a"] = rep[branches.a.to_numpy()]
    branches["b"] = rep[branches.b.to_numpy()]
    ext = _ext_grids(net, position, bus_ok, rep)
    root_pos = None
    if root is not None:
        root = _root_index(root)
        if root not in position:
            raise OptionError(f"root bus {root} is not a bus of the pandapower net", "--root")
        root_pos = int(rep[position.get_loc(root)])
        if not bus_ok[position.get_loc(root)]:
            raise FeederError(f"root bus {root} is out of service")
    # substation transformers: dropped with their HV bus unless the root is that HV bus
    hv_of_ext = set(ext.pos.tolist()) - ({root_pos} if root_pos is not None else set())
    trafo = branches.kind == "trafo"
    substation = trafo & branches.a.isin(hv_of_ext).to_numpy()
    dropped = branches[substation]
    sources = _sources(ext, dropped)
    branches = branches[~substation]

    a = branches.a.to_numpy()
    b = branches.b.to_numpy()
    graph = csr_array((np.ones(len(a), np.int8), (a, b)), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    alive = bus_ok & (rep == np.arange(n))
    for pos, _label in sources:
        alive[pos] = True

    load_table = _loads(net, position, bus_ok, rep)
    roots = _pick_roots(sources, component, root_pos, bus_ids)
    keep = alive & np.isin(component, [component[r] for r in roots])
    _check_islands(alive, keep, component, load_table, sources, roots[0], bus_ids, root)

    in_feeder = keep[a] & keep[b]
    branches = branches[in_feeder]
    a, b = a[in_feeder], b[in_feeder]
    loops = a == b
    if loops.any():
        k = int(np.argmax(loops))
        raise MeshedError(
            f"{branches.index[k]!r} joins buses merged by a closed bus-bus switch (bus "
            f"{bus_ids[a[k]]}): feeder is meshed (a radial reader; any network: docs/meshed.md)",
            [str(branches.index[k])],
        )
    vn = bus_table.vn_kv.to_numpy(float)
    lines = pd.DataFrame(
        {
            "from_bus": bus_ids[a],
            "to_bus": bus_ids[b],
            "length_km": branches.length_km.to_numpy(float),
            "r_ohm": branches.r_ohm.to_numpy(float),
            "x_ohm": branches.x_ohm.to_numpy(float),
            "limit_kw": branches.limit_kw.to_numpy(float) if ratings else np.inf,
            "kv_base": branches.v_kv.to_numpy(float),
        },
        index=pd.Index(branches.index, name="line"),
    )
    lines, _ = merge_parallel(lines)
    kept = np.flatnonzero(keep)
    xy, schematic = _coordinates(net, bus_table, kept)
    buses = pd.DataFrame(xy, columns=["x", "y"], index=pd.Index(bus_ids[kept], name="bus"))
    buses["vn_kv"] = vn[kept]
    costs = _costs(net)
    if fleet is None:
        generators = _fleet(net, position, bus_ok, rep, keep, ext, roots, dropped, costs)
    else:
        generators = _user_fleet(fleet, position, rep, bus_ids)
    injections = _fixed_injections(net, position, bus_ok, rep, costs[0])
    loads = pd.concat([load_table, injections]) if len(injections) else load_table
    loads = loads[keep[loads.pos.to_numpy()]]
    loads = pd.DataFrame(
        {
            "bus": bus_ids[loads.pos.to_numpy()],
            "p_kw": loads.p_kw.to_numpy(float),
            "q_kvar": loads.q_kvar.to_numpy(float),
            "kind": loads.kind.to_numpy(object),
        },
        index=pd.Index(loads.index, name="load"),
    )
    source_ids = [int(bus_ids[r]) for r in roots]
    if len(source_ids) > 1:
        buses, lines, source = join_feeders(buses, lines, source_ids)
    else:
        source = source_ids[0]
    feeder = Feeder(name or default_name, buses, lines, loads, source, generators)
    if schematic:
        _schematic_layout(feeder)
    return feeder


def _root_index(root) -> int:
    """The pandapower bus index ``root`` spells; :class:`FeederError` otherwise."""
    try:
        return int(str(root).strip())
    except ValueError:
        raise OptionError(f"root {root!r} is not a pandapower bus index", "--root") from None


# -- input ---------------------------------------------------------------------------------------


def _load(net_or_path):
    if isinstance(net_or_path, str | Path):
        import pandapower as pp

        path = Path(net_or_path)
        if not path.exists():
            raise FeederError(f"pandapower file {path} does not exist")
        try:
            net = pp.from_json(str(path))
        except Exception as exc:  # pandapower raises many kinds
            raise FeederError(f"cannot read pandapower JSON {path}: {_why(path, exc)}") from None
        default = path.stem
    else:
        net = net_or_path
        default = "pandapower"
    if not hasattr(net, "bus") or not hasattr(net, "line"):
        raise FeederError(f"not a pandapower net: {type(net).__name__}")
    own = net.get("name", None) if hasattr(net, "get") else None
    if isinstance(own, str) and own.strip():
        default = own.strip()
    return net, default


def _why(path: Path, exc: Exception) -> str:
    """What is wrong with a file pandapower cannot read: JSON that is no pandapower net (such
    as ``{}``: pandapower's own message is then about its internals), else its message."""
    import json

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return str(exc)
    if not isinstance(data, dict) or not ({"bus", "_object"} & set(data)):
        return ("the JSON holds no pandapower network (pandapower.to_json writes one: its "
                "bus, line, load, ... tables)")  # fmt: skip
    return str(exc)


def _table(net, name: str) -> pd.DataFrame | None:
    table = net.get(name) if hasattr(net, "get") else getattr(net, name, None)
    return table if isinstance(table, pd.DataFrame) and len(table) else None


def _in_service(table: pd.DataFrame) -> np.ndarray:
    if "in_service" not in table.columns:
        return np.ones(len(table), bool)
    return table.in_service.fillna(False).to_numpy(bool)


def _check_unsupported(net) -> None:
    for key, what in UNSUPPORTED.items():
        table = _table(net, key)
        if table is not None and _in_service(table).any():
            index = table.index[_in_service(table)][0]
            label = _label(table, index)
            raise FeederError(
                f"unsupported element {key} {index}{label} ({what}) is in service: popdispatch "
                "reads buses, lines, two-winding transformers, switches, loads and generators; "
                "take it out of service or remove it"
            )
    shunt = _table(net, "shunt")
    if shunt is not None:
        active = _in_service(shunt) & (shunt.p_mw.fillna(0).to_numpy(float) != 0)
        if active.any():
            index = shunt.index[active][0]
            raise FeederError(
                f"unsupported element shunt {index}{_label(shunt, index)} draws active power "
                f"({shunt.p_mw[index]} MW): popdispatch cannot represent it; remove it"
            )


def _label(table: pd.DataFrame, index) -> str:
    if "name" in table.columns:
        value = table.at[index, "name"]
        if isinstance(value, str) and value:
            return f" {value!r}"
    return ""


def _finite(table: pd.DataFrame, column: str, default: float) -> np.ndarray:
    if column not in table.columns:
        return np.full(len(table), default)
    values = pd.to_numeric(table[column], errors="coerce").to_numpy(float)
    return np.where(np.isfinite(values), values, default)


# -- topology ------------------------------------------------------------------------------------


def _merge_buses(net, position: pd.Index, bus_ok: np.ndarray) -> np.ndarray:
    """Per bus position, the position of its group's representative (smallest bus index)."""
    n = len(position)
    switch = _table(net, "switch")
    rep = np.arange(n)
    if switch is None:
        return rep
    closed = (switch.et == "b").to_numpy() & switch.closed.fillna(False).to_numpy(bool)
    closed &= _in_service(switch)
    if not closed.any():
        return rep
    sa = position.get_indexer(switch.bus[closed])
    sb = position.get_indexer(switch.element[closed].astype(np.int64))
    good = (sa >= 0) & (sb >= 0)
    sa, sb = sa[good], sb[good]
    good = bus_ok[sa] & bus_ok[sb]
    sa, sb = sa[good], sb[good]
    graph = csr_array((np.ones(len(sa), np.int8), (sa, sb)), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    ids = position.to_numpy(np.int64)
    smallest = np.full(group.max() + 1, np.iinfo(np.int64).max)
    np.minimum.at(smallest, group, ids)
    return position.get_indexer(smallest[group]).astype(np.int64)


def _open_switched(net, et: str) -> set:
    switch = _table(net, "switch")
    if switch is None:
        return set()
    opened = (switch.et == et).to_numpy() & ~switch.closed.fillna(False).to_numpy(bool)
    opened &= _in_service(switch)
    return set(switch.element[opened].astype(np.int64).tolist())


def _kept_branches(net, table, from_col: str, to_col: str, switch_et: str, position, bus_ok):
    """``(rows, a, b)``: the rows of a branch table that are in service, end on kept buses and
    are not opened by a switch of element type ``switch_et``, with their end positions."""
    a = position.get_indexer(table[from_col])
    b = position.get_indexer(table[to_col])
    ok = _in_service(table) & (a >= 0) & (b >= 0)
    ok[ok] &= bus_ok[a[ok]] & bus_ok[b[ok]]
    opened = _open_switched(net, switch_et)
    if opened:
        ok &= ~table.index.isin(list(opened))
    return table[ok], a[ok], b[ok]


def _branches(net, position: pd.Index, bus_ok: np.ndarray) -> pd.DataFrame:
    """In-service lines and transformers: end positions ``a``, ``b`` (``a`` is the HV side of
    a transformer: ``hv_first``), nominal kV ``v_kv`` of the impedances, ohm, limit kW."""
    vn = net.bus.vn_kv.to_numpy(float)
    parts = []
    line = _table(net, "line")
    if line is not None:
        line, a, b = _kept_branches(net, line, "from_bus", "to_bus", "l", position, bus_ok)
        parallel = _finite(line, "parallel", 1.0)
        length = line.length_km.to_numpy(float)
        i_ka = _finite(line, "max_i_ka", np.nan) * _finite(line, "df", 1.0) * parallel
        raw_i = _finite(line, "max_i_ka", np.nan)
        rated = np.isfinite(raw_i) & (raw_i > 0) & (raw_i < UNLIMITED_KA)
        loading = _finite(line, "max_loading_percent", 100.0) / 100.0
        limit = np.where(rated, SQRT3 * vn[a] * i_ka * 1000.0 * loading, np.inf)
        parts.append(
            pd.DataFrame(
                {
                    "kind": "line",
                    "a": a,
                    "b": b,
                    "hv_first": False,
                    "length_km": length,
                    "r_ohm": line.r_ohm_per_km.to_numpy(float) * length / parallel,
                    "x_ohm": line.x_ohm_per_km.to_numpy(float) * length / parallel,
                    "v_kv": vn[a],
                    "limit_kw": limit,
                },
                index=[f"line{i}" for i in line.index],
            )
        )
    trafo = _table(net, "trafo")
    if trafo is not None:
        trafo, a, b = _kept_branches(net, trafo, "hv_bus", "lv_bus", "t", position, bus_ok)
        parallel = _finite(trafo, "parallel", 1.0)
        sn = trafo.sn_mva.to_numpy(float)
        z = trafo.vk_percent.to_numpy(float) / 100.0
        r = trafo.vkr_percent.to_numpy(float) / 100.0
        x = np.sqrt(np.maximum(z**2 - r**2, 0.0))
        v = vn[b]  # ohm at the LV side's nominal voltage (referred to the source below)
        loading = _finite(trafo, "max_loading_percent", 100.0) / 100.0
        rated = np.isfinite(sn) & (sn > 0)
        limit = sn * _finite(trafo, "df", 1.0) * parallel * 1000.0 * loading
        parts.append(
            pd.DataFrame(
                {
                    "kind": "trafo",
                    "a": a,
                    "b": b,
                    "hv_first": True,
                    "length_km": 0.0,
                    "r_ohm": r * v**2 / sn / parallel,
                    "x_ohm": x * v**2 / sn / parallel,
                    "v_kv": v,
                    "limit_kw": np.where(rated, limit, np.inf),
                    "sn_mva": sn * parallel,
                },
                index=[f"trafo{i}" for i in trafo.index],
            )
        )
    if not parts:
        return pd.DataFrame(
            columns=["kind", "a", "b", "hv_first", "length_km", "r_ohm", "x_ohm", "v_kv",
                     "limit_kw", "sn_mva"]
        ).astype({"a": np.int64, "b": np.int64, "hv_first": bool})  # fmt: skip
    table = pd.concat(parts) if len(parts) > 1 else parts[0]
    return table.astype({"a": np.int64, "b": np.int64, "hv_first": bool})


def _ext_grids(net, position: pd.Index, bus_ok: np.ndarray, rep: np.ndarray) -> pd.DataFrame:
    """In-service ext_grids on in-service buses: index, ``pos`` (representative position).
    A net without any takes its slack ``gen`` rows (``slack=True``) as its sources."""
    ext = _table(net, "ext_grid")
    if ext is None or not _in_service(ext).any():
        gen = _table(net, "gen")
        if gen is None or "slack" not in gen.columns:
            return pd.DataFrame({"pos": np.array([], np.int64)})
        ext = gen[gen.slack.fillna(False).to_numpy(bool)]
    pos = position.get_indexer(ext.bus)
    ok = _in_service(ext) & (pos >= 0)
    ok[ok] &= bus_ok[pos[ok]]
    return pd.DataFrame({"pos": rep[pos[ok]]}, index=ext.index[ok])


def _sources(ext: pd.DataFrame, substation: pd.DataFrame) -> list[tuple[int, str]]:
    """(representative position, label) of every source bus: the LV side of substation
    transformers, or the ext_grid's own bus. Labels start ``ext_grid <index>``."""
    out = []
    for index, pos in ext.pos.items():
        through = substation[substation.a == pos]
        if len(through):
            for trafo_name, lv in through.b.items():
                out.append((int(lv), f"ext_grid {index} via {trafo_name}"))
        else:
            out.append((int(pos), f"ext_grid {index}"))
    return out


def _substation_mva(substation: pd.DataFrame, ext: pd.DataFrame, index, root_pos: int) -> float:
    """Rating (MVA) of the substation transformers from ext_grid ``index`` to the root."""
    rows = substation[(substation.a == ext.pos[index]) & (substation.b == root_pos)]
    return float(rows.sn_mva.sum()) if len(rows) else np.nan


def _pick_roots(sources, component, root_pos, bus_ids) -> list[int]:
    """The source positions of the feeder: ``root_pos`` (no other source in its tree), else
    every source, one per tree (several trees: several feeders, joined by the caller)."""
    if root_pos is not None:
        others = [
            (pos, label) for pos, label in sources
            if component[pos] == component[root_pos] and pos != root_pos
        ]  # fmt: skip
        if others:
            pos, label = others[0]
            raise FeederError(
                f"several sources feed the tree of root bus {bus_ids[root_pos]}: {label} at bus "
                f"{bus_ids[pos]}; take it out of service or name its bus as root (--root BUS)"
            )
        return [root_pos]
    if not sources:
        raise FeederError("the pandapower net has no in-service ext_grid (nor slack gen): name "
                          "the source bus (--root BUS)")  # fmt: skip
    distinct = {}
    for pos, label in sources:
        distinct.setdefault(pos, label)
    trees = [component[pos] for pos in distinct]
    if len(set(trees)) < len(trees):
        named = ", ".join(f"{label} at bus {bus_ids[pos]}" for pos, label in distinct.items())
        raise FeederError(
            f"several sources feed one connected network ({named}): popdispatch supports one "
            "source per radial feeder; take the others out of service"
        )
    return list(distinct)


def _on_kept_buses(table, position: pd.Index, bus_ok: np.ndarray):
    """``(rows, positions)``: the in-service rows of a bus-attached element table whose bus is
    kept, with their bus positions."""
    pos = position.get_indexer(table.bus)
    ok = _in_service(table) & (pos >= 0)
    ok[ok] &= bus_ok[pos[ok]]
    return table[ok], pos[ok]


def _loads(net, position: pd.Index, bus_ok: np.ndarray, rep: np.ndarray) -> pd.DataFrame:
    parts = []
    for key in ("load", "asymmetric_load"):
        table = _table(net, key)
        if table is None:
            continue
        table, pos = _on_kept_buses(table, position, bus_ok)
        scaling = _finite(table, "scaling", 1.0)
        if key == "load":
            p = table.p_mw.to_numpy(float)
            q = _finite(table, "q_mvar", 0.0)
        else:
            p = sum(table[f"p_{ph}_mw"].to_numpy(float) for ph in "abc")
            q = sum(_finite(table, f"q_{ph}_mvar", 0.0) for ph in "abc")
        parts.append(
            pd.DataFrame(
                {
                    "pos": rep[pos],
                    "p_kw": p * scaling * 1000.0,
                    "q_kvar": q * scaling * 1000.0,
                    "kind": "load",
                },
                index=[f"{key}{i}" for i in table.index],
            )
        )
    if not parts:
        return pd.DataFrame({"pos": np.array([], np.int64), "p_kw": [], "q_kvar": [], "kind": []})
    return pd.concat(parts) if len(parts) > 1 else parts[0]


def _check_islands(alive, keep, component, loads, sources, root_pos, bus_ids, root) -> None:
    """Name an island (a live part not in the feeder) that carries load; other trees with a
    source are left out only when ``root`` picked the feeder."""
    loaded = (loads.p_kw.to_numpy() != 0) | (loads.q_kvar.to_numpy() != 0)
    pos = loads.pos.to_numpy()[loaded]
    outside = pos[~keep[pos]]
    if not len(outside):
        return
    fed = {component[p] for p, _ in sources} if root is not None else set()
    for p in outside:
        island = component[p]
        if island in fed:
            continue
        members = np.flatnonzero(alive & (component == island))
        n_loads = int(np.isin(pos, members).sum())
        raise FeederError(
            f"buses {bus_ids[members[:5]].tolist()}{' ...' if len(members) > 5 else ''} "
            f"({len(members)} buses, {n_loads} loads) form an island not connected to source "
            f"bus {bus_ids[root_pos]}: connect it or take its loads out of service"
        )


# -- coordinates -----------------------------------------------------------------------------


def _coordinates(net, bus_table: pd.DataFrame, kept: np.ndarray) -> tuple[np.ndarray, bool]:
    """(x, y) of the kept bus positions, and whether a schematic layout is needed instead."""
    geodata = _table(net, "bus_geodata")
    if geodata is not None and {"x", "y"} <= set(geodata.columns):
        xy = geodata.reindex(bus_table.index[kept])[["x", "y"]].to_numpy(float)
        if np.isfinite(xy).all():
            return xy, False
    if "geo" in bus_table.columns:
        geo = bus_table.geo.to_numpy(object)[kept]
        xy = np.full((len(kept), 2), np.nan)
        for k, value in enumerate(geo):
            if isinstance(value, str):
                try:
                    point = json.loads(value).get("coordinates")
                    xy[k] = float(point[0]), float(point[1])
                except (ValueError, TypeError, AttributeError, IndexError):
                    break
            elif isinstance(value, dict) and "coordinates" in value:
                xy[k] = value["coordinates"][:2]
            else:
                break
        if np.isfinite(xy).all():
            return xy, False
    return np.zeros((len(kept), 2)), True


def _schematic_layout(feeder: Feeder) -> None:
    """x = hops from the source, y = depth-first position (in place: the tables are ours)."""
    tree = feeder.bus_tree()
    depth = np.zeros(tree.n_nodes)
    parent = tree.parent
    for node in tree.preorder[1:]:
        depth[node] = depth[parent[node]] + 1
    feeder.buses["x"] = depth
    feeder.buses["y"] = -tree.start.astype(float)


# -- fleet ---------------------------------------------------------------------------------------


def _user_fleet(fleet: pd.DataFrame, position: pd.Index, rep, bus_ids) -> pd.DataFrame:
    """The user's fleet with buses merged by closed bus-bus switches mapped to their group."""
    fleet = fleet.copy()
    pos = position.get_indexer(fleet.bus.astype(np.int64))
    fleet["bus"] = np.where(pos >= 0, bus_ids[rep[np.maximum(pos, 0)]], fleet.bus).astype(np.int64)
    return fleet


def _costs(net) -> tuple[dict[tuple[str, int], tuple[float, float, float]], set]:
    """``(poly_cost (a, b, c) by (table, index), pwl_cost keys)``."""
    costs = _table(net, "poly_cost")
    cost = {}
    if costs is not None:
        for row in costs.itertuples():
            key = (str(row.et), int(row.element))
            if key in cost:
                raise FleetError(f"{row.et} {row.element} has two poly_cost rows")
            cost[key] = (float(row.cp0_eur), float(row.cp1_eur_per_mw),
                         float(row.cp2_eur_per_mw2))  # fmt: skip
    pwl = _table(net, "pwl_cost")
    pwl_keys = (
        set()
        if pwl is None
        else {(str(e), int(i)) for e, i in zip(pwl.et, pwl.element, strict=True)}
    )
    return cost, pwl_keys


def _fixed_injections(net, position, bus_ok, rep, priced: dict) -> pd.DataFrame:
    """In-service ``gen`` and ``sgen`` rows without a ``poly_cost``: fixed injections, as
    load rows ``<table><index>`` with ``p_kw = -p_mw x scaling x 1000`` (kind: the table)."""
    parts = []
    for et in ("gen", "sgen"):
        table = _table(net, et)
        if table is None:
            continue
        table, pos = _on_kept_buses(table, position, bus_ok)
        if et == "gen" and "slack" in table.columns:
            slack = table.slack.fillna(False).to_numpy(bool)
            table, pos = table[~slack], pos[~slack]
        free = np.array([(et, int(i)) not in priced for i in table.index], dtype=bool)
        table, pos = table[free], pos[free]
        scaling = _finite(table, "scaling", 1.0)
        parts.append(
            pd.DataFrame(
                {
                    "pos": rep[pos],
                    "p_kw": -_finite(table, "p_mw", 0.0) * scaling * 1000.0,
                    "q_kvar": -_finite(table, "q_mvar", 0.0) * scaling * 1000.0,
                    "kind": et,
                },
                index=[f"{et}{i}" for i in table.index],
            )
        )
    return pd.concat(parts) if parts else _no_injections()


def _no_injections() -> pd.DataFrame:
    return pd.DataFrame({"pos": np.array([], np.int64), "p_kw": [], "q_kvar": [], "kind": []})


def _fleet(net, position, bus_ok, rep, keep, ext, roots, substation, costs) -> pd.DataFrame:
    """The priced generators of the feeder (possibly none: a network described without a
    fleet); ``gen``/``sgen`` without a poly_cost are fixed injections instead, ``storage``
    without one stays idle."""
    cost, pwl_keys = costs
    rows, names, unpriced = [], [], []

    def add(et, index, bus_id, pmin_mw, pmax_mw, sign=1.0):
        key = (et, int(index))
        if key not in cost:
            if key in pwl_keys or et == "storage":
                why = "a piecewise-linear cost (pwl_cost)" if key in pwl_keys else "no poly_cost"
                unpriced.append(f"{et} {index} at bus {bus_id} has {why}")
            return
        a, b, c = cost[key]
        rows.append((bus_id, a, sign * b, c, max(pmin_mw, 0.0) * 1000.0, pmax_mw * 1000.0))
        names.append(f"{et}{index}")

    bus_ids = position.to_numpy(np.int64)
    for et in ("gen", "sgen", "storage"):
        table = _table(net, et)
        if table is None:
            continue
        table, pos = _on_kept_buses(table, position, bus_ok)
        kept = keep[rep[pos]]
        table, pos = table[kept], pos[kept]
        sn = _finite(table, "sn_mva", np.nan)
        p = _finite(table, "p_mw", np.nan)
        lo, hi = _finite(table, "min_p_mw", np.nan), _finite(table, "max_p_mw", np.nan)
        for k, index in enumerate(table.index):
            bus_id = int(bus_ids[rep[pos[k]]])
            if et == "storage":
                pmax = -lo[k] if np.isfinite(lo[k]) else sn[k]
                pmin = -hi[k] if np.isfinite(hi[k]) else 0.0
                add(et, index, bus_id, pmin, _known(pmax, et, index), sign=-1.0)
            else:
                pmax = hi[k] if np.isfinite(hi[k]) else sn[k] if np.isfinite(sn[k]) else p[k]
                add(et, index, bus_id, lo[k] if np.isfinite(lo[k]) else 0.0,
                    _known(pmax, et, index))  # fmt: skip
    ext_table = _table(net, "ext_grid")
    for index, pos in ext.pos.items():
        root = next((r for r in roots if pos == r or len(
            substation[(substation.a == pos) & (substation.b == r)]) > 0), None)  # fmt: skip
        if root is None or ext_table is None or ("ext_grid", int(index)) not in cost:
            continue
        row = ext_table.loc[[index]]
        pmax = _finite(row, "max_p_mw", np.nan)[0]
        if not np.isfinite(pmax):
            pmax = _substation_mva(substation, ext, index, root)
        pmin = _finite(row, "min_p_mw", 0.0)[0]
        add("ext_grid", index, int(bus_ids[root]), pmin, _known(pmax, "ext_grid", index))
    if unpriced:
        warnings.warn(
            f"left out of the fleet: {'; '.join(unpriced)} (a dispatch of these needs a fleet: "
            "--fleet FILE)",
            UserWarning,
            stacklevel=4,
        )
    return make_fleet(rows, names)[FLEET_COLUMNS]


def _known(pmax: float, et: str, index) -> float:
    if not np.isfinite(pmax) or pmax < 0:
        raise FleetError(
            f"{et} {index} has no usable max_p_mw (nor sn_mva): give a fleet (--fleet FILE)"
        )
    return float(pmax)


# -- any network, meshed or radial: the DC model's tables ------------------------------------


#: The margin pandapower's conversion widens every generator's limits by (MW, its OPF option
#: ``delta``); the fleet read back takes it off again.
OPF_DELTA_MW = 1e-10


def read_pandapower_network(
    net_or_path, name: str = "", *, fleet: pd.DataFrame | None = None, ratings: bool = True
) -> DcNetwork:
    """A pandapower net of any shape (closed rings, meshes) as a
    :class:`~popdispatch.feeder.dcnet.DcNetwork`, from pandapower's own conversion to its
    internal MATPOWER-format case for a DC OPF (``rundcopp``'s: closed bus-bus switches fuse
    buses, transformers with their taps and shifts, ratings from ``max_loading_percent``; the
    net given is not changed). Buses keep the pandapower index of their fused group's smallest
    member; branches are named ``line<index>``/``trafo<index>``; the fleet is the ext_grids,
    gens and controllable sgens with their ``poly_cost`` (``G<table><index>``, e.g.
    ``Gsgen3``), within their ``min_p_mw``/``max_p_mw``, or ``fleet`` (buses by pandapower
    index); what is not controllable is fixed demand, as in ``rundcopp``. A ``pwl_cost`` of
    the net's own fleet is refused. ``ratings=False``: every line unlimited."""
    import copy

    from pandapower.auxiliary import _add_auxiliary_elements, _init_rundcopp_options
    from pandapower.pd2ppc import _pd2ppc

    net, default = _load(net_or_path)
    net = copy.deepcopy(net)
    pwl = _table(net, "pwl_cost")
    if fleet is None and pwl is not None and len(pwl):
        row = pwl.iloc[0]
        raise FleetError(f"{row.et} {row.element} has a piecewise-linear cost (pwl_cost): "
                         "popdispatch takes polynomial costs (poly_cost) only")  # fmt: skip
    _init_rundcopp_options(net, check_connectivity=True, switch_rx_ratio=2, delta=OPF_DELTA_MW,
                           trafo3w_losses="hv")  # fmt: skip
    _add_auxiliary_elements(net)
    ppc, ppci = _pd2ppc(net)
    lookups = net._pd2ppc_lookups
    bus, branch, gen, cost = ppci["bus"], ppci["branch"], ppci["gen"], ppci.get("gencost")
    ids = _internal_bus_ids(lookups["bus"], len(bus))
    live = bus[:, 1] != 4
    buses = pd.DataFrame({"pd_mw": bus[live, 2], "gs_mw": bus[live, 4]},
                         index=pd.Index(ids[live], name="bus"))  # fmt: skip
    names = np.array([f"branch{k}" for k in range(len(branch))], dtype=object)
    for table, (start, stop) in lookups.get("branch", {}).items():
        if stop - start and len(branch) == len(ppc["branch"]):
            names[start:stop] = [f"{table}{i}" for i in net[table].index[: stop - start]]
    on = branch[:, 10] != 0
    rate = branch[on, 5] * 1e3
    lines = pd.DataFrame(
        {"from_bus": ids[branch[on, 0].astype(int)], "to_bus": ids[branch[on, 1].astype(int)],
         "x_pu": branch[on, 3], "tap": branch[on, 8], "shift_deg": branch[on, 9],
         "limit_kw": np.where((rate > 0) & ratings, rate, np.inf)},
        index=pd.Index(names[on], name="line"),
    )  # fmt: skip
    fleet = _network_fleet(lookups, ids, gen, cost) if fleet is None else as_fleet(fleet)
    slack = int(ids[np.flatnonzero(bus[:, 1] == 3)[0]])
    return DcNetwork(name or default, float(ppci["baseMVA"]), buses, lines, fleet, slack)


def _internal_bus_ids(lookup: np.ndarray, n: int) -> np.ndarray:
    """Per bus of pandapower's internal case, the smallest pandapower bus index mapped to it."""
    ids = np.full(n, -1, dtype=np.int64)
    for pp_bus in range(len(lookup) - 1, -1, -1):
        internal = lookup[pp_bus]
        if 0 <= internal < n:
            ids[internal] = pp_bus
    return ids


def _network_fleet(lookups, ids, gen, cost) -> pd.DataFrame:
    """The fleet of pandapower's internal case: each in-service generator row with its
    polynomial cost (``gencost`` model 2, ``c2 P^2 + c1 P + c0``), named after its element."""
    element = {}
    for table, prefix in (("ext_grid", "ext_grid"), ("gen", "gen"),
                          ("sgen_controllable", "sgen")):  # fmt: skip
        rows = lookups.get(table)
        if rows is None:
            continue
        for index, row in enumerate(np.asarray(rows)):
            if row >= 0:
                element[int(row)] = f"G{prefix}{index}"
    rows, names = [], []
    if cost is None or len(cost) < len(gen):
        raise FleetError("the net's generators have no costs: give each ext_grid, gen and "
                         "controllable sgen a poly_cost")  # fmt: skip
    for k in np.flatnonzero(gen[:, 7] > 0):
        ncost = int(cost[k, 3])
        c = np.concatenate([cost[k, 4 : 4 + ncost][::-1], np.zeros(3)])[:3]
        pmin, pmax = gen[k, 9] + OPF_DELTA_MW, gen[k, 8] - OPF_DELTA_MW  # pandapower's widening
        rows.append((int(ids[int(gen[k, 0])]), c[0], c[1], c[2], pmin * KW_PER_MW,
                     pmax * KW_PER_MW))  # fmt: skip
        names.append(element.get(int(k), f"G{k}"))
    return make_fleet(rows, names)
