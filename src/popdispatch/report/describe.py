"""What a feeder is, for people: ``popdispatch feeder`` (JSON object and text).

Any network is described, with or without a fleet: its buses, the source (or the sources of
several feeders joined for one run), its loads by name with their kW, its fixed injections, its
lines with their ratings and impedances, its load shapes, and the generators a run dispatches.
Buses are named as the source format names them (:meth:`popdispatch.feeder.Feeder.bus_labels`).
"""

from __future__ import annotations

import math

import numpy as np

from popdispatch.constants import KW_PER_MW
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.fusion import (
    ideal_connections,
    threshold_phrase,
    zero_reactance_threshold,
)
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.radial import balance_lines
from popdispatch.feeder.reduction import ReducedFeeder
from popdispatch.feeder.shapes import SERIES, default_series

#: What a run without a fleet needs, said where a feeder has none.
NO_FLEET = "no fleet: opf, snapshot, day and agents need --fleet FILE, its buses named as here"


def feeder_summary(feeder: Feeder, reduced: ReducedFeeder, ratings: bool = True) -> dict:
    """The ``popdispatch feeder`` JSON object: counts, the source, the loads, lines and
    generators (kW; buses as the source format names them). ``ratings``: whether the
    network's own ratings were read (``--no-ratings`` not given)."""
    ids = feeder.buses.index.tolist()
    labels = dict(zip(ids, feeder.bus_labels(ids), strict=True))
    gens = reduced.generators
    loads = feeder.loads
    p_kw = loads["p_kw"].to_numpy(float) if "p_kw" in loads else np.full(len(loads), np.nan)
    kind = loads["kind"].astype(str).to_numpy() if "kind" in loads else np.full(len(loads), "load")
    balance = set(balance_lines(feeder.lines))
    lines = feeder.lines
    rated = np.isfinite(lines["limit_kw"].to_numpy(float)) & ~lines.index.isin(list(balance))
    return {
        "case": feeder.name,
        "meshed": False,
        "buses": len(feeder.buses),
        "original_lines": len(lines),
        "source_bus": labels[feeder.source_bus],
        "feeder_sources": [labels[int(b)] for b in lines.loc[list(balance), "to_bus"]],
        "nodes": reduced.n_nodes,
        "key_node_buses": feeder.bus_labels(reduced.nodes.bus),
        "lines": reduced.n_lines,
        "loads": int((kind == "load").sum()),
        "load_kw": _total(p_kw[kind == "load"]),
        "fixed_injections": int((kind != "load").sum()),
        "fixed_injection_kw": _total(-p_kw[kind != "load"]),
        "ratings": "the network's own" if ratings else "none (--no-ratings)",
        "rated_lines": int(rated.sum()),
        "series": _series(feeder),
        "load_table": [
            {"name": str(name), "bus": labels[bus], "p_kw": _number(kw), "kind": str(k)}
            for name, bus, kw, k in zip(
                loads.index, loads["bus"].tolist(), p_kw.tolist(), kind, strict=True
            )
        ],
        "line_table": _line_table(feeder, labels, balance),
        "generators": [
            {
                "name": name,
                "bus": labels[int(row.bus)],
                "node": int(row.node),
                "a_eur": float(row.a),
                "b_eur_per_mwh": float(row.b),
                "c_eur_per_mw2h": float(row.c),
                "pmin_kw": float(row.pmin_kw),
                "pmax_kw": float(row.pmax_kw),
            }
            for name, row in gens.iterrows()
        ],
        "capacity_kw": float(gens.pmax_kw.sum()),
        "fleet_note": None if len(gens) else NO_FLEET,
    }


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _total(values: np.ndarray) -> float | None:
    return None if np.isnan(values).any() else float(values.sum())


def _line_table(feeder: Feeder, labels: dict, balance: set) -> list[dict]:
    lines = feeder.lines
    n = len(lines)
    kinds = lines["kind"].astype(str).tolist() if "kind" in lines else ["line"] * n
    kv = lines["kv_base"].to_numpy(float) if "kv_base" in lines else np.full(n, np.nan)
    names = lines.index.astype(str).tolist()
    columns = zip(
        names, lines.from_bus.tolist(), lines.to_bus.tolist(), kinds,
        lines.length_km.to_numpy(float).tolist(), lines.r_ohm.to_numpy(float).tolist(),
        lines.x_ohm.to_numpy(float).tolist(), kv.tolist(),
        lines.limit_kw.to_numpy(float).tolist(), strict=True,
    )  # fmt: skip
    return [
        {
            "name": name,
            "from_bus": labels[a],
            "to_bus": labels[b],
            "kind": "balance" if name in balance else kind,
            "length_km": length,
            "r_ohm": r,
            "x_ohm": x,
            "kv_base": _number(base),
            "limit_kw": _number(limit),
        }
        for name, a, b, kind, length, r, x, base, limit in columns
    ]


def _series(feeder: Feeder) -> dict:
    """The load shapes per kind of series (``--series``): shapes used and steps, and the
    default (the one the loads use)."""
    loads = feeder.loads
    if not set(SERIES) <= set(loads.columns):
        return {"default": None}
    out: dict = {"default": default_series(loads)}
    for kind in SERIES:
        used = sorted(set(loads[kind].fillna("").astype(str)) - {""})
        shapes = [feeder.shapes[n] for n in used if n in feeder.shapes]
        if shapes:
            step = min(s.hours for s in shapes)
            steps = int(round(max(s.duration_hours for s in shapes) / step))
            out[kind] = {"shapes": len(used), "steps": steps, "step_hours": step}
    return out


def feeder_text(summary: dict) -> str:
    """``popdispatch feeder``: the summary, then every load and line (the names a fleet file,
    ``--limit`` and ``--root`` take)."""
    s = summary
    head = [
        f"feeder {s['case']}: {s['buses']} buses, {s['original_lines']} lines, "
        f"source bus {s['source_bus']}",
        f"reduced to {s['nodes']} key nodes and {s['lines']} lines",
        f"{s['loads']} loads, {_kw(s['load_kw'])}",
    ]
    if s["feeder_sources"]:
        sources = ", ".join(map(str, s["feeder_sources"]))
        head.insert(1, f"{len(s['feeder_sources'])} feeders (sources {sources}) joined at a "
                       "virtual bus by balance lines of 0 kW: each is balanced by its own "
                       "generators")  # fmt: skip
    if s["fixed_injections"]:
        head.append(f"{s['fixed_injections']} fixed injections (no cost data, not dispatched), "
                    f"{_kw(s['fixed_injection_kw'])}")  # fmt: skip
    head.append(f"line ratings: {s['ratings']}; {s['rated_lines']} of "
                f"{s['original_lines']} lines limited")  # fmt: skip
    head.append(_series_text(s["series"]))
    head.append(_generators_text(s))
    loads = [f"{'load':<24}{'bus':>16}{'kW':>12}  kind"]
    loads += [f"{r['name']:<24}{str(r['bus']):>16}{_num(r['p_kw']):>12}  {r['kind']}"
              for r in s["load_table"]]  # fmt: skip
    lines = [f"{'line':<28}{'from':>16}{'to':>16}{'limit kW':>11}{'r ohm':>11}{'kV':>8}  kind"]
    lines += [
        f"{r['name']:<28}{str(r['from_bus']):>16}{str(r['to_bus']):>16}"
        f"{_num(r['limit_kw'], 'none'):>11}{r['r_ohm']:>11.4g}{_num(r['kv_base'], '-'):>8}"
        f"  {r['kind']}"
        for r in s["line_table"]
    ]
    note = "impedances: each line's own ohms, on its own voltage base (kV)"
    return "\n".join(head + ["", "loads:"] + loads + ["", f"lines ({note}):"] + lines)


def network_summary(net: DcNetwork, ratings: bool = True) -> dict:
    """The ``popdispatch feeder`` JSON object of a meshed network (MATPOWER's DC model,
    :class:`~popdispatch.feeder.dcnet.DcNetwork`): counts, the slack bus, loads (kW), shunts,
    lines (per-unit reactance, tap, shift, limit in kW), the zero-reactance lines joined as
    ideal connections (how many, the buses they join, the groups those form, and the reactance
    in p.u. below which a line is one: :func:`~popdispatch.feeder.fusion.zero_reactance`) and
    generators."""
    loads, lines, gens = net.loads, net.lines, net.generators
    limit = lines.limit_kw.to_numpy(float)
    label = dict(zip(net.buses.index, net.bus_labels(net.buses.index), strict=True))
    zero, joined, groups = ideal_connections(net.buses.index, lines)
    return {
        "case": net.name,
        "meshed": True,
        "buses": len(net.buses),
        "original_lines": len(lines),
        "loops": len(lines) - len(net.buses) + 1,
        "zero_reactance_lines": zero,
        "fused_buses": joined,
        "fused_groups": groups,
        "zero_reactance_threshold_pu": zero_reactance_threshold(lines),
        "slack_bus": label[net.slack_bus],
        "base_mva": net.base_mva,
        "loads": len(loads),
        "load_kw": float(loads.p_kw.sum()),
        "shunt_kw": float(net.buses.gs_mw.sum() * KW_PER_MW),
        "ratings": "the network's own" if ratings else "none (--no-ratings)",
        "rated_lines": int(np.isfinite(limit).sum()),
        "load_table": [{"name": str(name), "bus": label[bus], "p_kw": float(kw), "kind": "load"}
                       for name, bus, kw in zip(loads.index, loads.bus, loads.p_kw, strict=True)],
        "line_table": [
            {"name": str(name), "from_bus": label[row.from_bus], "to_bus": label[row.to_bus],
             "x_pu": float(row.x_pu), "tap": float(row.tap), "shift_deg": float(row.shift_deg),
             "limit_kw": _number(row.limit_kw)}
            for name, row in lines.iterrows()
        ],
        "generators": [
            {"name": str(name), "bus": label[row.bus], "a_eur": float(row.a),
             "b_eur_per_mwh": float(row.b), "c_eur_per_mw2h": float(row.c),
             "pmin_kw": float(row.pmin_kw), "pmax_kw": float(row.pmax_kw)}
            for name, row in gens.iterrows()
        ],
        "capacity_kw": float(gens.pmax_kw.sum()),
        "fleet_note": None if len(gens) else NO_FLEET,
    }  # fmt: skip


def network_text(summary: dict) -> str:
    """``popdispatch feeder`` on a meshed network: the summary, then every load and line."""
    s = summary
    head = [
        f"network {s['case']}: {s['buses']} buses, {s['original_lines']} lines "
        f"({s['loops']} independent loops), slack bus {s['slack_bus']}; MATPOWER's DC model "
        f"on {s['base_mva']:g} MVA (docs/meshed.md)",
        f"{s['loads']} loads, {_kw(s['load_kw'])}; shunt conductances {_kw(s['shunt_kw'])} at "
        "1 p.u.",
        f"line ratings: {s['ratings']}; {s['rated_lines']} of {s['original_lines']} lines "
        "limited",
        *_ideal_text(s),
        _generators_text(s),
    ]
    loads = [f"{'load':<24}{'bus':>16}{'kW':>12}"]
    loads += [f"{r['name']:<24}{str(r['bus']):>16}{_num(r['p_kw']):>12}" for r in s["load_table"]]
    lines = [f"{'line':<28}{'from':>16}{'to':>16}{'limit kW':>11}{'x p.u.':>11}{'tap':>8}"
             f"{'shift deg':>10}"]  # fmt: skip
    lines += [
        f"{r['name']:<28}{str(r['from_bus']):>16}{str(r['to_bus']):>16}"
        f"{_num(r['limit_kw'], 'none'):>11}"
        f"{r['x_pu']:>11.4g}{r['tap']:>8.4g}{r['shift_deg']:>10.4g}"
        for r in s["line_table"]
    ]
    return "\n".join(head + ["", "loads:"] + loads + ["", "lines:"] + lines)


def _ideal_text(s: dict) -> list[str]:
    """The line on a meshed network's zero-reactance lines (none without any)."""
    if not s["zero_reactance_lines"]:
        return []
    below = threshold_phrase(s["zero_reactance_threshold_pu"])
    return [f"ideal connections: {s['zero_reactance_lines']} zero-reactance line(s){below} join "
            f"{s['fused_buses']} buses into {s['fused_groups']} group(s), each at one angle; "
            "their flows from Kirchhoff's current law"]  # fmt: skip


def _generators_text(s: dict) -> str:
    if not s["generators"]:
        return f"generators: none ({s['fleet_note']})"
    gens = ", ".join(f"{g['name']} (bus {g['bus']}, {g['pmax_kw']:g} kW)" for g in s["generators"])
    return f"generators: {gens}\ntotal capacity: {s['capacity_kw']:g} kW"


def _kw(value: float | None) -> str:
    return "kW unknown" if value is None else f"{value:.3f} kW"


def _num(value: float | None, missing: str = "-") -> str:
    return missing if value is None else f"{value:.6g}"


def _series_text(series: dict) -> str:
    kinds = [k for k in SERIES if k in series]
    if not kinds:
        return "load shapes: none (runs on the network's own loads, one step)"
    parts = [
        f"{k} ({series[k]['shapes']} shapes, {series[k]['steps']} steps of "
        f"{series[k]['step_hours']:g} h)" + (", the default" if k == series["default"] else "")
        for k in kinds
    ]
    return "load shapes (--series): " + "; ".join(parts)


__all__ = ["NO_FLEET", "feeder_summary", "feeder_text", "network_summary", "network_text"]
