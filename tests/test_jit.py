"""The engine's loop borrows its caller's arrays (popdispatch/jit.py): compiled without
reference counting, numba must refuse an allocation in it, and the arrays it is handed must
come back as the caller holds them. These hold for the numba installed, not only the one the
options were written against."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba as nb
import numpy as np
import pytest

from popdispatch.jit import ALLOCATING, BORROWING


def test_a_borrowing_kernel_that_allocates_does_not_compile() -> None:
    @nb.njit(**BORROWING)
    def allocates(x):
        y = np.empty(x.shape[0])
        y[:] = x
        return y.sum()

    with pytest.raises(nb.core.errors.TypingError):
        allocates(np.ones(3))


def test_a_borrowing_kernel_calls_an_allocating_one_and_leaks_nothing() -> None:
    @nb.njit(**ALLOCATING)
    def scratch_sum(x):
        y = np.empty(x.shape[0])
        for i in range(x.shape[0]):
            y[i] = 2.0 * x[i]
        return y.sum()

    @nb.njit(**BORROWING)
    def borrows(x, out, rows):
        total = 0.0
        for r in range(rows.shape[0]):
            row = rows[r]  # a view, not counted
            for i in range(row.shape[0]):
                out[i] += row[i]
            total += scratch_sum(row)
        return total + x.sum()

    x = np.arange(4.0)
    out = np.zeros(4)
    rows = np.arange(12.0).reshape(3, 4)
    held = [sys.getrefcount(a) for a in (x, out, rows)]
    for _ in range(100):
        total = borrows(x, out, rows)
    assert total == 2.0 * rows.sum() + x.sum()
    np.testing.assert_array_equal(out, 100 * rows.sum(axis=0))
    assert [sys.getrefcount(a) for a in (x, out, rows)] == held


ENGINE_RUNS = """
import sys
sys.path.insert(0, sys.argv[1])
from numba.core.runtime import rtsys
from helpers import random_fleet_problem
from popdispatch.online import RunSettings, run_snapshot

problem = random_fleet_problem(7, 5, 2)
names = list(problem.generators)
ring = [(names[i], names[(i + 1) % len(names)]) for i in range(len(names))]
import networkx as nx
for settings in (RunSettings(mode="exact"),
                 RunSettings(mode="exact", dynamics="distributed-smith", graph=nx.Graph(ring))):
    run_snapshot(problem, 1, settings)
    before = rtsys.get_allocation_stats()
    run = run_snapshot(problem, 1, settings)
    after = rtsys.get_allocation_stats()
    print(run.status, after.alloc - before.alloc, after.free - before.free)
"""


def test_the_engine_frees_every_array_it_allocates() -> None:
    """A snapshot with Smith and with distributed Smith on a ring (whose relay allocates its
    member lists): numba's own allocation counts, on, before and after."""
    out = subprocess.run([sys.executable, "-c", ENGINE_RUNS, str(Path(__file__).parent)],
                         capture_output=True, text=True, check=True,
                         env={**os.environ, "NUMBA_NRT_STATS": "1"})  # fmt: skip
    rows = [line.split() for line in out.stdout.splitlines()]
    assert len(rows) == 2
    for status, allocated, freed in rows:
        assert status == "converged"
        assert int(allocated) > 0  # the warm start projects the shares with scratch of its own
        assert int(allocated) == int(freed)
