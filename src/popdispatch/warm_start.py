"""Where the dynamics start when the demand changes between minutes (online operation).

- ``shares`` (the paper's rule, paper mode's default): the shares continue, ``p = x * P_d`` with
  the new demand ``P_d``; with generator limits (exact mode) they are projected onto
  ``lo <= x <= hi``.
- ``setpoints``: the set points continue and the demand step is taken by the generators that
  are trading (strictly inside their limits), in proportion to ``(p - Pmin) (Pmax - p)``, as
  participation factors would share it; a generator resting at a limit stays there. Only if no
  generator is trading is the step shared by headroom. Every generator needs only the step.
- ``merit`` (exact mode's default): the set points continue and the demand step is placed in
  merit order of marginal cost ``b + 2 c p`` (:func:`merit_step`): the incremental economic
  dispatch of the step, line limits ignored, as a feeder head that knows every generator's
  cost curve would broadcast it (AGC with economic participation factors). Not distributed in
  the paper's sense: the dynamics then only correct for the lines (and confirm the rest);
  ``setpoints`` is the warm start that uses no central knowledge (docs/exact-mode.md).

Generators that went offline hand their mass to the online ones (in proportion to their shares).
All functions are compiled: the day loop calls :func:`warm_start` every minute with the
policy and the mode's limits as plain values, so every policy runs the same compiled day loop
(a different policy compiles nothing new).
"""

from __future__ import annotations

from enum import IntEnum

import numba as nb
import numpy as np

from popdispatch.dynamics.capacity import project_to_box
from popdispatch.game.parameters import share_bounds
from popdispatch.integrate.steppers import copy_into
from popdispatch.jit import ALLOCATING


class WarmStart(IntEnum):
    """Warm-start policies (see the module docstring)."""

    SHARES = 0
    SETPOINTS = 1
    MERIT = 2


SHARES, SETPOINTS, MERIT = WarmStart
WARM_STARTS = {policy.name.lower(): policy for policy in WarmStart}


@nb.njit(cache=True, inline="always")
def redistribute_offline(x, active):
    """Hand the shares of offline generators to online ones, in proportion to their shares."""
    total = 0.0
    lost = False
    for i in range(x.shape[0]):
        if active[i]:
            total += x[i]
        elif x[i] > 0.0:
            lost = True
    if not lost:
        return
    if total <= 0.0:
        count = 0.0
        for i in range(x.shape[0]):
            count += 1.0 if active[i] else 0.0
        for i in range(x.shape[0]):
            x[i] = 1.0 / count if active[i] else 0.0
        return
    for i in range(x.shape[0]):
        x[i] = x[i] / total if active[i] else 0.0


@nb.njit(cache=True)
def _share_step(p, step, weight, pmin, pmax):
    """Add ``step`` (MW) to ``p`` in proportion to ``weight``, water-filling at the limits;
    returns what could not be placed (MW)."""
    n = p.shape[0]
    for _ in range(n + 1):
        total = 0.0
        for i in range(n):
            total += weight[i]
        if total <= 0.0 or abs(step) <= 0.0:
            return step
        placed = 0.0
        for i in range(n):
            if weight[i] <= 0.0:
                continue
            target = p[i] + step * weight[i] / total
            clipped = min(max(target, pmin[i]), pmax[i])
            if clipped != target:
                weight[i] = 0.0
            placed += clipped - p[i]
            p[i] = clipped
        step -= placed
    return step


@nb.njit(cache=True)
def _merit_target(p, lo, hi, b, c, price, up, out):
    """Set points (MW) into ``out`` when the marginal price rises (``up``) or falls to
    ``price`` (EUR/MWh): a generator moves only once the price passes its marginal cost
    ``b + 2 c p``, to ``(price - b) / (2 c)`` within its limits (``c <= 0``: to the limit);
    returns the total change (MW)."""
    total = 0.0
    for i in range(p.shape[0]):
        if c[i] > 0.0:
            target = (price - b[i]) / (2.0 * c[i])
        elif up:
            target = hi[i] if price > b[i] else lo[i]
        else:
            target = lo[i] if price < b[i] else hi[i]
        moved = min(max(p[i], target), hi[i]) if up else max(min(p[i], target), lo[i])
        out[i] = moved
        total += moved - p[i]
    return total


@nb.njit(cache=True)
def merit_step(p, step, lo, hi, b, c, out):
    """Place a demand ``step`` (MW) on the set points ``p`` (MW, in place) in merit order of
    marginal cost ``b + 2 c p`` (EUR/MWh): the economic dispatch of the new demand reached
    from ``p`` (the incremental form of participation factors ``1 / (2 c)``: generators with
    equal marginal costs share a step by them, the next in merit order joins when the price
    reaches its marginal cost). Returns what is left (MW: the rounding of the price's
    bisection, or what the limits cannot take); ``out`` is scratch."""
    if step == 0.0:
        return 0.0
    up = step > 0.0
    # the price where nothing moves yet (``start``) and where every movable one is at its
    # limit (``end``); the change placed grows from the one to the other
    sign = 1.0 if up else -1.0
    start = np.inf
    end = -np.inf
    for i in range(p.shape[0]):
        if (hi[i] - p[i] if up else p[i] - lo[i]) <= 0.0:
            continue
        start = min(start, sign * (b[i] + 2.0 * c[i] * p[i]))
        end = max(end, sign * (b[i] + 2.0 * c[i] * (hi[i] if up else lo[i])))
    if not start < np.inf:
        return step
    under, over = sign * start, sign * end
    if abs(_merit_target(p, lo, hi, b, c, over, up, out)) < abs(step):
        under = over
    else:
        for _ in range(200):
            middle = 0.5 * (under + over)
            if middle in (under, over):
                break
            if abs(_merit_target(p, lo, hi, b, c, middle, up, out)) < abs(step):
                under = middle
            else:
                over = middle
    placed = _merit_target(p, lo, hi, b, c, under, up, out)
    copy_into(out, p)
    return step - placed


@nb.njit(cache=True)
def continue_setpoints(x, old_demand, demand, pmin, pmax, active, weight, b=None, c=None):
    """Shares for ``demand`` (MW) keeping the set points ``x * old_demand`` (see module).
    With the cost coefficients ``b`` (EUR/MWh) and ``c`` (EUR/MW^2h) the step is placed in
    merit order (:func:`merit_step`), else by the trading generators in proportion to
    ``(p - Pmin)(Pmax - p)``; what is left is shared by headroom."""
    n = x.shape[0]
    p = np.empty(n)
    lo = np.empty(n)
    hi = np.empty(n)
    supplied = 0.0
    for i in range(n):
        lo[i] = pmin[i] if active[i] else 0.0
        hi[i] = pmax[i] if active[i] else 0.0
        p[i] = min(max(x[i] * old_demand, lo[i]), hi[i])
        supplied += p[i]
        weight[i] = max(p[i] - lo[i], 0.0) * max(hi[i] - p[i], 0.0)
    if b is not None and c is not None:
        step = merit_step(p, demand - supplied, lo, hi, b, c, weight)
    else:
        step = _share_step(p, demand - supplied, weight, lo, hi)
    if step != 0.0:
        for i in range(n):
            weight[i] = max(hi[i] - p[i], 0.0) if step > 0.0 else max(p[i] - lo[i], 0.0)
        _share_step(p, step, weight, lo, hi)
    for i in range(n):
        x[i] = p[i] / demand


@nb.njit(cache=True, **ALLOCATING)
def warm_start(policy, bounded, x, old_demand, demand, pmin, pmax, active, weight, b=None,
               c=None):  # fmt: skip
    """Shares to start a minute of ``demand`` (MW) from, in place: offline mass handed on
    (:func:`redistribute_offline`), then, in a mode with generator limits (``bounded``), the
    :class:`WarmStart` ``policy`` (its integer value) from the minute before's demand
    ``old_demand`` (MW; 0 if none: the shares projected onto the limits). ``b``, ``c``: the
    cost coefficients (EUR/MWh, EUR/MW^2h) for a set-point step in merit order (see
    :func:`continue_setpoints`)."""
    redistribute_offline(x, active)
    if not bounded:
        return
    if policy == WarmStart.MERIT and old_demand > 0.0:
        continue_setpoints(x, old_demand, demand, pmin, pmax, active, weight, b, c)
        return
    if policy == WarmStart.SETPOINTS and old_demand > 0.0:
        continue_setpoints(x, old_demand, demand, pmin, pmax, active, weight)
        return
    project_shares(x, demand, pmin, pmax, active)


@nb.njit(cache=True, inline="always")
def project_shares(x, demand, pmin, pmax, active):
    """Project the shares ``x`` (in place) onto the limits of a minute with ``demand`` (MW)."""
    lo = np.empty(x.shape[0])
    hi = np.empty(x.shape[0])
    share_bounds(pmin, pmax, active, demand, lo, hi)
    copy_into(project_to_box(x, lo, hi), x)
