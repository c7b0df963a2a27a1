"""Fitness of a generator node (paper eqs. 5-7). Powers in MW, fitness in EUR/MW.

``f_i = B - (b_i + 2 c_i p_i) + f_barr_i + s_i`` where ``s_i`` is the sum of the congestion
signals generator ``i`` received from the node controllers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np


@dataclass(frozen=True)
class FitnessParameters:
    """The game's constants.

    Attributes
    ----------
    B : bias that keeps fitness positive, EUR/MW (paper: 1000).
    m : slope of the generator-limit barrier, EUR/MW^2 (paper: 400; paper mode only).
    C : gain of the congestion signal, EUR/MW^2 (paper: 1000). In exact mode it is the
        proportional (augmented-Lagrangian) part of the line price.
    gain : exact mode: revision-rate multiplier of the fitness differences (dimensionless).
    price_rate : exact mode: how fast a line price integrates its overflow, EUR/MW per MW per s.
    """

    B: float = 1000.0
    m: float = 400.0
    C: float = 1000.0
    gain: float = 100.0
    price_rate: float = 1.0e5

    def __post_init__(self) -> None:
        for name in ("B", "m", "C", "gain", "price_rate"):
            value = getattr(self, name)
            if not (value >= 0 and value < float("inf")):
                raise ValueError(f"fitness constant {name} must be finite and >= 0, got {value}")

    @classmethod
    def parse(cls, text: str) -> FitnessParameters:
        """The paper's constants from ``"B=1000,m=400,C=1000"`` (any subset, the others at
        their defaults; a CLI's ``--constants``), each finite and >= 0. A bad entry raises
        :class:`~popdispatch.errors.OptionError` naming it."""
        from popdispatch.errors import OptionError

        known = ("B", "m", "C", "gain", "price_rate")
        values: dict[str, float] = {}
        for item in str(text).split(","):
            name, sep, value = item.partition("=")
            name = name.strip()
            if name not in known:
                raise OptionError(
                    f"{item!r}: unknown constant (known: {', '.join(known)})", "--constants"
                )
            number = _finite(value) if sep else None
            if number is None or number < 0:
                raise OptionError(
                    f"{item!r}: need {name}=VALUE with a finite VALUE >= 0", "--constants"
                )
            values[name] = number
        return cls(**values)


def _finite(text: str) -> float | None:
    """``text`` as a finite float, else None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


@nb.njit(cache=True, inline="always")
def barrier_at(p: float, pmin: float, pmax: float, m: float) -> float:
    """Eq. 7 for one generator: ``m p`` below ``pmin``, 0 inside the limits, ``-m p`` above
    ``pmax`` (MW in, EUR/MW out)."""
    if p < pmin:
        return m * p
    if p > pmax:
        return -m * p
    return 0.0


@nb.njit(cache=True)
def barrier(p: np.ndarray, pmin: np.ndarray, pmax: np.ndarray, m: float) -> np.ndarray:
    """Eq. 7 per generator (see :func:`barrier_at`)."""
    out = np.zeros_like(p)
    for i in range(p.shape[0]):
        out[i] = barrier_at(p[i], pmin[i], pmax[i], m)
    return out


@nb.njit(cache=True, inline="always")
def fitness_into(p, b, c, pmin, pmax, B, m, gain, signal, with_barrier, fitness):
    """The fitness kernel, eqs. 5-7: ``gain * (B - (b_i + 2 c_i p_i) + s_i [+ barrier_i])``
    into ``fitness`` (which may be ``signal`` itself). The engine (every mode), the public
    :func:`generator_fitness` and the plain-numpy reference all use it."""
    for i in range(p.shape[0]):
        f = B - (b[i] + 2.0 * c[i] * p[i]) + signal[i]
        if with_barrier:
            f += barrier_at(p[i], pmin[i], pmax[i], m)
        fitness[i] = gain * f


@nb.njit(cache=True)
def generator_fitness(
    p: np.ndarray,
    b: np.ndarray,
    c: np.ndarray,
    pmin: np.ndarray,
    pmax: np.ndarray,
    B: float,
    m: float,
    signal: np.ndarray,
    gain: float = 1.0,
    with_barrier: bool = True,
) -> np.ndarray:
    """Eqs. 5-7 plus congestion signals, ``gain * (B - (b + 2 c p) + barrier(p) + signal)``
    (exact mode: ``with_barrier=False`` and its revision ``gain``), by :func:`fitness_into`."""
    fitness = np.empty_like(p)
    fitness_into(p, b, c, pmin, pmax, B, m, gain, signal, with_barrier, fitness)
    return fitness
