"""What to run (:class:`RunSettings`) and where a run starts (:func:`initial_shares`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from popdispatch.dynamics import DYNAMICS, GRAPHS, Field, get_dynamics
from popdispatch.dynamics.fields import field_of, field_tag
from popdispatch.errors import OptionError
from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.parameters import PriceLaw
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import Integrator
from popdispatch.modes import get_mode
from popdispatch.modes.exact import ExactConstants
from popdispatch.warm_start import WARM_STARTS

if TYPE_CHECKING:
    import networkx as nx

SHARES_NAME = "shares"  # the paper's warm start, the only one for modes without limits

X0_CHOICES = ("uniform", "capacity")


@dataclass(frozen=True)
class RunSettings:
    """What to run: dynamics, mode, communication graph, initial state, constants, integrator,
    warm start between minutes (``None``: the mode's default; see :mod:`popdispatch.warm_start`).

    Constants: ``fitness`` holds the paper's (EUR/MW; paper mode, scale-dependent, see
    docs/paper-mode.md; :meth:`FitnessParameters.parse` reads ``"B=1000,m=400,C=1000"``),
    ``exact`` exact mode's dimensionless ones (:class:`~popdispatch.modes.exact.ExactConstants`);
    :meth:`game_constants` gives the EUR/MW values a run uses. ``tol_floor_kw``: the absolute
    floor of the convergence tolerance (kW), replacing the integrator's ``tol_kw`` (exact
    mode's tolerance is ``max(1e-6 P_d, tol_floor_kw)``). ``vmin_pu``/``vmax_pu``: voltage
    limits (p.u., ``None``: no bound; docs/voltage.md): with either given, exact mode becomes
    the ``voltage`` mode (its line prices plus LinDistFlow voltage prices), and the problem a
    run takes must carry the same limits (:func:`popdispatch.runs.with_voltage`).
    ``accuracy_kw`` and ``accuracy_rel``: the accuracy a mode that claims the DC-OPF must
    prove to call a minute converged, ``max(accuracy_kw, accuracy_rel * demand)`` (kW) on every
    set point (the distance certificate, :mod:`popdispatch.online.certificate`). ``eta``: the
    logit dynamics' noise level, EUR/MWh (a marginal cost; required by logit, refused by every
    other dynamic; docs/dynamics.md).

    Construction validates the combination without touching any data, so a command line can
    check its options before loading a feeder: bad values or combinations raise
    :class:`~popdispatch.errors.OptionError` with a one-line message naming them and the option
    to change (see :meth:`validate`).
    """

    dynamics: str = "smith"
    mode: str = "paper"
    graph: str | nx.Graph = "complete"
    x0: str | dict[str, float] = "uniform"
    fitness: FitnessParameters = field(default_factory=FitnessParameters)
    integrator: Integrator | None = None  # None: the mode's default
    warm_start: str | None = None
    exact: ExactConstants = field(default_factory=ExactConstants)
    tol_floor_kw: float | None = None
    vmin_pu: float | None = None
    vmax_pu: float | None = None
    accuracy_kw: float = 1e-3
    accuracy_rel: float = 1e-6
    eta: float | None = None

    def __post_init__(self) -> None:
        if self.voltage_limited and self.mode == "exact":
            object.__setattr__(self, "mode", "voltage")
        self.validate()

    @property
    def voltage_limited(self) -> bool:
        """Whether a voltage limit is given."""
        return self.vmin_pu is not None or self.vmax_pu is not None

    def validate(self) -> None:
        """Raise :class:`OptionError` for an unknown name or a combination that cannot run or
        would silently be ignored:

        - unknown ``dynamics`` (``--dynamics``), ``mode`` (``--mode``), ``graph``
          (``--graph``), ``x0`` name (``--x0``) or ``warm_start`` (``--warm-start``);
        - exact mode with dynamics that have no law inside the generator limits
          (:attr:`~popdispatch.dynamics.Dynamics.refusal`: the replicators' extinction, BNN's
          shifted mean) (``--mode``);
        - a graph other than ``complete`` with dynamics that ignore it (smith, replicator,
          bnn, logit) (``--graph``);
        - ``eta`` missing for logit, given for any other dynamic, or not finite and > 0
          (``--eta``);
        - a price law other than plain outside exact (voltage) mode (``--price-law``);
        - the ``setpoints`` warm start in a mode without generator limits in its revision rule
          (paper mode continues the shares, eq. 10's ``x``; ``--warm-start``).
        """
        dynamics = _lookup(get_dynamics, self.dynamics, "--dynamics")
        mode = _lookup(get_mode, self.mode, "--mode")
        if mode.bounded and dynamics.bounded_law is None:
            names = [d.name for d in DYNAMICS.values() if d.bounded_law is not None]
            users = ", ".join(names[:-1]) + f" or {names[-1]}"
            raise OptionError(
                f"{mode.name} mode cannot run {dynamics.name} dynamics: {dynamics.refusal}; "
                f"use {users}",
                "--mode",
            )
        graph = self.graph if isinstance(self.graph, str) else "custom"
        if isinstance(self.graph, str) and self.graph not in GRAPHS:
            raise OptionError(
                f"unknown communication graph {graph!r} (known: {', '.join(GRAPHS)})", "--graph"
            )
        if graph != "complete" and not dynamics.uses_graph:
            users = " or ".join(d.name for d in DYNAMICS.values() if d.uses_graph)
            raise OptionError(
                f"graph {graph!r} has no effect on {dynamics.name} dynamics, {dynamics.scope}; "
                f"use it with {users}, or leave the graph complete",
                "--graph",
            )
        self._validate_eta(dynamics)
        if isinstance(self.x0, str) and self.x0 not in X0_CHOICES:
            raise OptionError(
                f"unknown initial state {self.x0!r} (known: {', '.join(X0_CHOICES)}, or "
                "shares per generator)",
                "--x0",
            )
        self._validate_warm_start(mode)
        self._validate_voltage(mode)
        if self.exact.price_law != PriceLaw.PLAIN and not mode.claims_dc_opf:
            raise OptionError(
                f"the {self.exact.price_law.name.lower()} price law moves exact mode's line "
                f"prices; {mode.name} mode has none (use --mode exact)",
                "--price-law",
            )
        if not (0 < self.accuracy_kw < float("inf")):
            raise OptionError(f"accuracy must be positive, got {self.accuracy_kw} kW",
                              "--accuracy-kw")  # fmt: skip
        if not (0 <= self.accuracy_rel < 1):
            raise OptionError(f"relative accuracy must be in [0, 1), got {self.accuracy_rel}",
                              "--accuracy-rel")  # fmt: skip
        if self.tol_floor_kw is not None and not self.tol_floor_kw > 0:
            raise OptionError(
                f"tolerance floor must be positive, got {self.tol_floor_kw} kW", "--tol-floor-kw"
            )

    def _validate_eta(self, dynamics) -> None:
        """``eta`` given exactly to the dynamics that take it, finite and > 0 (``--eta``)."""
        takes = "eta" in dynamics.parameters
        if self.eta is None:
            if takes:
                raise OptionError(f"{dynamics.name} dynamics need their noise level: --eta ETA "
                                  "(EUR/MWh, > 0; docs/dynamics.md)", "--eta")  # fmt: skip
            return
        if not takes:
            raise OptionError(f"eta is the logit dynamics' noise level; {dynamics.name} dynamics "
                              "have none", "--eta")  # fmt: skip
        try:
            value = float(self.eta)
        except (TypeError, ValueError):
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise OptionError(f"eta must be a finite number > 0 EUR/MWh, got {self.eta!r}",
                              "--eta")  # fmt: skip

    def _validate_voltage(self, mode) -> None:
        """Limits in (0, 2) with ``vmin < vmax``, only in the voltage mode (exact mode becomes
        it), which needs them (``--vmin``/``--vmax``, ``--mode``)."""
        if self.voltage_limited:
            check_voltage_limits(self.vmin_pu, self.vmax_pu)
            if mode.name != "voltage":
                raise OptionError(
                    f"voltage limits need exact mode (its voltage prices); {mode.name} mode "
                    "has none",
                    "--vmin",
                )
        elif mode.name == "voltage":
            raise OptionError("voltage mode needs --vmin and/or --vmax (p.u.)", "--mode")

    def _validate_warm_start(self, mode) -> None:
        if self.warm_start is None:
            return
        if self.warm_start not in WARM_STARTS:
            raise OptionError(
                f"unknown warm start {self.warm_start!r} (known: {', '.join(WARM_STARTS)})",
                "--warm-start",
            )
        if self.warm_start != SHARES_NAME and not mode.bounded:
            raise OptionError(
                f"warm start {self.warm_start!r} needs a mode with generator limits in its "
                f"revision rule (exact); {mode.name} mode continues the shares",
                "--warm-start",
            )

    def accuracy_mw(self, demand_mw):
        """The accuracy to prove at a demand ``demand_mw`` (MW; one value or an array), MW:
        ``max(accuracy_kw / 1000, accuracy_rel * demand_mw)``."""
        return np.maximum(self.accuracy_kw / 1000.0, self.accuracy_rel * np.asarray(demand_mw))

    @property
    def field(self) -> Field | None:
        """The vector field a run integrates: the dynamic's own law; in a mode with generator
        limits its law inside the limits (capacity-constrained Smith, scaled by each
        generator's curvature under exact mode's ``newton`` revision, dynamics/newton.py; the
        logit inside the box); ``None`` where the dynamic has none (imitative dynamics, BNN)."""
        field = field_of(get_dynamics(self.dynamics), get_mode(self.mode).bounded)
        if field == Field.CAPACITY_SMITH and self.exact.revision == "newton":
            return Field.CAPACITY_NEWTON
        return field

    def field_tag(self, problem: DispatchProblem) -> tuple | None:
        """The compile-time record of :attr:`field` for ``problem`` (``None`` as the field),
        with the parameters its law takes: the logit's ``eta`` in the mode's fitness units
        (EUR/MWh times the fitness gain: 1 in paper mode, exact mode's ``gain / S``) and its
        revision rate ``gain`` (1/s: 1 in paper mode, exact mode's ``gain``; dynamics/logit.py)."""
        field = self.field
        if field is None:
            return None
        bounded = get_mode(self.mode).bounded
        scale = self.game_constants(problem).gain if bounded else 1.0
        gain = self.exact.gain if bounded else 1.0
        eta = math.nan if self.eta is None else self.eta * scale
        return field_tag(field, eta=eta, gain=gain)

    def revision_rates(self, problem: DispatchProblem, free_cap: float | None = None) -> np.ndarray:
        """The per-generator revision rates of the field in force (dimensionless; empty for a
        field that takes none): ``(S / P) / (2 c_i)`` capped at ``rate_cap``
        (dynamics/newton.py); with ``free_cap``, a quadratic generator whose output moves no
        priced row (:func:`priced_generators`) capped at ``free_cap`` instead. Without: the
        rates of fixed explicit steps, the engine's Euler steps and the agents' plain rounds."""
        if self.field != Field.CAPACITY_NEWTON:
            return np.zeros(0)
        from popdispatch.dynamics.newton import revision_rates
        from popdispatch.modes.exact import scales

        if free_cap is None:
            return revision_rates(problem.c, *scales(problem), self.exact.rate_cap)
        return revision_rates(problem.c, *scales(problem), self.exact.rate_cap,
                              priced_generators(problem), free_cap)  # fmt: skip

    def engine_revision_rates(self, problem: DispatchProblem) -> np.ndarray:
        """The revision rates the engine integrates with: with adaptive Heun steps capped at
        ``rate_cap`` only for the generators whose output moves a priced row and the linear
        ones, the others at ``free_rate_cap`` (:func:`priced_generators`,
        dynamics/newton.py); else :meth:`revision_rates`. Near a rest point an unpriced
        quadratic generator adds at most ``S / P`` to the field's fastest rate whatever its
        rate; far from rest a flat generator's fast moves are resolved by the adaptive steps,
        not by fixed ones. On a communication graph as on the complete graph: capped at
        ``rate_cap``, two flat neighbours on a path meet at a few % per iteration
        (docs/exact-mode.md, "Random fleets")."""
        return self.revision_rates(problem, self.exact.free_rate_cap if self.adaptive else None)

    @property
    def trading_graph(self) -> str | nx.Graph:
        """The communication graph the generators trade on: :attr:`graph` under a dynamic
        that takes one, else ``"complete"`` (a kind or a graph, as
        :func:`popdispatch.dynamics.communication_graph` takes it)."""
        return self.graph if get_dynamics(self.dynamics).uses_graph else "complete"

    @property
    def complete_graph(self) -> bool:
        """Do the generators trade on the complete graph (the dynamic takes no graph, or the
        graph is ``"complete"``)?"""
        graph = self.trading_graph
        return isinstance(graph, str) and graph == "complete"

    def engine_idle_rates(self, problem: DispatchProblem) -> np.ndarray:
        """The revision rates the engine gives a generator while every limited line above it
        is idle (dimensionless; empty: the rates do not follow the lines): in exact mode with
        adaptive steps, limited lines on a radial feeder and the curvature-scaled field, the
        rate of a generator below no priced row, ``free_rate_cap`` for a quadratic one
        (:func:`popdispatch.modes.exact.rates_in_force`). On a communication graph a
        generator slow by either set of rates relays always
        (:func:`~popdispatch.dynamics.pairwise.graph_of`): who relays is fixed for the run
        while its rates move between the two."""
        if not (self.adaptive and self.mode == "exact" and len(problem.limit)
                and not problem.meshed and self.field == Field.CAPACITY_NEWTON):  # fmt: skip
            return np.zeros(0)
        from popdispatch.dynamics.newton import revision_rates
        from popdispatch.modes.exact import scales

        unpriced = np.zeros(problem.n_generators, dtype=bool)
        return revision_rates(problem.c, *scales(problem), self.exact.rate_cap, unpriced,
                              self.exact.free_rate_cap)  # fmt: skip

    def engine_held_relays(self, problem: DispatchProblem) -> np.ndarray:
        """Which generators the engine relays always besides those slow by rate (bool, one
        per generator): with adaptive Heun steps the mode's own
        (:meth:`popdispatch.modes.mechanism.Mode.held_relays`), with fixed steps none. A
        relayed transfer is one more term of the field: the adaptive steps gain iterations by
        it, fixed steps (the engine's Euler steps, the agents' rounds, which follow them)
        lose rounds (the ELV congestion minute's ring took 61 instead of 31)."""
        if not self.adaptive:
            return np.zeros(problem.n_generators, dtype=np.bool_)
        return get_mode(self.mode).held_relays(problem)

    def engine_pinned_speed(self, problem: DispatchProblem) -> float:
        """The least speed of a pinned line's prices the engine integrates with, EUR/MWh per s
        (0: none): :attr:`hastens_pinned_lines` on a radial feeder with limited lines,
        ``pinned_speed`` times the marginal-cost spread ``S``
        (:func:`popdispatch.modes.exact.hasten_pinned`, docs/exact-mode.md "Pinned lines")."""
        if not self.hastens_pinned_lines or problem.meshed or not len(problem.limit):
            return 0.0
        from popdispatch.modes.exact import scales

        return float(self.exact.pinned_speed * scales(problem)[0])

    def engine_hastens_stuck_lines(self, problem: DispatchProblem) -> bool:
        """Does the engine also hasten the stuck lines' prices
        (:func:`popdispatch.modes.exact.stuck_gaps`, docs/exact-mode.md "Stuck lines")? Where
        it hastens the pinned lines, with a field that trades in pairs, from a generator to a
        fitter one (Smith's comparison kernel): there no trade moves a line's flow while every
        generator that could send is fitter than every one that could receive. The logit
        moves shares toward every strategy by a smooth response, so its flows answer every
        price."""
        from popdispatch.dynamics import Kernel
        from popdispatch.dynamics.fields import law_of

        if self.engine_pinned_speed(problem) <= 0.0:
            return False
        tag = self.field_tag(problem)
        return tag is not None and law_of(tag).kernel == Kernel.COMPARISON

    @property
    def hastens_pinned_lines(self) -> bool:
        """Does the engine hasten the pinned lines' prices (on a radial feeder with limited
        lines)? In exact mode with adaptive Heun steps
        (:func:`popdispatch.modes.exact.hasten_pinned`). Fixed steps (the engine's Euler
        steps, the agents' rounds, which follow them) and voltage mode keep each price at its
        rate."""
        return self.adaptive and self.mode == "exact"

    @property
    def adaptive(self) -> bool:
        """Does the engine take adaptive (Heun) steps? Its extras (the free rate cap, the
        held relays, the pinned lines' speed) apply only then."""
        return self.stepping.method == "heun"

    @property
    def stepping(self) -> Integrator:
        """The integrator in force: the given one, else the mode's default, with
        ``tol_floor_kw`` as its ``tol_kw`` when given. The default integrator of a mode that
        claims the DC-OPF stops at a tenth of the accuracy's floor and at the accuracy's
        relative part, ``max(accuracy_rel P_d, accuracy_kw / 10)``: a minute at rest within
        that is what the certificate then proves."""
        integrator = self.integrator
        if integrator is None:
            mode = get_mode(self.mode)
            integrator = Integrator(**mode.integrator_options)
            if mode.claims_dc_opf:
                integrator = replace(integrator, tol_kw=self.accuracy_kw / 10.0,
                                     tol_rel=self.accuracy_rel)  # fmt: skip
        if self.tol_floor_kw is None:
            return integrator
        return replace(integrator, tol_kw=float(self.tol_floor_kw))

    def game_constants(self, problem: DispatchProblem) -> FitnessParameters:
        """The game's constants in EUR/MW for ``problem``: paper mode ``fitness``; exact mode
        its dimensionless ``exact`` constants scaled by the problem
        (:func:`popdispatch.modes.exact.game_constants`)."""
        return get_mode(self.mode).game_constants(problem, self)

    def price_scale(self, problem: DispatchProblem) -> float:
        """EUR/MW per unit of the integrator's ``price_atol`` for ``problem``."""
        return get_mode(self.mode).price_scale(problem)

    @property
    def warm_start_policy(self) -> str:
        """The warm start in force: the given one, else the mode's default."""
        return self.warm_start or get_mode(self.mode).warm_start

    def x0_label(self) -> str:
        if isinstance(self.x0, str):
            return self.x0
        return ",".join(f"{k}={v:g}" for k, v in self.x0.items())


def _lookup(get: Callable, name: str, option: str):
    """``get(name)``, its ``ValueError`` (unknown name) re-raised as :class:`OptionError`."""
    try:
        return get(name)
    except ValueError as error:
        raise OptionError(str(error), option) from None


def initial_shares(problem: DispatchProblem, x0: str | dict[str, float], minute: int) -> np.ndarray:
    """Initial shares over the generators online at ``minute``.

    ``"uniform"``: equal shares; ``"capacity"``: proportional to Pmax; a mapping
    ``{generator: share}``: given shares (missing ones 0), normalised to sum 1.
    """
    online = problem.online[minute - 1]
    if isinstance(x0, dict):
        unknown = set(x0) - set(problem.generators)
        if unknown:
            raise ValueError(f"initial share given for unknown generator {sorted(unknown)[0]!r}")
        x = np.array([float(x0.get(g, 0.0)) for g in problem.generators])
        if (x < 0).any() or not np.isfinite(x).all():
            raise ValueError("initial shares must be finite and non-negative")
    elif x0 == "uniform":
        x = np.ones(problem.n_generators)
    elif x0 == "capacity":
        x = problem.pmax.copy()
    else:
        raise ValueError(f"unknown initial state {x0!r} (known: {', '.join(X0_CHOICES)})")
    x = np.where(online, x, 0.0)
    if x.sum() <= 0:
        raise ValueError("initial shares are all zero on the online generators")
    return x / x.sum()


def check_voltage_limits(vmin_pu: float | None, vmax_pu: float | None) -> tuple[float, float]:
    """``(vmin, vmax)`` in p.u. (a missing one: 0 or 2, i.e. no bound), or :class:`OptionError`
    naming the option for a value outside (0, 2) or ``vmin >= vmax``."""
    for value, option in ((vmin_pu, "--vmin"), (vmax_pu, "--vmax")):
        if value is not None and not (math.isfinite(value) and 0.0 < value < 2.0):
            raise OptionError(f"voltage limit {option} {value} p.u. is outside (0, 2)", option)
    low = 0.0 if vmin_pu is None else float(vmin_pu)
    high = 2.0 if vmax_pu is None else float(vmax_pu)
    if low >= high:
        raise OptionError(f"--vmin {low:g} p.u. is not below --vmax {high:g} p.u.", "--vmin")
    return low, high


def priced_generators(problem: DispatchProblem) -> np.ndarray:
    """Per generator: does its output move a row the controllers price (a limited line it is
    below, or on a meshed network with a non-zero distribution factor to; a monitored bus's
    voltage)?"""
    priced = np.zeros(problem.n_generators, dtype=bool)
    if len(problem.limit):
        priced |= np.any(problem.down != 0.0, axis=0)
    if problem.n_voltage:
        priced |= np.any(problem.voltage_sens != 0.0, axis=0)
    return priced
