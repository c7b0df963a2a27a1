"""A connected network of any shape (meshed or radial) in MATPOWER's lossless DC model.

The radial feeder (:mod:`popdispatch.feeder.model`, its tree and O(n) passes) is the radial
path; this module is the meshed one. Its tables are plain, in MATPOWER's own units (p.u. on
``base_mva``, degrees, MW), and its DC model is MATPOWER's ``makeBdc``:

- branch ``k`` from bus ``f`` to bus ``t`` has the series susceptance ``b_k = 1 / (x_k
  tau_k)`` (``x_k`` p.u., ``tau_k`` the off-nominal tap ratio, 1 where the case says 0) and
  the phase shift ``phi_k`` (rad); its flow from ``f`` to ``t`` is ``P_k = S (b_k (theta_f -
  theta_t) - b_k phi_k)`` (MW, ``S`` = ``base_mva``);
- bus balance: ``S B theta = P_inj - P_shift`` with ``B = C^T diag(b) C`` (``C`` the
  branch-bus incidence) and ``P_shift = -S C^T (b phi)``; a bus's shunt conductance ``G_s``
  (MW at 1 p.u.) is a load, as MATPOWER's DC model has it;
- a zero-reactance branch (``b_k`` infinite; ``|x_k|`` below 1e-6 of the network's median
  nonzero ``|x|`` counts as zero, :func:`~popdispatch.feeder.fusion.zero_reactance`) is an
  ideal connection: the buses such branches join share one angle, ``B`` is over these
  groups, and the flows on the zero-reactance branches follow from Kirchhoff's current law
  inside each group (:mod:`popdispatch.feeder.fusion`);
- the slack bus's angle is 0 and it balances the rest: with a sparse LU (SuperLU,
  :func:`scipy.sparse.linalg.splu`) of the reduced ``B`` the flow of any injection is two
  sparse solves away, and the power transfer distribution factors (PTDF) are formed only for
  the limited lines and the generators' buses, never as the full (lines x buses) matrix.

The engine's coefficient of generator ``i`` on limited line ``k`` is ``D_ki = -PTDF_k,bus(i)``
(injection at the generator's bus withdrawn at the slack), so that flows are ``load_flow - D
p`` as on the radial feeder, where ``D_ki`` is 1 below the line and 0 above it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import pandas as pd
from scipy import sparse

from popdispatch.constants import KW_PER_MW
from popdispatch.errors import FeederError
from popdispatch.feeder.fusion import ZeroFlows, bus_groups, check_zero_reactance, zero_reactance
from popdispatch.feeder.model import bus_id, bus_labels, tighter_limits

BUS_COLUMNS = ["pd_mw", "gs_mw"]
LINE_COLUMNS = ["from_bus", "to_bus", "x_pu", "tap", "shift_deg", "limit_kw"]


@dataclass(frozen=True)
class DcNetwork:
    """A connected network in the DC model (any shape), in service elements only.

    Attributes
    ----------
    name : case name.
    base_mva : the per-unit base, MVA.
    buses : index bus id (the source format's number); columns ``pd_mw`` (fixed demand, MW)
        and ``gs_mw`` (shunt conductance, MW demanded at 1 p.u.); optionally ``name``, the
        source format's bus name (OpenDSS), which outputs and options then use.
    lines : index branch name; columns ``from_bus``, ``to_bus``, ``x_pu`` (series reactance,
        p.u. on ``base_mva``), ``tap`` (off-nominal ratio, 0 or 1 for a line), ``shift_deg``
        (phase shift, degrees) and ``limit_kw`` (flow limit in kW, ``inf`` for none).
        Parallel branches are separate rows, each with its own limit.
    generators : the fleet (columns ``bus``, ``a``, ``b``, ``c``, ``pmin_kw``, ``pmax_kw``,
        :mod:`popdispatch.feeder.generators`), several per bus allowed.
    slack_bus : the angle reference, which balances the network in the PTDF.
    """

    name: str
    base_mva: float
    buses: pd.DataFrame
    lines: pd.DataFrame
    generators: pd.DataFrame
    slack_bus: int

    def __post_init__(self) -> None:
        validate_network(self)

    @property
    def demand_mw(self) -> float:
        """The network's total demand, MW: loads plus shunt conductances at 1 p.u."""
        return float(self.buses.pd_mw.sum() + self.buses.gs_mw.sum())

    @cached_property
    def model(self) -> DcModel:
        """The DC model (susceptances, LU of the reduced ``B``)."""
        return DcModel.of(self)

    # -- the radial feeder's interface, so that runs, reports and load tables take either ----

    @property
    def original(self) -> DcNetwork:
        """The network itself: a meshed network is never reduced."""
        return self

    @cached_property
    def line_map(self) -> pd.Series:
        """Each line's position in :attr:`lines` (a meshed network's lines are its own)."""
        return pd.Series(np.arange(len(self.lines)), index=self.lines.index)

    @cached_property
    def loads(self) -> pd.DataFrame:
        """The buses with a fixed demand as loads: index ``load<bus>`` (the bus as the source
        format names it), columns ``bus`` (its id) and ``p_kw`` (kW, ``pd_mw``), so that a
        load table names them by load or by bus."""
        rows = self.buses[self.buses.pd_mw != 0]
        return pd.DataFrame(
            {"bus": rows.index.to_numpy(), "p_kw": rows.pd_mw.to_numpy(float) * KW_PER_MW},
            index=pd.Index([f"load{label}" for label in self.bus_labels(rows.index)],
                           name="load"),
        )

    def bus_demand_mw(self, load_kw: np.ndarray) -> np.ndarray:
        """Per-bus demand (MW, (..., buses) in the order of :attr:`buses`) of per-load kW
        ``load_kw`` (..., loads in the order of :attr:`loads`)."""
        at = self.buses.index.get_indexer(self.loads.bus)
        weights = np.zeros((len(at), len(self.buses)))
        weights[np.arange(len(at)), at] = 1.0 / KW_PER_MW
        return np.asarray(load_kw, float) @ weights

    def bus_labels(self, buses) -> list[int | str]:
        """The source format's names of ``buses`` (int ids): the ``name`` column where the
        buses table has one (an OpenDSS circuit's), else the ids (MATPOWER's numbers)."""
        return bus_labels(self, buses)

    def bus_id(self, label: int | str) -> int:
        """The id of the bus ``label`` names (a name where buses have names, case ignored; a
        number); :class:`FeederError` naming it when the network has no such bus."""
        return bus_id(self, label)

    def path_lines(self, bus_a: int | str, bus_b: int | str) -> list[str]:
        """Names of the lines joining buses ``bus_a`` and ``bus_b`` directly (every parallel
        one); on a mesh a limit names a branch by its two ends. :class:`FeederError` when no
        line joins them."""
        a, b = self.bus_id(bus_a), self.bus_id(bus_b)
        ends = self.lines[["from_bus", "to_bus"]].to_numpy()
        joins = ((ends[:, 0] == a) & (ends[:, 1] == b)) | ((ends[:, 0] == b) & (ends[:, 1] == a))
        if not joins.any():
            raise FeederError(f"no line of network {self.name!r} joins buses {bus_a} and "
                              f"{bus_b} (on a meshed network a limit names one branch's two "
                              "ends)")  # fmt: skip
        return self.lines.index[joins].tolist()

    def with_line_limits(self, limits_kw: pd.Series) -> DcNetwork:
        """The network with ``limit_kw`` of the lines named in ``limits_kw`` (kW) set, the
        smaller kept where a line already has a limit."""
        return replace(self, lines=tighter_limits(self.lines, limits_kw))


def validate_network(net: DcNetwork) -> None:
    """One-line :class:`FeederError` on a table that the DC model cannot take: unknown buses,
    zero-reactance branches that close a loop among themselves or shift the phase
    (:func:`~popdispatch.feeder.fusion.check_zero_reactance`), a network in several parts."""
    for table, columns in (("buses", BUS_COLUMNS), ("lines", LINE_COLUMNS)):
        missing = [c for c in columns if c not in getattr(net, table).columns]
        if missing:
            raise FeederError(f"network {net.name!r}: the {table} table lacks {missing[0]}")
    index = net.buses.index
    for what, values in (
        ("line end", net.lines.from_bus), ("line end", net.lines.to_bus),
        ("generator bus", net.generators.bus),
    ):  # fmt: skip
        unknown = ~pd.Index(values).isin(index)
        if unknown.any():
            raise FeederError(f"network {net.name!r}: {what} {values.iloc[unknown.argmax()]} "
                              "is not a bus of the network")  # fmt: skip
    if net.slack_bus not in index:
        raise FeederError(f"network {net.name!r}: slack bus {net.slack_bus} is not a bus")
    from scipy.sparse.csgraph import connected_components

    n = len(index)
    a, b = index.get_indexer(net.lines.from_bus), index.get_indexer(net.lines.to_bus)
    check_zero_reactance(net.name, net.lines, (a, b), n)
    graph = sparse.csr_array((np.ones(len(a)), (a, b)), shape=(n, n))
    _, part = connected_components(graph, directed=False)
    apart = part != part[index.get_loc(net.slack_bus)]
    if apart.any():
        raise FeederError(
            f"network {net.name!r}: bus {index[apart.argmax()]} is not connected to slack bus "
            f"{net.slack_bus} (the network is in several parts)"
        )


@dataclass(frozen=True)
class DcModel:
    """MATPOWER's ``makeBdc`` of a :class:`DcNetwork` with its zero-reactance branches as ideal
    connections (:mod:`popdispatch.feeder.fusion`), and a sparse LU of its reduced ``B``.

    The buses that zero-reactance branches join form a *group* with one angle; without such
    branches every bus is its own group and this is ``makeBdc`` as it stands.

    ``branch_b``: per line, ``b_k = 1 / (x_k tau_k)`` (p.u.; 0 on a zero-reactance line,
    :func:`~popdispatch.feeder.fusion.zero_reactance`);
    ``incidence``: (lines x buses) sparse, +1 at the from bus and -1 at the to bus; ``group``:
    per bus, its group; ``members``: (groups x buses) sparse, 1 where the bus is in the group;
    ``Bf``: (lines x groups) sparse, ``b_k`` at the from bus's group and
    ``-b_k`` at the to bus's (a row of 0 for a line inside one group); ``Bbus``: (groups x
    groups) ``B`` of the groups (p.u.); ``p_shift``: per line, the flow of its phase shift alone,
    ``-S b_k phi_k`` (MW); ``bus_shift``: per bus, ``C^T p_shift`` (MW); ``slack``: the slack
    bus's position; ``keep``: the groups other than the slack's; ``lu``: SuperLU of ``Bbus`` on
    them; ``zero``: Kirchhoff's law for the zero-reactance lines (None without any).
    """

    base_mva: float
    branch_b: np.ndarray
    incidence: sparse.csr_array
    group: np.ndarray
    members: sparse.csr_array
    Bf: sparse.csr_array
    Bbus: sparse.csc_array
    p_shift: np.ndarray
    bus_shift: np.ndarray
    slack: int
    keep: np.ndarray
    lu: object
    zero: ZeroFlows | None

    @classmethod
    def of(cls, net: DcNetwork) -> DcModel:
        """The model of ``net`` (:func:`validate_network` has accepted it)."""
        from scipy.sparse.linalg import splu

        index = net.buses.index
        n = len(index)
        f, t = index.get_indexer(net.lines.from_bus), index.get_indexer(net.lines.to_bus)
        zero = zero_reactance(net.lines)
        tap = net.lines.tap.to_numpy(float)
        tap = np.where(tap == 0, 1.0, tap)
        x = np.where(zero, 1.0, net.lines.x_pu.to_numpy(float))
        b = np.where(zero, 0.0, 1.0 / (x * tap))
        incidence = _incidence(f, t, n)
        group = bus_groups(n, f, t, zero)
        n_groups = int(group.max()) + 1
        members = sparse.csr_array((np.ones(n), (group, np.arange(n))), shape=(n_groups, n))
        grouped = _incidence(group[f], group[t], n_groups)
        Bf = sparse.csr_array(sparse.diags(b) @ grouped)
        Bbus = (grouped.T @ Bf).tocsc()
        p_shift = -net.base_mva * b * np.deg2rad(net.lines.shift_deg.to_numpy(float))
        slack = index.get_loc(net.slack_bus)
        keep = np.flatnonzero(np.arange(Bbus.shape[0]) != group[slack])
        lu = splu(sparse.csc_matrix(Bbus[keep][:, keep]))
        kcl = ZeroFlows.of(incidence, zero) if zero.any() else None
        return cls(float(net.base_mva), b, incidence, group, members, Bf, Bbus, p_shift,
                   incidence.T @ p_shift, slack, keep, lu, kcl)  # fmt: skip

    def group_sums(self, per_bus: np.ndarray) -> np.ndarray:
        """Per group, the sum of ``per_bus`` (buses x columns) over its buses."""
        if self.zero is None:  # every bus its own group
            return per_bus
        return self.members @ per_bus

    def group_angles(
        self, injection_mw: np.ndarray, shifted: bool = True, base: float | None = None
    ) -> np.ndarray:
        """Group angles (rad, groups x columns; the slack's group 0) for bus injections
        ``injection_mw`` (MW, buses x columns; the slack's group balances the rest):
        ``S B_r theta = P_r - P_shift,r`` on the groups. ``shifted``: with the phase shifters'
        flows (without: the angles of the injections alone, linear in them); ``base``: ``S``
        (default ``base_mva``; 1 for angles per p.u. of injection)."""
        injection = self.group_sums(injection_mw)
        if shifted:
            injection = injection - self.group_sums(self.bus_shift)[:, None]
        theta = np.zeros(injection.shape)
        rhs = injection[self.keep] / (self.base_mva if base is None else base)
        theta[self.keep] = self.lu.solve(np.ascontiguousarray(rhs))
        return theta

    def angles(self, injection_mw: np.ndarray) -> np.ndarray:
        """Bus angles (rad, buses x columns) for injections ``injection_mw`` (MW, buses x
        columns; the slack's own entry is replaced by the balance): each bus its group's."""
        injection = np.atleast_2d(np.asarray(injection_mw, float).T).T
        return self.group_angles(injection)[self.group]

    def flows_mw(self, injection_mw: np.ndarray, lines: np.ndarray) -> np.ndarray:
        """Flows (MW, from bus to to bus) on ``lines`` (positions) for the bus injections
        ``injection_mw`` (MW, buses x columns), the slack balancing: (lines x columns). A
        zero-reactance line's flow is Kirchhoff's current law's in its group."""
        injection = np.atleast_2d(np.asarray(injection_mw, float).T).T
        return self._flows(injection, np.asarray(lines, np.int64), shifted=True)

    def ptdf(self, lines: np.ndarray, buses: np.ndarray) -> np.ndarray:
        """PTDF (MW per MW) of ``lines`` for injections at ``buses`` (positions) withdrawn at
        the slack: ``(lines, buses)``, by one sparse solve per distinct bus (the slack's
        column is 0; a zero-reactance line's factors from Kirchhoff's current law in its
        group); the full matrix is never formed."""
        unique, back = np.unique(np.asarray(buses, np.int64), return_inverse=True)
        rhs = np.zeros((self.incidence.shape[1], len(unique)))
        rhs[unique, np.arange(len(unique))] = 1.0
        return self._flows(rhs, np.asarray(lines, np.int64), shifted=False, base=1.0)[:, back]

    def _flows(
        self, injection: np.ndarray, lines: np.ndarray, shifted: bool, base: float | None = None
    ) -> np.ndarray:
        """:meth:`flows_mw` (``shifted``: with the phase shifters' own flows; ``base``: ``S``,
        as in :meth:`group_angles`)."""
        base = self.base_mva if base is None else base
        theta = self.group_angles(injection, shifted, base)

        def angle_flows(rows: np.ndarray) -> np.ndarray:
            """The flows the angles give ``rows`` (lines), with their shifts if ``shifted``."""
            flows = base * (self.Bf[rows] @ theta)
            return flows + self.p_shift[rows, None] if shifted else flows

        out = angle_flows(lines)
        if self.zero is None:
            return out
        at = np.flatnonzero(np.isin(lines, self.zero.lines))
        if len(at):
            touch = angle_flows(self.zero.touch)
            balanced = injection.copy()
            balanced[self.slack] -= balanced.sum(axis=0)  # the slack's entry: the balance
            ideal = self.zero.flows(balanced, touch)
            out[at] = ideal[np.searchsorted(self.zero.lines, lines[at])]
        return out


def _incidence(f: np.ndarray, t: np.ndarray, n: int) -> sparse.csr_array:
    """The (branches x ``n``) incidence of branches from ``f`` to ``t`` (positions): +1 at
    the from end, -1 at the to end (0 where the two are one)."""
    m = len(f)
    rows = np.r_[np.arange(m), np.arange(m)]
    return sparse.csr_array((np.r_[np.ones(m), -np.ones(m)], (rows, np.r_[f, t])), shape=(m, n))
