"""``report.md`` of a reproduction: the paper's reported figures, ours and the DC-OPF's.

Built from the ``summary.json`` object only, so the table and the JSON can never disagree.
"""

from __future__ import annotations

PAPER = {
    "minute_566": "Smith dynamics converge to the DC-OPF",
    "congestion": "detected at iteration 53, converged at iteration 201; G739 penalised, G1 up",
    "extinction": "replicator dynamics never use a generator that starts at zero; Smith do",
    "base_day": "Smith set points converge to the DC-OPF solution (fig. 4)",
}

PAPER_MODE_NOTE = """ In paper mode the base day does not land on the DC-OPF at
most minutes: with the paper's discontinuous barrier (eq. 7), generators sliding on their limits
create rest points of the dynamics away from the economic dispatch (see `docs/paper-mode.md`)."""

FIGURES = {
    "fig1_fitness": "Fitness of a generator node (paper fig. 1)",
    "fig2_congestion_detection": "Congestion detection on the 505-666 path (paper fig. 2)",
    "fig3_feeder_flows_566": "Reduced feeder, line flows at minute 566 (paper fig. 3)",
    "fig4_base_day": "Generator output over the base day (paper fig. 4)",
    "fig5_congestion_iterations": "Congestion scenario per iteration (paper fig. 5)",
    "fig6_extinction": "Extinction: replicator against Smith (section II-C)",
}


def _gens(snapshot: dict, key: str, names=None) -> str:
    rows = [g for g in snapshot["generators"] if names is None or g["name"] in names]
    return ", ".join(
        f"{g['name']} {g[key]:.3f}" if g[key] is not None else f"{g['name']} -" for g in rows
    )


def _iteration(value) -> str:
    return "never" if value is None else f"iteration {value}"


def _kw(value) -> str:
    return "-" if value is None else f"{value:.3f} kW"


def minute_566_row(s: dict) -> list[str]:
    ours = (
        f"{s['status']} ({_iteration(s['converged_iteration'])}); max |error| "
        f"{_kw(s['max_abs_error_kw'])}; {_gens(s, 'setpoint_kw')} kW"
    )
    return ["minute 566, no limits", PAPER["minute_566"], ours, f"{_gens(s, 'opf_kw')} kW"]


def congestion_row(s: dict) -> list[str]:
    pair = ("G739", "G1")
    ours = (
        f"detected at {_iteration(s['first_congestion_iteration'])}, converged at "
        f"{_iteration(s['converged_iteration'])}; {_gens(s, 'setpoint_kw', pair)} kW; "
        f"residual overflow {_kw(s['max_overflow_kw'])}"
    )
    opf = f"{_gens(s, 'opf_kw', pair)} kW, no overflow"
    return ["congestion: 505-666 at 28 kW, minute 566", PAPER["congestion"], ours, opf]


def extinction_row(s: dict) -> list[str]:
    name = s["generator"]
    rep, smith = s["replicator"], s["smith"]

    def of(snapshot: dict, key: str) -> float:
        return next(g[key] for g in snapshot["generators"] if g["name"] == name)

    ours = (
        f"replicator keeps {name} at {of(rep, 'setpoint_kw'):.3f} kW (max |error| "
        f"{_kw(rep['max_abs_error_kw'])}); Smith brings it to {of(smith, 'setpoint_kw'):.3f} kW "
        f"(max |error| {_kw(smith['max_abs_error_kw'])})"
    )
    return [
        f"extinction: {name} starts at zero",
        PAPER["extinction"],
        ours,
        f"{name} {of(rep, 'opf_kw'):.3f} kW",
    ]


def base_day_row(s: dict) -> list[str]:
    excess = 100.0 * (s["cost"] / s["opf_cost"] - 1.0) if s["opf_cost"] else float("nan")
    ours = (
        f"{s['minutes_within_0_1_kw']} of {s['minutes']} minutes within 0.1 kW; median max "
        f"|error| {_kw(s['median_max_abs_error_kw'])}, max {_kw(s['max_abs_error_kw'])}; "
        f"{s['converged_minutes']} minutes converged; cost {s['cost']:.4f} EUR "
        f"({excess:+.1f} % over the DC-OPF)"
    )
    span = f"minutes {s['first_minute']}-{s['last_minute']}"
    return [
        f"base day ({span}), no limits",
        PAPER["base_day"],
        ours,
        f"cost {s['opf_cost']:.4f} EUR",
    ]


def _table(rows: list[list[str]]) -> str:
    lines = ["| experiment | paper | popdispatch | DC-OPF |", "| --- | --- | --- | --- |"]
    lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def reproduction_report(summary: dict, stems: list[str]) -> str:
    """The Markdown report of a reproduction (``summary``: the ``summary.json`` object)."""
    rows = [
        minute_566_row(summary["minute_566"]),
        congestion_row(summary["congestion"]),
        extinction_row(summary["extinction"]),
        base_day_row(summary["base_day"]),
    ]
    figure_list = "\n".join(
        f"- {FIGURES.get(stem, stem)}: `figures/{stem}.png` (and `.pdf`)" for stem in stems
    )
    return f"""# popdispatch reproduction

Dispatch mode `{summary["mode"]}`, `{summary["dynamics"]}` dynamics (replicator and Smith in
the extinction row). Powers in kW; a day's cost in EUR is the sum of the per-minute cost (EUR/h,
Table I's coefficients on MW) divided by 60. "Error" is |set point - DC-OPF| over generators.

- Minute 566: official loads from pandapower's `on_peak_566` snapshot.
- Base day loads: {summary["profile_source"]}.

{_table(rows)}

These are the numbers this run produced.{PAPER_MODE_NOTE if summary["mode"] == "paper" else ""}

## Figures

{figure_list}

Time series: `base_day.csv` (per minute), `congestion.csv` and `extinction.csv` (per iteration
of 0.01 s); all numbers: `summary.json`.
"""
