"""The dispatch problem as engine arrays, in MW (paper eq. 1): fleet, demand, limited lines.

Everything people give in kW is converted here, once. Flows on the limited lines are affine in
the set points: ``flow = load_flow - D @ p`` where ``D[k, i] = 1`` if generator ``i`` sits below
line ``k`` (on its child side) and ``load_flow`` is the flow the loads alone would cause. The
engine never forms ``D``: it works on the tree of limited lines (:mod:`popdispatch.game.flows`);
``D`` is built on demand for the DC-OPF and reports.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import pandas as pd

from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FleetError, InfeasibleError, ProfileError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.profiles import LoadProfiles, check_minute
from popdispatch.feeder.reduction import ReducedFeeder
from popdispatch.feeder.tree import downstream, line_flows, selected_line_flows
from popdispatch.game.flows import limited_ancestors


@dataclass(frozen=True)
class DispatchProblem:
    """Engine data of one feeder, fleet and day of loads. Powers in MW, costs in EUR.

    Attributes
    ----------
    generators : generator names (order of every per-generator array).
    a, b, c : cost coefficients, EUR, EUR/MW, EUR/MW^2 (eq. 2).
    pmin, pmax : generator limits, MW.
    lines : reduced line numbers of the limited lines (finite ``limit_kw``).
    limit : their flow limits U, MW.
    line_up : per limited line, the nearest limited line above it (towards the source), -1.
    line_preorder : the limited lines in tree pre-order (every line after the one above it).
    generator_line : per generator, the nearest limited line above its node, -1 if none.
    demand : total demand per minute, MW, shape (minutes,) (1440 for a day).
    load_flow : the loads-only value of every controller's measurement, (minutes, lines + 2
        voltage rows): the flow on each limited line caused by the loads alone (MW), then, in
        a problem with voltage limits, each monitored bus's loads-only excess over its lower
        and its upper bound, ``(vmin^2 - v0^2) / s`` and ``(v0^2 - vmax^2) / s`` (MW
        equivalents, ``s`` = :attr:`voltage_scale`; :mod:`popdispatch.modes.voltage`). The
        voltage columns ride in this array so that every per-minute record the engine builds
        (``MinuteInputs``, the day loop's rows) carries them unchanged.
    online : per minute and generator, whether it is available, (minutes, generators).
    profile_source : where the loads come from.
    voltage_buses : original bus ids of the buses whose voltage is kept within limits (empty
        without voltage limits; :func:`popdispatch.ac.lindistflow.with_voltage_limits`).
    voltage_sens : ``(voltage rows, generators)``: LinDistFlow ``d(v_j^2)/d(p_i)`` divided by
        ``voltage_scale[j]`` (per MW over p.u.^2 per MW: dimensionless, largest spread 1).
    voltage_scale : per voltage row, ``s_j`` = the spread of ``d(v_j^2)/d(p_i)`` over the
        generators, p.u.^2 per MW.
    voltage_base : per minute and voltage row, the loads-only squared voltage ``v0_j^2``,
        p.u.^2 (LinDistFlow, loads at their reactive power).
    vmin_pu, vmax_pu : the voltage limits, p.u. (NaN without).
    fixed_injection : per minute, the fixed injections' total output, MW (the negative parts
        of the per-load series: generators without cost data following their profiles;
        ``demand`` is net of it). Zeros where there are none.
    factor : on a meshed network (:mod:`popdispatch.game.mesh`; ``feeder`` is then its
        :class:`~popdispatch.feeder.dcnet.DcNetwork`), ``(limited lines, generators)``: the
        coefficient ``D_ki`` of generator ``i`` on limited line ``k``, minus its PTDF (MW per
        MW, withdrawn at the slack); ``None`` on a radial feeder, whose coefficients are the
        tree's 0/1 (:attr:`down`) and whose engine works on the tree of limited lines.
    """

    feeder: ReducedFeeder | DcNetwork
    generators: pd.Index
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    pmin: np.ndarray
    pmax: np.ndarray
    lines: np.ndarray
    limit: np.ndarray
    line_up: np.ndarray
    line_preorder: np.ndarray
    generator_line: np.ndarray
    demand: np.ndarray
    load_flow: np.ndarray
    online: np.ndarray
    profile_source: str
    voltage_buses: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    voltage_sens: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    voltage_scale: np.ndarray = field(default_factory=lambda: np.zeros(0))
    voltage_base: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    vmin_pu: float = float("nan")
    vmax_pu: float = float("nan")
    fixed_injection: np.ndarray = field(default_factory=lambda: np.zeros(0))
    factor: np.ndarray | None = None

    @property
    def meshed(self) -> bool:
        """Whether the limited lines' coefficients are a network's distribution factors
        (:attr:`factor`, :mod:`popdispatch.game.mesh`) rather than the radial tree's."""
        return self.factor is not None

    @property
    def n_generators(self) -> int:
        return len(self.generators)

    @property
    def n_voltage(self) -> int:
        """Monitored buses (voltage rows; 0 without voltage limits)."""
        return len(self.voltage_buses)

    @property
    def line_load_flow(self) -> np.ndarray:
        """``(minutes, limited lines)``: the loads-only flows of the limited lines, MW."""
        return self.load_flow[:, : len(self.limit)]

    def voltage_sq(self, p: np.ndarray, minute: int) -> np.ndarray:
        """LinDistFlow squared voltages (p.u.^2) of the monitored buses for set points ``p``
        (MW, shape (..., generators)) at a 1-based minute."""
        if not self.n_voltage:
            return np.zeros(np.shape(p)[:-1] + (0,))
        sens = self.voltage_sens * self.voltage_scale[:, None]
        return self.voltage_base[minute - 1] + np.asarray(p) @ sens.T

    @cached_property
    def down(self) -> np.ndarray:
        """``(limited lines, generators)``: 1.0 where the generator is below the line (dense;
        for the DC-OPF and reports, never for the engine). On a meshed network, the
        distribution factors :attr:`factor` (which the engine does use)."""
        if self.factor is not None:
            return self.factor
        nodes = self.feeder.generators["node"].to_numpy()
        return downstream(self.feeder.tree, nodes)[self.lines].astype(float)

    def flows(self, p: np.ndarray, minute: int) -> np.ndarray:
        """Flows (MW) on the limited lines for set points ``p`` (MW) at a 1-based minute."""
        return self.line_load_flow[minute - 1] - self.down @ p

    def all_line_flows_mw(self, p: np.ndarray, minute: int, load_kw: np.ndarray) -> np.ndarray:
        """Flows (MW) on every reduced line for set points ``p`` (MW) and per-load kW."""
        injection = -self.feeder.load_injection_kw(load_kw) / KW_PER_MW
        np.add.at(injection, self.feeder.generators["node"].to_numpy(), p)
        return line_flows(self.feeder.tree, injection)

    def with_outage(
        self, generator: str, off_minute: int, on_minute: int | None = None, check: bool = True
    ):
        """The same problem with ``generator`` offline from step ``off_minute`` until step
        ``on_minute`` (excluded; ``None``: to the end), 1-based steps of the problem's series
        (minutes of the ELV day, quarter hours of a SimBench year, ...).

        ``check``: raise :class:`InfeasibleError` if the demand of some step then exceeds the
        online capacity (:func:`check_capacity`); without it the problem is kept as it is (a
        day with such steps runs them; their DC-OPF is infeasible).
        """
        if generator not in self.generators:
            raise ValueError(f"unknown generator {generator!r}")
        check_minute(off_minute, len(self.demand))
        if on_minute is not None:
            check_minute(on_minute, len(self.demand) + 1)
        online = self.online.copy()
        stop = on_minute - 1 if on_minute is not None else len(online)
        online[off_minute - 1 : stop, self.generators.get_loc(generator)] = False
        problem = replace(self, online=online)
        if check:
            check_capacity(problem)
        return problem


def build_problem(
    feeder: ReducedFeeder, profiles: LoadProfiles, check: bool = True
) -> DispatchProblem:
    """Assemble the engine arrays for a reduced feeder and a day of load profiles.

    ``check``: raise :class:`InfeasibleError` if some minute's demand is outside the fleet's
    range (:func:`check_capacity`); the CLI checks only the minutes it runs instead.
    """
    profiles = profiles.for_loads(feeder.original.loads.index)
    return build_problem_from_loads(feeder, profiles.kw.to_numpy(float), profiles.source, check)


def build_problem_from_loads(
    feeder: ReducedFeeder, load_kw: np.ndarray, source: str, check: bool = True
) -> DispatchProblem:
    """Engine arrays from per-load demand ``load_kw`` (kW, shape (minutes, loads) in the order
    of ``feeder.original.loads``); any number of minutes (1440 for a day, 1 for a snapshot).
    ``check`` as in :func:`build_problem`."""
    gens = feeder.generators
    if not len(gens):
        raise FleetError(
            f"feeder {feeder.original.name!r} has no generator to dispatch: give a fleet "
            "(--fleet FILE)"
        )
    load_kw = np.atleast_2d(np.asarray(load_kw, dtype=float))
    limited = np.flatnonzero(np.isfinite(feeder.lines.limit_kw.to_numpy(float)))
    flows_kw = selected_line_flows(feeder.tree, -feeder.load_injection_kw(load_kw), limited)
    line_up, line_preorder, generator_line = limited_line_tree(feeder, limited)
    problem = DispatchProblem(
        feeder=feeder,
        **fleet_columns(gens),
        lines=limited,
        limit=feeder.lines.limit_kw.to_numpy(float)[limited] / KW_PER_MW,
        line_up=line_up,
        line_preorder=line_preorder,
        generator_line=generator_line,
        demand=load_kw.sum(axis=1) / KW_PER_MW,
        load_flow=flows_kw / KW_PER_MW,
        online=np.ones((len(load_kw), len(gens)), dtype=bool),
        profile_source=source,
        fixed_injection=fixed_injection_kw(load_kw) / KW_PER_MW,
    )
    if check:
        check_capacity(problem)
    return problem


def fleet_columns(gens: pd.DataFrame) -> dict:
    """The fleet's columns as :class:`DispatchProblem` takes them: ``generators`` (names),
    ``a`` (EUR/h), ``b`` (EUR/MWh), ``c`` (EUR/MW^2h), ``pmin`` and ``pmax`` (MW, from the
    table's kW)."""
    return {
        "generators": gens.index,
        "a": gens.a.to_numpy(float),
        "b": gens.b.to_numpy(float),
        "c": gens.c.to_numpy(float),
        "pmin": gens.pmin_kw.to_numpy(float) / KW_PER_MW,
        "pmax": gens.pmax_kw.to_numpy(float) / KW_PER_MW,
    }


def fixed_injection_kw(load_kw: np.ndarray) -> np.ndarray:
    """Per step, the fixed injections' output (kW): minus the negative per-load values."""
    negative = np.flatnonzero((load_kw < 0).any(axis=0))
    return -np.minimum(load_kw[:, negative], 0.0).sum(axis=1)


def limited_line_tree(
    feeder: ReducedFeeder, limited: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(line_up, line_preorder, generator_line)`` of the limited lines (see the class)."""
    tree = feeder.tree
    limited_index = np.full(tree.n_lines, -1, dtype=np.int64)
    limited_index[limited] = np.arange(len(limited))
    nearest = limited_ancestors(tree.preorder, tree.parent, tree.parent_line, limited_index)
    line_up = nearest[tree.line_parent[limited]]
    line_preorder = np.argsort(tree.start[tree.line_child[limited]], kind="stable")
    generator_line = nearest[feeder.generators["node"].to_numpy()]
    return line_up, line_preorder.astype(np.int64), generator_line


def _minute_rows(problem: DispatchProblem, minutes) -> np.ndarray:
    """0-based rows of the given 1-based minutes (default: every minute of the problem)."""
    if minutes is None:
        return np.arange(len(problem.demand))
    return np.asarray(minutes, dtype=np.int64).reshape(-1) - 1


def _offline_note(problem: DispatchProblem, row: int) -> str:
    offline = problem.generators[~problem.online[row]]
    return f" (offline: {', '.join(offline)})" if len(offline) else ""


def check_capacity(problem: DispatchProblem, minutes=None) -> None:
    """Raise :class:`InfeasibleError` at the first of ``minutes`` (1-based; default every
    minute) whose demand exceeds the online capacity or is below the online minimum outputs.

    The message names that minute, its demand, its capacity (or floor) and the generators
    offline then, and how many other minutes of those checked fail the same way.
    """
    rows = _minute_rows(problem, minutes)
    online, demand = problem.online[rows], problem.demand[rows]
    for bound, limits, words in (
        (online @ problem.pmax, 1, "exceeds the available generation capacity"),
        (online @ problem.pmin, -1, "is below the sum of minimum outputs"),
    ):
        bad = np.flatnonzero(limits * (demand - bound) > np.abs(bound) * 1e-12)
        if len(bad):
            row = int(rows[bad[0]])
            more = f"; {len(bad) - 1} more of the minutes checked" if len(bad) > 1 else ""
            raise InfeasibleError(
                f"demand {problem.demand[row] * KW_PER_MW:.3f} kW at minute {row + 1} {words} "
                f"{bound[bad[0]] * KW_PER_MW:.3f} kW at that minute"
                f"{_offline_note(problem, row)}{more}"
            )


def feeder_shortfalls(problem: DispatchProblem, minutes=None) -> list[str]:
    """Where several feeders joined by 0 kW balance lines
    (:mod:`popdispatch.feeder.radial`) cannot each balance themselves: one sentence per feeder
    whose demand exceeds its own online generators' capacity (or falls below their minimum
    outputs) at some of ``minutes`` (1-based, default all), with the first such minute."""
    from popdispatch.feeder.radial import balance_lines

    reduced = problem.feeder
    names = balance_lines(reduced.original.lines)
    if not len(names):
        return []
    rows = _minute_rows(problem, minutes)
    position = {int(line): k for k, line in enumerate(problem.lines)}
    out = []
    for name in names:
        k = position.get(int(reduced.line_map[name]))
        if k is None:
            continue
        demand = problem.line_load_flow[rows, k]  # the feeder's own net demand, MW
        online = problem.online[rows] * problem.down[k]
        for bound, sign, words in (
            (online @ problem.pmax, 1, "exceeds its generators' capacity"),
            (online @ problem.pmin, -1, "is below their minimum outputs"),
        ):
            bad = np.flatnonzero(sign * (demand - bound) > 1e-9 * np.maximum(np.abs(bound), 1))
            if len(bad):
                j = bad[0]
                out.append(
                    f"the feeder of {name.removeprefix('balance:')} (balanced by its own "
                    f"generators): demand {demand[j] * KW_PER_MW:.3f} kW {words} "
                    f"{bound[j] * KW_PER_MW:.3f} kW at minute {rows[j] + 1}"
                    + (f" and {len(bad) - 1} more" if len(bad) > 1 else "")
                )
    return out


def check_net_demand(problem: DispatchProblem, minutes=None) -> None:
    """Raise :class:`InfeasibleError` at the first of ``minutes`` (1-based; default every
    minute) whose net demand is not positive: fixed injections (negative loads) that cover the
    loads leave the fleet nothing to supply (its outputs are >= 0), and shares of a non-positive
    demand are undefined."""
    rows = _minute_rows(problem, minutes)
    bad = np.flatnonzero(problem.demand[rows] <= 0)
    if len(bad):
        row = int(rows[bad[0]])
        fixed = problem.fixed_injection[row] * KW_PER_MW if len(problem.fixed_injection) else 0.0
        more = f"; {len(bad) - 1} more of the minutes asked for" if len(bad) > 1 else ""
        raise InfeasibleError(
            f"net demand {problem.demand[row] * KW_PER_MW:.3f} kW at minute {row + 1}: the fixed "
            f"injections ({fixed:.3f} kW) cover the loads, and the fleet cannot absorb power "
            f"(its outputs are >= 0): nothing to dispatch{more}"
        )


def check_online(problem: DispatchProblem, minutes=None) -> None:
    """Raise :class:`InfeasibleError` at the first of ``minutes`` (1-based; default every
    minute) at which no generator is online: the dynamics have nothing to dispatch then.

    Minutes whose demand merely exceeds the online capacity are left to run (their DC-OPF is
    infeasible; see :func:`check_capacity` for the strict check).
    """
    rows = _minute_rows(problem, minutes)
    none = np.flatnonzero(~problem.online[rows].any(axis=1))
    if len(none):
        row = int(rows[none[0]])
        more = f"; {len(none) - 1} more of the minutes asked for" if len(none) > 1 else ""
        raise InfeasibleError(
            f"no generator is online at minute {row + 1} (capacity 0.000 kW, demand "
            f"{problem.demand[row] * KW_PER_MW:.3f} kW; offline: "
            f"{', '.join(problem.generators)}){more}"
        )


__all__ = [
    "DispatchProblem", "InfeasibleError", "ProfileError", "build_problem", "check_capacity",
    "check_online",
]  # fmt: skip
