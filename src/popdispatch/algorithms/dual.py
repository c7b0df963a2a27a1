"""Dual decomposition: a balance price and line prices by projected gradient ascent on the
DC-OPF's dual, each DG best-responding to its locational price (Everett 1963; Boyd et al.,
"Notes on decomposition methods", 2007, dual decomposition).

Agents: one per DG, one node controller per limited line, and a coordinator at the
substation that holds the balance price ``lambda``. Each round

* every DG sets ``p_i = clip((pi_i - b_i) / (2 c_i), Pmin_i, Pmax_i)`` from its locational
  price ``pi_i = lambda + sum_k nu_k`` over the limited lines above it (the last ones received);
* the coordinator measures the substation's imbalance ``P_d - sum p`` at the applied set
  points and moves ``lambda += alpha (P_d - sum p)``; each line's controller measures its
  flow and moves its two directions' prices ``mu_up = max(0, mu_up + beta_k (flow - U))``,
  ``mu_down = max(0, mu_down + beta_k (-flow - U))``, ``nu_k = mu_up - mu_down``;
* the coordinator sends ``lambda`` to every DG, controller ``k`` sends ``nu_k`` to the DGs
  below its line.

The steps are scaled by the fleet's price response: ``alpha = balance_step / sum_i 1 / (2
c_i)`` and ``beta_k = line_step / sum_{i below k} 1 / (2 c_i)`` (EUR/MW per MW, over the DGs
with a range), from the cost curves each DG sends the coordinator and the controllers above
it once (configuration, round 0); the balance price starts at the DGs' mean marginal cost at
the uniform start (the start of the population dynamics), the line prices at 0. The applied
set points are the current best responses: they balance supply and demand only at the
optimum. On a meshed network (docs/meshed.md) each line price is weighed by the DG's
distribution factor ``D_ki``: ``pi_i = lambda + sum_k D_ki nu_k``, ``beta_k = line_step /
sum_i D_ki^2 / (2 c_i)``, controller ``k`` sends ``nu_k`` to every DG with ``D_ki != 0`` (on a
radial feeder ``D_ki`` is 1 below the line and 0 above it: the rules above). A DG with a
linear cost has no unique best response: such fleets are refused (:meth:`check`). Loss
handling: a DG keeps the last prices it received (stale); prices are measured, not
messaged, into the price holders.

Accelerated (``DualParams.accelerated``, the registry's ``fast-dual-decomposition``):
Nesterov's fast gradient on the dual (Giselsson, Doan, Keviczky and Rantzer, "Accelerated
gradient methods and dual decomposition in distributed model predictive control", Automatica
49(3), 2013) with the gradient restart of O'Donoghue and Candes ("Adaptive restart for
accelerated gradient schemes", Found. Comput. Math. 15, 2015), the restart test summed over
every price: each holder steps from the prices it sent, ``x = max(lower, y + step grad)``,
and sends ``x`` moved on by ``(t_k - 1) / t_{k+1}`` of its last move (``t_{k+1} = (1 +
sqrt(1 + 4 t_k^2)) / 2``); each controller sends the coordinator its term ``grad . (x -
x_last)`` every round, and when the coordinator's own term plus the controllers' latest is
negative it sets its ``t`` back to 1 and sends each controller a restart (no scalars), which
does the same. On near-linear costs the dual is flat between narrow steep pieces; the
momentum crosses the flat pieces that a step safe on the steep ones crawls over."""

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
class DualParams:
    """balance_step, line_step: the dimensionless steps of the balance and line prices (see
    the module docstring)."""

    balance_step: float = 1.0
    line_step: float = 1.0
    accelerated: bool = False


class DualDecomposition(Algorithm):
    loss_handling = "stale prices at the DGs; imbalance and flows measured by the price holders"

    @classmethod
    def check(cls, problem) -> None:
        """A DG with a range and a linear cost (``c = 0``) has no unique best response to a
        price (all or nothing): dual decomposition needs strictly convex costs, so such a
        fleet is refused, naming the DG."""
        linear = np.flatnonzero((problem.c <= 0.0) & (problem.pmax > problem.pmin))
        if len(linear):
            from popdispatch.errors import OptionError

            name = problem.generators[linear[0]]
            raise OptionError(f"dual decomposition needs strictly convex costs: generator "
                              f"{name!r} has a linear cost (c = 0), whose best response to a "
                              "price is not unique", "--algorithms")  # fmt: skip

    def __init__(self, minute: Minute, network: Network, params: DualParams):
        super().__init__(minute, network, params)
        problem, n = minute.problem, len(minute.names)
        # each DG's weight on each line price: 1 below the line, 0 above it on a radial
        # feeder; its distribution factor D_ki on a meshed network
        self.factor = problem.down
        tradable = minute.hi > minute.lo
        response = np.where(tradable, 1.0 / (2.0 * problem.c), 0.0)  # MW per EUR/MW
        self.alpha = params.balance_step / response.sum()
        line_response = (self.factor**2) @ response  # the dual's curvature along each price
        self.beta = params.line_step / np.where(line_response > 0, line_response, np.inf)
        self.controllers = [controller_name(problem, k) for k in range(len(problem.limit))]
        start = balanced_start(minute)  # the balance price starts at the DGs' mean
        self.lam = float(np.mean((problem.b + 2.0 * problem.c * start)[tradable]))  # marginal cost
        self.mu = np.zeros((len(problem.limit), 2))
        # acceleration: each holder's last ascent point, momentum counter and restart state
        self.x_last = np.r_[self.lam, self.mu.ravel()]
        self.t = np.ones(1 + len(problem.limit))
        self.terms = np.zeros(len(problem.limit))  # the controllers' terms, at the coordinator
        self.restart = np.zeros(len(problem.limit), dtype=bool)  # restarts to send
        self.lam_seen = np.full(n, self.lam)  # each DG's last balance price and its round
        self.lam_round = np.full(n, -1)
        self.nu_seen = np.zeros((n, len(problem.limit)))
        self.nu_round = np.full((n, len(problem.limit)), -1)
        self.p = self._best_response(np.arange(n))
        self.send_cost_curves(
            lambda i: (
                [COORDINATOR] + [self.controllers[k] for k in np.flatnonzero(self.factor[:, i])]
            )
        )

    def agents(self) -> list[str]:
        return self.m.names + self.controllers + [COORDINATOR]

    def applied_mw(self) -> np.ndarray:
        return self.p.copy()

    def _best_response(self, who) -> np.ndarray:
        problem = self.m.problem
        price = self.lam_seen[who] + (self.nu_seen[who] * self.factor[:, who].T).sum(axis=1)
        p = (price - problem.b[who]) / (2.0 * problem.c[who])
        return np.clip(p, self.m.lo[who], self.m.hi[who])

    def local_update(self, inbox: dict[str, list[Message]], round_: int) -> None:
        live = []
        for i, name in enumerate(self.m.names):
            if self.net.crashed(name):
                continue  # its inverter holds its set point
            live.append(i)
            for message in inbox.get(name, []):
                if message.kind == "balance price" and message.sent > self.lam_round[i]:
                    self.lam_seen[i], self.lam_round[i] = message.values[0], message.sent
                elif message.kind == "line price":
                    k = self.controllers.index(message.sender)
                    if message.sent > self.nu_round[i, k]:
                        self.nu_seen[i, k], self.nu_round[i, k] = message.values[0], message.sent
        self.p[live] = self._best_response(np.array(live, dtype=int))
        if self.params.accelerated:
            self._accelerated(inbox)
            return
        if not self.net.crashed(COORDINATOR):
            self.lam += self.alpha * (self.m.demand - self.p.sum())
        flows = self.m.flows(self.p)
        limit = self.m.problem.limit
        for k, name in enumerate(self.controllers):
            if not self.net.crashed(name):
                excess = np.array([flows[k] - limit[k], -flows[k] - limit[k]])
                self.mu[k] = np.maximum(0.0, self.mu[k] + self.beta[k] * excess)

    def _accelerated(self, inbox) -> None:
        """Nesterov's fast gradient on the dual with a joint gradient restart (the module
        docstring): every holder steps from the prices it sent, ``x = max(lower, y + step
        grad)``, and sends ``x`` moved on by ``(t_k - 1) / t_{k+1}`` of its last move;
        each controller sends the coordinator its restart term ``grad . (x - x_last)`` (EUR/h);
        the coordinator adds its own and the controllers' latest and, when the sum is
        negative, drops its momentum and tells the controllers to drop theirs."""
        for message in inbox.get(COORDINATOR, []):
            if message.kind == "restart term":
                self.terms[self.controllers.index(message.sender)] = message.values[0]
        flows = self.m.flows(self.p)
        limit = self.m.problem.limit
        if not self.net.crashed(COORDINATOR):
            grad = np.array([self.m.demand - self.p.sum()])
            own = self._momentum(0, np.array([self.lam]), grad, self.alpha, -np.inf)
            if own + self.terms.sum() < 0.0:
                self.t[0] = 1.0
                self.restart[:] = True
            self.lam = float(self._extrapolate(0, -np.inf)[0])
        for k, name in enumerate(self.controllers):
            if self.net.crashed(name):
                continue
            if any(m.kind == "restart" for m in inbox.get(name, [])):
                self.t[1 + k] = 1.0
            grad = np.array([flows[k] - limit[k], -flows[k] - limit[k]])
            term = self._momentum(1 + k, self.mu[k], grad, self.beta[k], 0.0)
            self.net.send(name, COORDINATOR, "restart term", [term],
                          reveals="price step")  # fmt: skip
            self.mu[k] = self._extrapolate(1 + k, 0.0)

    def _momentum(self, h: int, y, grad, step: float, lower: float) -> float:
        """Holder ``h``'s ascent point from the prices ``y`` it sent (kept as its pending
        point) and its restart term ``grad . (x - x_last)``."""
        block = self._block(h)
        x = np.maximum(y + step * grad, lower)
        term = float(np.sum(grad * (x - self.x_last[block])))
        self._pending = (block, x)
        return term

    def _extrapolate(self, h: int, lower: float) -> np.ndarray:
        block, x = self._pending
        t = (1.0 + np.sqrt(1.0 + 4.0 * self.t[h] ** 2)) / 2.0
        y = np.maximum(x + (self.t[h] - 1.0) / t * (x - self.x_last[block]), lower)
        self.x_last[block], self.t[h] = x, t
        return y

    def _block(self, h: int) -> slice:
        """Holder ``h``'s prices in ``x_last``: 0 the balance price, ``1 + k`` line ``k``'s."""
        return slice(0, 1) if h == 0 else slice(2 * h - 1, 2 * h + 1)

    def exchange(self, round_: int) -> None:
        for k in np.flatnonzero(self.restart):
            self.net.send(COORDINATOR, self.controllers[k], "restart", [])
        self.restart[:] = False
        for name in self.m.names:
            self.net.send(COORDINATOR, name, "balance price", [self.lam],
                          reveals="balance price")  # fmt: skip
        for k, name in enumerate(self.controllers):
            nu = self.mu[k, 0] - self.mu[k, 1]
            for i in np.flatnonzero(self.factor[k]):
                self.net.send(name, self.m.names[i], "line price", [nu], reveals="line price")
