"""Integration of the mean dynamics on the paper's 0.01 s grid.

The paper ran the MATLAB population-dynamics toolbox: an adaptive ODE solver whose state is
sampled every 0.01 s; one sample is one *iteration*. Its barrier (eq. 7) is discontinuous, so
generators at a limit slide along it; a fixed explicit step of 0.01 s would chatter by kW around
the limit. :class:`Integrator` resolves the sliding motion with small internal explicit steps
(``substeps`` per iteration) and reports the state on the 0.01 s grid.

Positivity: every vector field is split as ``x' = inflow - x * out_rate`` (both >= 0), so an
Euler step keeps ``x >= 0`` whenever ``h * out_rate <= 1``; the step is shortened to
``0.5 / max(out_rate)`` when needed. Mass is conserved because the fields sum to zero.

Convergence (documented criterion): the mean set point of every generator over the last
``window`` iterations differs by at most ``tol_kw`` kilowatts from its mean over the ``window``
iterations before. Means, not samples, because a generator sliding along its limit chatters on
the scale of the internal step. The iteration of convergence is the first iteration of the last
window; the run stops when the criterion first holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np


@dataclass(frozen=True)
class Integrator:
    """Step-size control and stopping rule.

    Attributes
    ----------
    dt : sampling interval, s (one iteration; paper: 0.01 s).
    substeps : explicit Euler steps per iteration (internal step ``dt / substeps``, s).
    tol_kw : convergence tolerance on window means of the set points, kW.
    window : iterations per averaging window.
    max_iterations : horizon per run (per minute in the day loop); 6000 = one minute.
    """

    dt: float = 0.01
    substeps: int = 100
    tol_kw: float = 0.01
    window: int = 20
    max_iterations: int = 6000

    def __post_init__(self) -> None:
        for name in ("dt", "tol_kw"):
            if not getattr(self, name) > 0:
                raise ValueError(f"integrator {name} must be positive, got {getattr(self, name)}")
        for name in ("substeps", "window", "max_iterations"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"integrator {name} must be >= 1, got {getattr(self, name)}")


@nb.njit(cache=True)
def _windows_agree(trajectory: np.ndarray, last: int, window: int, tol: float) -> bool:
    """Do the means of the last two windows of set points differ by at most ``tol``?"""
    for i in range(trajectory.shape[1]):
        recent = 0.0
        before = 0.0
        for k in range(window):
            recent += trajectory[last - k, i]
            before += trajectory[last - window - k, i]
        if abs(recent - before) > tol * window:
            return False
    return True


@nb.njit(cache=True)
def integrate(
    rates, game, x, z, demand, graph, lo, hi, params, dt, substeps, tol_mw, window, max_iterations
):
    """Run the dynamics from shares ``x`` (and controller state ``z``) at fixed ``demand`` (MW).

    ``game(p, z, params) -> (f, z_rate, congestion)`` gives fitness, the controllers' state rate
    and the largest congestion signal magnitude; ``rates`` is a vector field (see
    :mod:`popdispatch.dynamics`). Controller states are kept non-negative (prices).

    Returns ``(setpoints, x, z, converged_at, first_congestion)``: set points (MW) on the grid,
    rows ``0..last``, final state, the iteration of convergence (-1 if none) and the first
    iteration with a non-zero congestion signal (-1 if none).
    """
    n = x.shape[0]
    setpoints = np.empty((max_iterations + 1, n))
    setpoints[0] = x * demand
    h_nominal = dt / substeps
    converged_at = -1
    first_congestion = -1
    last = max_iterations
    for k in range(1, max_iterations + 1):
        remaining = dt
        congested = 0.0
        while remaining > 1e-12 * dt:
            f, z_rate, congestion = game(x * demand, z, params)
            congested = max(congested, congestion)
            inflow, out_rate = rates(x, f, graph, lo, hi)
            h = min(h_nominal, remaining)
            fastest = out_rate.max()
            if h * fastest > 0.5:
                h = 0.5 / fastest
            x = x + h * (inflow - x * out_rate)
            z = np.maximum(z + h * z_rate, 0.0)
            remaining -= h
        setpoints[k] = x * demand
        if first_congestion < 0 and congested > 0.0:
            first_congestion = k
        if k >= 2 * window and _windows_agree(setpoints, k, window, tol_mw):
            converged_at = k - window
            last = k
            break
    return setpoints[: last + 1], x, z, converged_at, first_congestion
