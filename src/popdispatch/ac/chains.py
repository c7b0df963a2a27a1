"""Series chains of a feeder: the exact reduction that makes the AC check fast.

A bus with exactly two lines and nothing connected to it (no load, no generator, not the
source) only passes current on: with no shunt admittance (the feeder tables carry none), the
current is the same in every line of a chain of such buses, so the chain is exactly one branch
whose impedance is the sum of its lines' (``z = sum(r + jx)``). The AC power flow is solved on
the *kept* buses (the source, buses with loads or generators, junctions and ends), and every
other bus and line is recovered exactly from the chain's current ``i`` (kVA per p.u. of
voltage, ``i = conj(S_top / v_top)``, ``S_top`` the power entering the chain at its top)::

    v_b = v_top - z_pu(top -> b) i          (Ohm's law along the chain)
    S_from = v_near conj(i),  S_to = -v_far conj(i)   (each line's end powers, kVA)
    |I| = |i| / (sqrt(3) vn_kv)  (A)

with ``z_pu = z_ohm / Z_base``, ``Z_base = vn_kv^2 * 1000`` ohm (p.u. on 1 kVA). On ieee-elv
this keeps 205 of 906 buses. Nothing is approximated: the results are those of the full
network to the power flow's tolerance (tests/ac compare both against pandapower and each
other).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from popdispatch.feeder.model import Feeder


@dataclass(frozen=True)
class Chains:
    """The kept buses, the branches between them and how each bus and line maps onto them.

    Positions are rows of ``feeder.buses`` / ``feeder.lines``.

    Attributes
    ----------
    kept : per bus, whether it is a node of the reduced network.
    node : per bus, its node index in the reduced network (-1 where not kept).
    branch_top, branch_bottom : per reduced branch, its upstream and downstream kept bus.
    branch_z_ohm : per reduced branch, its series impedance (complex ohm).
    bus_branch : per bus, the reduced branch it lies inside (-1 for kept buses).
    bus_z_ohm : per bus, the impedance from its branch's top to it (complex ohm; 0 if kept).
    line_branch : per line, its reduced branch.
    line_near, line_far : per line, its upstream and downstream bus.
    line_forward : per line, whether its ``from_bus`` is the upstream end.
    """

    kept: np.ndarray
    node: np.ndarray
    branch_top: np.ndarray
    branch_bottom: np.ndarray
    branch_z_ohm: np.ndarray
    bus_branch: np.ndarray
    bus_z_ohm: np.ndarray
    line_branch: np.ndarray
    line_near: np.ndarray
    line_far: np.ndarray
    line_forward: np.ndarray

    @property
    def n_branches(self) -> int:
        return len(self.branch_top)


def find_chains(feeder: Feeder, vn_kv: float | None = None) -> Chains:
    """The series chains of ``feeder`` (see the module docstring); impedances referred to the
    voltage base ``vn_kv`` (kV; default the source's, :meth:`Feeder.lines_on_base`)."""
    tree = feeder.bus_tree()
    buses, lines = feeder.buses.index, feeder.lines
    n = len(buses)
    ends = np.r_[buses.get_indexer(lines.from_bus), buses.get_indexer(lines.to_bus)]
    degree = np.bincount(ends, minlength=n)
    kept = degree != 2
    kept[buses.get_indexer(feeder.loads["bus"])] = True
    kept[buses.get_indexer(feeder.generators["bus"])] = True
    kept[tree.root] = True
    on_base = feeder.lines_on_base(vn_kv)
    z_line = on_base["r_ohm"].to_numpy(float) + 1j * on_base["x_ohm"].to_numpy(float)
    depth_z, top, bottom = _walk(tree, kept, z_line)
    node = np.full(n, -1, dtype=np.int64)
    node[kept] = np.arange(kept.sum())
    bottoms = np.flatnonzero(kept & (np.arange(n) != tree.root))
    branch_of_bottom = np.full(n, -1, dtype=np.int64)
    branch_of_bottom[bottoms] = np.arange(len(bottoms))
    bus_branch = np.where(kept, -1, branch_of_bottom[bottom])
    line_branch = branch_of_bottom[bottom[tree.line_child]]
    from_pos = buses.get_indexer(lines.from_bus)
    return Chains(
        kept=kept,
        node=node,
        branch_top=top[bottoms],
        branch_bottom=bottoms,
        branch_z_ohm=depth_z[bottoms] - depth_z[top[bottoms]],
        bus_branch=bus_branch,
        bus_z_ohm=np.where(kept, 0.0, depth_z - depth_z[top]),
        line_branch=line_branch,
        line_near=tree.line_parent,
        line_far=tree.line_child,
        line_forward=from_pos == tree.line_parent,
    )


def _walk(tree, kept: np.ndarray, z_line: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per bus: impedance from the source (complex ohm), the kept bus at the top of its chain
    (a kept bus: the kept bus above it) and the kept bus at the bottom of its chain (itself if
    kept). One pass down the pre-order and one up."""
    n = tree.n_nodes
    depth_z = np.zeros(n, dtype=complex)
    top = np.full(n, tree.root, dtype=np.int64)
    order = tree.preorder.tolist()
    parent, parent_line = tree.parent.tolist(), tree.parent_line.tolist()
    kept_list = kept.tolist()
    z = z_line.tolist()
    depth = [0j] * n
    top_list = top.tolist()
    child = [-1] * n
    for c in order[1:]:
        p = parent[c]
        depth[c] = depth[p] + z[parent_line[c]]
        top_list[c] = p if kept_list[p] else top_list[p]
        child[p] = c  # the only child, where it matters (a bus that is not kept)
    bottom = list(range(n))
    for b in reversed(order):
        if not kept_list[b]:
            bottom[b] = bottom[child[b]]
    depth_z[:] = depth
    return depth_z, np.array(top_list, dtype=np.int64), np.array(bottom, dtype=np.int64)
