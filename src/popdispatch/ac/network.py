"""The full feeder as a positive-sequence power-grid-model network (the AC check's model).

Every bus and line of the plain-table :class:`~popdispatch.feeder.model.Feeder` (not only the
key nodes the engine reduces to) is in the model: power-grid-model solves the network of the
*kept* buses (the source, buses with loads or generators, junctions and ends) joined by
branches that are exact series sums of the lines between them, and every other bus and line
is recovered exactly from its chain's current (:mod:`popdispatch.ac.chains`). A branch with
zero impedance (a switch or busbar coupler) is a power-grid-model ``link``. Rules (docs/ac.md):

- **Nominal voltage** ``vn_kv`` (line-to-line, kV) of every bus: every branch's ohms are
  referred to it (:meth:`~popdispatch.feeder.Feeder.lines_on_base`: ``ohm (vn_kv /
  kv_base)^2`` where the feeder states each branch's own base), so one voltage base serves
  the whole network, transformers included. It comes from, in order: the ``vn_kv``
  argument; a ``vn_kv`` column of the buses table (value at the source bus); a ``kv_ln_base``
  column (line-to-neutral, times sqrt(3)); the known built-in cases (:data:`KNOWN_VN_KV`: ieee-elv
  0.416 kV). Otherwise :class:`~popdispatch.errors.FeederError` asks for it.
- **Source**: an ideal voltage source at the source bus, ``source_pu`` (default 1.0 p.u. of
  ``vn_kv``, angle 0) behind a short-circuit power of :data:`SOURCE_SK_VA` (an internal
  impedance ~1e-17 p.u.: ideal to far below 1e-9 p.u.).
- **Lines**: series ``r_ohm + j x_ohm`` (whole line, positive sequence); no shunt capacitance
  (the feeder tables carry none). Rated current ``i_n = limit_kw / (sqrt(3) vn_kv)`` (A; the
  active power the line carries at unity power factor at nominal voltage), none where
  ``limit_kw`` is ``inf``.
- **Loads**: constant power, active power per time step as given (kW); reactive power
  ``q = p * q_per_kw`` per load, see :func:`load_q_per_kw` (constant power factor).
- **Generators**: constant power at their dispatched active power (kW) and reactive power
  ``q = p tan(acos(generator_pf))`` (default ``generator_pf = 1``: unity power factor; a
  negative value absorbs reactive power).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from popdispatch.ac.chains import Chains, find_chains
from popdispatch.errors import FeederError, OptionError
from popdispatch.feeder.model import Feeder

#: ``pip`` extra that installs power-grid-model.
AC_EXTRA = 'pip install "popdispatch[ac]"'
#: Nominal line-to-line voltage (kV) of the built-in cases whose tables do not carry it.
KNOWN_VN_KV = {"ieee-elv": 0.416}
#: Load power factor (lagging) of the built-in cases whose tables carry no reactive power:
#: ieee-elv's Loads.txt gives every load ``PF=0.95``.
KNOWN_LOAD_PF = {"ieee-elv": 0.95}
#: Short-circuit power of the source (VA): its internal impedance is vn^2 / SOURCE_SK_VA ohm,
#: i.e. 1/SOURCE_SK_VA p.u. on a 1 VA base; an ideal voltage source for every purpose here.
SOURCE_SK_VA = 1e20
W_PER_KW = 1000.0
V_PER_KV = 1000.0


def power_grid_model() -> Any:
    """The ``power_grid_model`` module, or a one-line error naming the extra that installs it."""
    try:
        import power_grid_model
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"the AC check needs power-grid-model: {AC_EXTRA} ({exc})") from exc
    return power_grid_model


@dataclass(frozen=True)
class ACModel:
    """The rules of the AC model (see the module docstring).

    Attributes
    ----------
    vn_kv : nominal line-to-line voltage of the network, kV.
    source_pu : voltage of the ideal source, p.u. of ``vn_kv``.
    load_q_per_kw : per load (feeder order), reactive power per active power, kvar/kW.
    load_q_rule : where ``load_q_per_kw`` comes from, in words.
    generator_pf : generators' power factor (1: unity; negative: absorbing).
    """

    vn_kv: float
    source_pu: float
    load_q_per_kw: np.ndarray
    load_q_rule: str
    generator_pf: float

    @property
    def generator_q_per_kw(self) -> float:
        """Generators' reactive power per active power, kvar/kW (0 at unity power factor)."""
        pf = abs(self.generator_pf)
        return math.copysign(math.tan(math.acos(pf)), self.generator_pf) if pf < 1 else 0.0

    def as_dict(self) -> dict:
        """The rules as JSON-ready values (kV, p.u., words)."""
        return {
            "vn_kv": self.vn_kv,
            "source_pu": self.source_pu,
            "load_q_rule": self.load_q_rule,
            "generator_pf": self.generator_pf,
        }


@dataclass(frozen=True)
class ACNetwork:
    """A feeder as power-grid-model input, with the maps back to its names.

    Attributes
    ----------
    feeder : the full feeder.
    model : the rules (:class:`ACModel`).
    chains : the kept buses and the branches between them (:class:`Chains`).
    input_data : power-grid-model input dataset of the kept buses (SI: V, ohm, W, var, A).
    line_rows, link_rows : the branches (rows of ``chains``) power-grid-model holds as
        ``line`` (with impedance) and ``link`` (without), in the order of its tables.
    rated_a : per feeder line, the rated current, A (NaN: no limit).
    """

    feeder: Feeder
    model: ACModel
    chains: Chains
    input_data: dict
    line_rows: np.ndarray
    link_rows: np.ndarray
    rated_a: np.ndarray

    @property
    def n_buses(self) -> int:
        """Buses of the feeder (all of them, kept or not)."""
        return len(self.feeder.buses)


def nominal_kv(feeder: Feeder, vn_kv: float | None = None) -> float:
    """The network's nominal line-to-line voltage, kV (rules in the module docstring)."""
    if vn_kv is not None:
        if not (math.isfinite(vn_kv) and vn_kv > 0):
            raise OptionError(f"nominal voltage vn_kv = {vn_kv} kV is not positive", "--vn-kv")
        return float(vn_kv)
    buses = feeder.buses
    for column, scale in (("vn_kv", 1.0), ("kv_ln_base", math.sqrt(3.0))):
        if column in buses.columns:
            value = float(buses.at[feeder.source_bus, column]) * scale
            if math.isfinite(value) and value > 0:
                return value
    if feeder.name in KNOWN_VN_KV:
        return KNOWN_VN_KV[feeder.name]
    raise FeederError(
        f"feeder {feeder.name!r} has no nominal voltage: give vn_kv (kV) or a vn_kv column in "
        "its buses table"
    )


def load_q_per_kw(feeder: Feeder, load_pf: float | None = None) -> tuple[np.ndarray, str]:
    """Per load, reactive over active power (kvar/kW), and the rule used, in words.

    In order: ``load_pf`` (every load at that lagging power factor); the loads' own ``q_kvar``
    and ``p_kw`` columns (each load keeps its ratio, i.e. its power factor, at every step; a
    load with ``p_kw`` 0 gets none); a ``pf`` column; the known built-in cases
    (:data:`KNOWN_LOAD_PF`); else unity power factor (the network has no reactive data).
    """
    loads = feeder.loads
    n = len(loads)
    if load_pf is not None:
        return np.full(n, _q_ratio(load_pf, "load_pf")), f"power factor {load_pf:g} (given)"
    if {"q_kvar", "p_kw"} <= set(loads.columns):
        p = loads["p_kw"].to_numpy(float)
        q = loads["q_kvar"].to_numpy(float)
        ratio = np.divide(q, p, out=np.zeros(n), where=p > 0)
        return ratio, "each load's own q_kvar / p_kw (network data)"
    if "pf" in loads.columns:
        ratios = [_q_ratio(pf, f"load {name!r} pf") for name, pf in loads["pf"].items()]
        return np.array(ratios, dtype=float), "each load's own power factor (network data)"
    if feeder.name in KNOWN_LOAD_PF:
        pf = KNOWN_LOAD_PF[feeder.name]
        return np.full(n, _q_ratio(pf, "pf")), f"power factor {pf:g} lagging ({feeder.name} data)"
    return np.zeros(n), "unity power factor (the network has no reactive data)"


def _q_ratio(pf: float, what: str) -> float:
    """tan(acos(pf)) for a lagging power factor in (0, 1]."""
    if not (0 < pf <= 1):
        raise OptionError(f"{what} = {pf} is not a power factor in (0, 1]", "--load-pf")
    return math.tan(math.acos(pf))


def build_network(
    feeder: Feeder,
    *,
    vn_kv: float | None = None,
    source_pu: float = 1.0,
    load_pf: float | None = None,
    generator_pf: float = 1.0,
) -> ACNetwork:
    """The feeder as a power-grid-model network (the rules in the module docstring).

    Parameters
    ----------
    feeder : the full feeder (all buses and lines).
    vn_kv : nominal line-to-line voltage, kV (default: from the network, :func:`nominal_kv`).
    source_pu : voltage of the ideal source at the source bus, p.u.
    load_pf : lagging power factor of every load (default: from the network,
        :func:`load_q_per_kw`).
    generator_pf : generators' power factor; 1 (default) is unity, negative absorbs.
    """
    if not (math.isfinite(source_pu) and 0 < source_pu < 2):
        raise OptionError(f"source voltage {source_pu} p.u. is outside (0, 2)", "--source-pu")
    if not (math.isfinite(generator_pf) and 0 < abs(generator_pf) <= 1):
        raise OptionError(f"generator power factor {generator_pf} is not in (0, 1]", "--gen-pf")
    ratio, rule = load_q_per_kw(feeder, load_pf)
    model = ACModel(nominal_kv(feeder, vn_kv), float(source_pu), ratio, rule, float(generator_pf))
    return _assemble(feeder, model)


def _assemble(feeder: Feeder, model: ACModel) -> ACNetwork:
    """power-grid-model input arrays of the kept buses: ids are nodes 0..n-1 (kept buses in
    feeder order), then branches, source, loads, generators."""
    pgm = power_grid_model()
    init, input_type = pgm.initialize_array, pgm.DatasetType.input
    buses = feeder.buses.index
    chains = find_chains(feeder, model.vn_kv)
    n_node = int(chains.kept.sum())
    node = init(input_type, "node", n_node)
    node["id"] = np.arange(n_node)
    node["u_rated"] = model.vn_kv * V_PER_KV
    z = chains.branch_z_ohm
    zero = z == 0
    line_rows, link_rows = np.flatnonzero(~zero), np.flatnonzero(zero)
    ends = (chains.node[chains.branch_top], chains.node[chains.branch_bottom])
    next_id = n_node
    data = {"node": node}
    for kind, rows in (("line", line_rows), ("link", link_rows)):
        table = init(input_type, kind, len(rows))
        table["id"] = next_id + rows
        table["from_node"], table["to_node"] = ends[0][rows], ends[1][rows]
        table["from_status"] = table["to_status"] = 1
        if kind == "line":
            table["r1"], table["x1"] = z[rows].real, z[rows].imag
            table["c1"] = table["tan1"] = 0.0  # i_n unset: loading is computed per feeder line
        data[kind] = table
    next_id += chains.n_branches
    source = init(input_type, "source", 1)
    source["id"], source["status"] = next_id, 1
    source["node"] = chains.node[buses.get_loc(feeder.source_bus)]
    source["u_ref"], source["u_ref_angle"], source["sk"] = model.source_pu, 0.0, SOURCE_SK_VA
    data["source"] = source
    next_id += 1
    for kind, table in (("sym_load", feeder.loads), ("sym_gen", feeder.generators)):
        units = init(input_type, kind, len(table))
        units["id"] = next_id + np.arange(len(table))
        units["node"] = chains.node[buses.get_indexer(table["bus"])]
        units["status"] = 1
        units["type"] = pgm.LoadGenType.const_power
        units["p_specified"] = units["q_specified"] = 0.0
        data[kind] = units
        next_id += len(table)
    rated_a = rated_current_a(feeder.lines["limit_kw"].to_numpy(float), model.vn_kv)
    return ACNetwork(feeder, model, chains, data, line_rows, link_rows, rated_a)


def rated_current_a(limit_kw: np.ndarray, vn_kv: float) -> np.ndarray:
    """A line's rated current, A: ``limit_kw / (sqrt(3) vn_kv)`` (kW / kV = A; the current of
    ``limit_kw`` at unity power factor and nominal voltage); NaN where the limit is ``inf``."""
    limit_kw = np.asarray(limit_kw, dtype=float)
    return np.where(np.isfinite(limit_kw), limit_kw / (math.sqrt(3.0) * vn_kv), np.nan)


def update_data(network: ACNetwork, load_kw: np.ndarray, generator_kw: np.ndarray) -> dict:
    """power-grid-model batch update: per step, every load's and generator's P and Q (W, var).

    ``load_kw``: (steps, loads) in the feeder's load order, kW; ``generator_kw``: (steps,
    generators) in the feeder's fleet order, kW.
    """
    pgm = power_grid_model()
    model = network.model
    update = {}
    for kind, kw, q_per_kw in (
        ("sym_load", load_kw, model.load_q_per_kw),
        ("sym_gen", generator_kw, model.generator_q_per_kw),
    ):
        table = pgm.initialize_array(pgm.DatasetType.update, kind, kw.shape)
        table["id"] = network.input_data[kind]["id"]
        table["p_specified"] = kw * W_PER_KW
        table["q_specified"] = kw * q_per_kw * W_PER_KW
        update[kind] = table
    return update


def check_step_arrays(
    network: ACNetwork,
    load_kw: np.ndarray,
    generator_kw: np.ndarray,
    steps: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(load_kw, generator_kw)`` as (steps, loads) and (steps, generators) float arrays;
    :class:`OptionError` naming the first non-finite entry (its load or generator and its
    minute, ``steps`` labelling the rows, default 1, 2, ...) or a shape mismatch."""
    feeder = network.feeder
    arrays = []
    for what, values, names in (
        ("load", load_kw, feeder.loads.index),
        ("generator", generator_kw, feeder.generators.index),
    ):
        values = np.atleast_2d(np.asarray(values, dtype=float))
        if values.shape[1] != len(names):
            raise OptionError(
                f"{values.shape[1]} {what} values per step for {len(names)} {what}s of feeder "
                f"{feeder.name!r}"
            )
        bad = ~np.isfinite(values)
        if bad.any():
            row, k = np.argwhere(bad)[0]
            minute = steps[row] if steps is not None else row + 1
            raise OptionError(f"{what} {names[k]!r} has {values[row, k]} kW at minute {minute}")
        arrays.append(np.ascontiguousarray(values))
    if len(arrays[0]) != len(arrays[1]):
        raise OptionError(f"{len(arrays[0])} steps of loads but {len(arrays[1])} of set points")
    if steps is not None and len(steps) != len(arrays[0]):
        raise OptionError(f"{len(steps)} minutes for {len(arrays[0])} steps of loads")
    return arrays[0], arrays[1]
