"""Export one minute of a dispatch problem for MATPOWER or pandapower, to cross-check the DC-OPF.

The exported case is the *reduced* feeder (key nodes, merged lines) with its generators, their
Table I costs, the loads of the chosen minute and the line limits. Buses keep their original
numbers (bus 1 = source). Units in the files are the tools' own: MW, MVA, p.u. on
``baseMVA = 1`` and ``baseKV`` the source bus's nominal line-to-line voltage (the reduced
feeder's ohms are on it; 0.416 kV for the ieee-elv case, or where a network states none).
Costs are polynomial in MW, EUR/h: ``a + b P + c P^2`` exactly as in the paper (eq. 2).
Fixed injections are the negative part of the buses' loads. The pandapower net's slack
generator marks its source, so popdispatch reads the file back as it wrote it.

- MATPOWER (``.m``): ``mpc.bus``, ``mpc.gen``, ``mpc.branch`` (``rateA`` = limit in MVA, 0 =
  unlimited) and ``mpc.gencost`` (model 2); ``rundcopf('file.m')`` solves the same DC-OPF.
- pandapower (JSON): a net with ``bus`` (index = original bus), ``line`` (limits through
  ``max_i_ka`` at 100 % loading), ``load``, controllable ``gen`` with ``poly_cost``; the
  generator at the source bus is the slack; ``pandapower.rundcopp(net)`` solves it. Built by
  the package's one pandapower builder (:mod:`popdispatch.ac.pandapower_net`), as the AC OPF
  anchor's net is.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.report.output import atomic_write, atomic_write_text

BASE_MVA = 1.0
BASE_KV = 0.416
FORMATS = ("matpower", "pandapower")


def base_kv(problem: DispatchProblem) -> float:
    """The exported case's voltage base, kV (see the module docstring)."""
    return problem.feeder.original.base_kv or BASE_KV


def case_tables(problem: DispatchProblem, minute: int, load_kw: np.ndarray) -> dict:
    """Buses, lines, loads and generators of the reduced feeder at ``minute`` (kW, ohm).

    ``load_kw``: per-load demand (kW) in the order of ``problem.feeder.original.loads``.
    """
    reduced = problem.feeder
    nodes = reduced.nodes
    buses = pd.DataFrame(
        {"bus": nodes.bus.to_numpy(), "pd_kw": reduced.load_injection_kw(load_kw)},
        index=nodes.index,
    )
    lines = reduced.lines.assign(
        from_bus=nodes.bus.to_numpy()[reduced.lines.from_node],
        to_bus=nodes.bus.to_numpy()[reduced.lines.to_node],
    )
    loads = reduced.loads.assign(p_kw=np.asarray(load_kw, float))
    gens = reduced.generators.assign(online=problem.online[minute - 1])
    source = int(reduced.original.source_bus)
    return {"buses": buses, "lines": lines, "loads": loads, "generators": gens, "source": source}


# -- MATPOWER -----------------------------------------------------------------------------------


def _rows(values) -> str:
    return "\n".join("\t" + "\t".join(_num(v) for v in row) + ";" for row in values)


def _num(value) -> str:
    return f"{value:.12g}" if isinstance(value, float) else str(value)


def matpower_text(problem: DispatchProblem, minute: int, load_kw: np.ndarray, name: str) -> str:
    """A MATPOWER case file (version 2) of the reduced feeder at ``minute``."""
    t = case_tables(problem, minute, load_kw)
    kv = base_kv(problem)
    zbase = kv**2 / BASE_MVA
    gen_buses = set(t["generators"].bus.astype(int))
    bus_rows = [
        (
            int(b),
            3 if b == t["source"] else (2 if b in gen_buses else 1),
            pd_kw / KW_PER_MW,
            0.0,
            0.0,
            0.0,
            1,
            1.0,
            0.0,
            kv,
            1,
            1.1,
            0.9,
        )
        for b, pd_kw in zip(t["buses"].bus, t["buses"].pd_kw, strict=True)
    ]
    gens = t["generators"]
    gen_rows = [
        (
            int(g.bus),
            0.0,
            0.0,
            g.pmax_kw / KW_PER_MW,
            -g.pmax_kw / KW_PER_MW,
            1.0,
            BASE_MVA,
            int(g.online),
            g.pmax_kw / KW_PER_MW,
            g.pmin_kw / KW_PER_MW,
        )
        + (0.0,) * 11
        for g in gens.itertuples()
    ]
    branch_rows = [
        (
            int(ln.from_bus),
            int(ln.to_bus),
            ln.r_ohm / zbase,
            ln.x_ohm / zbase,
            0.0,
            ln.limit_kw / KW_PER_MW if math.isfinite(ln.limit_kw) else 0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            1,
            -360.0,
            360.0,
        )
        for ln in t["lines"].itertuples()
    ]
    cost_rows = [(2, 0.0, 0.0, 3, float(g.c), float(g.b), float(g.a)) for g in gens.itertuples()]
    names = "; ".join(f"'{n}'" for n in gens.index)
    return f"""function mpc = {name}
%{name.upper()}  Reduced {problem.feeder.original.name} feeder at minute {minute}.
%   Written by popdispatch: {problem.feeder.n_nodes} key nodes, {problem.feeder.n_lines} lines.
%   Loads: {problem.profile_source}.
%   Powers in MW, impedances in p.u. (baseMVA {BASE_MVA:g}, baseKV {kv:g}),
%   branch rateA = line limit in MVA (0 = unlimited), costs in EUR/h with P in MW.
%   Cross-check: rundcopf('{name}').

%% MATPOWER Case Format : Version 2
mpc.version = '2';
mpc.baseMVA = {BASE_MVA:g};

%% bus data
%\tbus_i\ttype\tPd\tQd\tGs\tBs\tarea\tVm\tVa\tbaseKV\tzone\tVmax\tVmin
mpc.bus = [
{_rows(bus_rows)}
];

%% generator data ({names})
%\tbus\tPg\tQg\tQmax\tQmin\tVg\tmBase\tstatus\tPmax\tPmin\tPc1\tPc2\tQc1min\tQc1max\tQc2min\tQc2max\tramp_agc\tramp_10\tramp_30\tramp_q\tapf
mpc.gen = [
{_rows(gen_rows)}
];

%% branch data
%\tfbus\ttbus\tr\tx\tb\trateA\trateB\trateC\tratio\tangle\tstatus\tangmin\tangmax
mpc.branch = [
{_rows(branch_rows)}
];

%% generator cost data (polynomial: c2 c1 c0, EUR/h with P in MW)
%\t2\tstartup\tshutdown\tn\tc2\tc1\tc0
mpc.gencost = [
{_rows(cost_rows)}
];
"""


def matlab_name(path: Path) -> str:
    """A valid MATLAB function name from a file name (MATLAB calls the file by its name)."""
    name = re.sub(r"\W", "_", path.stem)
    return name if re.match(r"[A-Za-z]", name) else f"case_{name}"


# -- pandapower ---------------------------------------------------------------------------------


def pandapower_net(problem: DispatchProblem, minute: int, load_kw: np.ndarray):
    """A pandapower net of the reduced feeder at ``minute`` (see module docstring), built by
    :func:`popdispatch.ac.pandapower_net.pandapower_network` (``gen`` form)."""
    from popdispatch.ac.pandapower_net import pandapower_network

    t = case_tables(problem, minute, load_kw)
    lines = t["lines"].rename(index=lambda number: f"line {number}")
    loads = t["loads"].assign(q_kvar=0.0)
    net, _ = pandapower_network(
        t["buses"].bus, lines, loads, t["generators"], t["source"], base_kv(problem),
        dispatchable="gen", name=f"{problem.feeder.original.name} minute {minute}",
    )  # fmt: skip
    return net


# -- writing ------------------------------------------------------------------------------------


def write_case(
    path: str | Path, fmt: str, problem: DispatchProblem, minute: int, load_kw: np.ndarray
) -> Path:
    """Write the case as ``fmt`` (``matpower`` or ``pandapower``) to ``path``, atomically."""
    path = Path(path)
    if fmt == "matpower":
        return atomic_write_text(path, matpower_text(problem, minute, load_kw, matlab_name(path)))
    if fmt == "pandapower":
        import pandapower as pp

        net = pandapower_net(problem, minute, load_kw)
        return atomic_write(path, lambda tmp: pp.to_json(net, str(tmp)))
    raise ValueError(f"unknown export format {fmt!r} (known: {', '.join(FORMATS)})")
