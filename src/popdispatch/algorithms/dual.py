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
    balanced_shares,
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


# -- the rules, shared by this runtime and the mango agents (popdispatch.agents.dual) ------


def price_response(c, lo, hi) -> np.ndarray:
    """Each DG's price response ``1 / (2 c_i)`` (MW per EUR/MW) where it has a range
    (``hi > lo``), else 0: the slope of its best response inside its limits."""
    return np.where(hi > lo, 1.0 / (2.0 * np.asarray(c, dtype=float)), 0.0)


def balance_step_size(balance_step: float, response: np.ndarray) -> float:
    """The balance price's step ``alpha = balance_step / sum_i response_i`` (EUR/MW per MW)."""
    return balance_step / response.sum()


def line_step_sizes(line_step: float, factor: np.ndarray, response: np.ndarray) -> np.ndarray:
    """The line prices' steps ``beta_k = line_step / sum_i D_ki^2 response_i`` (EUR/MW per MW;
    ``factor``: the DGs' weights ``D_ki`` on each line price, lines x DGs; infinite curvature,
    a zero step, for a line no DG with a range moves)."""
    line_response = (factor**2) @ response  # the dual's curvature along each price
    return line_step / np.where(line_response > 0, line_response, np.inf)


def initial_balance_price(b, c, lo, hi, demand_mw: float) -> float:
    """The balance price's start, EUR/MW: the DGs' mean marginal cost ``b_i + 2 c_i p_i`` at
    the uniform start (:func:`~popdispatch.algorithms.base.balanced_shares`), over the DGs
    with a range."""
    start = balanced_shares(lo, hi, demand_mw)
    return float(np.mean((b + 2.0 * c * start)[hi > lo]))


def best_response(price, b, c, lo, hi):
    """The set point (MW) minimising ``b p + c p^2 - price p`` within ``[lo, hi]``: a DG's
    best response to its locational price (EUR/MW)."""
    return np.clip((price - b) / (2.0 * c), lo, hi)


def balance_price_step(lam: float, alpha: float, shortfall_mw: float) -> float:
    """Gradient ascent of the balance price on the measured shortfall ``P_d - sum p`` (MW)."""
    return lam + alpha * shortfall_mw


def line_gradient(flow_mw: float, limit_mw: float) -> np.ndarray:
    """The dual's gradient along a line's two direction prices: ``(flow - U, -flow - U)``."""
    return np.array([flow_mw - limit_mw, -flow_mw - limit_mw])


def line_price_step(mu: np.ndarray, beta: float, gradient: np.ndarray) -> np.ndarray:
    """Projected gradient ascent of a line's direction prices ``(mu_up, mu_down) >= 0``."""
    return np.maximum(0.0, mu + beta * gradient)


class Momentum:
    """One price holder's Nesterov state (the module docstring): its last ascent point
    ``x_last`` and its momentum counter ``t`` (1 after a restart)."""

    def __init__(self, x0):
        self.x_last = np.array(x0, dtype=float)
        self.t = 1.0
        self._x = self.x_last

    def ascend(self, y, grad, step: float, lower: float) -> float:
        """Step from the prices ``y`` it sent, ``x = max(lower, y + step grad)`` (kept
        pending), and return its restart term ``grad . (x - x_last)`` (EUR/h)."""
        self._x = np.maximum(y + step * grad, lower)
        return float(np.sum(grad * (self._x - self.x_last)))

    def extrapolate(self, lower: float) -> np.ndarray:
        """The prices to send: the pending ``x`` moved on by ``(t_k - 1) / t_{k+1}`` of the
        last move."""
        x = self._x
        t = (1.0 + np.sqrt(1.0 + 4.0 * self.t**2)) / 2.0
        y = np.maximum(x + (self.t - 1.0) / t * (x - self.x_last), lower)
        self.x_last, self.t = x, t
        return y

    def restart(self) -> None:
        """Drop the momentum (the joint restart test failed)."""
        self.t = 1.0


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
        response = price_response(problem.c, minute.lo, minute.hi)  # MW per EUR/MW
        self.alpha = balance_step_size(params.balance_step, response)
        self.beta = line_step_sizes(params.line_step, self.factor, response)
        self.controllers = [controller_name(problem, k) for k in range(len(problem.limit))]
        self.lam = initial_balance_price(problem.b, problem.c, minute.lo, minute.hi,
                                         minute.demand)  # fmt: skip
        self.mu = np.zeros((len(problem.limit), 2))
        # acceleration: each holder's Nesterov state (0 the coordinator, 1 + k controller k)
        self.momentum = [Momentum([self.lam])] + [Momentum(mu) for mu in self.mu]
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
        return best_response(price, problem.b[who], problem.c[who], self.m.lo[who],
                             self.m.hi[who])  # fmt: skip

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
            self.lam = balance_price_step(self.lam, self.alpha, self.m.demand - self.p.sum())
        flows = self.m.flows(self.p)
        limit = self.m.problem.limit
        for k, name in enumerate(self.controllers):
            if not self.net.crashed(name):
                gradient = line_gradient(flows[k], limit[k])
                self.mu[k] = line_price_step(self.mu[k], self.beta[k], gradient)

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
            own = self.momentum[0].ascend(np.array([self.lam]), grad, self.alpha, -np.inf)
            if own + self.terms.sum() < 0.0:
                self.momentum[0].restart()
                self.restart[:] = True
            self.lam = float(self.momentum[0].extrapolate(-np.inf)[0])
        for k, name in enumerate(self.controllers):
            if self.net.crashed(name):
                continue
            if any(m.kind == "restart" for m in inbox.get(name, [])):
                self.momentum[1 + k].restart()
            grad = line_gradient(flows[k], limit[k])
            term = self.momentum[1 + k].ascend(self.mu[k], grad, self.beta[k], 0.0)
            self.net.send(name, COORDINATOR, "restart term", [term],
                          reveals="price step")  # fmt: skip
            self.mu[k] = self.momentum[1 + k].extrapolate(0.0)

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
