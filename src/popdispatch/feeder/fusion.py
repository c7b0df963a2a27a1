"""Zero-reactance branches of a meshed network in the lossless DC model: ideal connections.

MATPOWER's ``makeBdc`` gives branch ``k`` the susceptance ``b_k = 1 / (x_k tau_k)``, infinite
at ``x_k = 0``. In the limit such a branch holds its two buses at one angle, so
:class:`~popdispatch.feeder.dcnet.DcModel` fuses the buses that zero-reactance branches join
(the connected components of their subgraph, *groups*) and takes one angle per group; a branch
with reactance whose two ends lie in one group carries only its phase shift's flow.

*Zero* means effectively zero: ``|x_k|`` below :data:`ZERO_X_RELATIVE` (1e-6) times the median
nonzero ``|x|`` of the network's branches (:func:`zero_reactance_threshold`, p.u.);
:func:`zero_reactance` is the one place that decides it. A near-zero branch left in ``B`` is
worse than an ideal connection. Its flow ``S (theta_f - theta_t) / x_k`` (MW) is a difference of
two angles known at best to float64's relative precision ``eps`` (2.2e-16) of their size
``|theta|``, about the demand's flow through the reactance ``x_path`` of the path from the
slack, so its rounding error is about ``eps x_path / x_k`` of the demand: EPRI ckt24's
``Line.Other_Feeders`` (1e-9 ohm, 8.4e-13 p.u., 2.7e-11 of the median) left in ``B`` misses
Kirchhoff's current law by 12 W of the 50.9 MW at bus ``feeders``. Fused, the branch errs
instead by the share of its flow that its reactance would push onto the rest of the network in
parallel with it, ``x_k / (x_k + x_th)`` (``x_th``: the reactance across its two ends without
it; none on a bridge). With ``r = x_k / x_typical`` and ``x_path`` about ``D`` typical branches,
the two errors are about ``r`` and ``eps D / r`` and balance at ``r = sqrt(eps D)``, the
truncation-rounding trade-off of a finite difference (Nocedal & Wright, *Numerical
Optimization*, 2nd ed., section 8.1). 1e-6 is that balance for the deepest feeders (``D`` =
10,000 branches: ``sqrt(2.2e-12)`` = 1.5e-6), so that on any network up to that depth neither a
fused branch nor one just above the threshold is off by more than about 1e-6 of the demand, the
engine's own relative accuracy (:class:`~popdispatch.online.RunSettings` ``accuracy_rel``). The
median makes the scale the network's typical branch, unmoved by a few busbars or large
transformers, and a relative bound holds on any per-unit base (OpenDSS circuits come on 1 MVA,
MATPOWER cases on 100 MVA). Not covered: a fused branch whose only parallel path has a reactance
of its own order (two near-zero branches in parallel, one each side of the threshold) takes that
path's share of the flow.

The flows on the zero-reactance branches do not follow from the angles but from Kirchhoff's
current law inside each group: with ``C_z`` the incidence of the zero-reactance branches and
``C_nz`` that of the others, ``C_z^T f_z = P_inj - C_nz^T f_nz`` (MW) per bus. Where the
zero-reactance branches form a forest, ``C_z`` has full row rank and the unique solution is
``f_z = (C_z C_z^T)^-1 C_z (P_inj - C_nz^T f_nz)`` (the edge Laplacian ``C_z C_z^T``, one sparse
LU). Where they close a loop among themselves the DC model leaves the split around it
undetermined (it would depend on the resistances, which the model has not): such a network,
and a zero-reactance branch with a phase shift (an ideal connection shifts no angle), are
refused in one line (:func:`check_zero_reactance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import sparse

from popdispatch.errors import FeederError

#: A branch whose ``|x|`` is below this fraction of the median nonzero ``|x|`` of its network's
#: branches has zero reactance in the DC model (the module's docstring argues the value).
ZERO_X_RELATIVE = 1e-6


def zero_reactance_threshold(lines: pd.DataFrame) -> float:
    """The reactance (p.u., on the ``x_pu`` column's base) below which a branch of a meshed
    network's ``lines`` table is zero in the DC model: :data:`ZERO_X_RELATIVE` times the
    median of the nonzero ``|x_pu|`` (0 where no branch has reactance: then only ``x_pu = 0``
    is zero)."""
    x = np.abs(lines.x_pu.to_numpy(float))
    x = x[x != 0]
    return float(ZERO_X_RELATIVE * np.median(x)) if len(x) else 0.0


def zero_reactance(lines: pd.DataFrame) -> np.ndarray:
    """Per line of a meshed network's ``lines`` table, whether its reactance is zero in the DC
    model (an ideal connection): ``x_pu`` is 0 or ``|x_pu|`` is below
    :func:`zero_reactance_threshold` (p.u.)."""
    x = np.abs(lines.x_pu.to_numpy(float))
    return (x == 0) | (x < zero_reactance_threshold(lines))


def check_zero_reactance(name: str, lines: pd.DataFrame, ends: tuple[np.ndarray, np.ndarray],
                         n_buses: int) -> None:  # fmt: skip
    """One-line :class:`FeederError` when the zero-reactance branches of network ``name``
    cannot be ideal connections: one has a phase shift, or some close a loop among themselves
    (``ends``: each line's from and to bus positions among ``n_buses``)."""
    zero = zero_reactance(lines)
    threshold = zero_reactance_threshold(lines)
    shifted = zero & (lines.shift_deg.to_numpy(float) != 0)
    if shifted.any():
        k = int(shifted.argmax())
        x = float(lines.x_pu.iloc[k])
        which = f" ({x:.3g} p.u., below {threshold:.3g} p.u.)" if x else ""
        raise FeederError(f"network {name!r}: line {lines.index[k]!r} has zero reactance{which} "
                          f"and a phase shift of {lines.shift_deg.iloc[k]:g} deg (an ideal "
                          "connection shifts no angle in the DC model)")  # fmt: skip
    k = loop_branch(n_buses, ends[0], ends[1], zero)
    if k is not None:
        below = f"reactance below {threshold:.3g} p.u.; " if threshold > 0 else ""
        raise FeederError(f"network {name!r}: line {lines.index[k]!r} closes a loop of "
                          f"zero-reactance branches ({below}the DC model cannot split a flow "
                          "among ideal connections in a loop: give one of them a "
                          "reactance)")  # fmt: skip


def loop_branch(n: int, f: np.ndarray, t: np.ndarray, zero: np.ndarray) -> int | None:
    """The position of the first zero-reactance branch (``zero``; ends ``f``, ``t`` among
    ``n`` buses) whose two ends the ones before it already join (union-find), None when the
    zero-reactance branches form a forest."""
    parent = np.arange(n)

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for k in np.flatnonzero(zero):
        a, b = root(int(f[k])), root(int(t[k]))
        if a == b:
            return int(k)
        parent[a] = b
    return None


def bus_groups(n: int, f: np.ndarray, t: np.ndarray, zero: np.ndarray) -> np.ndarray:
    """Per bus (``n`` of them), its group: the connected component of the subgraph of the
    zero-reactance branches (``zero``; ends ``f``, ``t``), numbered 0, 1, ... in the order of
    each group's first bus, so that without zero-reactance branches every bus is its own group
    and keeps its position."""
    from scipy.sparse.csgraph import connected_components

    graph = sparse.csr_array((np.ones(int(zero.sum())), (f[zero], t[zero])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    _, first = np.unique(label, return_index=True)
    order = np.empty(len(first), np.int64)
    order[np.argsort(first, kind="stable")] = np.arange(len(first))
    return order[label]


def ideal_connections(buses: pd.Index, lines: pd.DataFrame) -> tuple[int, int, int]:
    """How a network (its bus ids ``buses``, its ``lines`` table) fuses: the number of its
    zero-reactance lines, of the buses they join and of the groups those buses form."""
    zero = zero_reactance(lines)
    if not zero.any():
        return 0, 0, 0
    f, t = buses.get_indexer(lines.from_bus), buses.get_indexer(lines.to_bus)
    joined = np.unique(np.r_[f[zero], t[zero]])
    groups = bus_groups(len(buses), f, t, zero)
    return int(zero.sum()), len(joined), len(np.unique(groups[joined]))


def ideal_note(buses: pd.Index, lines: pd.DataFrame) -> str:
    """What the DC model does with a network's zero-reactance lines (its bus ids ``buses``, its
    ``lines`` table) and below which reactance (p.u.) a line is one, one phrase; empty without
    any."""
    count, joined, groups = ideal_connections(buses, lines)
    if not count:
        return ""
    below = threshold_phrase(zero_reactance_threshold(lines))
    return (f"{count} zero-reactance line(s){below} joined as ideal connections ({joined} buses "
            f"in {groups} group(s), each at one angle; their flows from Kirchhoff's current "
            "law)")  # fmt: skip


def threshold_phrase(threshold: float) -> str:
    """`` (reactance below <threshold> p.u.)``, how the texts say what zero is (p.u.); empty
    where the threshold is 0 (only ``x_pu = 0`` is zero)."""
    return f" (reactance below {threshold:.3g} p.u.)" if threshold > 0 else ""


@dataclass(frozen=True)
class ZeroFlows:
    """Kirchhoff's current law for the zero-reactance branches (a forest).

    ``lines``: their positions; ``incidence``: ``C_z`` (their rows of the branch-bus
    incidence, +1 at the from bus, -1 at the to bus); ``touch``: the positions of the branches
    with reactance that end at a bus of a zero-reactance branch; ``across``: ``C_z C_touch^T``;
    ``lu``: SuperLU of the edge Laplacian ``C_z C_z^T`` (nonsingular on a forest).
    """

    lines: np.ndarray
    incidence: sparse.csr_array
    touch: np.ndarray
    across: sparse.csr_array
    lu: object

    @classmethod
    def of(cls, incidence: sparse.csr_array, zero: np.ndarray) -> ZeroFlows:
        """The law for the zero-reactance branches ``zero`` (a mask over the rows of the
        branch-bus ``incidence``, lines x buses)."""
        from scipy.sparse.linalg import splu

        lines = np.flatnonzero(zero)
        Cz = sparse.csr_array(incidence[lines])
        at = np.zeros(incidence.shape[1], bool)
        at[Cz.indices] = True
        touch = np.flatnonzero(~zero & (abs(incidence) @ at.astype(float) > 0))
        across = sparse.csr_array(Cz @ incidence[touch].T)
        lu = splu(sparse.csc_matrix(Cz @ Cz.T))
        return cls(lines, Cz, touch, across, lu)

    def flows(self, injection: np.ndarray, touch_flows: np.ndarray) -> np.ndarray:
        """The flows on the zero-reactance branches (from bus to to bus, zero lines x
        columns) for the bus injections ``injection`` (buses x columns, balanced: the slack's
        entry is the balance) and the flows ``touch_flows`` on :attr:`touch` (same unit, MW or
        MW per MW): ``(C_z C_z^T)^-1 C_z (P - C_nz^T f_nz)``."""
        rhs = self.incidence @ injection - self.across @ touch_flows
        return self.lu.solve(np.ascontiguousarray(rhs))
