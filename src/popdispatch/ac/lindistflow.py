"""LinDistFlow voltage sensitivities of a radial feeder (the building block of issue 14 part 2).

LinDistFlow (Baran and Wu's DistFlow with the losses dropped) writes, along each line ``k``
from its upstream bus to its downstream bus, in p.u.::

    v_down^2 = v_up^2 - 2 (r_k P_k + x_k Q_k)

with ``P_k``, ``Q_k`` the power flowing down the line. An injection at bus ``i`` lowers the
flow of every line on the path source -> ``i`` by the same amount, so the squared voltage of a
bus ``j`` moves with the active power ``p_i`` injected at ``i`` by twice the resistance of the
path the two buses share from the source::

    d(v_j^2) / d(p_i) = 2 R_ij,   R_ij = sum of r_k over the lines on both paths

(and with reactive power by ``2 X_ij``). In people's units, with ``p`` in kW and ``R`` in ohm,
``R_ij`` in p.u. is ``R_ij / Z_base`` with ``Z_base = vn_kv^2 * 1000`` ohm (1 kVA base), so
``d(v_j^2)/d(p_i)`` is in p.u.^2 per kW. The linearisation is exact at zero flow and 1 p.u.;
at a loaded state the AC sensitivity differs by the order of the voltage drop (tests/ac
measure it against finite differences of the AC power flow).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from popdispatch.ac.network import nominal_kv
from popdispatch.errors import FeederError
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.tree import downstream


def shared_path_ohm(
    feeder: Feeder, buses_i: Sequence[int], buses_j: Sequence[int], column: str = "r_ohm"
) -> np.ndarray:
    """``(len(buses_i), len(buses_j))``: the sum of ``column`` (``r_ohm`` or ``x_ohm``, ohm) over
    the lines on both the path source -> ``i`` and the path source -> ``j``."""
    tree = feeder.bus_tree()
    down_i = downstream(tree, _positions(feeder, buses_i))  # (lines, i): line above bus i?
    down_j = downstream(tree, _positions(feeder, buses_j))
    values = feeder.lines[column].to_numpy(float)
    return (down_i.T * values) @ down_j.astype(float)


def voltage_sensitivity(
    feeder: Feeder,
    injection_buses: Sequence[int],
    observed_buses: Sequence[int] | None = None,
    *,
    vn_kv: float | None = None,
    reactive: bool = False,
) -> pd.DataFrame:
    """LinDistFlow ``d(v_j^2) / d(p_i)``, p.u.^2 per kW (``reactive``: per kvar of ``q_i``).

    Rows: the observed buses ``j`` (default every bus); columns: the injection buses ``i``.
    ``vn_kv``: nominal voltage, kV (default from the network, see
    :func:`popdispatch.ac.network.nominal_kv`).
    """
    observed = list(feeder.buses.index if observed_buses is None else observed_buses)
    z_base_ohm = nominal_kv(feeder, vn_kv) ** 2 * 1e3
    column = "x_ohm" if reactive else "r_ohm"
    shared = shared_path_ohm(feeder, observed, injection_buses, column)
    return pd.DataFrame(
        2.0 * shared / z_base_ohm,
        index=pd.Index(observed, name="bus"),
        columns=pd.Index(list(injection_buses), name="injection_bus"),
    )


def _positions(feeder: Feeder, buses: Sequence[int]) -> np.ndarray:
    """Rows of ``feeder.buses`` of the given bus ids; :class:`FeederError` naming an unknown one."""
    positions = feeder.buses.index.get_indexer(list(buses))
    if (positions < 0).any():
        bad = list(buses)[int(np.flatnonzero(positions < 0)[0])]
        raise FeederError(f"unknown bus {bad} of feeder {feeder.name!r} in a sensitivity query")
    return positions
