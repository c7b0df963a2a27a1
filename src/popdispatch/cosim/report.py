"""A co-simulation beside the DC online day of the same minutes (:func:`cosim_summary`), and
its per-minute table (:func:`cosim_table`).

The difference losses make: where no limited line binds, the dispatcher's set points are the
DC day's (the offsets shift only the limited lines' flows, and a line that does not bind
prices nothing). Where a line binds, its controller holds the *measured AC* flow at the limit:
the generation below the line moves by the line's offset (the AC flow the DC model misses,
losses between the generators and the line), and the generators above it take the opposite
step (the demand is the same). ``vs_dc_day`` reports both: the largest set-point difference
and, per binding minute, the offset of the binding line.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from popdispatch.cosim.scenario import CosimResult

#: A limited line binds at a minute when its measured AC flow is within this of the limit (kW).
BINDING_KW = 0.01


def cosim_summary(result: CosimResult, day_setpoints_kw: np.ndarray, accuracy_kw: float) -> dict:
    """The JSON summary (units in the keys): status, minutes, per limited line the AC flow
    against its limit, the same-time rounds, the losses and the set points against the DC
    day's (``day_setpoints_kw``: (minutes, generators), kW, same order); ``accuracy_kw``:
    the run's certificate accuracy, the tolerance of "equal"."""
    s = result.steps
    diff = np.abs(result.setpoints_kw - np.asarray(day_setpoints_kw, dtype=float))
    lines, binding = [], np.zeros(len(s), dtype=bool)
    for name, limit in result.limits_kw.items():
        flow = s[f"{name}_ac_flow_kw"].to_numpy(float)
        at_limit = np.abs(np.abs(flow) - limit) <= BINDING_KW
        binding |= at_limit
        lines.append({
            "line": name, "limit_kw": limit,
            "max_abs_ac_flow_kw": float(np.abs(flow).max()),
            "max_overflow_kw": float(np.maximum(np.abs(flow) - limit, 0.0).max()),
            "binding_minutes": [int(m) for m in s.index[at_limit]],
            "max_abs_offset_kw": float(s[f"{name}_offset_kw"].abs().max()),
        })  # fmt: skip
    free = ~binding
    return {
        "status": _status(s["status"]),
        "minutes": len(s),
        "first_minute": int(s.index[0]),
        "last_minute": int(s.index[-1]),
        "engine": "online, exact mode (certified against the DC-OPF of the offset-corrected "
        "problem)",
        "plant": "pandapower AC power flow (Newton-Raphson), full feeder",
        "converged_minutes": int((s["status"] == "converged").sum()),
        "stalled_minutes": [int(m) for m in s.index[s["status"] != "converged"]],
        "rounds": int(s["rounds"].sum()),
        "rounds_per_minute_max": int(s["rounds"].max()),
        "iterations": int(s["iterations"].sum()),
        "limited_lines": lines,
        "losses_kwh": float(s["losses_kw"].sum() / 60.0),
        "source_kwh": float(s["source_kw"].sum() / 60.0),
        "v_min_pu": float(s["v_min_pu"].min()),
        "v_max_pu": float(s["v_max_pu"].max()),
        "vs_dc_day": {
            "max_abs_diff_kw": float(diff.max()),
            "max_abs_diff_kw_free_minutes": float(diff[free].max()) if free.any() else None,
            "accuracy_kw": accuracy_kw,
            "free_minutes_equal": bool(not free.any() or diff[free].max() <= 2 * accuracy_kw),
            "binding_minutes": {
                str(m): float(diff[i].max()) for i, m in enumerate(s.index) if binding[i]
            },
        },  # fmt: skip
        "result_csv": result.csv.name,
    }


def cosim_table(result: CosimResult) -> pd.DataFrame:
    """Per minute: ``minute``, the set points (``<generator>_setpoint_kw``) and the steps."""
    points = pd.DataFrame(result.setpoints_kw, index=result.steps.index,
                          columns=[f"{g}_setpoint_kw" for g in result.generators])  # fmt: skip
    return pd.concat([points, result.steps], axis=1).reset_index()


def _status(status: pd.Series) -> str:
    if (status == "infeasible").any():
        return "infeasible"
    if (status == "converged").all():
        return "converged"
    return "stalled" if (status == "stalled").any() else "not_converged"


def cosim_text(summary: dict) -> str:
    """What a person reads."""
    lines = [
        f"co-simulation (mosaik, AC plant) minutes {summary['first_minute']}-"
        f"{summary['last_minute']}: {summary['status']} "
        f"({summary['converged_minutes']}/{summary['minutes']} certified), "
        f"{summary['rounds']} dispatch runs (at most {summary['rounds_per_minute_max']} a minute)",
    ]
    for line in summary["limited_lines"]:
        lines.append(
            f"  line {line['line']}: limit {line['limit_kw']:g} kW, largest AC flow "
            f"{line['max_abs_ac_flow_kw']:.4f} kW, overflow {line['max_overflow_kw']:.2g} kW, "
            f"binding at {len(line['binding_minutes'])} minutes, offset up to "
            f"{line['max_abs_offset_kw']:.4f} kW"
        )
    vs = summary["vs_dc_day"]
    free = vs["max_abs_diff_kw_free_minutes"]
    lines.append(
        f"  vs the DC day: set points differ by at most {vs['max_abs_diff_kw']:.4f} kW "
        f"(minutes without a binding line: {'-' if free is None else f'{free:.2g}'} kW)"
    )
    lines.append(
        f"  losses {summary['losses_kwh']:.4f} kWh, voltages {summary['v_min_pu']:.4f}-"
        f"{summary['v_max_pu']:.4f} p.u.; mosaik's record: {summary['result_csv']}"
    )
    return "\n".join(lines) + "\n"
