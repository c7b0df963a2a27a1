"""Consensus ADMM for the DC-OPF with line limits, on any network, radial or meshed: general
form consensus (Boyd, Parikh, Chu, Peleato and Eckstein, "Distributed optimization and
statistical learning via the alternating direction method of multipliers", Found. Trends
Mach. Learn. 3(1), 2011, sec. 7.2), one agent per term of the problem.

The DC-OPF ``min sum_i b_i p_i + c_i p_i^2`` s.t. ``Pmin_i <= p_i <= Pmax_i``, ``sum_i p_i =
P_d`` and ``|F_k - sum_i D_ki p_i| <= U_k`` (``F_k`` the flow of the loads alone, ``D_ki`` the
distribution factors: on a radial feeder 1 for the DGs below line ``k``, else 0) is split
into terms, each held by one agent with a copy of the set points it touches:

* DG ``i``: its cost and its range, on its own set point;
* the coordinator: the balance, on a copy of every set point;
* line ``k``'s node controller: its limit, on a copy of the set points with ``D_ki != 0``.

DG ``i`` also holds the consensus value ``z_i`` of its set point. One iteration, two rounds
(``rounds_per_iteration``; scaled form, penalty ``rho`` EUR/MW per MW):

1. (odd rounds) every holder ``j`` moves its scaled prices ``u_ji += x_ji - z_i`` by the
   ``z`` it last heard (from the second iteration on), takes its x-update at ``v = z -
   u_j``: the DG the prox of its cost, ``x = clip((rho v - b) / (2 c + rho), Pmin, Pmax)``
   (unique for a linear cost too); the coordinator the projection onto the balance, ``y = v
   + (P_d - sum v) / n``; line ``k`` the projection onto its slab ``F_k - U_k <= a.y <= F_k
   + U_k`` (``a = D_k``), ``y = v + a (clip(a.v) - a.v) / |a|^2``; and sends ``x_ji +
   u_ji`` to each DG ``i`` of its copy (one scalar);
2. (even rounds) DG ``i`` averages the latest of these over its holders (its own term
   included), ``z_i = mean_j (x_ji + u_ji)``, and sends ``z_i`` with its applied set point
   ``x_ii`` to each holder.

The penalty is fixed (``rho = rho_scale S / P``, exact mode's scales
:func:`popdispatch.modes.exact.scales`), so ADMM's convergence for any ``rho > 0`` applies
(Boyd et al. sec. 3.2); the equal-effort grid tunes ``rho_scale`` (docs/comparison.md). The
applied set points are the DGs' own x-updates (within their ranges; supply meets demand only
at the optimum). ``z`` starts at the balanced start, ``u`` at 0. Loss handling: a DG
averages the last value each holder sent (stale), a holder steps from the last ``z`` it
heard; a DG silent for ``silent_rounds`` rounds counts as gone (a crashed DG's inverter holds
its set point): each holder fixes its copy at the set point the DG last applied and projects
the others. The DGs send their cost curves to the coordinator once (configuration,
counted), which sets the penalty.

The rules are functions and one class (:func:`penalty`, :func:`prox_cost`, :func:`onto_slab`,
:func:`slab_of_line`, :func:`consensus_value`, :class:`Holder`: the holder's price update,
x-update, what it hears and the silence rule), which the mango agents of
:mod:`popdispatch.agents.consensus_admm` call as well."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from popdispatch.algorithms.base import (
    COORDINATOR,
    Algorithm,
    Minute,
    balanced_start,
    controller_name,
)
from popdispatch.algorithms.network import Message, Network


@dataclass(frozen=True)
class ConsensusAdmmParams:
    """rho_scale: the penalty in units of exact mode's scales ``S / P`` (dimensionless);
    silent_rounds: rounds without a DG's consensus value after which its holders count it
    as gone."""

    rho_scale: float = 1.0
    silent_rounds: int = 40


class Holder:
    """One term's agent: its copy ``x`` of the set points ``members`` (indices of DGs), its
    scaled prices ``u``, the consensus values ``z`` and applied set points it last heard
    (MW), and which members it counts as gone (``free`` False: fixed at their last applied
    set point)."""

    def __init__(self, name: str, members: np.ndarray, z: np.ndarray):
        self.name, self.members = name, members
        self.x = z[members].copy()
        self.u = np.zeros(len(members))
        self.z = z[members].copy()
        self.applied = z[members].copy()
        self.z_round = np.zeros(len(members), dtype=int)  # configured at round 0
        self.free = np.ones(len(members), dtype=bool)
        self.stepped = False  # whether it has taken an x-update (then u moves by z)

    def hear(self, slot: int, sent: int, z: float, applied: float) -> None:
        """DG ``members[slot]``'s consensus value and applied set point (MW), sent in round
        ``sent``: kept when newer than what it holds (older or repeated ones are stale)."""
        if sent > self.z_round[slot]:
            self.z[slot], self.applied[slot] = z, applied
            self.z_round[slot] = sent

    def step(self, project) -> None:
        """Prices by the latest ``z``, then the x-update ``project(v, free)`` at ``v = z -
        u`` with the gone members at their last applied set points."""
        if self.stepped:
            self.u += np.where(self.free, self.x - self.z, 0.0)
        v = np.where(self.free, self.z - self.u, self.applied)
        self.x = project(v, self.free)
        self.stepped = True

    def proposals(self) -> np.ndarray:
        """``x + u`` of each member (MW): what it sends each free member."""
        return self.x + self.u

    def forget_silent(self, round_: int, silent_rounds: int) -> None:
        """Count as gone (for good) the members not heard for more than ``silent_rounds``
        rounds at round ``round_``."""
        self.free &= round_ - self.z_round <= silent_rounds


class ConsensusAdmm(Algorithm):
    loss_handling = ("stale values at the DGs (the last x + u of each holder), stale consensus "
                     "values at the holders")  # fmt: skip
    rounds_per_iteration = 2

    def __init__(self, minute: Minute, network: Network, params: ConsensusAdmmParams):
        super().__init__(minute, network, params)
        problem, n = minute.problem, len(minute.names)
        self.rho = penalty(params.rho_scale, problem.b, problem.c, problem.pmin, problem.pmax,
                           float(np.max(problem.demand)))  # fmt: skip
        self.z = balanced_start(minute)
        self.controllers = [controller_name(problem, k) for k in range(len(problem.limit))]
        self.factor = problem.down  # D_ki
        everyone = np.arange(n)
        self.dgs = [Holder(name, np.array([i]), self.z) for i, name in enumerate(minute.names)]
        self.coordinator = Holder(COORDINATOR, everyone, self.z)
        self.lines = [Holder(name, np.flatnonzero(self.factor[k]), self.z)
                      for k, name in enumerate(self.controllers)]  # fmt: skip
        # what each DG last heard of each other holder's x + u: holder -> (value, round)
        self.heard: list[dict[str, tuple[float, int]]] = [
            {h.name: (self.z[i], -1) for h in self._holders_of(i)[1:]} for i in range(n)
        ]
        self.p = self.z.copy()
        self.send_cost_curves(lambda i: [COORDINATOR])

    def agents(self) -> list[str]:
        return self.m.names + self.controllers + [COORDINATOR]

    def applied_mw(self) -> np.ndarray:
        return self.p.copy()

    def _holders_of(self, i: int) -> list[Holder]:
        """The agents holding a copy of DG ``i``'s set point: itself, the coordinator and
        the lines it has a factor on."""
        lines = [self.lines[k] for k in np.flatnonzero(self.factor[:, i])]
        return [self.dgs[i], self.coordinator, *lines]

    # -- a round -------------------------------------------------------------------------
    def local_update(self, inbox: dict[str, list[Message]], round_: int) -> None:
        self._read(inbox)
        if round_ % 2 == 1:
            self._x_updates(round_)
        else:
            self._averages()

    def _read(self, inbox) -> None:
        by_name = {h.name: h for h in (*self.dgs, self.coordinator, *self.lines)}
        for receiver, messages in inbox.items():
            for msg in messages:
                if msg.kind == "consensus":  # (z_i, x_ii) from DG i to a holder
                    holder, i = by_name[receiver], self.m.position[msg.sender]
                    holder.hear(int(np.searchsorted(holder.members, i)), msg.sent, *msg.values)
                elif msg.kind == "copy":  # x_ji + u_ji from holder j to DG i
                    i = self.m.position[receiver]
                    if msg.sent > self.heard[i][msg.sender][1]:
                        self.heard[i][msg.sender] = (msg.values[0], msg.sent)

    def _x_updates(self, round_: int) -> None:
        problem, m, rho = self.m.problem, self.m, self.rho
        for i, dg in enumerate(self.dgs):
            if self.net.crashed(dg.name):
                continue
            dg.z[0] = self.z[i]  # its own consensus value: local

            dg.step(lambda v, free, i=i: prox_cost(v, problem.b[i], problem.c[i], m.lo[i],
                                                   m.hi[i], rho))  # fmt: skip
            self.p[i] = dg.x[0]
        for k, holder in enumerate((self.coordinator, *self.lines)):
            if self.net.crashed(holder.name) or not len(holder.members):
                continue
            holder.forget_silent(round_, self.params.silent_rounds)
            a = np.ones(len(holder.members)) if k == 0 else self.factor[k - 1, holder.members]
            lo, hi = (m.demand, m.demand) if k == 0 else \
                slab_of_line(m.load_flow[k - 1], problem.limit[k - 1])  # fmt: skip
            holder.step(lambda v, free, a=a, lo=lo, hi=hi: onto_slab(v, free, a, lo, hi))

    def _averages(self) -> None:
        for i, dg in enumerate(self.dgs):
            if self.net.crashed(dg.name):
                continue
            self.z[i] = consensus_value(dg, [value for value, _ in self.heard[i].values()])

    def exchange(self, round_: int) -> None:
        names = self.m.names
        if round_ % 2 == 0:  # each DG its consensus value to its holders
            for i, name in enumerate(names):
                for holder in self._holders_of(i)[1:]:
                    self.net.send(name, holder.name, "consensus", [self.z[i], self.p[i]],
                                  reveals="set point")  # fmt: skip
            return
        for holder in (self.coordinator, *self.lines):
            values = holder.proposals()
            for slot in np.flatnonzero(holder.free):
                self.net.send(holder.name, names[holder.members[slot]], "copy", [values[slot]],
                              reveals="set-point proposal")  # fmt: skip


def penalty(rho_scale: float, b: np.ndarray, c: np.ndarray, pmin: np.ndarray,
            pmax: np.ndarray, reference_demand_mw: float) -> float:  # fmt: skip
    """The penalty ``rho = rho_scale S / P``, EUR/MW per MW, from the DGs' cost curves ``b``
    (EUR/MWh), ``c`` (EUR/MW^2h) and ratings ``pmin``, ``pmax`` (MW) and the reference demand
    ``P`` (MW, the problem's largest): exact mode's scales
    (:func:`popdispatch.modes.exact.scales`), the spread ``S = max(b + 2 c Pmax) - min(b + 2 c
    Pmin)`` (if zero, the largest marginal cost, at least 1)."""
    top = b + 2.0 * c * pmax
    spread = float(top.max() - (b + 2.0 * c * pmin).min())
    if not spread > 0.0:
        spread = max(float(np.abs(top).max()), 1.0)
    return rho_scale * spread / reference_demand_mw


def prox_cost(v: np.ndarray, b: float, c: float, lo: float, hi: float,
              rho: float) -> np.ndarray:  # fmt: skip
    """A DG's x-update: the prox of its cost ``b p + c p^2`` (EUR/MWh, EUR/MW^2h) on its range
    ``[lo, hi]`` (MW) at ``v`` (MW) with penalty ``rho``, ``clip((rho v - b) / (2 c + rho),
    lo, hi)`` (unique for a linear cost too)."""
    return np.clip((rho * v - b) / (2.0 * c + rho), lo, hi)


def slab_of_line(load_flow_mw: float, limit_mw: float) -> tuple[float, float]:
    """Line ``k``'s slab ``(F_k - U_k, F_k + U_k)`` for ``a.y`` (MW): the flow of the loads
    alone ``F_k`` and the limit ``U_k``."""
    return load_flow_mw - limit_mw, load_flow_mw + limit_mw


def consensus_value(own: Holder, others: list[float]) -> float:
    """A DG's average: ``z_i = mean_j (x_ji + u_ji)`` (MW) over its own term (``own``, its
    :class:`Holder` of one member) and the latest ``x_ji + u_ji`` of each other holder
    (``others``, in the order coordinator, lines)."""
    return (own.x[0] + own.u[0] + sum(others)) / (1 + len(others))


def onto_slab(v: np.ndarray, free: np.ndarray, a: np.ndarray, lo: float,
              hi: float) -> np.ndarray:  # fmt: skip
    """The Euclidean projection of ``v`` (MW) onto ``lo <= a.y <= hi`` moving only the
    ``free`` entries: the balance (``a = 1``, ``lo = hi = P_d``) or a line's limit (``a`` its
    distribution factors, ``F_k - U_k <= a.y <= F_k + U_k``)."""
    a_free = np.where(free, a, 0.0)
    norm = float(a_free @ a_free)
    av = float(a @ v)
    if norm == 0.0:
        return v
    return v + a_free * (min(max(av, lo), hi) - av) / norm
