"""The stopping rule: converged, not (yet) converged, or infeasible.

Convergence (documented criterion), with the minute's tolerance ``tol = max(tol_rel * P_d,
tol_kw)`` (relative to the demand ``P_d``, with an absolute floor): the mean set point of every
generator over the last ``window`` iterations differs by at most ``tol`` from its mean over the
``window`` iterations before, and the controllers' residual (exact mode: overflow, or slack
under a positive price) is at most ``tol`` at every iteration of the last window; with
``extrapolate`` (exact mode) the geometric tail of the window means must be within ``tol`` as
well. Means, not samples, because a generator sliding along its limit chatters on the
scale of the internal step. The iteration of convergence is the first iteration of the last
window. *Fixed-point stop* (``fixed_point``): an iteration that leaves the state unchanged
within round-off, with the residual within ``tol``, ends the run at once (later iterations
would repeat it); its iteration of convergence is the one before. A controller state above
``z_cap`` means the controllers cannot relieve the congestion: the run is infeasible. Only
the last ``3 * window`` samples are kept (a ring).
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

import numba as nb
import numpy as np


class Status(IntEnum):
    """How a run ended (``NOT_CONVERGED`` also while it is still running)."""

    CONVERGED = 0
    NOT_CONVERGED = 1
    INFEASIBLE = 2


class StopRule(NamedTuple):
    """The stopping rule's settings: ``tol_mw`` (the floor ``tol_kw`` in MW), ``tol_rel``
    (relative to the demand), ``window`` (iterations), ``max_iterations`` (horizon), ``z_cap``
    (EUR/MW), ``extrapolate`` and ``fixed_point`` (stop where an iteration leaves the state
    unchanged within round-off, :func:`at_rest`)."""

    tol_mw: float
    tol_rel: float
    window: int
    max_iterations: int
    z_cap: float
    extrapolate: bool
    fixed_point: bool


@nb.njit(cache=True)
def window_mean(ring, last, window, i):
    """Mean of sample column ``i`` over the ``window`` samples ending at iteration ``last``."""
    size = ring.shape[0]
    total = 0.0
    for k in range(window):
        total += ring[(last - k) % size, i]
    return total / window


@nb.njit(cache=True)
def windows_agree(ring, last, window, tol, extrapolate):
    """Do the means of the last two windows of set points differ by at most ``tol``?

    With ``extrapolate`` (needs three windows), a geometric tail is also projected: if the
    window means keep moving the same way with ratio ``r < 1``, the distance still to go,
    ``|d| r / (1 - r)``, must be within ``tol`` too. Slow exponential tails (several generators
    inside their limits, whose split is set by tiny quadratic costs) otherwise look converged.
    """
    for i in range(ring.shape[1]):
        recent = window_mean(ring, last, window, i)
        middle = window_mean(ring, last - window, window, i)
        step = recent - middle
        if abs(step) > tol:
            return False
        if extrapolate:
            previous = middle - window_mean(ring, last - 2 * window, window, i)
            ratio = step / previous if previous != 0.0 else 0.0
            if 0.0 < ratio < 1.0 and abs(step) * ratio / (1.0 - ratio) > tol:
                return False
    return True


#: What an iteration may move a state that it leaves "unchanged within round-off": 65536 units
#: of round-off (``2**-36``, about 1.5e-11) of the demand for a set point, of its own size for
#: a controller state. At rest the field is round-off and the steps add it up: a set point
#: moves by about 1e-12 of the demand an iteration (docs/exact-mode.md, "Step size and
#: stopping"), 1e-6 of the convergence tolerance ``1e-6 P_d``.
ROUND_OFF = 65536 * np.finfo(np.float64).eps


@nb.njit(cache=True, inline="always")
def at_rest(x, last_x, z, last_z):
    """Did the last iteration leave ``(x, z)`` where it was (``last_x``, ``last_z``) within
    round-off (:data:`ROUND_OFF`): every share within ``ROUND_OFF`` (so every set point
    within ``ROUND_OFF * demand``) and every controller state within ``ROUND_OFF`` of its
    size?"""
    for i in range(x.shape[0]):
        if abs(x[i] - last_x[i]) > ROUND_OFF:
            return False
    for k in range(z.shape[0]):  # noqa: SIM110 (numba compiles no generator expression)
        if abs(z[k] - last_z[k]) > ROUND_OFF * abs(z[k]):
            return False
    return True


@nb.njit(cache=True, inline="always")
def tolerance(rule, demand):
    """The minute's tolerance ``max(tol_rel * demand, tol_mw)``, MW (``demand`` in MW)."""
    return max(rule.tol_rel * demand, rule.tol_mw)


@nb.njit(cache=True, inline="always")
def check(rule, ring, k, z, residual, calm, demand, still):
    """``(status, calm, converged_at)`` after iteration ``k`` (its sample already in
    ``ring``): the status, the updated count ``calm`` of iterations in a row with the residual
    within the minute's tolerance ``max(tol_rel * demand, tol_mw)`` (``demand`` in MW), and
    the iteration of convergence (-1 unless converged). ``still``: the iteration left the
    state unchanged within round-off (:func:`at_rest`), for the fixed-point stop."""
    for line in range(z.shape[0]):
        if z[line] > rule.z_cap:
            return Status.INFEASIBLE, calm, -1
    tol = tolerance(rule, demand)
    # the residual within tolerance over the whole last window, not at one sample: the
    # price loop can oscillate with a period of 2-3 iterations whose window means agree
    # while every other sample overflows (by 1e-4 kW on random feeders)
    calm = calm + 1 if residual <= tol else 0
    window = rule.window
    need = (3 if rule.extrapolate else 2) * window
    if k >= need and calm >= window and windows_agree(ring, k, window, tol, rule.extrapolate):
        return Status.CONVERGED, calm, k - window
    if rule.fixed_point and still and residual <= tol:
        return Status.CONVERGED, calm, k - 1  # the iteration left the state where it was
    return Status.NOT_CONVERGED, calm, -1
