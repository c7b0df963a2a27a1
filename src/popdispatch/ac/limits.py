"""Whether AC voltages keep the voltage limits a run was asked for, and by how much they miss.

The voltage mode keeps the limits in the LinDistFlow model (docs/voltage.md); the AC power
flow of its dispatch says what the voltages really are. Wherever a run with ``--vmin`` or
``--vmax`` meets an AC power flow (``--ac``, ``--ac-correct``), its output carries the
verdict of this module: per step the AC voltage's miss below ``vmin`` and above ``vmax``
(p.u., 0 where kept), and over the steps the worst miss with its bus and step, how many steps
miss, and whether the limits are kept within :data:`KEEP_TOL_PU`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: AC voltages within this of a limit keep it, p.u.: the AC correction's stopping tolerance
#: (:data:`popdispatch.ac.correct.TOL_PU`), the accuracy its dispatch promises.
KEEP_TOL_PU = 1e-5


def has_bounds(vmin_pu: float, vmax_pu: float) -> bool:
    """Whether a problem's limits (``vmin_pu`` 0 / ``vmax_pu`` 2 or NaN: no bound) bound
    anything."""
    return bool(vmin_pu > 0.0 or vmax_pu < 2.0)


def miss_columns(steps: pd.DataFrame, vmin_pu: float, vmax_pu: float) -> pd.DataFrame:
    """Per step (``steps``' index; its ``v_min_pu``, ``v_max_pu``: the AC extremes, p.u.):
    ``below_vmin_pu`` = ``max(vmin - v_min, 0)`` and ``above_vmax_pu`` = ``max(v_max - vmax,
    0)`` (p.u.), each only where that bound is set."""
    out = pd.DataFrame(index=steps.index)
    if vmin_pu > 0.0:
        out["below_vmin_pu"] = np.maximum(vmin_pu - steps["v_min_pu"].to_numpy(float), 0.0)
    if vmax_pu < 2.0:
        out["above_vmax_pu"] = np.maximum(steps["v_max_pu"].to_numpy(float) - vmax_pu, 0.0)
    return out


def limits_summary(
    steps: pd.DataFrame, vmin_pu: float, vmax_pu: float, tolerance_pu: float = KEEP_TOL_PU
) -> dict:
    """The ``voltage_limits`` JSON object of an AC check (``steps``: index ``minute``, columns
    ``v_min_pu``, ``v_min_bus``, ``v_max_pu``, ``v_max_bus`` as :data:`popdispatch.ac.
    STEP_COLUMNS`): the limits (``null``: no bound), ``tolerance_pu``, ``kept`` (every step's
    AC voltages within the limits up to the tolerance), the worst ``below_vmin_pu`` and
    ``above_vmax_pu`` (p.u., 0 where kept; ``null`` without that bound) with their ``_bus``
    and ``_minute``, ``steps`` and ``steps_outside`` (steps missing a limit by more than the
    tolerance)."""
    misses = miss_columns(steps, vmin_pu, vmax_pu)
    out: dict = {
        "vmin_pu": float(vmin_pu) if vmin_pu > 0.0 else None,
        "vmax_pu": float(vmax_pu) if vmax_pu < 2.0 else None,
        "tolerance_pu": float(tolerance_pu),
    }
    for column, where in (("below_vmin_pu", "v_min_bus"), ("above_vmax_pu", "v_max_bus")):
        stem = column.removesuffix("_pu")
        if column not in misses:
            out.update({column: None, f"{stem}_bus": None, f"{stem}_minute": None})
            continue
        at = misses[column].idxmax()
        out[column] = float(misses.at[at, column])
        out[f"{stem}_bus"] = _plain(steps.at[at, where]) if out[column] > 0.0 else None
        out[f"{stem}_minute"] = int(at) if out[column] > 0.0 else None
    worst = misses.max(axis=1) if len(misses.columns) else pd.Series(0.0, steps.index)
    out["steps"] = len(steps)
    out["steps_outside"] = int((worst > tolerance_pu).sum())
    out["kept"] = out["steps_outside"] == 0
    return out


def _plain(value):
    """A bus id as JSON (numpy integers as int)."""
    return value.item() if isinstance(value, np.generic) else value
