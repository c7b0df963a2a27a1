"""Exact mode's price laws (modes/exact.py, docs/exact-mode.md "Nested limits"): the tree law's
compiled rates equal the preconditioner ``M = L^-T W^-1 L^-1`` built as dense matrices in numpy,
its broadcast prices equal the plain law's, and the law is chosen by name."""

from __future__ import annotations

import numpy as np
import pytest
from price_laws import law_payoff

from popdispatch.errors import OptionError
from popdispatch.game.parameters import MinuteInputs, PriceLaw
from popdispatch.modes.exact import (
    EMPTY_REGION,
    ExactConstants,
)


def _payoff(problem, law, p, z):
    minute = MinuteInputs.of(problem, 1)
    return (*law_payoff(problem, law, p, z, minute), minute)


def _ancestors(line_up: np.ndarray) -> np.ndarray:
    """``below[k, r]``: line ``r`` is line ``k`` or below it (dense, from the parent links)."""
    n = len(line_up)
    below = np.eye(n, dtype=bool)
    for r in range(n):
        k = line_up[r]
        while k >= 0:
            below[k, r] = True
            k = line_up[k]
    return below


def dense_tree_rates(problem, p, z, fp, minute) -> np.ndarray:
    """The tree law from its definition with dense matrices: on the active lines (priced or
    overflowing in one direction) ``nu' = price_rate * L^-T W^-1 L^-1 eps``; ``L`` the ancestor
    matrix of the active lines, ``W^-1`` per line (tradable generators below it + 1e-4) /
    (those in its own region + 1e-4); every other line ``z' = price_rate * excess``."""
    n = len(problem.limit)
    flow = problem.load_flow[0] - problem.down @ p
    excess = np.concatenate([flow - problem.limit, -flow - problem.limit])
    rate = fp.price_rate * excess
    up = (z[:n] > 0) | (excess[:n] > 0)
    down = (z[n:] > 0) | (excess[n:] > 0)
    sign = np.where(up & ~down, 1.0, np.where(down & ~up, -1.0, 0.0))
    active = np.flatnonzero(sign != 0)
    L = _ancestors(problem.line_up)[np.ix_(active, active)].astype(float)
    tradable = (minute.hi > minute.lo).astype(float)
    below = problem.down[active] @ tradable
    strict = L - np.eye(len(active))  # active lines strictly below
    nearest = strict - (strict @ strict > 0)  # ... with no active line between
    own = below - nearest @ below  # the generators in each line's own region
    w_inv = (below + EMPTY_REGION) / (own + EMPTY_REGION)
    eps = flow[active] - sign[active] * problem.limit[active]
    L_inv = np.linalg.inv(L)
    step = L_inv.T @ (w_inv * (L_inv @ eps))
    up_rows = active[sign[active] > 0]
    down_rows = active[sign[active] < 0]
    rate[up_rows] = fp.price_rate * step[sign[active] > 0]
    rate[n + down_rows] = -fp.price_rate * step[sign[active] < 0]
    return rate


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tree_rates_equal_the_dense_preconditioner(problem, seed):
    rng = np.random.default_rng(seed)
    n = len(problem.limit)
    p = problem.pmin + (problem.pmax - problem.pmin) * rng.uniform(0, 1, problem.n_generators)
    p *= problem.demand[0] / p.sum()
    z = np.where(rng.uniform(0, 1, 2 * n) < 0.3, rng.uniform(0, 50, 2 * n), 0.0)
    fitness, rate, fp, minute = _payoff(problem, PriceLaw.TREE, p, z)
    expected = dense_tree_rates(problem, p, z, fp, minute)
    flow = problem.load_flow[0] - problem.down @ p
    assert ((z[:n] > 0) | (flow > problem.limit)).sum() >= 3  # several active lines
    np.testing.assert_allclose(rate, expected, rtol=1e-9, atol=1e-9 * fp.price_rate)
    # the law changes how the prices move, not what they broadcast
    plain_fitness, plain_rate, _, _ = _payoff(problem, PriceLaw.PLAIN, p, z)
    np.testing.assert_array_equal(fitness, plain_fitness)
    np.testing.assert_allclose(plain_rate, fp.price_rate * np.concatenate(
        [flow - problem.limit, -flow - problem.limit]), rtol=1e-12, atol=1e-12)  # fmt: skip


def test_run_settings_carry_the_law_to_the_engine(problem):
    """``RunSettings.exact.price_law`` reaches the engine as its term's compile-time mode
    record (a choice of kernel, so a run compiles only its own law); paper mode has no line
    prices and keeps its record. With limited lines and adaptive steps the laws' kernels
    hasten the pinned lines or pairs (modes/exact.py ``hasten_pinned``); with fixed steps
    they do not."""
    from popdispatch.integrate import Integrator
    from popdispatch.modes.exact import (
        ExactPinnedTag,
        ExactScaledPinnedTag,
        ExactScaledTag,
        ExactTag,
        ExactTreePinnedTag,
        ExactTreeTag,
    )
    from popdispatch.modes.paper import PaperTag
    from popdispatch.online import Engine, RunSettings

    assert problem.limit.size
    euler = Integrator(method="euler")
    for law, adaptive, fixed in [("plain", ExactPinnedTag, ExactTag),
                                 ("tree", ExactTreePinnedTag, ExactTreeTag),
                                 ("scaled", ExactScaledPinnedTag, ExactScaledTag)]:  # fmt: skip
        settings = RunSettings(mode="exact", exact=ExactConstants(price_law=law))
        assert type(Engine(problem, settings).term.mode) is adaptive
        settings = RunSettings(mode="exact", exact=ExactConstants(price_law=law), integrator=euler)
        assert type(Engine(problem, settings).term.mode) is fixed
    assert type(Engine(problem, RunSettings(mode="paper")).term.mode) is PaperTag


def test_price_law_is_chosen_by_name_and_unknown_names_are_refused():
    assert ExactConstants(price_law="tree").price_law is PriceLaw.TREE
    assert ExactConstants(price_law=1).price_law is PriceLaw.TREE
    assert ExactConstants().price_law is PriceLaw.PLAIN
    with pytest.raises(OptionError, match="'nested'.*plain, tree"):
        ExactConstants(price_law="nested")
