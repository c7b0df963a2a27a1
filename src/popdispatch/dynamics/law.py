"""Flow laws: the one form every dynamic of this package takes, and the records that state one.

A mean dynamic on the shares ``x`` (``x_i = p_i / P_d``) moves mass from strategy ``j`` to
strategy ``i`` at the rate

    T_ij = g_ij * w_i * v_j * K(f_i, f_j),        x_i' = sum_j T_ij - sum_j T_ji,

with ``g`` the communication graph, ``w_i`` the receiver weight, ``v_j`` the sender weight
and a kernel ``K`` of one of two kinds (:class:`Kernel`):

- ``COMPARISON``, ``K = [f_i - f_j]_+``: pairwise comparison (Smith, its capacity-constrained
  and curvature-scaled variants) and imitation (the replicator: ``w = v = x``); summed by
  :mod:`popdispatch.dynamics.pairwise` (sorted running sums on the complete graph);
- ``TARGET``, ``K = 1``: the receiver weight is a target computed from the whole fitness
  vector (BNN's excess payoff, the logit choice); summed by
  :mod:`popdispatch.dynamics.targets`, on the complete graph.

A dynamic's module states its law as a :class:`FlowLaw`: its compile-time record class
(:class:`FieldTag`), its compiled weights and the same weights in plain numpy (the reference's,
:mod:`popdispatch.reference`), and its kernel. The engine, the flux limiter of
:mod:`popdispatch.integrate.steppers` and the reference all sum ``T`` from these weights, so a
new law changes none of them. Its :class:`Dynamics` record names it for people
(``--dynamics``). The registry is :mod:`popdispatch.dynamics.fields`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import numba as nb
import numpy as np


class Kernel(IntEnum):
    """The kernel ``K(f_i, f_j)`` of a flow law (see the module docstring)."""

    COMPARISON = 0  # K = [f_i - f_j]_+
    TARGET = 1  # K = 1


class FieldTag(NamedTuple):
    """A field as the compiled kernels take it: its :class:`~popdispatch.dynamics.fields.Field`
    value in ``code``; the *class* (one per weight kernel) picks the kernels when numba types
    a call, at compile time. A law with parameters has its own record class with ``code``
    first and its parameters after it (:class:`~popdispatch.dynamics.logit.LogitTag`)."""

    code: int


@dataclass(frozen=True)
class FlowLaw:
    """One flow law (see the module docstring), as its module states it.

    Attributes
    ----------
    name : its :class:`~popdispatch.dynamics.fields.Field` member's name (``"SMITH"``).
    tag : its record class (:class:`FieldTag` or a record with ``code`` first).
    weights : compiled ``(tag, x, f, lo, hi, active, rate, w, v, room, mass)``: receiver
        weight ``w``, sender weight ``v``, the ``room`` below the upper share limit and the
        movable ``mass`` above the lower one (shares; the flux limiter empties ``mass`` and
        fills ``room``) at shares ``x`` and fitness ``f`` (EUR/MW), share bounds ``lo``,
        ``hi``, online ``active``; ``rate``: the game's per-generator revision rates.
    reference : the same in plain numpy, ``(tag, x, f, lo, hi, active, rate) -> (w, v, room,
        mass)``, written from the law's definition (the reference's, and the tests').
    kernel : :class:`Kernel`.
    local : compiled ``(indptr, indices, rate, w, v, room, mass)``: the receiver and sender
        weights on a communication graph (CSR), in place, for a law that normalises them
        over the neighbourhood; ``None``: the same weights on every graph.
    reference_local : the same in plain numpy, ``(adjacency, rate, w, v, room, mass) -> (w,
        v)``.
    """

    name: str
    tag: type
    weights: Callable
    reference: Callable
    kernel: Kernel = Kernel.COMPARISON
    local: Callable | None = None
    reference_local: Callable | None = None

    @property
    def parameters(self) -> tuple[str, ...]:
        """The names of the parameters its record carries after ``code``."""
        return tuple(self.tag._fields[1:])


@dataclass(frozen=True)
class Dynamics:
    """A mean dynamic as people name it (``--dynamics``).

    Attributes
    ----------
    name : CLI name.
    law : its flow law in a mode without generator limits in the revision rule (paper).
    uses_graph : whether the communication graph matters (else the complete graph is used).
    scope : why a graph has no effect on it (when ``uses_graph`` is false), after "which".
    bounded_law : its flow law in a mode with generator limits (exact, voltage); ``None``:
        such a mode refuses it, for the reason ``refusal``.
    refusal : why a mode with generator limits cannot run it (when ``bounded_law`` is None).
    rests_at_optimum : whether its rest points are the game's equilibria (in exact mode the
        DC-OPF's KKT points); false for a perturbed best response (logit), whose rest points
        are not, so that no run of it is ever called converged to the DC-OPF.
    parameters : the settings it reads (``"eta"``: the logit's noise level).
    """

    name: str
    law: FlowLaw
    uses_graph: bool
    scope: str = "which compare every pair of generators"
    bounded_law: FlowLaw | None = None
    refusal: str = ""
    rests_at_optimum: bool = True
    parameters: tuple[str, ...] = ()


@nb.njit(cache=True, inline="always")
def copy_into(source, target):
    """``target[:] = source`` as a loop (numba compiles an array assignment with its
    broadcasting checks, seconds of the first run)."""
    for i in range(source.shape[0]):
        target[i] = source[i]


def movable(x: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Plain numpy: the shares of the online strategies, clipped at zero (the sender weight
    and movable mass of the laws without a lower limit)."""
    return np.where(active, np.maximum(x, 0.0), 0.0)
