"""What the compiled game takes, by name: the game's parameters, one minute's inputs and the
game's scratch arrays. ``typing.NamedTuple``\\ s, which numba compiles and caches like tuples:
fields are read by name in the kernels, and each record is built in one place (its
constructor here), never by position.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba as nb
import numpy as np

from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.flows import generator_spans
from popdispatch.game.mesh import lever_scale
from popdispatch.game.problem import DispatchProblem

NO_VOLTAGE_ROWS = np.zeros((0, 0))  # empty: nothing in it to change
NO_FACTORS = np.zeros((0, 0))  # a radial feeder's: its kernels work on the tree
NO_RATES = np.zeros(0)  # empty: the dynamics that take no per-generator revision rate
NO_ORDER = np.zeros(0, dtype=np.int64)  # no spans of generators below limited lines
NO_SPANS = np.zeros((0, 2), dtype=np.int64)


class PriceLaw(IntEnum):
    """How exact mode's line controllers move their prices (modes/exact.py, docs/exact-mode.md).

    ``PLAIN``: each price integrates its own line's overflow (dual ascent, one controller per
    line, its own measurement only). ``TREE``: the prices of the active (priced or overflowing)
    lines integrate their overflows preconditioned by the tree of active lines, ``nu' =
    price_rate * L^-T W^-1 L^-1 eps`` ("Nested limits"); each controller also reads the
    excesses of its nearest active neighbours on the tree. ``SCALED``: each line's price rate
    times ``s_k = N / N_k`` (tradable generators in the fleet over those below the line) and
    its augmented-Lagrangian weight times ``sqrt(s_k)`` ("Per-line scaling"); each controller
    needs only those two counts. Same rest points (the DC-OPF).
    """

    PLAIN = 0
    TREE = 1
    SCALED = 2

    @classmethod
    def parse(cls, value: str | int) -> PriceLaw:
        """A law from its name (``"plain"``, ``"tree"``, ``"scaled"``, any case) or number; an
        unknown one raises :class:`~popdispatch.errors.OptionError` naming ``--price-law``."""
        if isinstance(value, str) and value.strip().upper() in cls.__members__:
            return cls[value.strip().upper()]
        if not isinstance(value, str | bool) and value in set(cls):
            return cls(value)
        from popdispatch.errors import OptionError

        names = ", ".join(m.name.lower() for m in cls)
        raise OptionError(f"unknown price law {value!r} (known: {names})", "--price-law")


class GameParameters(NamedTuple):
    """The game's parameters, the same for every minute of a problem (one layout for all modes,
    so one compiled kernel). Powers MW, costs EUR/MWh and EUR/MW^2h, signals EUR/MW."""

    b: np.ndarray  # linear cost coefficient per generator
    c: np.ndarray  # quadratic cost coefficient per generator
    pmin: np.ndarray  # generator limits, MW
    pmax: np.ndarray
    B: float  # fitness constants (FitnessParameters)
    m: float
    C: float
    gain: float
    price_rate: float
    limit: np.ndarray  # per limited line, MW
    generator_line: np.ndarray  # tree of limited lines (game/flows.py)
    line_up: np.ndarray
    line_preorder: np.ndarray
    # per monitored bus and generator, d(v^2)/dp over the bus's scale (modes/voltage.py);
    # (0, 0) without voltage limits (the default, for records built by hand in tests)
    voltage_sens: np.ndarray = NO_VOLTAGE_ROWS
    # per generator, the revision rate of the dynamics that scale each generator's revision by
    # its own cost curve (dynamics/newton.py), dimensionless; empty for the others
    revision_rate: np.ndarray = NO_RATES
    # on a meshed network, per limited line and generator the distribution factor D_ki
    # (game/mesh.py; the mesh kernels read it instead of the tree); (0, 0) on a radial feeder
    factor: np.ndarray = NO_FACTORS
    # on a meshed network, per limited line the multiplier of price_rate and C (game/mesh.py
    # lever_scale, dimensionless); empty on a radial feeder
    line_scale: np.ndarray = NO_RATES
    # exact mode on a radial feeder: the least speed of a pinned line's prices, EUR/MW per s
    # (modes/exact.py hasten_pinned); 0: none
    pinned_speed: float = 0.0
    # per generator, the revision rate while every limited line above it is idle (modes/exact.py
    # rates_in_force), dimensionless; empty: the rates are revision_rate throughout
    idle_rate: np.ndarray = NO_RATES
    # exact mode's stuck lines on a radial feeder (modes/exact.py stuck_gaps): the generators
    # in an order where those below each limited line are a run (game/flows.py
    # generator_spans), and each line's run, order[span[k, 0]:span[k, 1]]; empty: the stuck
    # lines are not hastened
    stuck_order: np.ndarray = NO_ORDER
    stuck_span: np.ndarray = NO_SPANS

    @classmethod
    def of(
        cls, problem: DispatchProblem, fp: FitnessParameters, revision_rate: np.ndarray = NO_RATES,
        pinned_speed: float = 0.0, idle_rate: np.ndarray = NO_RATES, stuck_lines: bool = False,
    ) -> GameParameters:
        """The parameters of ``problem`` with the constants ``fp`` (EUR/MW), the dynamic's
        per-generator ``revision_rate`` (dimensionless; empty when it takes none), exact
        mode's least speed of a pinned line's prices (EUR/MW per s; 0: none), the revision
        rates while the lines above are idle (dimensionless; empty: none) and whether the
        stuck lines' prices are hastened too (``stuck_lines``: the generators' spans below
        the lines, :func:`~popdispatch.game.flows.generator_spans`)."""
        return cls(
            problem.b, problem.c, problem.pmin, problem.pmax, float(fp.B), float(fp.m),
            float(fp.C), float(fp.gain), float(fp.price_rate), problem.limit,
            problem.generator_line, problem.line_up, problem.line_preorder,
            np.ascontiguousarray(problem.voltage_sens, dtype=float),
            np.ascontiguousarray(revision_rate, dtype=float),
            NO_FACTORS if problem.factor is None
            else np.ascontiguousarray(problem.factor, dtype=float),
            NO_RATES if problem.factor is None else lever_scale(problem.factor),
            float(pinned_speed),
            np.ascontiguousarray(idle_rate, dtype=float),
            *(_stuck_spans(problem) if stuck_lines else (NO_ORDER, NO_SPANS)),
        )  # fmt: skip


def _stuck_spans(problem: DispatchProblem) -> tuple[np.ndarray, np.ndarray]:
    """The generators' order and each limited line's run in it
    (:func:`~popdispatch.game.flows.generator_spans`) on a radial feeder with limited lines;
    empty on a mesh or without limited lines."""
    if problem.factor is not None or not len(problem.limit):
        return NO_ORDER, NO_SPANS
    return generator_spans(problem.generator_line, problem.line_up, problem.line_preorder)


class MinuteInputs(NamedTuple):
    """What changes from minute to minute: demand (MW), the loads-only flow of each limited
    line (MW; then the voltage rows' loads-only excesses, see
    :attr:`~popdispatch.game.problem.DispatchProblem.load_flow`), the share bounds
    ``lo``/``hi`` (``Pmin / P_d``, ``Pmax / P_d`` online, 0 offline), the online
    generators, per limited line how many online generators with room to trade
    (``hi > lo``) are below it (:func:`tradable_below`; a count, as a float) and how many the
    fleet has (:func:`tradable_count`, the scaled price law's ``N``)."""

    demand: float
    load_flow: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    active: np.ndarray
    below: np.ndarray
    tradable: float

    @classmethod
    def of(cls, problem: DispatchProblem, minute: int) -> MinuteInputs:
        """The inputs of the 1-based ``minute``."""
        row = minute - 1
        n = problem.n_generators
        demand = float(problem.demand[row])
        lo, hi = np.empty(n), np.empty(n)
        active = problem.online[row]
        below = np.empty(problem.line_up.shape[0])
        tradable = minute_bounds(problem.pmin, problem.pmax, active, demand,
                                 problem.generator_line, problem.line_up, problem.line_preorder,
                                 lo, hi, below)  # fmt: skip
        return cls(demand, problem.load_flow[row], lo, hi, active, below, tradable)


@nb.njit(cache=True)
def minute_bounds(pmin, pmax, active, demand, generator_line, line_up, preorder, lo, hi, below):
    """A minute's share bounds into ``lo``, ``hi`` (:func:`share_bounds`) and the tradable
    generators below each limited line into ``below`` (:func:`tradable_below`); returns how
    many the fleet has (:func:`tradable_count`): the fields :class:`MinuteInputs` adds to the
    demand, the loads and the online generators."""
    share_bounds(pmin, pmax, active, demand, lo, hi)
    tradable_below(generator_line, line_up, preorder, lo, hi, below)
    return tradable_count(lo, hi)


@nb.njit(cache=True, inline="always")
def share_bounds(pmin, pmax, active, demand, lo, hi):
    """Share bounds ``lo = Pmin / P_d``, ``hi = Pmax / P_d`` of the online generators (0 for the
    offline ones), into ``lo`` and ``hi``."""
    for i in range(pmin.shape[0]):
        lo[i] = pmin[i] / demand if active[i] else 0.0
        hi[i] = pmax[i] / demand if active[i] else 0.0


@nb.njit(cache=True)
def tradable_count(lo, hi):
    """The online generators with room to trade (``hi > lo``), a count as a float."""
    total = 0.0
    for i in range(lo.shape[0]):
        total += 1.0 if hi[i] > lo[i] else 0.0
    return total


@nb.njit(cache=True)
def tradable_below(generator_line, line_up, preorder, lo, hi, below):
    """Per limited line, the online generators with room to trade (``hi > lo``) below it,
    into ``below`` (counts, as floats); ``generator_line``, ``line_up`` and ``preorder`` as in
    :class:`~popdispatch.game.problem.DispatchProblem`."""
    below[:] = 0.0
    for i in range(generator_line.shape[0]):
        k = generator_line[i]
        if k >= 0 and hi[i] > lo[i]:
            below[k] += 1.0
    for r in range(preorder.shape[0] - 1, -1, -1):
        k = preorder[r]
        if line_up[k] >= 0:
            below[line_up[k]] += below[k]


class GameWork(NamedTuple):
    """Scratch of one game evaluation, one value per limited line: flows (MW), the values sent
    to the parent and child sides of each line, path sums of the broadcast; and, for a game
    whose revision rates follow its state, the rates in force, one per generator
    (dimensionless; empty otherwise, the field then reads the parameters' own).

    Kept from one evaluation to the next (exact mode's pinned lines, modes/exact.py
    ``count_at_limits``): each generator's limit state (-1 at its lower limit, +1 at its
    upper, -2/+2 near them, 0 inside them or not counted) and, per limited line, how many
    generators below it are at their lower limit, at their upper limit and near one; all zero
    to start with (a consistent state), and changed only where a generator's state changes."""

    flow: np.ndarray
    parent_side: np.ndarray
    child_side: np.ndarray
    path: np.ndarray
    rate: np.ndarray
    limit_state: np.ndarray
    at_low: np.ndarray
    at_high: np.ndarray
    near: np.ndarray
    # exact mode's stuck lines (modes/exact.py stuck_gaps), EUR/MW: per limited line, the best
    # fitness below it that can rise, the worst that can fall, and the gaps its up and down
    # prices wait for; per position r of the generators' order (and one past the last), the
    # best that can rise and the worst that can fall before r, and the same from r on
    line_ends: np.ndarray
    order_ends: np.ndarray

    @classmethod
    def empty(cls, n_lines: int, n_rates: int = 0, *, n_generators: int) -> GameWork:
        """Scratch for ``n_lines`` limited lines, ``n_rates`` rates in force and the limit
        states of the game's ``n_generators`` generators (every evaluation that counts them
        reads one per generator, unchecked)."""
        return cls(*(np.zeros(n_lines) for _ in range(4)), np.zeros(n_rates),
                   np.zeros(n_generators), *(np.zeros(n_lines) for _ in range(3)),
                   np.zeros((n_lines, 4)),
                   np.zeros((n_generators + 1 if n_lines else 0, 4)))  # fmt: skip
