"""Brown-von Neumann-Nash (BNN) dynamics: a target (excess-payoff) flow law.

Every revising agent compares its options with the population's *mean* fitness
``f_bar = sum_j x_j f_j / sum_j x_j`` (the sum over the online strategies; the shares sum to
1) and moves to strategy ``i`` at the rate of its excess payoff ``[f_i - f_bar]_+``:

    flow j -> i = x_j [f_i - f_bar]_+,     x_i' = [f_i - f_bar]_+ - x_i sum_k [f_k - f_bar]_+.

As a flow law (:mod:`popdispatch.dynamics.law`): kernel 1, receiver weight the excess payoff
``[f_i - f_bar]_+`` (EUR/MW, read as a rate in 1/s like the paper's Smith), sender weight
``x_j``, no upper limit (summed by :mod:`popdispatch.dynamics.targets`).

Rest points: exactly the Nash equilibria. At rest with some excess payoff, every strategy in
use would be above the mean, which is their average; so no strategy is above the mean, and
the strategies in use, whose average it is, are all at it. Extinction: a strategy at zero
share that is better than the mean receives mass, so BNN uses an efficient generator that
starts at zero (unlike the replicator).

The complete graph only: the mean is the whole population's. A generator agent would need
``f_bar`` from messages: the fitness and share of every online generator (each DG's status
message carries both, so on the complete graph every DG can form it from one round of
statuses), or on a sparse graph an average-consensus over its neighbours of ``(x_j f_j,
x_j)`` before each revision.

Generator limits (exact mode) are refused: the mean is shifted by generators held at a limit,
so with limits BNN rests at points that are not the DC-OPF's KKT points (whichever mean is
taken; docs/dynamics.md has an example). Exact mode runs smith, distributed-smith or logit.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from popdispatch.dynamics.law import Dynamics, FieldTag, FlowLaw, Kernel, movable

#: Why a mode with generator limits refuses BNN.
SHIFTED_MEAN = (
    "its excess payoff compares each generator with the population's mean fitness, which a "
    "generator held at a limit shifts, so with limits it rests at points that are not the "
    "DC-OPF's (docs/dynamics.md)"
)


@nb.njit(cache=True, inline="always")
def weights(tag, x, f, lo, hi, active, rate, w, v, room, mass):
    """Receiver weight ``[f_i - f_bar]_+`` (EUR/MW), sender weight and movable mass ``x``
    (shares) on the online strategies, unbounded room; ``f_bar`` the share-weighted mean
    fitness of the online strategies."""
    total = 0.0
    weighted = 0.0
    for i in range(x.shape[0]):
        share = max(x[i], 0.0) if active[i] else 0.0
        v[i] = share
        mass[i] = share
        room[i] = np.inf
        total += share
        weighted += share * f[i]
    mean = weighted / total if total > 0.0 else 0.0
    for i in range(x.shape[0]):
        w[i] = max(f[i] - mean, 0.0) if active[i] else 0.0


def reference(tag, x, f, lo, hi, active, rate):
    """Plain numpy: ``w = [f - x.f / sum x]_+``, ``v = mass = x`` on the online strategies."""
    share = movable(x, active)
    mean = share @ f / share.sum() if share.sum() > 0 else 0.0
    return np.where(active, np.maximum(f - mean, 0.0), 0.0), share, np.full(len(x), np.inf), share


class BnnTag(FieldTag):
    """BNN's weights (:func:`weights`)."""

    __slots__ = ()


LAW = FlowLaw("BNN", BnnTag, weights, reference, Kernel.TARGET)
LAWS = (LAW,)
DYNAMICS = (
    Dynamics("bnn", LAW, False, scope="whose excess payoff is over the whole population's "
             "mean fitness", refusal=SHIFTED_MEAN),
)  # fmt: skip
