"""Where the dynamics start when the demand changes between minutes (online operation).

- ``shares`` (the paper's rule, paper mode's default): the shares continue, ``p = x * P_d`` with
  the new demand ``P_d``; with generator limits (exact mode) they are projected onto
  ``lo <= x <= hi``.
- ``setpoints`` (exact mode's default): the set points continue and the demand step is taken by
  the generators that are trading (strictly inside their limits), in proportion to
  ``(p - Pmin) (Pmax - p)``, as participation factors would share it; a generator resting at a
  limit stays there. Only if no generator is trading is the step shared by headroom.

Generators that went offline hand their mass to the online ones (in proportion to their shares).
All functions are compiled: the day loop calls them every minute.
"""

from __future__ import annotations

from enum import IntEnum

import numba as nb
import numpy as np

from popdispatch.dynamics.capacity import project_to_box
from popdispatch.game.parameters import share_bounds


class WarmStart(IntEnum):
    """Warm-start policies (see the module docstring)."""

    SHARES = 0
    SETPOINTS = 1


SHARES, SETPOINTS = WarmStart
WARM_STARTS = {policy.name.lower(): policy for policy in WarmStart}


@nb.njit(cache=True)
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
def continue_setpoints(x, old_demand, demand, pmin, pmax, active, weight):
    """Shares for ``demand`` (MW) keeping the set points ``x * old_demand`` (see module)."""
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
    step = _share_step(p, demand - supplied, weight, lo, hi)
    if step != 0.0:
        for i in range(n):
            weight[i] = max(hi[i] - p[i], 0.0) if step > 0.0 else max(p[i] - lo[i], 0.0)
        _share_step(p, step, weight, lo, hi)
    for i in range(n):
        x[i] = p[i] / demand


@nb.njit(cache=True)
def warm_start(policy, bounded, x, old_demand, demand, pmin, pmax, active, weight):
    """Shares to start a minute from (in place), after ``redistribute_offline``."""
    redistribute_offline(x, active)
    if not bounded:
        return
    if policy == WarmStart.SETPOINTS and old_demand > 0.0:
        continue_setpoints(x, old_demand, demand, pmin, pmax, active, weight)
        return
    lo = np.empty(x.shape[0])
    hi = np.empty(x.shape[0])
    share_bounds(pmin, pmax, active, demand, lo, hi)
    x[:] = project_to_box(x, lo, hi)
