"""ADMM for the DC-OPF with line limits: proximal message passing (Kraning, Chu, Lavaei and
Boyd, "Dynamic network energy management via proximal message passing", Foundations and
Trends in Optimization 1(2), 2014, sec. 3-4), with the residual-based penalty adaptation of
Boyd et al., "Distributed optimization and statistical learning via ADMM" (2011), sec. 3.4.1.

The network is cut at the limited lines into *zones* (nets): the zone above every limited
line (held by the coordinator at the substation) and one below each limited line (held by
that line's node controller). Devices have terminals on nets: each DG one on its zone (cost
``b p + c p^2``, ``Pmin <= p <= Pmax``), each zone's loads one (fixed, ``-load``: the zone's
demand net of the zones below it), each limited line two (``-s`` on the zone above, ``+s``
on its own, ``|s| <= U``; held by its controller). A net's constraint is that its terminal
powers sum to zero. One iteration, in two rounds:

1. (even rounds) every device takes the proximal step of its cost at ``p_t - pbar_n - u_n``
   (DG: ``p = clip((rho v - b) / (2 c + rho), Pmin, Pmax)``; line: ``s = clip((rho_own v_own
   - rho_above v_above) / (rho_own + rho_above), -U, U)``) and sends its terminal power to
   its net's holder (a DG to its zone's controller, a line's controller its upper terminal
   to the zone above);
2. (odd rounds) every net's holder averages its terminals' latest powers, ``pbar_n``, moves
   its scaled price ``u_n += pbar_n`` (the price is ``rho u_n`` EUR/MW), reports its squared
   primal and dual residuals (``T_n pbar_n^2``, ``rho^2 sum_t ((p_t - pbar_n) - (p_t' -
   pbar_n'))^2``) to the coordinator and sends ``(pbar_n, u_n, rho)`` to the devices on it.

The coordinator sums the residuals ``r``, ``s`` and sets ``rho <- tau rho`` if ``r > mu s``,
``rho <- rho / tau`` if ``s > mu r`` (``mu = 10``, ``tau = 2``; sec. 3.4.1) in the first
``adapt_iterations`` iterations (then the penalty stays: adapting for good flaps) and sends
it to the zone holders, which rescale their ``u`` by ``rho_old / rho_new``. The penalty
starts at ``rho = rho_scale S / P`` EUR/MW per MW (exact mode's scales,
:func:`popdispatch.modes.exact. scales`) and every net's price ``-rho u`` at the DGs' mean
marginal cost at the uniform start (dual decomposition's start). The applied set points are
the DGs' current proposals. Loss handling: a holder averages the last terminal powers it
received (stale), a device steps from the last ``(pbar, u, rho)`` it received."""

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
from popdispatch.modes.exact import scales

MU, TAU = 10.0, 2.0


@dataclass(frozen=True)
class AdmmParams:
    """rho_scale: the starting penalty in units of ``S / P``; adapt: residual-based
    adaptation of the penalty on or off; adapt_iterations: the iterations it may change in
    (then fixed, so that fixed-penalty ADMM's convergence applies; Boyd et al. sec. 3.4.1)."""

    rho_scale: float = 100.0
    adapt: bool = True
    adapt_iterations: int = 100


class Zones:
    """The nets of a problem: zone 0 above every limited line, zone ``k + 1`` below line
    ``k`` (and above the limited lines below it)."""

    def __init__(self, minute: Minute):
        problem = minute.problem
        self.of_generator = problem.generator_line + 1
        self.above_line = problem.line_up + 1  # the zone holding each line's upper terminal
        n_zones = len(problem.limit) + 1
        top = problem.line_up < 0
        load = np.zeros(n_zones)
        load[0] = minute.demand - minute.load_flow[top].sum()
        for k in range(len(problem.limit)):
            children = problem.line_up == k
            load[k + 1] = minute.load_flow[k] - minute.load_flow[children].sum()
        self.load = load  # MW, each zone's own loads (net of the zones below)
        self.count = (np.bincount(self.of_generator, minlength=n_zones) + 1  # + the loads
                      + np.bincount(self.above_line, minlength=n_zones) + np.r_[0, np.ones(
                          n_zones - 1, dtype=int)])  # fmt: skip

    def holder(self, z: int, controllers: list[str]) -> str:
        return COORDINATOR if z == 0 else controllers[z - 1]


class Admm(Algorithm):
    loss_handling = ("stale terminal powers at the net holders, stale (pbar, u, rho) at the "
                     "devices")  # fmt: skip
    rounds_per_iteration = 2

    @classmethod
    def check(cls, problem) -> None:
        """The nets follow the radial tree of limited lines (:class:`Zones`): a meshed network
        with limited lines is refused."""
        if problem.meshed and len(problem.limit):
            from popdispatch.errors import OptionError

            raise OptionError(f"admm's nets follow a radial feeder's limited lines; "
                              f"{problem.feeder.name} is meshed (consensus-admm and the "
                              "other algorithms run on it)", "--algorithms")  # fmt: skip

    def __init__(self, minute: Minute, network: Network, params: AdmmParams):
        super().__init__(minute, network, params)
        problem = minute.problem
        self.zones = Zones(minute)
        self.controllers = [controller_name(problem, k) for k in range(len(problem.limit))]
        n_zones = len(problem.limit) + 1
        spread, demand = scales(problem)
        self.rho = params.rho_scale * spread / demand
        self.p = balanced_start(minute)
        self.s = minute.flows(self.p)  # line devices start at the flows of the start
        # what each net holder last heard of its terminals
        self.heard_p = self.p.copy()
        self.heard_up = -self.s.copy()  # each line's upper terminal, at the zone above
        self.heard_round = np.full(len(self.p), -1)
        self.heard_up_round = np.full(len(self.s), -1)
        self.pbar = np.zeros(n_zones)
        mean_marginal = np.mean((problem.b + 2.0 * problem.c * self.p)[minute.hi > minute.lo])
        self.u = np.full(n_zones, -mean_marginal / self.rho)  # price -rho u: DD's start
        self.zone_rho = np.full(n_zones, self.rho)
        self.last_dev = None  # terminal deviations of the last iteration, per net
        # what each device last heard of its net(s): (pbar, u, rho)
        n = len(self.p)
        self.dg_net = np.tile([0.0, self.u[0], self.rho], (n, 1))
        self.dg_net_round = np.full(n, -1)
        self.line_above = np.tile([0.0, self.u[0], self.rho], (len(self.s), 1))
        self.line_above_round = np.full(len(self.s), -1)
        self.residuals = np.zeros((n_zones, 2))
        self.residual_round = np.full(n_zones, -1)
        self._pending_residuals: dict[int, tuple[float, float]] = {}  # a holder's, to report
        self.iteration = 0
        self.send_cost_curves(lambda i: [self.zones.holder(self.zones.of_generator[i],
                                                           self.controllers)])  # fmt: skip

    def agents(self) -> list[str]:
        return self.m.names + self.controllers + [COORDINATOR]

    def applied_mw(self) -> np.ndarray:
        return self.p.copy()

    def _terminals(self, z: int) -> np.ndarray:
        """The latest powers of net ``z``'s terminals (MW) as its holder knows them."""
        zones = self.zones
        own_line = [self.s[z - 1]] if z > 0 else []
        return np.concatenate([self.heard_p[zones.of_generator == z], [-zones.load[z]],
                               self.heard_up[zones.above_line == z], own_line])  # fmt: skip

    def local_update(self, inbox: dict[str, list[Message]], round_: int) -> None:
        self._read(inbox)
        if round_ % 2 == 0:
            self._devices()
        else:
            self._nets()

    def _read(self, inbox) -> None:
        holders = [COORDINATOR] + self.controllers
        for receiver, messages in inbox.items():
            for msg in messages:
                if msg.kind == "terminal" and msg.sender in self.m.position:
                    i = self.m.position[msg.sender]
                    if msg.sent > self.heard_round[i]:
                        self.heard_p[i], self.heard_round[i] = msg.values[0], msg.sent
                elif msg.kind == "terminal":
                    k = self.controllers.index(msg.sender)
                    if msg.sent > self.heard_up_round[k]:
                        self.heard_up[k], self.heard_up_round[k] = msg.values[0], msg.sent
                elif msg.kind == "net" and receiver in self.m.position:
                    i = self.m.position[receiver]
                    if msg.sent > self.dg_net_round[i]:
                        self.dg_net[i], self.dg_net_round[i] = msg.values, msg.sent
                elif msg.kind == "net":
                    k = self.controllers.index(receiver)
                    if msg.sent > self.line_above_round[k]:
                        self.line_above[k], self.line_above_round[k] = msg.values, msg.sent
                elif msg.kind == "residuals":
                    z = holders.index(msg.sender)
                    if msg.sent > self.residual_round[z]:
                        self.residuals[z], self.residual_round[z] = msg.values, msg.sent
                elif msg.kind == "penalty":
                    z = holders.index(receiver)
                    self._rescale(z, msg.values[0])

    def _rescale(self, z: int, rho: float) -> None:
        self.u[z] *= self.zone_rho[z] / rho
        self.zone_rho[z] = rho

    def _devices(self) -> None:
        problem, m = self.m.problem, self.m
        for i, name in enumerate(m.names):
            if self.net.crashed(name):
                continue
            pbar, u, rho = self.dg_net[i]
            v = self.p[i] - pbar - u
            self.p[i] = np.clip((rho * v - problem.b[i]) / (2 * problem.c[i] + rho), m.lo[i],
                                m.hi[i])  # fmt: skip
        for k, name in enumerate(self.controllers):
            if self.net.crashed(name):
                continue
            z = k + 1  # its own net: local
            v_own = self.s[k] - self.pbar[z] - self.u[z]
            pbar_a, u_a, rho_a = self.line_above[k]
            v_above = -self.s[k] - pbar_a - u_a
            rho_own = self.zone_rho[z]  # the two nets' penalties differ while a change travels
            s = (rho_own * v_own - rho_a * v_above) / (rho_own + rho_a)
            self.s[k] = np.clip(s, -problem.limit[k], problem.limit[k])

    def _nets(self) -> None:
        holders = [COORDINATOR] + self.controllers
        devs = []
        for z, name in enumerate(holders):
            if self.net.crashed(name):
                devs.append(None)
                continue
            t = self._terminals(z)
            self.pbar[z] = t.mean()
            self.u[z] += self.pbar[z]
            dev = t - self.pbar[z]
            last = None if self.last_dev is None else self.last_dev[z]
            dual = 0.0 if last is None else self.zone_rho[z] ** 2 * np.sum((dev - last) ** 2)
            self.residuals[z] = (len(t) * self.pbar[z] ** 2, dual) if z == 0 else \
                self.residuals[z]  # fmt: skip
            self._pending_residuals[z] = (len(t) * self.pbar[z] ** 2, dual)
            devs.append(dev)
        self.last_dev = devs
        self.iteration += 1
        adapting = self.params.adapt and self.iteration <= self.params.adapt_iterations
        if adapting and not self.net.crashed(COORDINATOR):
            self._adapt()

    def _adapt(self) -> None:
        r, s = np.sqrt(self.residuals.sum(axis=0))
        rho = self.zone_rho[0]
        new = rho * TAU if r > MU * s else rho / TAU if s > MU * r else rho
        if new != rho:
            self._rescale(0, new)
            for name in self.controllers:
                self.net.send(COORDINATOR, name, "penalty", [new])

    def exchange(self, round_: int) -> None:
        zones, names = self.zones, self.m.names
        if round_ % 2 == 0:  # devices to their nets
            for i, name in enumerate(names):
                holder = zones.holder(zones.of_generator[i], self.controllers)
                self.net.send(name, holder, "terminal", [self.p[i]], reveals="set point")
            for k, name in enumerate(self.controllers):
                holder = zones.holder(zones.above_line[k], self.controllers)
                self.net.send(name, holder, "terminal", [-self.s[k]], reveals="line flow")
            return
        pending = self._pending_residuals
        for z, holder in enumerate([COORDINATOR] + self.controllers):
            state = [self.pbar[z], self.u[z], self.zone_rho[z]]
            for i in np.flatnonzero(zones.of_generator == z):
                self.net.send(holder, names[i], "net", state, reveals="price")
            for k in np.flatnonzero(zones.above_line == z):
                self.net.send(holder, self.controllers[k], "net", state, reveals="price")
            if z > 0 and self.params.adapt and z in pending:
                self.net.send(holder, COORDINATOR, "residuals", pending[z],
                              reveals="residuals")  # fmt: skip
        self._pending_residuals = {}
