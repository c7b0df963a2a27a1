"""Running the agents of a dispatch algorithm, and their result.

:func:`run_agents` picks the algorithm by name (:mod:`popdispatch.agents.algorithms`), refuses
what it cannot use before any work, and lets it build its agents and run them in the generic
world (:mod:`popdispatch.agents.world`: registration, topology, clock, faults, rest, message
metrics). :class:`AgentSettings` are the run's options (the world's and the algorithm's),
:class:`AgentRun` its result; the run is compared with nothing here: callers compare it with
the DC-OPF or the engine.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from popdispatch.agents.algorithms import DEFAULT_ALGORITHM, get_algorithm, refuse_options
from popdispatch.agents.network import Faults
from popdispatch.constants import KW_PER_MW
from popdispatch.game.problem import DispatchProblem
from popdispatch.modes import get_mode
from popdispatch.online.settings import RunSettings

#: Watts per MW.
W_PER_MW = 1.0e6
#: Paper mode's rest tolerance, kW (it claims a rest point of its dynamics, no accuracy).
PAPER_TOL_KW = 1e-3


@dataclass(frozen=True)
class AgentSettings:
    """How the agents run, beyond the dynamics' :class:`~popdispatch.online.RunSettings`.

    Attributes
    ----------
    step_s : the round's Euler step ``h``, s (None: :func:`default_step`).
    max_rounds : horizon, rounds.
    window : rounds over which the set points must move less than ``tol_kw`` to be at rest
        (and every controller's residual, modes/exact.py, be within ``tol_kw``: a price may
        still be decaying on a slack line while the set points wait at their limits).
    tol_kw : rest tolerance, kW (None: :meth:`tol_for`, the engine's; 0: neither a rest nor
        a proof ends the run, it runs to its horizon).
    drain_rounds : most rounds after rest to decide and acknowledge every transaction.
    timeout : rounds an offer stays open (None: ``2 * delay_max + 1`` of the faults, so that
        an offer and its acceptance can both arrive as late as the network delays them).
    lag : rounds from a commit to the change of both inverters (see :meth:`lag_for`).
    paced : rounds paced to the network's latency (default): each phase lasts one tick more
        than the longest simulated delay, so agents act on this round's messages only (a
        synchronizer); a round then takes ``1 + 6 * delay_max`` times the simulated time of
        an unpaced one, and delays cost time, not staleness. Unpaced, agents act on the
        latest messages they have, however old (docs/agents.md: exact mode does not settle).
    decision_copies : copies of each commit or abort sent per round (see :meth:`copies_for`).
    engine_limiter : receivers scale offers by the engine's limiter factor (None: no, they
        accept ``room / offered``; see :mod:`popdispatch.agents.generator`). With it the
        agents follow the engine's Euler trajectory exactly; without it a receiver scales
        by the room it has left now over every offer that arrived (late or repeated ones).
    local_step : curvature-scaled field (exact mode): every generator scales the steps of its
        pairs by its own factor ``1 / (1 + h lam)`` and the round step is bounded by the line
        prices and the economic dispatch's rate only (docs/agents.md, "The local step"), and
        the node controllers hasten a still line's price (:mod:`popdispatch.agents.controller`);
        False: plain Euler rounds of the default step, the engine's Euler steps.
    """

    step_s: float | None = None
    max_rounds: int = 4000
    window: int = 10
    tol_kw: float | None = None
    drain_rounds: int = 200
    timeout: int | None = None
    lag: int | None = None
    paced: bool = True
    decision_copies: int | None = None
    engine_limiter: bool | None = None
    stale_rounds: int = 10
    local_step: bool = True

    def tol_for(self, problem: DispatchProblem, settings: RunSettings, minute: int) -> float:
        """The rest tolerance in force, kW: the given one, else the engine's in a mode that
        claims the DC-OPF (``settings.stepping``: a tenth of the accuracy's floor or its
        relative part, ``max(accuracy_rel P_d, accuracy_kw / 10)``, so that the rest is what
        the distance certificate then proves), else :data:`PAPER_TOL_KW`."""
        if self.tol_kw is not None:
            return float(self.tol_kw)
        if not get_mode(settings.mode).claims_dc_opf:
            return PAPER_TOL_KW
        return settings.stepping.tol_mw(float(problem.demand[minute - 1])) * KW_PER_MW

    def stale_for(self, faults: Faults) -> int:
        """Rounds of silence after which a price or a neighbour's status counts as stale
        (``stale_rounds``, plus ``delay_max`` in unpaced rounds, where messages may be that
        late): at 30 % loss ten rounds in a row are lost with probability 6e-6."""
        return self.stale_rounds + (0 if self.paced else int(faults.delay_max))

    def engine_limiter_for(self, faults: Faults) -> bool:
        """Whether receivers use the engine's limiter factor (None: no; set it to follow the
        engine's Euler trajectory exactly, tests/agents/test_equality.py)."""
        return bool(self.engine_limiter)

    def lag_for(self, faults: Faults) -> int:
        """Rounds from a commit to the inverters' change (None: 0; a lag holds the inverters
        behind the planned set points the revision rule works with, and on the congestion
        minute with delays it stalled the run 3.4 kW from the DC-OPF, docs/agents.md)."""
        return self.lag if self.lag is not None else 0

    def copies_for(self, faults: Faults) -> int:
        """Copies of each decision per round (None: 1 on a lossless network, else 3: a lost
        decision leaves a transaction half done and the source bus, then the lines, carry
        the difference, which the exact mode's line prices amplify)."""
        if self.decision_copies is not None:
            return self.decision_copies
        return 3 if faults.loss else 1

    def timeout_for(self, faults: Faults) -> int:
        """Rounds an offer stays open (see the attribute; 1 in paced rounds)."""
        if self.timeout is not None:
            return self.timeout
        return 1 if self.paced else 2 * int(faults.delay_max) + 1

    def phase_ticks_for(self, faults: Faults, ticks_per_round: int) -> int:
        """Ticks per phase: 1, or in paced rounds one more than the longest simulated delay
        (``delay_max`` unpaced rounds of the algorithm's ``ticks_per_round`` ticks), so that
        every message of a phase is in before the next phase acts."""
        return 1 + ticks_per_round * int(faults.delay_max) if self.paced else 1

    def rest_window(self, faults: Faults) -> int:
        """Rounds of rest required: ``window`` times ``1 + delay_max`` (a late network can
        hold every transaction up for ``delay_max`` rounds; ``window`` in paced rounds)."""
        return self.window * (1 if self.paced else 1 + int(faults.delay_max))




@dataclass(frozen=True)
class AgentRun:
    """A run of the agents. Powers in kW, imbalances in W.

    ``trajectory_kw``: set points at the start of every round (rows), as the plant saw them;
    ``setpoints_kw``: after the drain; ``rest_round``: the round the set points came to rest
    (None if never); ``messages``: every message sent (lost ones and duplicate copies
    included); ``scalars_sent``: the real numbers those messages carried
    (:func:`popdispatch.agents.messages.scalars`); ``lost``: of them lost; ``duplicated``:
    messages the network delivered twice; ``max_imbalance_w``: largest |supply - demand| of the
    committed state at any round; ``max_transient_w``: largest |supply - demand| of the
    inverters as they were at a measurement (taken up by the source bus while a commit is in
    flight); ``final_imbalance_w``: of the inverters after the drain; ``open_transactions``:
    undecided or unacknowledged transactions left after the drain; ``prices``: exact mode,
    each controller's ``(line, z_up, z_down)`` EUR/MW; ``step_s``: the round's Euler step;
    ``phase_ticks``: ticks per phase (paced rounds); ``events``: the faults and what the
    agents noticed (trips, crashes and restarts, stale prices, controllers taken over), each
    ``{"round", "event", "agent", ...}``; ``source_kw``: the source bus's committed position
    left after the drain (power a trip moved to it that the generators could not take
    back); ``stall_reason``: why a run at rest is
    not at the DC-OPF (exact mode's KKT check, :func:`popdispatch.online.kkt_violations`, on
    the set points and the controllers' prices), None otherwise; ``horizon_reason``: why a run
    never came to rest (:func:`horizon_reason`, :func:`runaway`), None otherwise;
    ``infeasible``: the line prices ran away (:func:`runaway`);
    ``line_price_eur_per_mwh``: an algorithm's own price of each limited line at the end
    (``mu_up - mu_down``, dual decomposition), None where ``prices`` hold the mode's states.
    """

    generators: list[str]
    trajectory_kw: np.ndarray
    setpoints_kw: np.ndarray
    rounds: int
    rest_round: int | None
    messages: int
    lost: int
    duplicated: int
    max_imbalance_w: float
    max_transient_w: float
    final_imbalance_w: float
    open_transactions: int
    residual_kw: float
    wall_seconds: float
    agents: int
    step_s: float
    phase_ticks: int = 1
    prices: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    source_kw: float = 0.0
    scalars_sent: int = 0

    stall_reason: str | None = None
    horizon_reason: str | None = None
    infeasible: bool = False
    certified: bool = False
    distance_bound_kw: float | None = None
    accuracy_kw: float | None = None
    line_price_eur_per_mwh: np.ndarray | None = None

    @property
    def status(self) -> str:
        """As the engine's snapshot: ``converged`` (in exact mode the distance certificate
        proves every set point within ``accuracy_kw`` of the DC-OPF; in paper mode, at rest),
        ``stalled`` (at rest without that proof: ``stall_reason``), ``infeasible`` (the line
        prices ran away: ``horizon_reason``) or ``not_converged`` (never at rest and not
        proved: ``horizon_reason``)."""
        if self.infeasible:
            return "infeasible"
        if self.certified:
            return "converged"
        return "not_converged" if self.rest_round is None else "stalled"

    @property
    def reason(self) -> str | None:
        """Why the run is not ``converged`` (None if it is)."""
        if self.status == "converged":
            return None
        return self.horizon_reason if self.rest_round is None else self.stall_reason

    def line_states(self, n_lines: int) -> np.ndarray:
        """Exact mode's line prices at the end, EUR/MW: ``z_up`` of every limited line, then
        ``z_down``, each the mean of its live end controllers' copies (0 in paper mode)."""
        return line_states(self.prices, n_lines)

    @property
    def messages_per_agent_round(self) -> float:
        return self.messages / max(self.agents * max(self.rounds, 1), 1)


def line_states(prices: dict, n_lines: int) -> np.ndarray:
    """``z_up`` of every limited line, then ``z_down`` (EUR/MW), each the mean of the copies
    in ``prices`` (per controller, ``(line, z_up, z_down)`` of each line it ends)."""
    z, ends = np.zeros(2 * n_lines), np.zeros(n_lines)
    for copies in prices.values():
        for line, z_up, z_down in copies:
            z[line] += z_up
            z[n_lines + line] += z_down
            ends[line] += 1
    return z / np.concatenate([ends, ends]).clip(min=1)



def run_agents(
    problem: DispatchProblem,
    minute: int,
    settings: RunSettings | None = None,
    faults: Faults | None = None,
    agent_settings: AgentSettings | None = None,
    on_round=None,
    algorithm: str = DEFAULT_ALGORITHM,
) -> AgentRun:
    """One minute of dispatch by the agents in mango's simulated world (module docstring).

    ``on_round(system, rnd)``: called after every round's measurement (fault injection,
    probes); it may crash, restart or trip agents of ``system``. ``algorithm``: a name of
    :data:`popdispatch.agents.algorithms.ALGORITHMS`; options and settings it cannot use are
    refused before any work (:func:`popdispatch.agents.algorithms.refuse_options`).
    """
    settings = settings or RunSettings()
    faults = faults or Faults()
    agent_settings = agent_settings or AgentSettings()
    chosen = get_algorithm(algorithm)
    refuse_options(chosen, settings, agent_settings, faults)
    agent_settings = replace(agent_settings,
                             tol_kw=agent_settings.tol_for(problem, settings, minute))
    return chosen.run(problem, minute, settings, faults, agent_settings, on_round)


def without(problem: DispatchProblem, minute: int, names: list[str]) -> DispatchProblem:
    """``problem`` with the generators ``names`` offline in ``minute`` (tripped: the DC-OPF a
    run with trips must reach)."""
    if not names:
        return problem
    online = problem.online.copy()
    online[minute - 1, problem.generators.get_indexer(names)] = False
    return replace(problem, online=online)


def check_events(events, generators: list[str], controllers: list[str]) -> None:
    """Every fault event names an agent of its kind: a controller crash one of the node
    controllers ``controllers``, any other fault one of the ``generators`` (one-line
    :class:`~popdispatch.errors.OptionError` naming the option and the agents known)."""
    from popdispatch.errors import OptionError

    for event in events:
        known = list(controllers) if event.kind == "controller-crash" else list(generators)
        if event.agent not in known:
            what = "node controller" if event.kind == "controller-crash" else "generator"
            raise OptionError(f"{event.kind}: no {what} {event.agent!r} (known: "
                              f"{', '.join(map(str, known)) or 'none'})",
                              "--" + event.kind)  # fmt: skip
