"""The interactive report as one self-contained HTML page (plotly.js embedded, no network).

The page holds a header with the run's parameters, the feeder map (frames, slider, play) and
the time panels; a short script links them: the map's slider and animation move the panels'
cursor, a click on a panel moves the map to the nearest frame.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping

import numpy as np

MAP_ID, PANELS_ID = "popdispatch-map", "popdispatch-panels"

#: Header rows: key of the run's summary (the CLI's ``--json`` object) and its label.
HEADER_KEYS = [
    ("case", "case"), ("status", "status"), ("mode", "mode"), ("dynamics", "dynamics"),
    ("graph", "communication graph"), ("x0", "initial shares"), ("warm_start", "warm start"),
    ("minute", "minute"), ("time", "time"), ("first_minute", "first minute"),
    ("last_minute", "last minute"), ("first_time", "first time"), ("last_time", "last time"),
    ("step_minutes", "step, min"),
    ("demand_kw", "demand, kW"), ("limits", "line limits"),
    ("limits_in_force", "line limits in force"), ("events", "events"),
    ("profile_source", "profile source"), ("iterations", "iterations"),
    ("converged_iteration", "converged at iteration"),
    ("first_congestion_iteration", "congestion detected at iteration"),
    ("converged_minutes", "converged minutes"), ("infeasible_minutes", "infeasible minutes"),
    ("max_abs_error_kw", "max |error| to the DC-OPF, kW"),
    ("max_overflow_kw", "max overflow, kW"), ("cost_eur", "cost, EUR"),
    ("opf_cost_eur", "DC-OPF cost, EUR"), ("cost_eur_per_h", "cost, EUR/h"),
    ("opf_cost_eur_per_h", "DC-OPF cost, EUR/h"), ("wall_seconds", "engine time, s"),
]  # fmt: skip

STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 16px 24px;
       color: #222; }
h1 { font-size: 20px; margin: 0 0 8px 0; }
div.run { display: flex; flex-wrap: wrap; gap: 2px 22px; font-size: 13px; max-width: 1300px;
          margin-bottom: 6px; }
div.run span b { font-weight: 600; color: #555; margin-right: 5px; }
p.note { font-size: 12px; color: #555; max-width: 1100px; margin: 4px 0; }
details { font-size: 12px; margin: 4px 0 10px 0; }
.plot { width: 100%; }
"""


EXTRA = 'pip install "popdispatch[html]"'


def require_plotly():
    """``plotly.io``, or an ImportError naming the extra to install."""
    try:
        import plotly.io as pio
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"the HTML report needs plotly: {EXTRA} ({exc})") from exc
    return pio


def format_value(key: str, value) -> str:
    """A summary value as header text (lists of limits and events spelled out)."""
    if key == "limits":
        if not value:
            return "none"
        return ", ".join(
            f"{row['from_bus']}-{row['to_bus']} at {row['limit_kw']:g} kW" for row in value
        )
    if key == "limits_in_force":
        shown = 6
        rows = [f"{row['from_bus']}-{row['to_bus']} at {row['limit_kw']:.6g} kW ("
                + ("--limit " if row["source"] == "--limit" else "rating of ")
                + f"{row['element']})" for row in value[:shown]]  # fmt: skip
        more = f" and {len(value) - shown} more" if len(value) > shown else ""
        return ", ".join(rows) + more if rows else "none"
    if isinstance(value, list | tuple):
        return ", ".join(str(v) for v in value) if value else "none"
    if isinstance(value, float):
        return f"{value:.6g}"
    return "-" if value is None else str(value)


def header_html(title: str, run_info: Mapping, notes: list[str], step: str = "minute") -> str:
    """The page's header: title, a table of the run's parameters, notes, the whole summary.
    ``step``: what a step of the series is called (``"minute"``, or ``"step"`` in a series of
    other steps, e.g. quarter hours), in the labels that name one."""
    rows = "".join(
        f"<span><b>{html.escape(label.replace('minute', step))}</b>"
        f"{html.escape(format_value(key, run_info[key]))}</span>"
        for key, label in HEADER_KEYS
        if key in run_info
    )
    paragraphs = "".join(f'<p class="note">{html.escape(n)}</p>' for n in notes)
    summary = html.escape(json.dumps(dict(run_info), indent=1, default=str))
    return (
        f'<header><h1>{html.escape(title)}</h1><div class="run">{rows}</div>{paragraphs}'
        f"<details><summary>all run parameters and results (JSON)</summary><pre>{summary}"
        "</pre></details></header>"
    )


def link_script(frame_names: list[str]) -> str:
    """The script that links the map's slider and the panels' cursor (both ways)."""
    names = json.dumps([float(n) for n in frame_names])
    return f"""<script type="text/javascript">
(function () {{
  var map = document.getElementById("{MAP_ID}");
  var panels = document.getElementById("{PANELS_ID}");
  var frames = {names};
  window.popdispatchReport = {{frames: frames, step: frames[frames.length - 1]}};
  // Plotly.animate rejects its promise with no reason when a newer animation (pause, the
  // slider, a click on a panel) interrupts it; plotly's own buttons leave that uncaught.
  window.addEventListener("unhandledrejection", function (e) {{
    if (e.reason === undefined) {{ e.preventDefault(); }}
  }});
  function cursor(step) {{
    window.popdispatchReport.step = step;
    Plotly.relayout(panels, {{"shapes[0].x0": step, "shapes[0].x1": step}});
  }}
  map.on("plotly_animatingframe", function (e) {{ cursor(Number(e.name)); }});
  map.on("plotly_sliderchange", function (e) {{ cursor(Number(e.step.label)); }});
  panels.on("plotly_click", function (e) {{
    if (!e.points.length) {{ return; }}
    var x = e.points[0].x, best = frames[0];
    frames.forEach(function (f) {{ if (Math.abs(f - x) < Math.abs(best - x)) {{ best = f; }} }});
    Plotly.animate(map, [String(best)], {{mode: "immediate", transition: {{duration: 0}},
                                         frame: {{duration: 0, redraw: true}}}});
  }});
}})();
</script>"""


def page_html(title: str, header: str, map_fig: dict, panel_fig: dict) -> str:
    """The whole page: plotly.js embedded once (with the map), then the panels and the link."""
    pio = require_plotly()
    config = {"displaylogo": False, "responsive": True}
    map_div = pio.to_html(map_fig, full_html=False, include_plotlyjs=True, div_id=MAP_ID,
                          auto_play=False, validate=False, config=config)  # fmt: skip
    panel_div = pio.to_html(panel_fig, full_html=False, include_plotlyjs=False,
                            div_id=PANELS_ID, validate=False, config=config)  # fmt: skip
    names = [frame["name"] for frame in map_fig["frames"]]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
        f'{header}<div class="plot">{map_div}</div><div class="plot">{panel_div}</div>'
        f"{link_script(names)}</body></html>\n"
    )


def frame_count_note(kind: str, kept: np.ndarray, total: int, every: int) -> str:
    """How the map's frames were chosen (``every`` 0: evenly spaced, the changes being too
    many to keep)."""
    if len(kept) == total:
        return f"Map: one frame per {kind} ({total})."
    if every == 0:
        return (
            f"Map: {len(kept)} evenly spaced frames of {total} {kind}s (more {kind}s "
            "change state than a page can hold). Click a panel to move the map there."
        )
    return (
        f"Map: {len(kept)} frames of {total} {kind}s: every {every}th {kind}, plus each {kind} "
        "where a limited line's state (idle, binding, overloaded), the generators at a limit, "
        f"a generator's availability or the DC-OPF's feasibility changes. Click a panel to "
        "move the map there."
    )
