"""The linked time panels of the interactive report: one plotly figure, shared step axis.

Rows: set points against the DC-OPF (kW); the limited lines' loading (%); line prices and
congestion signals (EUR/MWh); the largest error to the DC-OPF (kW, log scale); the demand (kW).
Every step is drawn up to :data:`MAX_POINTS` steps (a day's 1440 minutes are); a longer series
keeps every k-th step plus the map's frames. A vertical cursor marks the map's step; the page's
script moves it and a click on a panel moves the map.
"""

from __future__ import annotations

import numpy as np

from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.report.interactive.feeder_map import generator_colors
from popdispatch.report.interactive.steps import Steps

#: Errors below this are drawn at it on the log axis (kW).
ERROR_FLOOR_KW = 1e-9
#: Steps drawn per curve at most, beyond the map's frames (a year at 15 min has 35,136).
MAX_POINTS = 5000
#: Tick spacings, in steps (with one-minute steps: 2 h, 6 h, a day, a week, ...).
TICK_STEPS = (1, 2, 5, 10, 15, 30, 60, 120, 240, 360, 720, 1440, 2880, 5760, 10080, 20160,
              40320, 80640)  # fmt: skip
ROWS = ("setpoints", "loading", "prices", "error", "demand")
TITLES = {
    "setpoints": "set points (solid) vs DC-OPF (dotted), kW",
    "loading": "limited lines: |flow| / limit, % (dynamics)",
    "prices": "line prices: DC-OPF dual (dashed), eq.-8 signal of the dynamics' flows "
    "(solid), EUR/MWh",
    "error": "largest |set point - DC-OPF|, kW",
    "demand": "demand, kW",
}


def _clean(values, decimals: int = 4) -> list:
    """A list for JSON rounded to ``decimals`` (kW: 0.1 W), NaN as None (a gap)."""
    array = np.round(np.asarray(values, dtype=float), decimals)
    return [float(v) if np.isfinite(v) else None for v in array]


def _significant(values) -> list:
    """A list for JSON with 4 significant digits (errors of 1e-9 kW stay on the log axis)."""
    return [float(f"{v:.4g}") if np.isfinite(v) else None for v in np.asarray(values, float)]


def panel_rows(steps: Steps, frames: np.ndarray) -> np.ndarray:
    """Rows drawn in the panels: all, or every k-th (at most :data:`MAX_POINTS`) plus the map's
    frame rows ``frames``."""
    n = len(steps.values)
    if n <= MAX_POINTS:
        return np.arange(n)
    every = int(np.ceil(n / MAX_POINTS))
    return np.union1d(np.arange(0, n, every), frames)


def panel_figure(problem: DispatchProblem, steps: Steps, cursor: int) -> dict:
    """The panels as a plotly figure dict (``steps``: the rows to draw), with the cursor at
    step ``cursor``."""
    x = steps.values.tolist()
    data = _setpoints(problem, steps, x) + _loading(problem, steps, x)
    data += _prices(problem, steps, x) + _error(steps, x) + _demand(steps, x)
    if steps.kind == "minute":
        _hover_times(data, steps.times)
    layout = {
        "height": 1050, "hovermode": "x unified", "plot_bgcolor": "#ffffff",
        "margin": {"l": 70, "r": 20, "t": 30, "b": 50},
        "legend": {"orientation": "h", "y": 1.04, "yanchor": "bottom", "x": 0.0},
        "shapes": [_cursor(cursor)], "annotations": [],
    }  # fmt: skip
    _stack_rows(layout)
    bottom = layout[f"xaxis{len(ROWS)}"]
    if steps.kind == "minute":
        bottom.update(_time_ticks(steps))
        bottom["title"] = {"text": f"{steps.step_name} (labelled by the time it starts)"}
    else:
        bottom["title"] = {"text": "iteration (0.01 s each)"}
    layout["yaxis4"]["type"] = "log"
    return {"data": data, "layout": layout}


def _stack_rows(layout: dict) -> None:
    """One x/y axis pair per row, stacked top to bottom, x axes matched, titles above."""
    gap, n = 0.035, len(ROWS)
    height = (1.0 - gap * (n - 1)) / n
    for r, name in enumerate(ROWS):
        top = 1.0 - r * (height + gap)
        suffix = "" if r == 0 else str(r + 1)
        layout[f"yaxis{suffix}"] = {"domain": [top - height, top], "anchor": f"x{suffix}",
                                    "gridcolor": "#e5e5e5", "zeroline": False}  # fmt: skip
        layout[f"xaxis{suffix}"] = {"anchor": f"y{suffix}", "gridcolor": "#e5e5e5",
                                    "showticklabels": r == n - 1}  # fmt: skip
        if r:
            layout[f"xaxis{suffix}"]["matches"] = "x"
        layout["annotations"].append({
            "text": TITLES[name], "xref": "paper", "yref": "paper", "x": 0.0, "y": top,
            "xanchor": "left", "yanchor": "bottom", "showarrow": False, "font": {"size": 12},
        })  # fmt: skip


def _hover_times(data: list[dict], times: list[str]) -> None:
    """The first trace of each row names the step's time in the unified hover."""
    seen = set()
    for trace in data:
        if trace["yaxis"] in seen or trace.get("hoverinfo") == "skip":
            continue
        seen.add(trace["yaxis"])
        trace["customdata"] = times
        trace["hovertemplate"] = "%{customdata}: " + trace["hovertemplate"]


def _cursor(step: int) -> dict:
    return {"type": "line", "xref": "x", "yref": "paper", "x0": step, "x1": step, "y0": 0,
            "y1": 1, "line": {"color": "#444444", "width": 1.5, "dash": "dot"}}  # fmt: skip


def _time_ticks(steps: Steps) -> dict:
    """About 6-12 ticks at round step counts (every 2 h over a day of minutes), labelled with
    the time each step starts."""
    values = steps.values
    span = int(values[-1] - values[0]) if len(values) else 0
    spacing = next((t for t in TICK_STEPS if span / t <= 12), TICK_STEPS[-1])
    ticks = [v for v in range(int(values[0]), int(values[-1]) + 1) if (v - 1) % spacing == 0]
    positions = np.searchsorted(values, ticks)
    keep = [(t, p) for t, p in zip(ticks, positions, strict=True)
            if p < len(values) and values[p] == t]  # fmt: skip
    return {"tickvals": [t for t, _ in keep], "ticktext": [steps.times[p] for _, p in keep]}


def _setpoints(problem: DispatchProblem, steps: Steps, x: list) -> list[dict]:
    colors = generator_colors(problem.generators)
    traces = []
    for k, name in enumerate(problem.generators):
        common = {"type": "scatter", "mode": "lines", "x": x, "legendgroup": name,
                  "xaxis": "x", "yaxis": "y"}  # fmt: skip
        traces.append({**common, "name": f"{name} set point", "y": _clean(steps.setpoints_kw[:, k]),
                       "line": {"color": colors[k], "width": 1.6},
                       "hovertemplate": "%{y:.3f} kW"})  # fmt: skip
        traces.append({**common, "name": f"{name} DC-OPF", "y": _clean(steps.opf_kw[:, k]),
                       "line": {"color": colors[k], "width": 1.2, "dash": "dot"},
                       "showlegend": False, "hovertemplate": "%{y:.3f} kW"})  # fmt: skip
    return traces


def _limited_names(problem: DispatchProblem) -> list[str]:
    rows = problem.feeder.lines.loc[problem.lines]
    return [f"line {int(a)}-{int(b)}" for a, b in zip(rows.from_bus, rows.to_bus, strict=True)]


def _loading(problem: DispatchProblem, steps: Steps, x: list) -> list[dict]:
    if not len(problem.lines):
        return [_empty_note(x, "x2", "y2", "no limited lines")]
    loading = 100.0 * steps.loading(problem)
    traces = [{"type": "scatter", "mode": "lines", "x": x, "y": _clean(loading[:, k]),
               "name": f"{name} loading", "xaxis": "x2", "yaxis": "y2", "showlegend": False,
               "hovertemplate": f"{name} (limit {u * KW_PER_MW:g} kW): %{{y:.1f}} %"}
              for k, (name, u) in enumerate(zip(_limited_names(problem), problem.limit,
                                                strict=True))]  # fmt: skip
    traces.append({"type": "scatter", "mode": "lines", "x": [x[0], x[-1]], "y": [100, 100],
                   "xaxis": "x2", "yaxis": "y2", "showlegend": False, "hoverinfo": "skip",
                   "line": {"color": "#c0392b", "dash": "dash", "width": 1}})  # fmt: skip
    return traces


def _prices(problem: DispatchProblem, steps: Steps, x: list) -> list[dict]:
    if not len(problem.lines):
        return [_empty_note(x, "x3", "y3", "no limited lines")]
    traces = []
    for k, name in enumerate(_limited_names(problem)):
        common = {"type": "scatter", "mode": "lines", "x": x, "xaxis": "x3", "yaxis": "y3",
                  "showlegend": False}  # fmt: skip
        traces.append({**common, "name": f"{name} DC-OPF price",
                       "y": _clean(steps.opf_price[:, k]), "line": {"dash": "dash"},
                       "hovertemplate": f"{name} DC-OPF price %{{y:.2f}} EUR/MWh"})  # fmt: skip
        traces.append({**common, "name": f"{name} eq.-8 signal",
                       "y": _clean(steps.signal[:, k]),
                       "hovertemplate": f"{name} eq.-8 signal %{{y:.2f}} EUR/MWh"})  # fmt: skip
    return traces


def _error(steps: Steps, x: list) -> list[dict]:
    error = np.maximum(steps.abs_error_kw, ERROR_FLOOR_KW)
    return [{"type": "scatter", "mode": "lines", "x": x, "y": _significant(error),
             "name": "max error", "xaxis": "x4", "yaxis": "y4", "showlegend": False,
             "line": {"color": "#34495e"},
             "hovertemplate": "max |error| %{y:.2e} kW"}]  # fmt: skip


def _demand(steps: Steps, x: list) -> list[dict]:
    return [{"type": "scatter", "mode": "lines", "x": x, "y": _clean(steps.demand_kw),
             "name": "demand", "xaxis": "x5", "yaxis": "y5", "showlegend": False,
             "line": {"color": "#000000"}, "hovertemplate": "demand %{y:.3f} kW"}]  # fmt: skip


def _empty_note(x: list, xaxis: str, yaxis: str, text: str) -> dict:
    return {
        "type": "scatter",
        "mode": "text",
        "x": [x[len(x) // 2]],
        "y": [0],
        "text": [text],
        "xaxis": xaxis,
        "yaxis": yaxis,
        "showlegend": False,
        "hoverinfo": "skip",
    }
