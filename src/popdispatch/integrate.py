"""Integration of the mean dynamics on the paper's 0.01 s grid.

The paper ran the MATLAB population-dynamics toolbox: an adaptive ODE solver whose state is
sampled every 0.01 s; one sample is one *iteration*. :class:`Integrator` separates the solver
and its step control from the vector field (:mod:`popdispatch.dynamics`) and the game
(:mod:`popdispatch.modes`):

- ``method="euler"``: ``substeps`` explicit Euler steps per iteration. Paper mode uses it: its
  barrier (eq. 7) is discontinuous, generators slide along their limits, and an explicit step
  chatters around a limit with an amplitude proportional to the step (0.01 s: kW; 1e-4 s,
  the default: tens of W), so small fixed steps resolve the sliding motion.
- ``method="heun"``: adaptive Heun-Euler pair (second order, SSP) with error control
  ``rtol``/``atol`` on the shares and ``price_atol`` on the controller states. Exact mode uses
  it: its field is continuous, but its price loop is stiff on small feeders, and a fixed step
  can lock into a period-2 oscillation that looks converged on the grid.

Domain: every vector field is split as ``x' = inflow - x * out_rate`` (both >= 0) and reports a
``rate_bound``; an Euler stage keeps ``x`` in its domain whenever ``h * rate_bound <= 1``, so
every stage is shortened to ``0.9 / rate_bound`` when needed (Heun is a convex combination of
Euler stages, so it inherits this). Mass is conserved because the fields sum to zero.

Controller states ``z`` (exact mode's line prices) are integrated alongside and kept
non-negative. A state above ``z_cap`` means the controllers cannot relieve the congestion: the
run stops and reports the problem infeasible.

Convergence (documented criterion): the mean set point of every generator over the last
``window`` iterations differs by at most ``tol_kw`` kilowatts from its mean over the ``window``
iterations before, and the controllers' residual (exact mode: overflow, or slack under a
positive price) is at most ``tol_kw``; with ``extrapolate`` (exact mode) the geometric tail of
the window means must be within ``tol_kw`` as well. Means, not samples, because a generator
sliding along its limit chatters on the scale of the internal step. The iteration of
convergence is the first iteration of the last window; the run stops when the criterion first
holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from popdispatch.dynamics.fields import vector_field
from popdispatch.game.payoffs import game

METHODS = {"euler": 0, "heun": 1}


@dataclass(frozen=True)
class Integrator:
    """Solver, step-size control and stopping rule.

    Attributes
    ----------
    dt : sampling interval, s (one iteration; paper: 0.01 s).
    method : ``"euler"`` (fixed substeps) or ``"heun"`` (adaptive), see the module docstring.
    substeps : Euler steps per iteration (internal step ``dt / substeps``, s).
    rtol, atol : Heun error control: relative, and absolute on the shares (dimensionless).
    price_atol : Heun error control: absolute on controller states, EUR/MW.
    tol_kw : convergence tolerance on window means of the set points and on the residual, kW.
    window : iterations per averaging window.
    max_iterations : horizon per run (per minute in the day loop); 6000 = one minute.
    extrapolate : also require the geometrically projected remaining motion to be within
        ``tol_kw`` (for smooth, slowly converging runs; chatter in paper mode defeats it).
    """

    dt: float = 0.01
    method: str = "euler"
    substeps: int = 100
    rtol: float = 1e-4
    atol: float = 1e-8
    price_atol: float = 1e-4
    tol_kw: float = 0.01
    window: int = 20
    max_iterations: int = 6000
    extrapolate: bool = False

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"unknown integration method {self.method!r} (euler or heun)")
        for name in ("dt", "tol_kw", "rtol", "atol", "price_atol"):
            if not getattr(self, name) > 0:
                raise ValueError(f"integrator {name} must be positive, got {getattr(self, name)}")
        for name in ("substeps", "window", "max_iterations"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"integrator {name} must be >= 1, got {getattr(self, name)}")

    @property
    def method_code(self) -> int:
        return METHODS[self.method]


@nb.njit(cache=True)
def _window_mean(trajectory: np.ndarray, last: int, window: int, i: int) -> float:
    total = 0.0
    for k in range(window):
        total += trajectory[last - k, i]
    return total / window


@nb.njit(cache=True)
def _windows_agree(
    trajectory: np.ndarray, last: int, window: int, tol: float, extrapolate: bool
) -> bool:
    """Do the means of the last two windows of set points differ by at most ``tol``?

    With ``extrapolate`` (needs three windows), a geometric tail is also projected: if the
    window means keep moving the same way with ratio ``r < 1``, the distance still to go,
    ``|d| r / (1 - r)``, must be within ``tol`` too. Slow exponential tails (several generators
    inside their limits, whose split is set by tiny quadratic costs) otherwise look converged.
    """
    for i in range(trajectory.shape[1]):
        recent = _window_mean(trajectory, last, window, i)
        middle = _window_mean(trajectory, last - window, window, i)
        step = recent - middle
        if abs(step) > tol:
            return False
        if extrapolate:
            previous = middle - _window_mean(trajectory, last - 2 * window, window, i)
            ratio = step / previous if previous != 0.0 else 0.0
            if 0.0 < ratio < 1.0 and abs(step) * ratio / (1.0 - ratio) > tol:
                return False
    return True


#: ``converged_at`` value of a run stopped because a controller state exceeded ``z_cap``.
INFEASIBLE = -2


@nb.njit(cache=True)
def _stage(field, mode, x, z, demand, graph, lo, hi, params):
    """One evaluation: ``(x', z', largest stable step, congestion, residual)``."""
    f, z_rate, congestion, residual = game(mode, x * demand, z, params)
    inflow, out_rate, rate_bound = vector_field(field, x, f, graph, lo, hi)
    h_stable = 0.9 / rate_bound if rate_bound > 0.0 else np.inf
    return inflow - x * out_rate, z_rate, h_stable, congestion, residual


@nb.njit(cache=True)
def _error_norm(x_high, x_low, z_high, z_low, rtol, atol, price_atol):
    err = 0.0
    for i in range(x_high.shape[0]):
        err = max(err, abs(x_high[i] - x_low[i]) / (atol + rtol * abs(x_high[i])))
    for k in range(z_high.shape[0]):
        err = max(err, abs(z_high[k] - z_low[k]) / (price_atol + rtol * abs(z_high[k])))
    return err


@nb.njit(cache=True)
def _advance_euler(field, mode, x, z, demand, graph, lo, hi, params, dt, substeps):
    remaining = dt
    congested = 0.0
    residual = 0.0
    while remaining > 1e-12 * dt:
        dx, dz, h_stable, congestion, residual = _stage(
            field, mode, x, z, demand, graph, lo, hi, params
        )
        congested = max(congested, congestion)
        h = min(dt / substeps, remaining, h_stable)
        x = x + h * dx
        z = np.maximum(z + h * dz, 0.0)
        remaining -= h
    return x, z, congested, residual


@nb.njit(cache=True)
def _advance_heun(field, mode, x, z, demand, graph, lo, hi, params, dt, h_try, tol):
    rtol, atol, price_atol = tol
    remaining = dt
    congested = 0.0
    residual = 0.0
    while remaining > 1e-12 * dt:
        dx1, dz1, h_stable, congestion, residual = _stage(
            field, mode, x, z, demand, graph, lo, hi, params
        )
        congested = max(congested, congestion)
        h = min(h_try, remaining, h_stable)
        x1 = x + h * dx1
        z1 = np.maximum(z + h * dz1, 0.0)
        dx2, dz2, h_stable2, _, _ = _stage(field, mode, x1, z1, demand, graph, lo, hi, params)
        if h > h_stable2:
            h_try = h_stable2
            continue
        x2 = 0.5 * (x + x1 + h * dx2)
        z2 = np.maximum(0.5 * (z + z1 + h * dz2), 0.0)
        err = _error_norm(x2, x1, z2, z1, rtol, atol, price_atol)
        if err <= 1.0:
            x, z = x2, z2
            remaining -= h
        h_try = h * min(5.0, max(0.2, 0.9 / np.sqrt(err))) if err > 0.0 else 5.0 * h
    return x, z, congested, residual, h_try


@nb.njit(cache=True)
def integrate(
    field,
    mode,
    x,
    z,
    demand,
    graph,
    lo,
    hi,
    params,
    dt,
    method,
    substeps,
    tol,
    tol_mw,
    window,
    max_iterations,
    z_cap,
    extrapolate,
):
    """Run the dynamics from shares ``x`` (and controller state ``z``) at fixed ``demand`` (MW).

    ``field`` is a vector-field code (:mod:`popdispatch.dynamics.fields`) and ``mode`` a game
    code (:func:`popdispatch.game.payoffs.game`): the game gives fitness, the controllers'
    state rate, the largest congestion signal magnitude and the controllers' residual (MW; a
    run converges only once it is below ``tol_mw`` too). ``method``: 0 Euler with
    ``substeps``, 1 adaptive Heun with ``tol = (rtol, atol, price_atol)``.

    Returns ``(setpoints, x, z, converged_at, first_congestion)``: set points (MW) on the grid,
    rows ``0..last``, final state, the iteration of convergence (-1 if none, :data:`INFEASIBLE`
    if a controller state passed ``z_cap``) and the first iteration with a non-zero congestion
    signal (-1 if none).
    """
    n = x.shape[0]
    setpoints = np.empty((max_iterations + 1, n))
    setpoints[0] = x * demand
    converged_at = -1
    first_congestion = -1
    last = max_iterations
    h_try = dt
    for k in range(1, max_iterations + 1):
        if method == 0:
            x, z, congested, residual = _advance_euler(
                field, mode, x, z, demand, graph, lo, hi, params, dt, substeps
            )
        else:
            x, z, congested, residual, h_try = _advance_heun(
                field, mode, x, z, demand, graph, lo, hi, params, dt, h_try, tol
            )
        setpoints[k] = x * demand
        if first_congestion < 0 and congested > 0.0:
            first_congestion = k
        if z.size > 0 and z.max() > z_cap:
            converged_at = INFEASIBLE
            last = k
            break
        steady = k >= (3 if extrapolate else 2) * window and residual <= tol_mw
        if steady and _windows_agree(setpoints, k, window, tol_mw, extrapolate):
            converged_at = k - window
            last = k
            break
    return setpoints[: last + 1], x, z, converged_at, first_congestion
