"""Integration of the mean dynamics on the paper's 0.01 s grid.

The paper ran the MATLAB population-dynamics toolbox: an adaptive ODE solver whose state is
sampled every 0.01 s; one sample is one *iteration*. As in diffrax, the pieces are apart:

- :mod:`~popdispatch.integrate.term`: the ODE term, evaluation of the vector field (the mode's
  payoff map, :mod:`popdispatch.modes`, and the dynamic's weights and pairwise flows,
  :mod:`popdispatch.dynamics`) into a :class:`~popdispatch.integrate.term.Stage`;
- :mod:`~popdispatch.integrate.steppers`: one iteration of flux-limited Euler substeps or
  adaptive Heun with a stiffness cap (:class:`Method`);
- :mod:`~popdispatch.integrate.stopping`: the stopping rule, a :class:`Status`;
- :mod:`~popdispatch.integrate.solve`: :func:`integrate`, steps until the stopping rule says.

:class:`Integrator` holds the settings a person chooses and builds the named records the
compiled kernels take. The online day loop is :mod:`popdispatch.online.day`.
"""

from __future__ import annotations

from dataclasses import dataclass

from popdispatch.constants import KW_PER_MW
from popdispatch.integrate.solve import Outcome, integrate
from popdispatch.integrate.steppers import (
    HEUN_STEP,
    STABLE_STEP,
    Method,
    StepperSettings,
    Workspace,
    method_tag,
    workspace,
)
from popdispatch.integrate.stopping import ROUND_OFF, Status, StopRule
from popdispatch.integrate.term import Stage, Term

METHODS = {method.name.lower(): method for method in Method}


@dataclass(frozen=True)
class Integrator:
    """Solver, step-size control and stopping rule.

    Attributes
    ----------
    dt : sampling interval, s (one iteration; paper: 0.01 s).
    method : ``"euler"`` (fixed substeps) or ``"heun"`` (adaptive), see
        :mod:`popdispatch.integrate.steppers`.
    substeps : Euler steps per iteration (internal step ``dt / substeps``, s).
    rtol, atol : Heun error control: relative, and absolute on the shares (dimensionless).
    price_atol : Heun error control: absolute on controller states, in units of the mode's
        price scale (exact mode: the marginal-cost spread, so dimensionless; see
        :func:`popdispatch.modes.exact.scales`).
    tol_kw : convergence tolerance on window means of the set points and on the residual, kW;
        with ``tol_rel`` the absolute floor of the tolerance.
    tol_rel : convergence tolerance relative to the minute's demand (dimensionless): a
        minute's tolerance is ``max(tol_rel * P_d, tol_kw)`` (0: ``tol_kw`` alone).
    window : iterations per averaging window.
    max_iterations : horizon per run (per minute in the day loop); 6000 = one minute.
    extrapolate : also require the geometrically projected remaining motion to be within
        ``tol_kw`` (for smooth, slowly converging runs; chatter in paper mode defeats it).
    fixed_point : also stop as soon as an iteration leaves the state unchanged within
        round-off (shares within ``2**-36``, prices within ``2**-36`` of their size) with the
        residual within tolerance (:mod:`popdispatch.integrate.stopping`).
    """

    dt: float = 0.01
    method: str = "euler"
    substeps: int = 100
    rtol: float = 1e-4
    atol: float = 1e-8
    price_atol: float = 1e-4
    tol_kw: float = 0.01
    tol_rel: float = 0.0
    window: int = 20
    max_iterations: int = 6000
    extrapolate: bool = False
    fixed_point: bool = True

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown integration method {self.method!r} (euler or heun)")
        for name in ("dt", "tol_kw", "rtol", "atol", "price_atol"):
            if not getattr(self, name) > 0:
                raise ValueError(f"integrator {name} must be positive, got {getattr(self, name)}")
        if not 0.0 <= self.tol_rel < 1.0:
            raise ValueError(f"integrator tol_rel must be in [0, 1), got {self.tol_rel}")
        for name in ("substeps", "window", "max_iterations"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"integrator {name} must be >= 1, got {getattr(self, name)}")

    @property
    def method_code(self) -> Method:
        return METHODS[self.method]

    def stepper(self, price_scale: float = 1.0) -> StepperSettings:
        """The stepper's settings for the compiled kernels; ``price_scale`` (EUR/MW) turns
        ``price_atol`` into EUR/MW."""
        return StepperSettings(
            method_tag(self.method_code), float(self.dt), int(self.substeps), float(self.rtol),
            float(self.atol), float(self.price_atol * price_scale),
        )  # fmt: skip

    def stop_rule(self, z_cap: float) -> StopRule:
        """The stopping rule's settings for the compiled kernels (``tol_kw`` in MW)."""
        return StopRule(float(self.tol_kw / KW_PER_MW), float(self.tol_rel), int(self.window),
                        int(self.max_iterations), float(z_cap), bool(self.extrapolate),
                        bool(self.fixed_point))  # fmt: skip

    def tol_mw(self, demand_mw: float) -> float:
        """The convergence tolerance of a minute with demand ``demand_mw``, MW."""
        return max(self.tol_rel * demand_mw, self.tol_kw / KW_PER_MW)


__all__ = [
    "METHODS",
    "ROUND_OFF",
    "HEUN_STEP",
    "STABLE_STEP",
    "Integrator",
    "Method",
    "Outcome",
    "Stage",
    "Status",
    "StepperSettings",
    "StopRule",
    "Term",
    "Workspace",
    "integrate",
    "workspace",
]
