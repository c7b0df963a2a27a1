"""The AC check of a dispatch: one power-grid-model power flow per time step, in one batch.

Public functions:

- :func:`power_flow`: the raw AC power flow of a built network (:mod:`popdispatch.ac.network`)
  for per-step loads and generator set points (kW) -> :class:`ACFlows` (per step and bus or
  line, people's units);
- :func:`check_setpoints`: a feeder, loads and set points (kW, any number of steps) ->
  :class:`ACDay`;
- :func:`check_snapshot` / :func:`check_day`: what the ``snapshot`` / ``day`` commands hold
  (the problem, the load profiles and the run or its comparison with the DC-OPF) ->
  :class:`ACSnapshot` / :class:`ACDay`, each with a JSON-ready ``summary()``.

Units: kW, kvar, A, p.u. of the nominal voltage, degrees. The source bus is an ideal voltage
source; what it supplies beyond the dispatched generators (``source_extra_kw``) is the losses
plus whatever the dispatch leaves unbalanced (``dc_mismatch_kw``, load minus dispatched
generation, 0 for a balanced dispatch).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from popdispatch.ac.network import (
    W_PER_KW,
    ACModel,
    ACNetwork,
    build_network,
    check_step_arrays,
    power_grid_model,
    update_data,
)
from popdispatch.errors import InfeasibleError, OptionError, ProfileError
from popdispatch.feeder.model import Feeder

if TYPE_CHECKING:  # the engine's modules are not needed to check a dispatch
    from popdispatch.feeder.profiles import LoadProfiles
    from popdispatch.game.problem import DispatchProblem

#: Per-step columns of :attr:`ACDay.steps` (units in the names).
STEP_COLUMNS = [
    "losses_kw", "v_min_pu", "v_min_bus", "v_max_pu", "v_max_bus", "max_loading_percent",
    "max_loading_line", "max_current_a", "source_extra_kw", "source_kvar", "load_kw",
    "generation_kw",
]  # fmt: skip
#: Default power-flow tolerance: largest voltage change between iterations, p.u.
#: (power-grid-model's default; the tests find 1e-6 p.u. and 1e-3 kW agreement with pandapower)
TOLERANCE_PU = 1e-8


@dataclass(frozen=True)
class ACFlows:
    """AC power-flow results of several time steps, every bus and line of the feeder.

    Held per chain (:mod:`popdispatch.ac.chains`): the complex voltage of every bus and the
    current of every branch between kept buses; the per-line arrays are computed when first
    read (a day's summary needs only voltages, branch currents and losses).

    Attributes
    ----------
    network : the network solved (its ``chains`` map buses and lines onto branches).
    v : (buses, steps) complex voltage, p.u. (buses in feeder order).
    current : (branches, steps) complex current flowing down each branch, kVA per p.u. of
        voltage (``|current| / (sqrt(3) vn_kv)`` is in A).
    source_kw, source_kvar : (steps,) what the ideal source supplies, kW / kvar.

    Per-step arrays (properties, feeder order): ``v_pu``, ``angle_deg`` (steps, buses; p.u.,
    degrees); ``p_from_kw``, ``q_from_kvar``, ``p_to_kw``, ``q_to_kvar`` (steps, lines: power
    entering each line at its ``from_bus`` / ``to_bus`` end, kW / kvar), ``loss_kw`` (their
    sum), ``current_a`` (A, the same at both ends: no shunts); ``losses_kw`` (steps,) in total.
    """

    network: ACNetwork
    v: np.ndarray
    current: np.ndarray
    source_kw: np.ndarray
    source_kvar: np.ndarray

    def first(self) -> ACFlows:
        """The first step alone."""
        return ACFlows(self.network, self.v[:, :1], self.current[:, :1], self.source_kw[:1],
                       self.source_kvar[:1])  # fmt: skip

    @cached_property
    def v_pu(self) -> np.ndarray:
        return np.abs(self.v).T

    @property
    def angle_deg(self) -> np.ndarray:
        return np.degrees(np.angle(self.v)).T

    @cached_property
    def _line_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """(lines, steps) complex power entering each line at its from and to end, kVA."""
        chains = self.network.chains
        i_line = np.conj(self.current[chains.line_branch])
        s_near = self.v[chains.line_near] * i_line  # entering at the upstream end
        s_far = -self.v[chains.line_far] * i_line  # entering at the downstream end
        backward = ~chains.line_forward
        s_from, s_to = s_near, s_far
        s_from[backward], s_to[backward] = s_far[backward], s_near[backward]
        return s_from, s_to

    @property
    def p_from_kw(self) -> np.ndarray:
        return self._line_ends[0].real.T

    @property
    def q_from_kvar(self) -> np.ndarray:
        return self._line_ends[0].imag.T

    @property
    def p_to_kw(self) -> np.ndarray:
        return self._line_ends[1].real.T

    @property
    def q_to_kvar(self) -> np.ndarray:
        return self._line_ends[1].imag.T

    @property
    def loss_kw(self) -> np.ndarray:
        """(steps, lines) each line's active-power loss, kW."""
        return self.p_from_kw + self.p_to_kw

    @cached_property
    def current_a(self) -> np.ndarray:
        """(steps, lines) each line's current, A."""
        return self.line_current_a(np.arange(len(self.network.feeder.lines))).T

    @cached_property
    def branch_current_a(self) -> np.ndarray:
        """(branches, steps) each chain's current, A (kVA per p.u. / (sqrt(3) vn_kv))."""
        return np.abs(self.current) / (np.sqrt(3.0) * self.network.model.vn_kv)

    def line_current_a(self, lines: np.ndarray) -> np.ndarray:
        """(len(lines), steps) the current of the given lines (rows of the lines table), A."""
        return self.branch_current_a[self.network.chains.line_branch[lines]]

    @property
    def losses_kw(self) -> np.ndarray:
        """(steps,) total active-power loss of the lines, kW: ``|i|^2 R`` of every branch
        (each chain's lines carry its current)."""
        chains = self.network.chains
        r_pu = chains.branch_z_ohm.real / (self.network.model.vn_kv**2 * 1e3)
        return r_pu @ (self.current.real**2 + self.current.imag**2)


#: power-grid-model outputs read: the kept buses' voltages, the power entering each branch at
#: its top (the chain's current follows, :mod:`popdispatch.ac.chains`), the source's power.
_OUTPUTS = {"node": ["u_pu", "u_angle"], "branch": ["p_from", "q_from"], "source": ["p", "q"]}


def power_flow(
    network: ACNetwork,
    load_kw: np.ndarray,
    generator_kw: np.ndarray,
    *,
    tolerance_pu: float = TOLERANCE_PU,
    steps: np.ndarray | None = None,
    threads: int = 0,
) -> ACFlows:
    """AC power flow of every step in one power-grid-model batch calculation.

    ``load_kw``: (steps, loads), feeder load order, kW; ``generator_kw``: (steps, generators),
    feeder fleet order, kW; ``steps``: labels of the steps for error messages (e.g. minutes).
    Method: power-grid-model's iterative current (fixed-point on the factorised admittance
    matrix; the same solution as Newton-Raphson, to the tolerance, and faster on radial
    feeders), until no voltage changes by more than ``tolerance_pu`` p.u.
    ``threads``: power-grid-model's batch threads (0: one per core; -1: sequential).
    Solved on the kept buses, recovered exactly on every bus and line
    (:mod:`popdispatch.ac.chains`).
    Raises :class:`InfeasibleError` naming the first step whose power flow does not converge.
    """
    pgm = power_grid_model()
    from power_grid_model.errors import PowerGridError

    load_kw, generator_kw = check_step_arrays(network, load_kw, generator_kw, steps)
    outputs = {"node": _OUTPUTS["node"], "source": _OUTPUTS["source"]}
    for kind, rows in (("line", network.line_rows), ("link", network.link_rows)):
        if len(rows):
            outputs[kind] = _OUTPUTS["branch"]
    model = pgm.PowerGridModel(network.input_data)
    try:
        out = model.calculate_power_flow(
            update_data=update_data(network, load_kw, generator_kw),
            calculation_method=pgm.CalculationMethod.iterative_current,
            error_tolerance=tolerance_pu,
            max_iterations=100,
            output_component_types=outputs,
            threading=threads,
        )
    except PowerGridError as exc:
        raise InfeasibleError(_divergence_message(exc, steps)) from exc
    return _flows(network, out, len(load_kw))


def _divergence_message(exc: Exception, steps: np.ndarray | None) -> str:
    """One line naming the first step that failed (power-grid-model's batch error)."""
    failed = getattr(exc, "failed_scenarios", None)
    first = int(failed[0]) if failed is not None and len(failed) else None
    label = steps[first] if steps is not None and first is not None else first
    where = f" at minute {label}" if label is not None else ""
    errors = getattr(exc, "errors", None)
    detail = errors[0] if errors is not None and len(errors) else exc
    reason = " ".join(str(detail).split()) or type(exc).__name__
    return f"AC power flow did not converge{where} (voltage collapse?): {reason}"


def _flows(network: ACNetwork, out: dict, n_steps: int) -> ACFlows:
    """power-grid-model output of the kept buses (SI) -> :class:`ACFlows`: every bus's voltage
    and every branch's current, by Ohm's law along each chain (:mod:`popdispatch.ac.chains`).
    Buses and branches are rows (steps contiguous: gathering a bus is one copy)."""
    chains = network.chains
    z_base_ohm = network.model.vn_kv**2 * 1e3  # p.u. on 1 kVA: kVA, kVA per p.u. of voltage
    s_top = np.empty((chains.n_branches, n_steps), dtype=complex)
    for kind, rows in (("line", network.line_rows), ("link", network.link_rows)):
        if len(rows):
            s_top[rows] = (out[kind]["p_from"] + 1j * out[kind]["q_from"]).T / W_PER_KW
    node = out["node"]
    v = np.empty((len(chains.kept), n_steps), dtype=complex)
    v[chains.kept] = (node["u_pu"] * np.exp(1j * node["u_angle"])).T
    current = np.conj(s_top / v[chains.branch_top])  # per branch, downstream
    inside = np.flatnonzero(~chains.kept)
    branch = chains.bus_branch[inside]
    z_pu = (chains.bus_z_ohm[inside] / z_base_ohm)[:, None]
    v[inside] = v[chains.branch_top[branch]] - z_pu * current[branch]
    source = out["source"]
    return ACFlows(network, v, current, source["p"][:, 0] / W_PER_KW, source["q"][:, 0] / W_PER_KW)


def loading_percent(network: ACNetwork, flows: ACFlows) -> np.ndarray:
    """(steps, lines) each line's current in percent of its rated current (NaN: no rating)."""
    return 100.0 * flows.current_a / network.rated_a


def step_table(
    network: ACNetwork,
    flows: ACFlows,
    load_kw: np.ndarray,
    generator_kw: np.ndarray,
    index: pd.Index,
) -> pd.DataFrame:
    """Per step: losses, voltage extremes with their buses, the most loaded rated line, what
    the source supplied (columns :data:`STEP_COLUMNS`)."""
    buses, lines = network.feeder.buses.index, network.feeder.lines.index
    rows = np.arange(len(index))
    v_pu = flows.v_pu
    low, high = v_pu.argmin(axis=1), v_pu.argmax(axis=1)
    rated = np.flatnonzero(np.isfinite(network.rated_a))
    if len(rated):
        loading = 100.0 * flows.line_current_a(rated) / network.rated_a[rated, None]
        worst = loading.argmax(axis=0)
        worst_loading, worst_line = loading[worst, rows], lines[rated[worst]]
    else:
        worst_loading, worst_line = np.full(len(index), np.nan), [None] * len(index)
    return pd.DataFrame(
        {
            "losses_kw": flows.losses_kw,
            "v_min_pu": v_pu[rows, low],
            "v_min_bus": buses[low],
            "v_max_pu": v_pu[rows, high],
            "v_max_bus": buses[high],
            "max_loading_percent": worst_loading,
            "max_loading_line": worst_line,
            "max_current_a": flows.branch_current_a.max(axis=0),
            "source_extra_kw": flows.source_kw,
            "source_kvar": flows.source_kvar,
            "load_kw": load_kw.sum(axis=1),
            "generation_kw": generator_kw.sum(axis=1),
        },
        index=index,
    )


def _json(value: Any) -> Any:
    """numpy scalars and NaN as JSON values (NaN -> None)."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


#: Day summary extremes: (key prefix, step column, largest?, column naming where it occurs);
#: keys ``<prefix><unit>`` (e.g. ``max_losses_kw``), ``<prefix>minute`` and the where.
_DAY_EXTREMES = [
    ("max_losses_", "losses_kw", True, None),
    ("v_min_", "v_min_pu", False, "v_min_bus"),
    ("v_max_", "v_max_pu", True, "v_max_bus"),
    ("max_loading_", "max_loading_percent", True, "max_loading_line"),
    ("max_source_extra_", "source_extra_kw", True, None),
]


@dataclass(frozen=True)
class ACDay:
    """The AC check of several time steps (a day, or any minutes).

    Attributes
    ----------
    network : the power-grid-model network (rules in ``network.model``).
    steps : index ``minute``; columns :data:`STEP_COLUMNS` (kW, kvar, p.u., A, percent).
    flows : the full results per step, bus and line (:class:`ACFlows`).
    """

    network: ACNetwork
    steps: pd.DataFrame
    flows: ACFlows

    @property
    def model(self) -> ACModel:
        return self.network.model

    def v_pu(self) -> pd.DataFrame:
        """Voltage (p.u.) per step (rows) and bus (columns)."""
        return pd.DataFrame(self.flows.v_pu, self.steps.index, self.network.feeder.buses.index)

    def loading_percent(self) -> pd.DataFrame:
        """Loading (percent of the rated current) per step and rated line."""
        rated = np.isfinite(self.network.rated_a)
        table = loading_percent(self.network, self.flows)[:, rated]
        return pd.DataFrame(table, self.steps.index, self.network.feeder.lines.index[rated])

    def summary(self, step_hours: np.ndarray | None = None) -> dict:
        """The extremes over the steps, each with its step (minute), bus or line; energies
        (kWh) = sum of kW x each step's duration ``step_hours`` (h; default one minute each)."""
        s = self.steps
        hours = np.full(len(s), 1 / 60) if step_hours is None else np.asarray(step_hours, float)
        out: dict[str, Any] = {"steps": len(s)}
        out["losses_kwh"] = float(s.losses_kw.to_numpy(float) @ hours)
        out["source_extra_kwh"] = float(s.source_extra_kw.to_numpy(float) @ hours)
        for prefix, column, largest, where in _DAY_EXTREMES:
            values = s[column].astype(float)
            found = values.notna().any()
            at = (values.idxmax() if largest else values.idxmin()) if found else None
            out[f"{prefix}{column.rsplit('_', 1)[-1]}"] = _json(values[at]) if found else None
            if where is not None:
                out[where] = _json(s.at[at, where]) if found else None
            out[f"{prefix}minute"] = _json(at)
        out["model"] = self.model.as_dict()
        return out


@dataclass(frozen=True)
class ACSnapshot:
    """The AC check of one time step.

    Attributes
    ----------
    minute : the step (1-based minute), or None.
    network : the power-grid-model network (rules in ``network.model``).
    buses : index ``bus``; columns ``v_pu``, ``angle_deg``.
    lines : index line name; columns ``from_bus``, ``to_bus``, ``p_from_kw``, ``q_from_kvar``,
        ``p_to_kw``, ``q_to_kvar``, ``loss_kw``, ``current_a``, ``rated_a``, ``limit_kw``,
        ``loading_percent`` (NaN where the line has no rating).
    totals : the step's row of :data:`STEP_COLUMNS`.
    """

    minute: int | None
    network: ACNetwork
    buses: pd.DataFrame
    lines: pd.DataFrame
    totals: pd.Series

    @property
    def model(self) -> ACModel:
        return self.network.model

    def summary(self) -> dict:
        """The ``ac`` JSON object: ``losses_kw``, ``v_min_pu``/``v_min_bus``,
        ``v_max_pu``/``v_max_bus``, ``max_loading_percent``/``max_loading_line`` (None when no
        line has a rating), ``max_current_a``, ``source_extra_kw`` (what the source supplied
        beyond the dispatched generators), ``source_kvar``, ``load_kw``, ``generation_kw``,
        ``dc_mismatch_kw`` (load minus dispatched generation) and the model's rules."""
        out = {"minute": self.minute}
        out.update({key: _json(value) for key, value in self.totals.items()})
        out["dc_mismatch_kw"] = out["load_kw"] - out["generation_kw"]
        out["model"] = self.model.as_dict()
        return out


def check_setpoints(
    feeder: Feeder | ACNetwork,
    load_kw: np.ndarray,
    setpoints_kw: np.ndarray,
    minutes: np.ndarray | None = None,
    *,
    tolerance_pu: float = TOLERANCE_PU,
    threads: int = 0,
    **model_options: Any,
) -> ACDay:
    """AC check of set points on a feeder, any number of steps, in one batch.

    Parameters
    ----------
    feeder : the full feeder, or a network already built from it (:func:`build_network`).
    load_kw : (steps, loads) per-load demand in the feeder's load order, kW.
    setpoints_kw : (steps, generators) set points in the feeder's fleet order, kW.
    minutes : step labels (default 1..steps).
    tolerance_pu : power-flow tolerance, p.u.
    threads : power-grid-model's batch threads (0: one per core; -1: one thread).
    model_options : ``vn_kv``, ``source_pu``, ``load_pf``, ``generator_pf`` of
        :func:`popdispatch.ac.network.build_network`.
    """
    network = feeder if isinstance(feeder, ACNetwork) else build_network(feeder, **model_options)
    steps = None if minutes is None else np.asarray(minutes)
    load_kw, setpoints_kw = check_step_arrays(network, load_kw, setpoints_kw, steps)
    if steps is None:
        steps = np.arange(1, len(load_kw) + 1)
    flows = power_flow(
        network,
        load_kw,
        setpoints_kw,
        tolerance_pu=tolerance_pu,
        steps=steps,
        threads=threads,
    )
    index = pd.Index(steps, name="minute")
    return ACDay(network, step_table(network, flows, load_kw, setpoints_kw, index), flows)


def snapshot_of(day: ACDay, row: int = 0) -> ACSnapshot:
    """One step of an :class:`ACDay` as an :class:`ACSnapshot` (bus and line tables)."""
    network, flows = day.network, day.flows
    feeder = network.feeder
    lines = feeder.lines
    buses = pd.DataFrame(
        {"v_pu": flows.v_pu[row], "angle_deg": flows.angle_deg[row]}, index=feeder.buses.index
    )
    line_table = pd.DataFrame(
        {
            "from_bus": lines["from_bus"],
            "to_bus": lines["to_bus"],
            "p_from_kw": flows.p_from_kw[row],
            "q_from_kvar": flows.q_from_kvar[row],
            "p_to_kw": flows.p_to_kw[row],
            "q_to_kvar": flows.q_to_kvar[row],
            "loss_kw": flows.loss_kw[row],
            "current_a": flows.current_a[row],
            "rated_a": network.rated_a,
            "limit_kw": lines["limit_kw"],
            "loading_percent": loading_percent(network, flows)[row],
        },
        index=lines.index,
    )
    minute = int(day.steps.index[row])
    return ACSnapshot(minute, network, buses, line_table, day.steps.iloc[row])


def fleet_setpoints(feeder: Feeder, generators: pd.Index, setpoints_kw: np.ndarray) -> np.ndarray:
    """Set points (steps, generators) in ``generators`` order -> the feeder's fleet order."""
    missing = feeder.generators.index.difference(generators)
    if len(missing):
        raise OptionError(f"no set point for generator {missing[0]!r} of feeder {feeder.name!r}")
    order = pd.Index(generators).get_indexer(feeder.generators.index)
    return np.atleast_2d(np.asarray(setpoints_kw, dtype=float))[:, order]


def minute_loads(feeder: Feeder, profiles: LoadProfiles | None, minutes: np.ndarray) -> np.ndarray:
    """(minutes, loads) per-load demand, kW, from ``profiles`` or, without them, the network's
    own loads (``p_kw`` column) at every minute."""
    if profiles is not None:
        table = profiles.for_loads(feeder.loads.index).kw
        return table.loc[np.asarray(minutes)].to_numpy(float)
    if "p_kw" not in feeder.loads.columns:
        raise ProfileError(f"feeder {feeder.name} has no load values (p_kw) and no profiles")
    return np.tile(feeder.loads["p_kw"].to_numpy(float), (len(minutes), 1))


def _run_of(result: Any) -> Any:
    """The run of a comparison with the DC-OPF (``.run``), or the run itself."""
    return getattr(result, "run", result)


def check_snapshot(
    problem: DispatchProblem,
    profiles: LoadProfiles | None,
    result: Any,
    *,
    tolerance_pu: float = TOLERANCE_PU,
    **model_options: Any,
) -> ACSnapshot:
    """AC check of a snapshot run's set points on the full feeder of ``problem``.

    Parameters
    ----------
    problem : the run's :class:`~popdispatch.game.problem.DispatchProblem` (its
        ``feeder.original`` is the full feeder, path limits included).
    profiles : the run's load profiles (``runs.load_run``'s second value); ``None``: the
        network's own loads.
    result : a :class:`~popdispatch.scenarios.SnapshotComparison` or
        :class:`~popdispatch.online.SnapshotResult` (its ``minute``, ``generators``,
        ``setpoints_kw``).
    model_options : see :func:`check_setpoints`.
    """
    run = _run_of(result)
    feeder = problem.feeder.original
    minutes = np.array([int(run.minute)])
    day = check_setpoints(
        feeder,
        minute_loads(feeder, profiles, minutes),
        fleet_setpoints(feeder, run.generators, run.setpoints_kw),
        minutes,
        tolerance_pu=tolerance_pu,
        **model_options,
    )
    return snapshot_of(day)


def check_day(
    problem: DispatchProblem,
    profiles: LoadProfiles | None,
    result: Any,
    *,
    tolerance_pu: float = TOLERANCE_PU,
    **model_options: Any,
) -> ACDay:
    """AC check of every simulated minute of a day run, in one batch calculation.

    ``result``: a :class:`~popdispatch.scenarios.DayComparison` or
    :class:`~popdispatch.online.DayResult` (its ``minutes``, ``generators``, ``setpoints_kw``);
    the other parameters as in :func:`check_snapshot`.
    """
    run = _run_of(result)
    feeder = problem.feeder.original
    minutes = np.asarray(run.minutes)
    return check_setpoints(
        feeder,
        minute_loads(feeder, profiles, minutes),
        fleet_setpoints(feeder, run.generators, run.setpoints_kw),
        minutes,
        tolerance_pu=tolerance_pu,
        **model_options,
    )
