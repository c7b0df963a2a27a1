"""Human-readable text of the CLI's summaries (the ``--json`` objects rendered for people).

Every text says which limits and events were applied, prints what is known and says what is
not: no table of ``nan`` where the DC-OPF is infeasible, the minutes it is infeasible named,
comparisons over the minutes where both sides exist, and set points outside their limits
marked with ``*`` and explained.
"""

from __future__ import annotations

from collections.abc import Sequence

OUTSIDE_MARK = "*"


def _fmt(value, unit: str = "", digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def minute_ranges(minutes: Sequence[int]) -> str:
    """Sorted 1-based minutes as compact ranges: ``[566, 600, 601, 602]`` -> ``566, 600-602``."""
    parts: list[str] = []
    ordered = sorted(minutes)
    start = None
    for k, minute in enumerate(ordered):
        start = minute if start is None else start
        if k + 1 == len(ordered) or ordered[k + 1] != minute + 1:
            parts.append(str(minute) if start == minute else f"{start}-{minute}")
            start = None
    return ", ".join(parts)


def limits_text(limits: Sequence[dict], in_force: Sequence[dict] = (), shown: int = 6) -> str:
    """``limits: 505:666=28 kW (3 lines)`` for the ``--limit`` options applied, then the
    network's own ratings in force (``in_force``: the ``limits_in_force`` rows; ``shown`` of
    them named: those the DC-OPF holds at their limit first, then the tightest), or
    ``none``."""
    options = []
    for row in limits:
        count = row.get("lines_on_path")
        lines = "" if count is None else f" ({count} line{'s' if count != 1 else ''})"
        options.append(f"{row['from_bus']}:{row['to_bus']}={row['limit_kw']:g} kW{lines}")
    parts = [", ".join(options)] if options else []
    ratings = sorted((r for r in in_force if r["source"] == "rating"),
                     key=lambda r: (-(r.get("binding_minutes") or 0), r["limit_kw"]))  # fmt: skip
    if ratings:
        named = ", ".join(
            f"{r['from_bus']}-{r['to_bus']} {r['limit_kw']:.6g} kW ({r['element']})"
            + _binding(r.get("binding_minutes"))
            for r in ratings[:shown]
        )
        more = (f" and {len(ratings) - shown} more (--json: limits_in_force)"
                if len(ratings) > shown else "")  # fmt: skip
        count = f"{len(ratings)} line{'s' if len(ratings) != 1 else ''}"
        parts.append(f"the network's ratings on {count}: {named}{more}")
    return "limits: " + ("; ".join(parts) if parts else "none")


def _binding(minutes: int | None) -> str:
    if not minutes:
        return ""
    return " binding" if minutes == 1 else f" binding at {minutes} minutes"


def events_text(events: Sequence[str]) -> str:
    """``events: 739:off@600, 739:on@720`` for the ``--event`` options applied, or ``none``."""
    return "events: " + (", ".join(events) if events else "none")


def generator_lines(rows: list[dict], columns: Sequence[str], mark: str = "outside_limits") -> str:
    """A table of generators (name, bus) with the given kW columns; ``-`` where unknown and
    :data:`OUTSIDE_MARK` after a row whose ``mark`` flag is set."""
    header = f"{'generator':<10}{'bus':>6}" + "".join(f"{c:>14}" for c in columns)
    body = [
        f"{r['name']:<10}{r['bus']:>6}"
        + "".join(f"{r[c]:>14.3f}" if r[c] is not None else f"{'-':>14}" for c in columns)
        + (f" {OUTSIDE_MARK}" if r.get(mark) else "")
        for r in rows
    ]
    return "\n".join([header, *body])


def _why_outside(mode: str | None) -> str:
    if mode == "paper":
        return "the paper's barrier penalises leaving the limits but does not forbid it"
    return "not a dispatch the generators can follow"


def outside_note(rows: list[dict], mode: str | None = None) -> str | None:
    """The note under a table whose rows carry ``outside_limits`` flags (None if none is)."""
    outside = [r for r in rows if r.get("outside_limits")]
    if not outside:
        return None
    which = ", ".join(
        f"{r['name']} {r['setpoint_kw']:.3f} kW (limits {r['pmin_kw']:g}-{r['pmax_kw']:g} kW)"
        for r in outside
    )
    return f"{OUTSIDE_MARK} set point outside its limits: {which}; {_why_outside(mode)}"


def _inputs(s: dict) -> str:
    """Feeder, profiles, fixed injections (where there are any) and limits lines shared by
    every minute and day text."""
    case = s.get("case")
    fixed = ""
    if s.get("fixed_injection_kw"):
        fixed = f"fixed injections (not dispatched): {s['fixed_injection_kw']:.3f} kW\n"
    elif s.get("fixed_injection_kwh"):
        fixed = (f"fixed injections (not dispatched): {s['fixed_injection_kwh']:.3f} kWh "
                 "(per step: fixed_injection_kw in day.csv)\n")  # fmt: skip
    return (f"feeder: {case}\n" if case else "") + (
        f"profiles: {s['profile_source']}\n{fixed}"
        f"{limits_text(s.get('limits', []), s.get('limits_in_force') or [])}"
    )


def _when(s: dict) -> str:
    """`` (time 09:25:00)`` for a summary that carries its step's time, else nothing."""
    return f" (time {s['time']})" if s.get("time") else ""


def opf_text(summary: dict) -> str:
    """``popdispatch opf``."""
    s = summary
    head = f"DC-OPF, minute {s['minute']}{_when(s)}: "
    demand = f"demand {s['demand_kw']:.3f} kW"
    if s.get("capacity_kw") is not None:
        demand += f", online capacity {s['capacity_kw']:.3f} kW"
    if s["status"] != "optimal":
        return f"{head}{_no_dispatch(s)}\n{demand}\n{_inputs(s)}"
    price = s.get("marginal_price_eur_per_mwh")
    return (
        f"{head}{s['status']}; {demand}; cost {_fmt(s['cost'], ' EUR/h', 6)}"
        + (f"; marginal price {price:.3f} EUR/MWh" if price is not None else "")
        + f"\n{_inputs(s)}\n"
        + generator_lines(s["generators"], ["p_kw"])
    )


def _run_line(s: dict) -> str:
    """What the dynamics did: converged when, stopped why, and the times."""
    total, done = s["iterations"], s["converged_iteration"]
    if done is not None:
        run = f"converged at iteration {done} of {total}{_proved(s)}"
    elif s.get("dynamics_status") == "stalled":
        run = (
            f"at rest from iteration {_fmt(s.get('rest_iteration'), '', 0)} of {total}, "
            f"away from the DC-OPF: {s.get('stall_reason')}"
        )
    elif s.get("dynamics_status") == "infeasible":
        run = f"stopped at iteration {total}: {_priced(s)} prices ran away (no feasible rest point)"
    else:
        run = f"not converged within {total} iterations{_proved(s)}"
    return (
        f"{run}{_first_signal(s)}; engine {s['wall_seconds']:.3f} s, "
        f"whole command {s['command_seconds']:.1f} s"
    )


def _proved(s: dict) -> str:
    """The distance certificate's bound against the accuracy, where the mode has one."""
    bound, accuracy = s.get("distance_bound_kw", "missing"), s.get("accuracy_kw")
    if accuracy is None:
        return ""
    shown = "unbounded" if bound is None else f"within {bound:.3g} kW"
    return f" (proved {shown} of the DC-OPF; accuracy {accuracy:.3g} kW)"


def _priced(s: dict) -> str:
    """What carries prices in a run: ``line``, ``voltage`` or ``line and voltage``."""
    lines = bool(s.get("limits_in_force") or s.get("limits"))
    if s.get("mode") != "voltage":
        return "line"
    return "line and voltage" if lines else "voltage"


def _first_signal(s: dict) -> str:
    """``; first congestion at iteration K`` (``; no congestion``) where lines are limited; in
    voltage mode the first price of a voltage limit (or a line); nothing without limits."""
    first = s["first_congestion_iteration"]
    if s.get("mode") == "voltage":
        what = f"first {_priced(s)} price"
        return f"; no {_priced(s)} price" if first is None else f"; {what} at iteration {first}"
    if not (s.get("limits_in_force") or s.get("limits")):
        return ""
    return "; no congestion" if first is None else f"; first congestion at iteration {first}"


def _no_dispatch(s: dict) -> str:
    """``infeasible: <why>`` (:func:`popdispatch.report.infeasibility.cause_text`)."""
    from popdispatch.report.infeasibility import cause_text, ratings_hint

    why = s.get("infeasibility")
    return f"infeasible: {cause_text(why)}{ratings_hint(why)}"


def ac_text(ac: dict | None) -> str:
    """The AC check's line (``--ac``): losses, voltage extremes, loading, source's extra supply;
    empty without one. ``ac``: a snapshot's (``losses_kw``) or a day's (``losses_kwh``)."""
    if not ac:
        return ""
    if "losses_kwh" in ac:
        losses = f"losses {ac['losses_kwh']:.3f} kWh (at most {ac['max_losses_kw']:.3f} kW)"
    else:
        losses = f"losses {ac['losses_kw']:.3f} kW"
    loading = ac.get("max_loading_percent")
    rated = "no rated line" if loading is None else (
        f"max loading {loading:.1f} % ({ac['max_loading_line']})")  # fmt: skip
    return (
        f"\nAC check: {losses}; voltage {ac['v_min_pu']:.4f} p.u. (bus {ac['v_min_bus']}) to "
        f"{ac['v_max_pu']:.4f} p.u. (bus {ac['v_max_bus']}); {rated}"
    )


def voltage_text(v: dict | None) -> str:
    """The voltage limits' line (``--vmin``/``--vmax``): the run's LinDistFlow extremes, the
    binding buses with their prices, the linearization error with ``--ac``; empty without."""
    if not v:
        return ""
    limits = " to ".join(f"{v[k]:g}" if v[k] is not None else "-" for k in ("vmin_pu", "vmax_pu"))
    binding = ", ".join(
        f"bus {b['bus']} at {b['bound']} ({b['price_eur_per_mwh']:.4g} EUR/MWh)"
        for b in v["binding"]
    )
    text = (
        f"\nVoltage limits {limits} p.u. (LinDistFlow, {v['monitored_buses']} key nodes): "
        f"{v['v_min_pu']:.4f} p.u. (bus {v['v_min_bus']}) to {v['v_max_pu']:.4f} p.u. "
        f"(bus {v['v_max_bus']}); binding: {binding or 'none'}"
    )
    if "linearization_error_pu" in v:
        text += (
            f"\nAC minimum {v['ac_v_min_pu']:.4f} p.u.: linearization error "
            f"{v['linearization_error_pu']:.4f} p.u."
        )
    return text


def ac_correct_text(c: dict | None) -> str:
    """The ``--ac-correct`` lines: rounds, AC minimum voltage, cost, whether the AC voltages
    keep the limits; a day's: its status and the loop's cost per step; empty without."""
    if not c:
        return ""
    if "steps" in c:
        return _ac_correct_day_text(c)
    points = ", ".join(f"{g} {kw:.3f}" for g, kw in c["setpoints_kw"].items())
    return (
        f"\nAC-corrected ({c['rounds']} rounds, {c['status']}): {points} kW; AC voltage "
        f"{c['ac_v_min_pu']:.6f} p.u. (bus {c['ac_v_min_bus']}) and up; losses "
        f"{c['losses_kw']:.3f} kW; cost {c['cost_eur_per_h']:.6f} EUR/h with the losses"
    ) + voltage_limits_text(c.get("voltage_limits"), "AC-corrected: AC voltages")


def _ac_correct_day_text(c: dict) -> str:
    return (
        f"\nAC-corrected ({c['status']}): {c['converged_steps']} of {c['steps']} steps "
        f"converged, {c['settled_steps']} settled (model within {c['tolerance_pu']:g} p.u. of "
        f"AC); per step (median): {c['rounds_per_step_median']:g} rounds (at most "
        f"{c['rounds_per_step_max']}), {c['power_flows_per_step_median']:g} AC power flows, "
        f"{c['seconds_per_step_median']:.3f} s; losses {c['losses_kwh']:.3f} kWh; cost "
        f"{c['cost_eur']:.6f} EUR with the losses{_corrected_infeasible(c)}"
    ) + voltage_limits_text(c.get("voltage_limits"), "AC-corrected: AC voltages")


def _corrected_infeasible(c: dict) -> str:
    """The steps whose corrected problem is infeasible (their voltage limits out of reach
    with the AC offsets), where there are any."""
    steps = c.get("infeasible_minutes") or []
    if not steps:
        return ""
    shown = ", ".join(str(m) for m in steps[:10]) + (", ..." if len(steps) > 10 else "")
    return f"; infeasible with the AC corrections at {len(steps)} steps ({shown})"


def voltage_limits_text(lim: dict | None, label: str = "AC voltages") -> str:
    """Whether AC voltages keep the voltage limits and by how much they miss
    (:func:`popdispatch.ac.limits.limits_summary`'s object); empty without limits."""
    if not lim:
        return ""
    several = lim["steps"] > 1
    parts = []
    for bound, key, side in (("vmin", "below_vmin", "below"), ("vmax", "above_vmax", "above")):
        limit, miss = lim[f"{bound}_pu"], lim[f"{key}_pu"]
        if limit is None:
            continue
        if not miss > 0.0:
            parts.append(f"{bound} {limit:g} kept")
            continue
        where = f"bus {lim[f'{key}_bus']}" + (f", minute {lim[f'{key}_minute']}" if several else "")
        parts.append(f"{'up to ' if several else ''}{miss:.2g} p.u. {side} {bound} {limit:g} "
                     f"({where})")  # fmt: skip
    verdict = "keep the limits" if lim["kept"] else "miss the limits"
    if not lim["kept"] and several:
        verdict += f" at {lim['steps_outside']} of {lim['steps']} steps"
    return f"\n{label} {verdict} (tolerance {lim['tolerance_pu']:g} p.u.): {'; '.join(parts)}"


def snapshot_text(s: dict) -> str:
    """``popdispatch snapshot``."""
    extra = voltage_text(s.get("voltage")) + ac_correct_text(s.get("ac_correct"))
    ac = ac_text(s.get("ac")) + voltage_limits_text((s.get("ac") or {}).get("voltage_limits"))
    return _yardstick(s, _snapshot_text(s)) + ac + extra


def _snapshot_text(s: dict) -> str:
    head = (
        f"minute {s['minute']}{_when(s)}, demand {s['demand_kw']:.3f} kW: {s['dynamics']} "
        "dynamics, "
        f"{s['mode']} mode, x0 {s['x0']}\n{_inputs(s)}\n"
    )
    rows = s["generators"]
    note = outside_note(rows, s.get("mode"))
    tail = f"\n{note}" if note else ""
    dynamics = f"status: {s['status']} ({_run_line(s)})\n"
    if s["status"] == "infeasible":
        return (
            head + f"DC-OPF: {_no_dispatch(s)}\n" + dynamics
            + generator_lines(rows, ["setpoint_kw", "pmax_kw"]) + tail
            + f"\nmax overflow = {s['max_overflow_kw']:.3f} kW; cost of the set points "
            f"{s['cost']:.6f} EUR/h (no DC-OPF to compare with)"
        )  # fmt: skip
    return (
        head + dynamics + generator_lines(rows, ["setpoint_kw", "opf_kw"]) + tail
        + f"\nmax |set point - DC-OPF| = {_fmt(s['max_abs_error_kw'], ' kW')}; "
        f"max overflow = {s['max_overflow_kw']:.3f} kW; cost {s['cost']:.6f} EUR/h "
        f"(DC-OPF {_fmt(s['opf_cost'], ' EUR/h', 6)})"
    )  # fmt: skip


def _energy(s: dict) -> str:
    return ", ".join(
        f"bus {b}: {e:.2f} (DC-OPF {_fmt(s['opf_energy_kwh'][b], '', 2)})"
        for b, e in s["energy_kwh"].items()
    )


def _day_comparison(s: dict) -> str:
    """Errors, cost and energy against the DC-OPF, over the minutes where it exists."""
    compared, infeasible = s["compared_minutes"], s["infeasible_minutes"]
    if compared == 0:
        return "no minute has a DC-OPF: nothing to compare with"
    over = (
        f"over the {compared} minutes with a DC-OPF (of {s['minutes']})"
        if infeasible
        else f"over the {compared} minutes"
    )
    return (
        f"compared with the DC-OPF {over}:\n"
        f"{s['minutes_within_0_1_kw']} minutes within 0.1 kW of the DC-OPF; max |error| "
        f"{_fmt(s['max_abs_error_kw'], ' kW')}, mean {_fmt(s['mean_abs_error_kw'], ' kW')}\n"
        f"cost {s['cost']:.5f} EUR (DC-OPF {_fmt(s['opf_cost'], ' EUR', 5)})\n"
        f"energy, kWh: {_energy(s)}"
    )


def _day_notes(s: dict) -> list[str]:
    """What happened outside the comparison: infeasible minutes, set points out of limits."""
    notes = []
    infeasible = s["infeasible_minutes"]
    if infeasible:
        count = len(infeasible)
        why = s.get("infeasibility")
        first = f"\n  at minute {why['minute']}: {_no_dispatch(s)}" if why else ""
        notes.append(
            f"DC-OPF infeasible at {count} minute{'s' if count != 1 else ''}: "
            f"{minute_ranges(infeasible)} (no DC-OPF values there; the dynamics ran them: "
            f"all {s['minutes']} minutes cost {s['cost_all_minutes']:.5f} EUR; --out writes "
            f"their set points and overflow to day.csv){first}"
        )
    stalled = s.get("stalled_minutes") or []
    if stalled:
        notes.append(
            f"stalled (at rest away from the DC-OPF) at {len(stalled)} minute"
            f"{'s' if len(stalled) != 1 else ''}: {minute_ranges(stalled)}"
        )
    outside = s.get("minutes_outside_limits_by_generator") or {}
    if outside:
        which = ", ".join(f"{name} in {n}" for name, n in outside.items())
        notes.append(
            f"{OUTSIDE_MARK} set points outside their limits in {s['minutes_outside_limits']} "
            f"minutes, by up to {s['max_outside_limits_kw']:.3f} kW ({which}; "
            f"{_why_outside(s.get('mode'))})"
        )
    return notes


def _span(s: dict) -> str:
    """What a day run covers: ``online day, minutes 1-1440 (00:00:00 .. 23:59:00)`` for
    one-minute steps, else ``online run, steps 1-35136 of 15 min (2016-01-01T00:00:00 ..
    2016-12-31T23:45:00)``."""
    times = f" ({s['first_time']} .. {s['last_time']})" if s.get("first_time") else ""
    step = s.get("step_minutes", 1.0)
    if step == 1.0:
        return f"online day, minutes {s['first_minute']}-{s['last_minute']}{times}"
    length = "irregular steps" if step is None else f"steps of {step:g} min"
    return f"online run, {length} {s['first_minute']}-{s['last_minute']}{times}"


def day_text(s: dict) -> str:
    """``popdispatch day``."""
    outcome = [
        f"status: {s['status']} ({s['converged_minutes']} of {s['minutes']} minutes converged"
        f"{_day_proof(s)}; engine {s['wall_seconds']:.3f} s, whole command "
        f"{s['command_seconds']:.1f} s)",
        *_day_notes(s),
        _day_comparison(s),
        f"max overflow {s['max_overflow_kw']:.3f} kW (over all {s['minutes']} minutes)",
    ]
    if s.get("step_minutes", 1.0) != 1.0:  # a series of other steps counts steps
        outcome = [line.replace(" minute", " step") for line in outcome]
    head = f"{_span(s)}: {s['dynamics']} dynamics, {s['mode']} mode"
    body = "\n".join([head, _inputs(s), events_text(s.get("events", [])), *outcome])
    ac = ac_text(s.get("ac")) + voltage_limits_text((s.get("ac") or {}).get("voltage_limits"))
    extra = voltage_text(s.get("voltage")) + ac_correct_text(s.get("ac_correct"))
    return _yardstick(s, body) + ac + extra


def _day_proof(s: dict) -> str:
    """The day's largest proved distance to the DC-OPF, where the mode has a certificate."""
    if s.get("accuracy_kw") is None:
        return ""
    bound = s.get("max_distance_bound_kw")
    shown = "unbounded at some minute" if bound is None else f"each within {bound:.3g} kW"
    return f", proved {shown} of the DC-OPF, accuracy {s['accuracy_kw']:.3g} kW"


def _yardstick(s: dict, text: str) -> str:
    """With voltage limits the yardstick is the LinDistFlow OPF: say so where the text says
    DC-OPF."""
    return text.replace("DC-OPF", "LinDistFlow OPF") if s.get("voltage") else text


def reproduce_text(out, html: bool = False) -> str:
    """``popdispatch reproduce``: where the results are and what each file holds."""
    pages = "\n  base_day.html, congestion.html: the interactive reports" if html else ""
    return (
        f"results in {out}:\n"
        "  report.md: each experiment, the paper's reported figure against ours and the DC-OPF\n"
        "  figures/: the figures as PNG and PDF\n"
        "  summary.json: every number of report.md (the --json object)\n"
        "  *.csv: the time series of each experiment" + pages
    )


def cases_summary(table) -> dict:
    """``popdispatch cases --json``: ``{"cases": [...]}``, one object per built-in case."""
    rows = table.to_dict(orient="index").items()
    return {"cases": [{"name": name, **row} for name, row in rows]}


def cases_text(table) -> str:
    """``popdispatch cases``: one line per built-in case."""
    lines = [f"{'case':<32}{'buses':>7}{'lines':>7}{'loads':>7}{'load kW':>11}  source"]
    for name, row in table.iterrows():
        lines.append(
            f"{name:<32}{row.buses:>7}{row.lines:>7}{row.loads:>7}"
            f"{row.total_load_kw:>11.1f}  {row.source}"
        )
    return "\n".join(lines)


def infeasible_minute_message(summary: dict) -> str:
    """One line: the DC-OPF (LinDistFlow OPF with voltage limits) of a minute is infeasible,
    and why (:func:`popdispatch.report.infeasibility.cause_text`)."""
    from popdispatch.report.infeasibility import cause_text, ratings_hint

    why = summary.get("infeasibility")
    if why is None:  # a summary made without the diagnosis: demand and capacity
        why = {"cause": None}
        text = (f"no dispatch meets the demand {summary['demand_kw']:.3f} kW within the "
                f"generator limits (online capacity {summary['capacity_kw']:.3f} kW) and the "
                "line limits")  # fmt: skip
    else:
        text = cause_text(why)
    minute = summary["minute"]
    return _yardstick(
        summary, f"the DC-OPF of minute {minute} is infeasible: {text}{ratings_hint(why)}"
    )


def infeasible_day_message(summary: dict, shown: int = 5) -> str:
    """One line naming how many minutes, and which first, have no feasible DC-OPF, and why
    the first of them has none."""
    from popdispatch.report.infeasibility import cause_text, ratings_hint

    bad = summary["infeasible_minutes"]
    ranges = minute_ranges(bad).split(", ")
    listed = ", ".join(ranges[:shown]) + (", ..." if len(ranges) > shown else "")
    why = summary.get("infeasibility")
    first = f"; at minute {why['minute']}: {cause_text(why)}{ratings_hint(why)}" if why else ""
    return _yardstick(summary, (
        f"the DC-OPF is infeasible at {len(bad)} of {summary['minutes']} minutes ({listed}) "
        f"with the limits and events in force{first}; every minute was run and reported "
        "(infeasible_minutes)"
    ))  # fmt: skip
