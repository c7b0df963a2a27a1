"""Human-readable text of the CLI's summaries (the ``--json`` objects rendered for people)."""

from __future__ import annotations

from collections.abc import Sequence


def _fmt(value, unit: str = "", digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def generator_lines(rows: list[dict], columns: Sequence[str]) -> str:
    """A table of generators (name, bus) with the given kW columns; ``-`` where unknown."""
    header = f"{'generator':<10}{'bus':>6}" + "".join(f"{c:>14}" for c in columns)
    body = [
        f"{r['name']:<10}{r['bus']:>6}"
        + "".join(f"{r[c]:>14.3f}" if r[c] is not None else f"{'-':>14}" for c in columns)
        for r in rows
    ]
    return "\n".join([header, *body])


def feeder_text(summary: dict) -> str:
    """``popdispatch feeder``."""
    gens = ", ".join(
        f"{g['name']} (bus {g['bus']}, {g['pmax_kw']:g} kW)" for g in summary["generators"]
    )
    return (
        f"feeder {summary['case']}: {summary['buses']} buses, {summary['original_lines']} lines, "
        f"source bus {summary['source_bus']}\nreduced to {summary['nodes']} key nodes and "
        f"{summary['lines']} lines\n{summary['loads']} loads\ngenerators: {gens}\n"
        f"total capacity: {summary['capacity_kw']:g} kW"
    )


def opf_text(summary: dict) -> str:
    """``popdispatch opf``."""
    return (
        f"DC-OPF, minute {summary['minute']}: {summary['status']}; "
        f"demand {summary['demand_kw']:.3f} kW; "
        f"cost {_fmt(summary['cost'], ' EUR/h', 6)}\nprofiles: {summary['profile_source']}\n"
        + generator_lines(summary["generators"], ["p_kw"])
    )


def snapshot_text(s: dict) -> str:
    """``popdispatch snapshot``."""
    return (
        f"minute {s['minute']}, demand {s['demand_kw']:.3f} kW: {s['dynamics']} dynamics, "
        f"{s['mode']} mode, x0 {s['x0']}\nprofiles: {s['profile_source']}\n"
        f"status: {s['status']} (converged at iteration {_fmt(s['converged_iteration'], '', 0)}"
        f" of {s['iterations']}; first congestion at iteration "
        f"{_fmt(s['first_congestion_iteration'], '', 0)}; engine {s['wall_seconds']:.3f} s, "
        f"whole command {s['command_seconds']:.1f} s)\n"
        + generator_lines(s["generators"], ["setpoint_kw", "opf_kw"])
        + f"\nmax |set point - DC-OPF| = {_fmt(s['max_abs_error_kw'], ' kW')}; "
        f"max overflow = {s['max_overflow_kw']:.3f} kW"
    )


def day_text(s: dict) -> str:
    """``popdispatch day``."""
    energy = ", ".join(
        f"bus {b}: {e:.2f} (DC-OPF {s['opf_energy_kwh'][b]:.2f})"
        for b, e in s["energy_kwh"].items()
    )
    return (
        f"online day, minutes {s['first_minute']}-{s['last_minute']}: {s['dynamics']} dynamics, "
        f"{s['mode']} mode\nprofiles: {s['profile_source']}\nstatus: {s['status']} "
        f"({s['converged_minutes']} of {s['minutes']} minutes converged; engine "
        f"{s['wall_seconds']:.3f} s, whole command {s['command_seconds']:.1f} s)\n"
        f"{s['minutes_within_0_1_kw']} minutes within 0.1 kW of the "
        f"DC-OPF; max |error| {_fmt(s['max_abs_error_kw'], ' kW')}, mean "
        f"{_fmt(s['mean_abs_error_kw'], ' kW')}\ncost {s['cost']:.5f} EUR (DC-OPF "
        f"{s['opf_cost']:.5f} EUR); max overflow {s['max_overflow_kw']:.3f} kW\n"
        f"energy, kWh: {energy}"
    )
