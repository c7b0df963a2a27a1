"""Logit dynamics (perturbed best response) with noise level ``eta``: a target flow law.

Every revising agent picks strategy ``i`` with the logit choice probability
``L_i(f) = exp(f_i / eta) / sum_k exp(f_k / eta)`` (the online strategies), whatever it
holds:

    flow j -> i = r x_j L_i(f),      x' = r (L(f) - x),

with ``r`` the revision rate (1/s). As a flow law (:mod:`popdispatch.dynamics.law`): kernel 1,
receiver weight ``r L_i(f)``, sender weight ``x_j`` (summed by
:mod:`popdispatch.dynamics.targets`). ``eta`` is given in EUR/MWh (a marginal cost, the unit
of the paper's fitness) and reaches the kernels in the mode's fitness units
(:class:`LogitTag`); paper mode revises at ``r = 1/s`` (the population-dynamics toolbox's
``x' = L(f) - x``), exact mode at its revision gain (``ExactConstants.gain``, 1/s: the rate at
which curvature-scaled Smith relaxes each marginal cost, so its line prices see the same time
scale).

Rest points: the logit equilibria ``x = L(f(x))``: every online strategy keeps a share, the
fitter ones more (``f_i - f_j = eta ln(x_i / x_j)``), so they are *not* the Nash equilibria
(nor, in exact mode, the DC-OPF) and approach them as ``eta -> 0``. Extinction: every online
strategy receives ``r L_i > 0``, so none stays at zero.

With generator limits (exact mode) the choice is made inside the limits: the target is the
perturbed best response over the shares' box,

    T = argmax { f.y - eta sum_i y_i ln y_i : lo <= y <= hi, sum_i y_i = sum_i x_i }
      = clip(exp((f - lambda) / eta), lo, hi),  lambda such that the shares sum as before,

which is ``L(f)`` without limits. The flows then run from every strategy above its target to
every one below it, ``flow j -> i = r [x_j - T_j]_+ [T_i - x_i]_+ / D`` (``D = sum_k [T_k -
x_k]_+``): the same ``x' = r (T - x)``, but a generator whose target is its limit stops there
(flows as ``x_j L_i`` would send and receive at once at the limit, and the limiter could stop
only the receiving). Its rest points are the logit equilibria inside the limits; exact mode
reports how far they are from the DC-OPF and never calls such a run converged.

The complete graph only: ``L`` normalises over the whole fleet. A generator agent would need
``sum_k exp(f_k / eta)`` (exact mode: ``lambda``) from messages: on the complete graph from one
round of every DG's fitness (its status message carries it); on a sparse graph an
average-consensus of ``exp(f_k / eta)`` over its neighbours.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from popdispatch.dynamics.capacity import box, capacity_smith_weights
from popdispatch.dynamics.law import Dynamics, FlowLaw, Kernel, movable

#: Bisection steps of the box target's ``lambda`` at most (it stops once the bracket does not
#: shrink: machine precision, about 60 steps).
BISECTION_STEPS = 200
#: ``exp`` of less than this underflows to zero: the box target's upper bracket of ``lambda``
#: sits this many ``eta`` above the fittest strategy's reach of its upper limit.
UNDERFLOW = 746.0


class LogitTag(NamedTuple):
    """The logit's record: its :class:`~popdispatch.dynamics.fields.Field` value in ``code``,
    the noise level ``eta`` in the mode's fitness units (EUR/MW times the fitness gain) and
    the revision rate ``gain`` (1/s, ``r``)."""

    code: int
    eta: float
    gain: float


class BoxLogitTag(NamedTuple):
    """The logit inside the generator limits (:func:`box_weights`); fields as
    :class:`LogitTag`."""

    code: int
    eta: float
    gain: float


@nb.njit(cache=True, inline="always")
def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """Receiver weight ``r L_i(f)`` (1/s), sender weight and movable mass ``x`` (shares) on the
    online strategies, unbounded room (``tag``: a :class:`LogitTag`)."""
    top = -np.inf
    for i in range(x.shape[0]):
        if active[i]:
            top = max(top, f[i])
    total = 0.0
    for i in range(x.shape[0]):
        w[i] = math.exp((f[i] - top) / tag.eta) if active[i] else 0.0
        total += w[i]
        share = max(x[i], 0.0) if active[i] else 0.0
        v[i] = share
        mass[i] = share
        room[i] = np.inf
    for i in range(x.shape[0]):
        w[i] = w[i] * (tag.gain / total) if total > 0.0 else 0.0


@nb.njit(cache=True, inline="always")
def clipped_choice(f, lo, hi, eta, level, i):
    """``clip(exp((f_i - level) / eta), lo_i, hi_i)`` (shares) without overflow."""
    exponent = (f[i] - level) / eta
    if exponent >= math.log(hi[i]):
        return hi[i]
    return max(math.exp(exponent), lo[i])


@nb.njit(cache=True, inline="always")
def box_sum(f, lo, hi, part, eta, level):
    """The box target's total at ``lambda = level`` (see :func:`box_target`)."""
    total = 0.0
    for i in range(f.shape[0]):
        if part[i] > 0.0:
            total += clipped_choice(f, lo, hi, eta, level, i)
    return total


@nb.njit(cache=True)
def box_target(f, lo, hi, part, eta, mass, target):
    """The perturbed best response inside the box into ``target``:
    ``clip(exp((f - lambda) / eta), lo, hi)`` on the strategies taking part (``part > 0``), 0
    elsewhere, with ``lambda`` found by bisection so that it sums to ``mass`` (shares; at least
    ``sum lo`` and at most ``sum hi``). ``f`` and ``eta`` in the same units."""
    low = np.inf
    high = -np.inf
    for i in range(f.shape[0]):
        if part[i] > 0.0:
            reach = f[i] - eta * math.log(hi[i])  # at or below this level, i is at hi
            low = min(low, reach)
            high = max(high, reach)
    high += UNDERFLOW * eta  # every clip at its lower limit
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (low + high)
        if middle <= low or middle >= high:
            break
        if box_sum(f, lo, hi, part, eta, middle) > mass:
            low = middle
        else:
            high = middle
    level = 0.5 * (low + high)
    held = 0.0  # at a limit
    free = 0.0
    for i in range(f.shape[0]):
        target[i] = clipped_choice(f, lo, hi, eta, level, i) if part[i] > 0.0 else 0.0
        if part[i] > 0.0 and lo[i] < target[i] < hi[i]:
            free += target[i]
        else:
            held += target[i]
    # lambda is known to a few ulp of its size, the shares to that over eta: the free ones
    # are scaled to the mass (as a last move of lambda would) so the target sums to it
    if free > 0.0:
        scale = (mass - held) / free
        for i in range(f.shape[0]):
            if part[i] > 0.0 and lo[i] < target[i] < hi[i]:
                target[i] = min(max(target[i] * scale, lo[i]), hi[i])


@nb.njit(cache=True, inline="always")
def box_weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """From every strategy above its box target ``T`` to every one below it: receiver weight
    ``r [T_i - x_i]_+ / D`` (1/s), sender weight ``[x_j - T_j]_+`` (shares), room ``hi - x``
    and movable mass ``x - lo`` as capacity-constrained Smith's (``tag``: a
    :class:`BoxLogitTag`; a strategy with no width or offline takes no part)."""
    capacity_smith_weights(x, lo, hi, active, w, v, room)  # room; v: the movable mass
    total = 0.0
    for i in range(x.shape[0]):
        mass[i] = v[i]
        w[i] = 1.0 if active[i] and hi[i] > lo[i] else 0.0
        total += max(x[i], 0.0) if w[i] > 0.0 else 0.0
    box_target(f, lo, hi, w, tag.eta, total, v)
    excess = 0.0
    for i in range(x.shape[0]):
        if w[i] > 0.0:
            gap = v[i] - max(x[i], 0.0)
            w[i] = max(gap, 0.0)
            v[i] = max(-gap, 0.0)
            excess += w[i]
    for i in range(x.shape[0]):
        w[i] = w[i] * (tag.gain / excess) if excess > 0.0 else 0.0


def reference(tag, x, f, lo, hi, active, rate):
    """Plain numpy: ``w = r softmax(f / eta)`` over the online strategies, ``v = mass = x``."""
    share = movable(x, active)
    choice = np.where(active, np.exp((f - f[active].max()) / tag.eta), 0.0)
    return tag.gain * choice / choice.sum(), share, np.full(len(x), np.inf), share


def reference_box_target(f, lo, hi, part, eta, mass):
    """Plain numpy: the perturbed best response inside the box (see :func:`box_target`),
    ``lambda`` by Brent's method on the total."""
    from scipy.optimize import brentq

    def choice(level):
        with np.errstate(over="ignore"):
            return np.where(part, np.clip(np.exp((f - level) / eta), lo, hi), 0.0)

    reach = f[part] - eta * np.log(hi[part])
    level = brentq(lambda lam: choice(lam).sum() - mass, reach.min(), reach.max() + UNDERFLOW * eta,
                   xtol=1e-300, rtol=4 * np.finfo(float).eps)  # fmt: skip
    return choice(level)


def reference_box(tag, x, f, lo, hi, active, rate):
    """Plain numpy: from the strategies above their box target to those below it."""
    room, mass = box(x, lo, hi, active)
    part = active & (hi > lo)
    share = np.maximum(x, 0.0)
    gap = reference_box_target(f, lo, hi, part, tag.eta, share[part].sum()) - share
    above = np.where(part, np.maximum(gap, 0.0), 0.0)
    below = np.where(part, np.maximum(-gap, 0.0), 0.0)
    w = tag.gain * above / above.sum() if above.sum() > 0 else np.zeros(len(x))
    return w, below, room, mass


LAW = FlowLaw("LOGIT", LogitTag, weights, reference, Kernel.TARGET)
BOX_LAW = FlowLaw("BOX_LOGIT", BoxLogitTag, box_weights, reference_box, Kernel.TARGET)
LAWS = (LAW, BOX_LAW)
DYNAMICS = (
    Dynamics("logit", LAW, False, scope="whose choice probabilities are normalised over the "
             "whole fleet", bounded_law=BOX_LAW, rests_at_optimum=False, parameters=("eta",)),
)  # fmt: skip
