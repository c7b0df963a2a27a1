"""Node controllers (paper section II-B) and their congestion signals (eq. 8).

A controller sits at each key node and measures the flows of the lines joined there. For a
limited line ``(i, j)`` both end controllers see the same flow with opposite signs: the one
where the overflow leaves computes a penalty, the one where it arrives an incentive, and each
broadcasts its value to every generator on its own side of the line. Signals of several
congested lines add up at a generator.

Lines are oriented away from the root (see :mod:`popdispatch.feeder.tree`): for line ``k`` the
*parent-end* controller sees ``p_ij = flow_k`` and the *child-end* controller ``-flow_k``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
import pandas as pd

from popdispatch.game.problem import DispatchProblem


@nb.njit(cache=True)
def overflow_signal(flow: float, limit: float, C: float) -> float:
    """Eq. 8 for a controller that measures ``flow`` (MW, positive = leaving its node)."""
    if flow > limit:
        return -(flow - limit) * C
    if flow < -limit:
        return -(flow + limit) * C
    return 0.0


@nb.njit(cache=True)
def broadcast_signals(
    flow: np.ndarray, limit: np.ndarray, down: np.ndarray, C: float
) -> np.ndarray:
    """Sum of the signals every generator receives (EUR/MW).

    ``flow``/``limit`` per limited line (MW); ``down[k, i] = 1`` if generator ``i`` is on the
    child side of line ``k``. The parent-end controller broadcasts to the parent side, the
    child-end controller (which measures ``-flow``) to the child side.
    """
    n_lines, n_gen = down.shape
    signal = np.zeros(n_gen)
    for k in range(n_lines):
        parent_end = overflow_signal(flow[k], limit[k], C)
        if parent_end == 0.0:
            continue
        child_end = overflow_signal(-flow[k], limit[k], C)
        for i in range(n_gen):
            signal[i] += child_end if down[k, i] > 0.0 else parent_end
    return signal


@dataclass(frozen=True)
class NodeControllers:
    """The controllers of a problem as a table, one row per (controller, measured limited line).

    Columns: ``node`` and ``bus`` of the controller, ``line`` (reduced line number), ``end``
    (``"parent"`` or ``"child"``), ``orientation`` (+1 if a positive line flow leaves this node),
    ``limit_kw`` and ``receivers`` (the generators on this controller's side of the line).
    This is the view a distributed runtime needs to run each controller as its own agent.
    """

    table: pd.DataFrame

    @classmethod
    def from_problem(cls, problem: DispatchProblem) -> NodeControllers:
        if problem.meshed:
            return cls.of_mesh(problem)
        lines = problem.feeder.lines.loc[problem.lines]
        gens = np.asarray(problem.generators)
        rows = []
        for k, (line, row) in enumerate(lines.iterrows()):
            below = problem.down[k] > 0
            for end, node, bus, sign, side in (
                ("parent", row.from_node, row.from_bus, 1, ~below),
                ("child", row.to_node, row.to_bus, -1, below),
            ):
                rows.append((node, bus, line, end, sign, row.limit_kw, list(gens[side])))
        columns = ["node", "bus", "line", "end", "orientation", "limit_kw", "receivers"]
        return cls(pd.DataFrame(rows, columns=columns))

    @classmethod
    def of_mesh(cls, problem: DispatchProblem) -> NodeControllers:
        """The controllers of a meshed network: one at each end bus of every limited line
        (``node`` is the bus), the from bus the parent end; every generator hears both ends,
        weighing them by its distribution factor (:mod:`popdispatch.game.mesh`)."""
        lines = problem.feeder.lines.iloc[np.asarray(problem.lines, dtype=int)]
        gens = list(problem.generators)
        rows = []
        for line, row in zip(problem.lines, lines.itertuples(), strict=True):
            for end, bus, sign in (("parent", row.from_bus, 1), ("child", row.to_bus, -1)):
                rows.append((bus, bus, int(line), end, sign, row.limit_kw, gens))
        columns = ["node", "bus", "line", "end", "orientation", "limit_kw", "receivers"]
        return cls(pd.DataFrame(rows, columns=columns))

    def signals(self, flows_mw: np.ndarray, C: float) -> pd.Series:
        """Each controller's eq.-8 value (EUR/MW) for the limited-line flows ``flows_mw`` (MW)."""
        line_pos = {line: k for k, line in enumerate(dict.fromkeys(self.table.line))}
        values = [
            overflow_signal(o * flows_mw[line_pos[line]], lim / 1000.0, C)
            for line, o, lim in zip(
                self.table.line, self.table.orientation, self.table.limit_kw, strict=True
            )
        ]
        return pd.Series(values, index=self.table.index, name="signal")
