"""Fitness of a generator node (paper eqs. 5-7). Powers in MW, fitness in EUR/MW.

``f_i = B - (b_i + 2 c_i p_i) + f_barr_i + s_i`` where ``s_i`` is the sum of the congestion
signals generator ``i`` received from the node controllers.
"""

from __future__ import annotations

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


@nb.njit(cache=True)
def barrier(p: np.ndarray, pmin: np.ndarray, pmax: np.ndarray, m: float) -> np.ndarray:
    """Eq. 7: ``m p`` below ``pmin``, 0 inside the limits, ``-m p`` above ``pmax`` (MW in)."""
    out = np.zeros_like(p)
    for i in range(p.shape[0]):
        if p[i] < pmin[i]:
            out[i] = m * p[i]
        elif p[i] > pmax[i]:
            out[i] = -m * p[i]
    return out


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
) -> np.ndarray:
    """Eqs. 5-7 plus congestion signals: ``B - (b + 2 c p) + barrier(p) + signal``."""
    return B - (b + 2.0 * c * p) + barrier(p, pmin, pmax, m) + signal
