"""Population dynamics by messages: Smith on the complete graph, distributed Smith on a sparse
graph, in exact mode (the curvature-scaled capacity field and integrated line prices,
docs/exact-mode.md), one explicit Euler step of ``h = step x round_step`` per round
(:func:`popdispatch.online.stiffness.round_step`: the agents' round step, the largest stable
explicit step of exact mode's dynamics on the minute).

The numbers come from the plain-numpy reference (:mod:`popdispatch.reference`): the fitness
is the engine's kernel (``generator_fitness``, as ``reference.fitness`` calls it), the
receiver and sender weights ``reference.weights`` on each DG's view of its neighbourhood,
the pairwise flow ``w_j v_i [f_j - f_i]_+`` of ``reference.pair_flows``; the game's
constants and revision rates are the run settings' (``RunSettings(mode="exact")``).

Agents: one per DG and one node controller per limited line. Each round

* a controller measures its line's flow at the applied set points, integrates its two
  directions' prices (``z <- max(0, z + h price_rate e)``) and sends the net price ``nu =
  mu_up - mu_down`` (``mu = max(0, z + C e)``) to every DG (those below take ``+nu/2``,
  the others ``-nu/2``: exact mode's split);
* a DG reads its partners' last reported ``(fitness, receiver weight, set point)``, sends
  mass ``h P_d w_j v_i [f_j - f_i]_+`` (MW) to each better partner in a *transfer* (at most
  its movable mass in all, at most the partner's reported room each), and reports its own
  ``(fitness, receiver weight, set point)`` to its partners.

Supply = demand through the transactions: a transfer names the round it takes effect; the
sender lowers its set point by the amount in that round, the receiver raises its own by what
it accepts (at most its room) when the transfer arrives and acknowledges it; the sender takes
back what was not accepted when the acknowledgement arrives. On a perfect network both sides
move in the same round; a lost or late transfer leaves the difference to the source bus
until it arrives (the imbalance the runner reports). Loss handling: stale partner reports and
prices are used as they are; a transfer not acknowledged within ``2 (1 + delay) + 1`` rounds
is sent again under the same identity (receivers accept an identity once and acknowledge it
again), by the receiver's current route (a relayed one recovers from a relay that crashed);
a partner silent for ``silent_rounds`` is dropped from the view and its open transfers are
taken back (a crashed DG: its inverter still makes the set-point changes its agent committed
before the crash, then holds). A transfer relayed through a DG that crashes, to a receiver
no other route reaches, stays open: its amount is missing from the supply, and the run
reports the imbalance and does not converge.

The relay (distributed Smith's, :func:`popdispatch.reference.relay_matrix`): a DG relays
when it is blocked (at a limit, or without receiver weight) or slow (its revision rate below
a tenth of a neighbour's: :func:`popdispatch.reference.slow_members`, from the cost curves it
holds). A relaying DG tells its neighbours every round the receivers of its relay group it
knows, each with its last report and the route to it: its neighbours that can receive, and
what its relaying neighbours tell it. Every member of the group (the relaying DGs and their
neighbours) so learns every receiver of the group, and sends to each better one at the
pairwise rate ``w_b v_a [f_b - f_a]_+``, on top of the direct flow to a neighbour: the
engine's relay, the flow shared among the group's receivers (continuous in the fitness), not
switched to the best one. A relayed transfer and its acknowledgement cross the route hop by
hop (one message and one round per hop).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, partial

import numpy as np

from popdispatch.algorithms.base import Algorithm, Minute, balanced_start, controller_name
from popdispatch.algorithms.network import Message, Network
from popdispatch.dynamics import communication_graph
from popdispatch.dynamics.fields import field_tag, law_of
from popdispatch.dynamics.pairwise import receives_relayed, relays_at_limit
from popdispatch.game.controllers import overflow_signal
from popdispatch.game.fitness import generator_fitness
from popdispatch.online import RunSettings
from popdispatch.online.stiffness import round_step
from popdispatch.reference import pair_flows, slow_members


@dataclass(frozen=True)
class SmithParams:
    """step: the Euler step of one round in units of
    :func:`~popdispatch.online.stiffness.round_step` (dimensionless); price_rate: exact mode's
    price rate (dimensionless, :class:`~popdispatch.modes.exact.ExactConstants`; None: its
    default);
    graph: the communication graph (complete, or a sparse one of
    :data:`popdispatch.dynamics.GRAPHS`); silent_rounds: rounds without a report after which
    a partner counts as gone; mode: ``"exact"`` or ``"paper"`` (the paper's rule: the
    generator-limit barrier of eq. 7 and the memoryless congestion signals of eq. 8, one
    round the engine's Euler substep times ``step``; ``price_rate`` unused)."""

    step: float = 0.3
    price_rate: float | None = 1000.0
    graph: str = "complete"
    silent_rounds: int = 40
    mode: str = "exact"


class PopulationDynamics(Algorithm):
    """Smith (complete graph) or distributed Smith (sparse graph) in exact mode."""

    loss_handling = ("stale reports and prices; transfers resent until acknowledged (same "
                     "identity, accepted once, by the current route); a silent partner dropped, "
                     "its transfers taken back")  # fmt: skip

    def __init__(self, minute: Minute, network: Network, params: SmithParams):
        super().__init__(minute, network, params)
        problem, n = minute.problem, len(minute.names)
        from popdispatch.modes.exact import ExactConstants, controller_constants

        exact = ExactConstants() if params.price_rate is None else \
            ExactConstants(price_rate=params.price_rate)  # fmt: skip
        sparse = params.graph != "complete"
        settings = RunSettings(mode=params.mode,
                               dynamics="distributed-smith" if sparse else "smith",
                               graph=params.graph, exact=exact)  # fmt: skip
        self.paper = params.mode == "paper"
        self.claims_optimum = not self.paper  # paper mode rests away from the DC-OPF
        self.fp = settings.game_constants(problem)
        self.field = settings.field
        tag = field_tag(self.field)
        self._law_weights = partial(law_of(tag).reference, tag)
        self.rate = settings.revision_rates(problem)
        self.h = params.step * round_step(problem, settings, minute.minute)
        self.graph = communication_graph(params.graph, minute.names)
        self.neighbours = [np.flatnonzero(self.graph[i]) for i in range(n)]
        self.complete = bool((self.graph + np.eye(n) > 0).all())
        self.p = balanced_start(minute)
        # the range the transfers keep each DG in: its limits (exact mode's capacity rule),
        # or any share of the demand (paper mode: the barrier of eq. 7 keeps the limits)
        online = problem.online[minute.minute - 1]
        self.lo_box, self.hi_box = (np.zeros(n), np.where(online, minute.demand, 0.0)) \
            if self.paper else (minute.lo, minute.hi)  # fmt: skip
        # each DG's share of each line price: D_ki - 1/2 (+1/2 below the line and -1/2 above
        # it on a radial feeder; its distribution factor on a meshed network)
        self.split = np.ascontiguousarray(problem.down.T - 0.5)
        self.factor_t = np.ascontiguousarray(problem.down.T)
        self._boxes: dict[tuple, tuple] = {}  # a view's (lo, hi, active, rate)
        self.controllers = [controller_name(problem, k) for k in range(len(problem.limit))]
        self.controller_index = {name: k for k, name in enumerate(self.controllers)}
        self.z = np.zeros((len(problem.limit), 2))
        # each line's proportional weight and price rate, as the engine's (a mesh's lever scale)
        self.line_C, self.line_rate = controller_constants(
            problem, exact.price_law, self.fp.C, self.fp.price_rate, minute.minute
        )
        # each DG's view: the last report of each partner (f, w, p) and its round
        self.report = np.zeros((n, n, 4))
        self.heard = np.zeros((n, n), dtype=int)
        self.gone = np.zeros((n, n), dtype=bool)
        self.nu = np.zeros((n, len(problem.limit)))  # each DG's last price from each line
        self.sides = np.zeros((n, len(problem.limit), 2))  # paper: (parent, child) signals
        self.nu_round = np.full((n, len(problem.limit)), -1)
        self.seq = np.zeros(n, dtype=int)
        self.outstanding = [OpenTransfers() for _ in range(n)]
        self.accepted: list[dict] = [{} for _ in range(n)]  # key -> amount accepted
        self.debits: list[list] = [[] for _ in range(n)]  # (round, amount) due
        self.own = np.zeros((n, 4))
        # relaying neighbour -> (its receivers [(b, f, w, p, route)], round it told them)
        self.announced: list[dict] = [{} for _ in range(n)]
        self.slow = slow_members(self.rate, self.graph) if sparse else np.zeros(n, dtype=bool)
        self.send_cost_curves(lambda i: [minute.names[j] for j in self.neighbours[i]])
        for i in range(n):
            for j in self.neighbours[i]:
                self.report[i, j] = (0.0, 0.0, self.p[j], 0.0)

    def agents(self) -> list[str]:
        return self.m.names + self.controllers

    def applied_mw(self) -> np.ndarray:
        return self.p.copy()

    def held_mw(self, i: int) -> float:
        """The applied set point less the transfers the crashed DG committed and its
        inverter has still to make (a relayed one takes effect a round per hop later)."""
        return float(self.p[i] - sum(amount for _, amount in self.debits[i]))

    # -- a round -------------------------------------------------------------------------
    def local_update(self, inbox: dict[str, list[Message]], round_: int) -> None:
        self._controllers(inbox, round_)
        for i, name in enumerate(self.m.names):
            due = [a for r, a in self.debits[i] if r <= round_]
            self.debits[i] = [(r, a) for r, a in self.debits[i] if r > round_]
            self.p[i] -= sum(due)  # the inverter's schedule, kept by a crashed DG's too
            if self.net.crashed(name):
                continue
            for message in inbox.get(name, []):
                self._receive(i, message, round_)
            self._resend(i, round_)
            self._forget_silent(i, round_)

    def exchange(self, round_: int) -> None:
        names = self.m.names
        for i, name in enumerate(names):
            if self.net.crashed(name):
                continue
            with np.errstate(divide="ignore", invalid="ignore"):
                group = self._transfers(i, round_)
            report = self.own[i].tolist()
            for j in self._partners(i):
                self.net.send(name, names[j], "report", report, reveals="fitness")
            if group:
                self._announce(i, group)

    # -- node controllers ----------------------------------------------------------------
    def _controllers(self, inbox, round_: int) -> None:
        h, fp = self.h, self.fp
        flows = self.m.flows(self.p)  # measured
        limit = self.m.problem.limit
        for k, name in enumerate(self.controllers):
            if self.net.crashed(name):
                continue
            if self.paper:
                for dg in self.m.names:
                    self.net.send(name, dg, "price", paper_signals(flows[k], limit[k], fp.C),
                                  reveals="line price")  # fmt: skip
                continue
            excess = np.array([flows[k] - limit[k], -flows[k] - limit[k]])
            mu = np.maximum(0.0, self.z[k] + self.line_C[k] * excess)
            self.z[k] = np.maximum(self.z[k] + h * self.line_rate[k] * excess, 0.0)
            for dg in self.m.names:
                self.net.send(name, dg, "price", [mu[0] - mu[1]], reveals="line price")

    # -- generators ----------------------------------------------------------------------
    def _partners(self, i: int) -> list[int]:
        neighbours = self.neighbours[i]
        return neighbours[~self.gone[i, neighbours]].tolist()

    def _receive(self, i: int, message: Message, round_: int) -> None:
        names = self.m.names
        if message.kind == "price":
            k = self.controller_index[message.sender]
            if message.sent > self.nu_round[i, k]:
                self.nu_round[i, k] = message.sent
                if self.paper:
                    self.sides[i, k] = message.values
                else:
                    self.nu[i, k] = message.values[0]
        elif message.kind == "report":
            j = self.m.position[message.sender]
            if message.sent > self.heard[i, j]:
                self.report[i, j], self.heard[i, j] = message.values, message.sent
                self.gone[i, j] = False
        elif message.kind == "transfer":
            if message.key not in self.accepted[i]:
                room = max(self.hi_box[i] - self.p[i] - self.outstanding[i].total(), 0.0)
                take = min(message.values[0], room)
                self.accepted[i][message.key] = take
                self.p[i] += take
            self.net.send(names[i], message.sender, "ack", [self.accepted[i][message.key]],
                          key=message.key, via=message.via[::-1])  # fmt: skip
        elif message.kind == "relay":
            k = self.m.position[message.sender]
            if message.sent >= self.announced[i].get(k, ((), -1))[1]:
                f, w, p = np.reshape(message.values, (-1, 3)).T
                self.announced[i][k] = ([(b, f[e], w[e], p[e], via) for e, (b, via)
                                         in enumerate(message.key)], message.sent)  # fmt: skip
        elif message.kind == "ack":
            open_ = self.outstanding[i].pop(message.key, None)
            if open_ is not None:
                self.p[i] += open_[1] - message.values[0]

    def _resend(self, i: int, round_: int) -> None:
        """Send again, under the same identity, each transfer not acknowledged in time, by
        the receiver's current route (a relay on the old one may have crashed: a transfer
        or an acknowledgement lost there is recovered through another)."""
        wait = 2 * (1 + self.net.faults.delay_max) + 1
        routes = None
        for key, entry in self.outstanding[i].items():
            to, amount, sent, _, via = entry
            if round_ - sent >= wait * (1 + len(via)):
                if routes is None:
                    targets, relayed = self._relay_targets(i, round_)
                    routes = {t[0]: r for t, r in zip(targets, relayed, strict=True)}
                    routes.update({j: () for j in self._partners(i)})
                via = entry[4] = routes.get(to, via)
                entry[2], entry[3] = round_, entry[3] + 1
                self.net.send(self.m.names[i], self.m.names[to], "transfer", [amount, sent],
                              key=key, via=via)  # fmt: skip

    def _forget_silent(self, i: int, round_: int) -> None:
        for j in self.neighbours[i]:
            if not self.gone[i, j] and round_ - self.heard[i, j] > self.params.silent_rounds:
                self.gone[i, j] = True
                for key in [k for k, e in self.outstanding[i].items() if e[0] == j]:
                    self.p[i] += self.outstanding[i].pop(key)[1]  # taken back

    def _transfers(self, i: int, round_: int) -> dict | None:
        """Compute the own report and send this round's transfers to better partners; the
        receivers of its relay group (:meth:`_group_receivers`) if it relays on a sparse
        graph, else None."""
        m = self.m
        partners = self._partners(i)
        view = [i] + partners
        seen = self.report[i, partners]  # (partners, 4): their last reports
        p_view = np.concatenate(([self.p[i]], seen[:, 2]))
        f_i = self._fitness(i, self._signal(i))
        f_view = np.concatenate(([f_i], seen[:, 0]))
        w, v, room, mass = self._weights(view, p_view, f_view)
        blocked = relays_at_limit(float(w[0]), float(mass[0]), float(room[0]))
        refunds = self.outstanding[i].total()
        relays = blocked or bool(self.slow[i])
        self.own[i] = (f_i, w[0], self.p[i] + refunds, float(relays))  # p: at most, once
        # the open transfers' refunds are back (the room partners may fill)
        group = self._group_receivers(i, round_) if relays and not self.complete else None
        targets, relayed = self._relay_targets(i, round_, group)
        if len(view) == 1 and not targets:
            return group
        w_view = np.concatenate(([w[0]], seen[:, 1]))
        members = [(b, f_view[e], w_view[e], p_view[e]) for e, b in enumerate(view)]
        view, f_view, w_view, p_view, routes = _with_relay_targets(members, targets, relayed)
        known = (v, room, mass) if len(view) == len(members) else None  # the view's weights
        hops = np.array([1 + len(r) for r in routes])
        out = self._limited_outflows(view, f_view, w_view, p_view, hops, known)
        pending = sum(a for _, a in self.debits[i])
        movable = max(self.p[i] - self.lo_box[i] - pending, 0.0)
        total = out.sum()
        if total > movable:
            out = out * (movable / total)
        for j, amount, via in zip(view[1:], out, routes, strict=True):
            if amount > 1e-12 * m.demand:
                self._send_transfer(i, j, amount, round_, via)
        return group

    def _weights(self, view: list[int], p: np.ndarray, f: np.ndarray) -> tuple:
        """Receiver and sender weights, rooms and movable masses of the DGs ``view`` at set
        points ``p`` (MW) and fitness ``f``: the field's plain-numpy law
        (:func:`popdispatch.reference.weights`), in shares of the demand."""
        box = self._boxes.get(tuple(view))
        if box is None:
            demand = self.m.demand
            lo, hi = self.lo_box[view] / demand, self.hi_box[view] / demand
            rate = self.rate[view] if len(self.rate) else self.rate  # none in paper mode
            box = self._boxes[tuple(view)] = (lo, hi, hi > lo, rate)
        return self._law_weights(p / self.m.demand, f, *box)

    def _limited_outflows(self, view, f, w, p, hops, known=None) -> np.ndarray:
        """The MW ``view[0]`` sends each other member of its view this round: ``h D w_j v_i
        [f_j - f_i]_+``, each receiver's share cut by the reference's receiver limiter
        (``room_j / (h inflow_j)``, the inflow from every member of the view as this DG
        knows them: :func:`popdispatch.reference.pair_flows`), and at most the receiver's
        reported room over ``4 (1 + delay) hops (N - 1)``: the senders of the rounds of transfers
        its report does not yet show (two on a perfect network, each wave at most a quarter
        of a room that shrinks by at most that much a round) cannot overfill it, so no
        transfer is turned back and supply = demand every round. ``known``: ``(v, room,
        mass)`` of the view at ``p`` and ``f`` when already computed."""
        m, h = self.m, self.h
        v, room, mass = known if known is not None else self._weights(view, p, f)[1:]
        inflow, _ = pair_flows(f, w, v, _everyone(len(view)), mass, room)
        beta = np.where(h * inflow > room, room / (h * inflow), 1.0)
        out = h * beta[1:] * w[1:] * v[0] * np.maximum(f[1:] - f[0], 0.0) * m.demand
        waves = 4 * (1 + self.net.faults.delay_max) * hops * max(1, len(self.m.names) - 1)
        return np.minimum(out, np.maximum(self.hi_box[view[1:]] - p[1:], 0.0) / waves)

    def _signal(self, i: int) -> float:
        """DG ``i``'s congestion signal from the line prices it last heard, EUR/MW: exact
        mode's split ``(D_ki - 1/2) nu_k``; paper mode's side of each line, ``parent_k + D_ki
        (child_k - parent_k)`` (eq. 8's value at the end of the line facing the DG)."""
        if self.paper:
            sides = self.sides[i]
            return float(sides[:, 0].sum() + self.factor_t[i] @ (sides[:, 1] - sides[:, 0]))
        return float(self.split[i] @ self.nu[i])

    def _fitness(self, i: int, signal: float) -> float:
        """DG ``i``'s fitness (the engine's kernel, as the reference calls it): exact mode's
        (scaled by its gain, no barrier) or the paper's (eqs. 5-7, the barrier)."""
        pr, one = self.m.problem, slice(i, i + 1)
        fp = self.fp
        gain = 1.0 if self.paper else float(fp.gain)
        return float(generator_fitness(self.p[one], pr.b[one], pr.c[one], self.m.lo[one],
                                       self.m.hi[one], float(fp.B), float(fp.m),
                                       np.array([signal]), gain, self.paper)[0])  # fmt: skip

    def _send_transfer(self, i: int, j: int, amount: float, round_: int, via=()) -> None:
        key = (self.m.names[i], int(self.seq[i]))
        self.seq[i] += 1
        self.outstanding[i][key] = [j, amount, round_, 0, via]
        self.debits[i].append((round_ + 1 + len(via), amount))
        self.net.send(self.m.names[i], self.m.names[j], "transfer", [amount, round_ + 1],
                      reveals="set point change", key=key, via=via)  # fmt: skip

    def _fresh(self, round_: int) -> int:
        return 2 * (1 + self.net.faults.delay_max) + 2

    def _relay_targets(self, i: int, round_: int, group: dict | None = None) -> tuple:
        """The receivers of DG ``i``'s relay groups beyond itself, the shortest route to each
        (``()``: a neighbour): ``([(b, f_b, w_b, p_b), ...], [route, ...])``. A relaying DG
        knows its ``group``'s (:meth:`_group_receivers`); otherwise what its relaying
        neighbours tell it of theirs."""
        if group is not None:
            best = {b: r for b, r in group.items() if b != i}
        else:
            best = {}
            for k, (told, _) in self._told(i, round_):
                self._merge(best, told, k, i)
        return [(b, *r[:3]) for b, r in best.items()], [r[3] for r in best.values()]

    def _group_receivers(self, i: int, round_: int) -> dict[int, tuple]:
        """The receivers of relaying DG ``i``'s group it knows, ``{b: (f_b, w_b, p_b,
        route)}``: itself and its neighbours that can receive
        (:func:`~popdispatch.dynamics.pairwise.receives_relayed`), and the receivers its
        relaying neighbours tell it of."""
        receivers: dict[int, tuple] = {}
        reports = [(i, *self.own[i, :3])] + [(j, *self.report[i, j, :3])
                                             for j in self._partners(i)]  # fmt: skip
        for j, f, w, p in reports:  # its own, and its partners' last
            if receives_relayed(float(w), float((self.hi_box[j] - p) / self.m.demand)):
                receivers[j] = (f, w, p, ())
        for k, (told, _) in self._told(i, round_):
            self._merge(receivers, told, k, i)
        return receivers

    def _told(self, i: int, round_: int) -> list:
        """The receiver lists DG ``i``'s relaying partners told it of lately, by partner."""
        fresh = self._fresh(round_)
        return [(k, entry) for k, entry in self.announced[i].items()
                if not self.gone[i, k] and round_ - entry[1] <= fresh]  # fmt: skip

    def _merge(self, receivers: dict, told: list, k: int, i: int) -> None:
        """Add to ``receivers`` (of DG ``i``) the receivers relaying neighbour ``k`` told of,
        by the shortest route (through ``k``; none through ``i`` itself)."""
        names = self.m.names
        for b, f, w, p, via in told:
            route = () if b == k else (names[k],) + tuple(via)
            if b == i or names[i] in route:
                continue
            if b not in receivers or len(route) < len(receivers[b][3]):
                receivers[b] = (f, w, p, route)

    def _announce(self, i: int, receivers: dict[int, tuple]) -> None:
        """A relaying DG tells its partners the ``receivers`` of its group it knows, with the
        route to each (:meth:`_group_receivers`)."""
        names = self.m.names
        key = tuple((b, r[3]) for b, r in receivers.items())
        values = [x for r in receivers.values() for x in r[:3]]
        for j in self._partners(i):
            self.net.send(names[i], names[j], "relay", values, key=key, reveals="fitness")


class OpenTransfers(dict):
    """A DG's transfers not yet acknowledged, ``key -> [to, amount (MW), sent, tries,
    route]``, with their total amount (summed once after each change)."""

    _total: float | None = None

    def __setitem__(self, key, entry) -> None:
        self._total = None
        super().__setitem__(key, entry)

    def pop(self, key, *default):
        self._total = None
        return super().pop(key, *default)

    def total(self) -> float:
        """The MW the open transfers would give back if none were accepted."""
        if self._total is None:
            self._total = sum(e[1] for e in self.values())
        return self._total


def paper_signals(flow: float, limit: float, C: float) -> tuple[float, float]:
    """Eq. 8 at a limited line's two ends (EUR/MW), from its flow ``flow`` and rating
    ``limit`` (MW, + towards the loads below): the parent-end controller's value and the
    child-end one's (0 unless the parent end signals), as paper mode's engine computes them
    (:func:`popdispatch.modes.paper.controller_values`)."""
    parent = overflow_signal(flow, limit, C)
    return parent, (overflow_signal(-flow, limit, C) if parent != 0.0 else 0.0)


def _with_relay_targets(members: list[tuple], targets: list[tuple], routes: list) -> tuple:
    """A DG's view (``members``: itself first, then its partners, each ``(index, f, w, p)``)
    extended by its relay groups' receivers ``targets`` (reached by ``routes``): ``(view, f,
    w, p, routes)`` over the view, each receiver weight times its share of the pairwise
    rate (1 for a neighbour, one more where a relay group shares it: the relay's flow on top
    of the direct one), the routes of the members after the first (``()``: a neighbour)."""
    index = {m[0]: e for e, m in enumerate(members)}
    rows = [list(m) for m in members]
    via = [()] * (len(members) - 1)
    for target, route in zip(targets, routes, strict=True):
        if target[0] in index:
            rows[index[target[0]]][2] += members[index[target[0]]][2]
        else:
            rows.append(list(target))
            via.append(route)
    view = [int(r[0]) for r in rows]
    f, w, p = (np.array([r[k] for r in rows], dtype=float) for k in (1, 2, 3))
    return view, f, w, p, via


@cache
def _everyone(n: int) -> np.ndarray:
    """The complete graph on ``n`` members (a DG's view as it knows it)."""
    return np.ones((n, n)) - np.eye(n)
