"""Dispatch modes: how node controllers turn line flows into fitness signals.

- ``paper``: the paper's rule. Barrier for generator limits (eq. 7) and a congestion signal
  proportional to the present overflow (eq. 8). Memoryless; leaves a residual overflow, and its
  discontinuous barrier has rest points away from the DC-OPF (docs/paper-mode.md).
- ``exact``: capacity-constrained revision (no barrier) and a non-negative price per limited
  line and direction that integrates the overflow (dual ascent), broadcast like the paper's
  signals. Its equilibria are the KKT points of the DC-OPF (docs/exact-mode.md).

Each mode is a compiled payoff mechanism ``(p, z, params) -> (fitness, z_rate, congestion,
residual)`` in :mod:`popdispatch.game.payoffs`, reached by its code, with one parameter layout
for all modes, so the integrator and the dynamics never depend on the mode.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from popdispatch.game.fitness import FitnessParameters
from popdispatch.game.payoffs import EXACT, PAPER
from popdispatch.game.problem import DispatchProblem
from popdispatch.integrate import Integrator


def game_parameters(problem: DispatchProblem, minute: int, fp: FitnessParameters) -> tuple:
    """The parameter tuple every game takes (one layout for all modes, so one compiled kernel):
    costs, limits (MW), constants, and the tree of limited lines with their loads-only flows at
    the 1-based ``minute``."""
    return (
        problem.b, problem.c, problem.pmin, problem.pmax, float(fp.B), float(fp.m), float(fp.C),
        float(fp.gain), float(fp.price_rate), problem.limit, problem.generator_line,
        problem.line_up, problem.line_preorder, problem.load_flow[minute - 1],
    )  # fmt: skip


@dataclass(frozen=True)
class Mode:
    """A dispatch mode (see module docstring).

    ``code``: its branch in :func:`popdispatch.game.payoffs.game`. ``bounded``: generator
    limits are kept by a capacity-constrained revision rule (the dynamics' ``bounded_field``)
    and warm starts respect the limits, instead of a barrier. ``warm_start``: the default
    policy between minutes (:mod:`popdispatch.warm_start`). ``claims_dc_opf``: whether a run
    that comes to rest claims the DC-OPF optimum, so that its end state is checked against the
    DC-OPF's KKT conditions (:func:`popdispatch.online.kkt_violations`) and reported
    ``stalled`` where they fail. Paper mode claims only that its dynamics came to rest: its
    rules are known not to land on the DC-OPF (docs/paper-mode.md).
    """

    name: str
    code: int
    controller_states: Callable[[DispatchProblem], int]
    bounded: bool
    integrator: Integrator
    warm_start: str = "shares"
    claims_dc_opf: bool = False

    def price_cap(self, problem: DispatchProblem) -> float:
        """Price (EUR/MW) beyond which congestion is deemed impossible to relieve: ten times
        the spread of marginal costs; an optimal line price never exceeds that spread."""
        marginal = problem.b + 2.0 * problem.c * problem.pmax
        return 10.0 * float(marginal.max() - problem.b.min()) + 10.0


MODES = {
    "paper": Mode("paper", PAPER, lambda problem: 0, False, Integrator()),
    "exact": Mode(
        "exact",
        EXACT,
        lambda problem: 2 * len(problem.limit),
        True,
        Integrator(method="heun", tol_kw=1e-5, window=5, extrapolate=True),
        "setpoints",
        claims_dc_opf=True,
    ),
}


def get_mode(name: str) -> Mode:
    try:
        return MODES[name]
    except KeyError:
        raise ValueError(f"unknown mode {name!r} (known: {', '.join(MODES)})") from None
