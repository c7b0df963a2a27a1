"""The feeder map of the interactive report: a plotly figure with one frame per kept step.

Drawn from the original feeder's coordinates (a layered tree layout where it has none): every
original line, coloured and widened by the flow of the reduced line it belongs to; limited
lines outlined and their node controllers marked by their state; generators sized by set point;
buses coloured by voltage when voltages are given. Frames update only what changes (line
colours and widths, the hover numbers, generator sizes, controller states, bus colours) and a
slider with a play button steps through them.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pandas as pd

from popdispatch.feeder.model import Feeder
from popdispatch.game.problem import KW_PER_MW, DispatchProblem
from popdispatch.report.interactive.steps import BINDING, OVERLOADED, Steps

#: Above this many reduced lines the lines are drawn once in grey and the flows shown by
#: coloured markers at their middles only (one trace per line would make the page slow).
MAX_LINE_TRACES = 400
#: |flow| from low (light) to high (dark): the upper part of ColorBrewer's YlGnBu.
FLOW_SCALE = [[0.0, "#c7e9b4"], [0.3, "#41b6c4"], [0.65, "#225ea8"], [1.0, "#081d58"]]
#: Bus voltage from low (blue) through 1.0 p.u. (white) to high (red): ColorBrewer's RdBu
#: reversed, written out so that the markers (coloured here) and the colour bar (drawn by
#: plotly.js) read from one scale; plotly.py's "RdBu" and plotly.js's run opposite ways.
VOLTAGE_SCALE = [
    [k / 10, color] for k, color in enumerate([
        "#053061", "#2166ac", "#4393c3", "#92c5de", "#d1e5f0", "#f7f7f7", "#fddbc7", "#f4a582",
        "#d6604d", "#b2182b", "#67001f",
    ])
]  # fmt: skip
STATE_COLORS = {0: "#ffffff", BINDING: "#f39c12", OVERLOADED: "#c0392b"}
STATE_NAMES = {0: "idle", BINDING: "binding", OVERLOADED: "overloaded"}
OFFLINE_COLOR = "#9e9e9e"
GENERATOR_PALETTE = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"]


def generator_colors(names) -> list[str]:
    """One fixed colour per generator, as in the static figures."""
    return [GENERATOR_PALETTE[k % len(GENERATOR_PALETTE)] for k in range(len(names))]


#: A feeder's own coordinates are drawn when at least this share of its buses sit at distinct
#: places (the ELV puts 906 buses at 866: a few buses share a spot with a neighbour).
DISTINCT_SHARE = 0.5


def bus_coordinates(feeder: Feeder) -> pd.DataFrame:
    """``x``, ``y`` per bus: the feeder's own (as the static figures draw them) where every bus
    has finite ones and at least :data:`DISTINCT_SHARE` of the buses sit at distinct places,
    else a layered tree layout (``x`` = lines from the source, ``y`` = leaf order, a parent
    centred over its children)."""
    xy = feeder.buses[["x", "y"]].to_numpy(float)
    if np.isfinite(xy).all() and len(np.unique(xy, axis=0)) >= DISTINCT_SHARE * len(xy):
        return feeder.buses[["x", "y"]].astype(float)
    tree = feeder.bus_tree()
    depth = np.zeros(tree.n_nodes)
    for node in tree.preorder[1:]:
        depth[node] = depth[tree.parent[node]] + 1
    total, count = np.zeros(tree.n_nodes), np.zeros(tree.n_nodes)
    y, leaves = np.zeros(tree.n_nodes), 0
    for node in tree.preorder[::-1]:
        if count[node] == 0:
            y[node], leaves = leaves, leaves + 1
        else:
            y[node] = total[node] / count[node]
        parent = tree.parent[node]
        if parent >= 0:
            total[parent] += y[node]
            count[parent] += 1
    return pd.DataFrame({"x": depth, "y": -y}, index=feeder.buses.index)


def shown_voltages(voltages: pd.DataFrame | None, key_buses: pd.Series) -> pd.DataFrame | None:
    """The voltages the map shows: those of key-node buses (loads, generators, branching points,
    the source) when the table has any, else all it has. A full-feeder AC check gives every
    bus (906 on the ELV); the buses along a chain between two key nodes add bytes, not news."""
    if voltages is None:
        return None
    key = [bus for bus in voltages.columns if bus in set(key_buses)]
    return voltages[key] if key else voltages


def _segments(xy: pd.DataFrame, from_bus, to_bus) -> tuple[list, list]:
    """x and y lists of line segments separated by None (one plotly trace for all of them)."""
    start, end = xy.loc[from_bus].to_numpy(), xy.loc[to_bus].to_numpy()
    xs, ys = [], []
    for (x0, y0), (x1, y1) in zip(start, end, strict=True):
        xs += [float(x0), float(x1), None]
        ys += [float(y0), float(y1), None]
    return xs, ys


class MapBuilder:
    """Builds the map's traces, frames and slider for one problem and its steps."""

    def __init__(self, problem: DispatchProblem, steps: Steps):
        self.problem = problem
        self.steps = steps
        self.reduced = problem.feeder
        self.xy = bus_coordinates(self.reduced.original)
        self.per_line = self.reduced.n_lines <= MAX_LINE_TRACES
        self.flow_max = max(float(np.abs(steps.flows_kw).max(initial=0.0)), 1e-9)
        self.limited_kw = steps.limited_flows_kw(problem)
        self.loading = 100.0 * steps.loading(problem)
        self.states = steps.line_states(problem)
        self.voltages = shown_voltages(steps.voltages_pu, self.reduced.nodes.bus)
        self.traces: list[dict] = []
        self.dynamic: dict[str, list[int]] = {}

    # -- static and dynamic traces --------------------------------------------------------

    def _add(self, trace: dict, role: str | None = None) -> None:
        if role is not None:
            self.dynamic.setdefault(role, []).append(len(self.traces))
        self.traces.append(trace)

    def build_traces(self, row: int) -> list[dict]:
        """Every trace, in the state of step row ``row``."""
        original = self.reduced.original
        which = self.reduced.line_map.to_numpy()
        lines = original.lines
        pruned = lines[which < 0]
        xs, ys = _segments(self.xy, pruned.from_bus, pruned.to_bus)
        self._add(_line_trace(xs, ys, "#d0d0d0", 0.6, "lines without load or generator"))
        self._add_limited_outline(which)
        if self.per_line:
            for k in range(self.reduced.n_lines):
                part = lines[which == k]
                xs, ys = _segments(self.xy, part.from_bus, part.to_bus)
                self._add(_line_trace(xs, ys, "#888888", 1.0, None), "lines")
        else:
            kept = lines[which >= 0]
            xs, ys = _segments(self.xy, kept.from_bus, kept.to_bus)
            self._add(_line_trace(xs, ys, "#b0b0b0", 1.0, "lines"))
        self._add(self._midpoints(), "midpoints")
        self._add_buses()
        self._add(self._controllers(), "controllers")
        self._add(self._generators(), "generators")
        self._apply(row)
        return self.traces

    def _add_limited_outline(self, which: np.ndarray) -> None:
        lines = self.reduced.original.lines
        part = lines[np.isin(which, self.problem.lines)]
        xs, ys = _segments(self.xy, part.from_bus, part.to_bus)
        name = f"limited lines ({len(self.problem.lines)} reduced)"
        trace = _line_trace(xs, ys, "#000000", 12.0, name)
        trace["opacity"] = 0.35
        self._add(trace)

    def _midpoints(self) -> dict:
        rows = self.reduced.lines
        start = self.xy.loc[rows.from_bus].to_numpy()
        end = self.xy.loc[rows.to_bus].to_numpy()
        middle = (start + end) / 2
        limit = rows.limit_kw.to_numpy(float)
        text = [
            f"reduced line {k} (buses {int(a)}-{int(b)}, {int(n)} original)<br>"
            + (f"limit {u:g} kW" if np.isfinite(u) else "no limit")
            for k, a, b, n, u in zip(rows.index, rows.from_bus, rows.to_bus, rows.n_original,
                                     limit, strict=True)
        ]  # fmt: skip
        return {
            "type": "scatter", "mode": "markers", "name": "line flow",
            "x": middle[:, 0].tolist(), "y": middle[:, 1].tolist(), "text": text,
            "marker": {
                "size": 6 if self.per_line else 9, "color": [0.0] * len(rows),
                "colorscale": FLOW_SCALE, "cmin": 0.0,
                "cmax": self.flow_max, "opacity": 0.4 if self.per_line else 1.0,
                "colorbar": {"title": {"text": "|flow|, kW"}, "len": 0.45, "y": 0.75},
            },
            "hovertemplate": "%{text}<br>flow %{customdata:.3f} kW (+ away from the source)"
            "<extra></extra>",
        }  # fmt: skip

    def _add_buses(self) -> None:
        voltages = self.voltages
        nodes = self.reduced.nodes
        if voltages is None:
            xy = self.xy.loc[nodes.bus]
            self._add({
                "type": "scatter", "mode": "markers", "name": "key nodes",
                "x": xy.x.tolist(), "y": xy.y.tolist(),
                "marker": {"size": 4, "color": "#555555"},
                "text": [f"bus {b} (key node {n})" for n, b in zip(nodes.index, nodes.bus,
                                                                   strict=True)],
                "hovertemplate": "%{text}<extra></extra>",
            })  # fmt: skip
        else:
            self._add(self._voltage_trace(voltages), "voltages")
        source = self.xy.loc[self.reduced.original.source_bus]
        self._add({
            "type": "scatter", "mode": "markers", "name": "source",
            "x": [float(source.x)], "y": [float(source.y)],
            "marker": {"symbol": "square", "size": 14, "color": "#000000"},
            "hovertemplate": f"source, bus {self.reduced.original.source_bus}<extra></extra>",
        })  # fmt: skip
        loads = self.reduced.original.loads
        xy = self.xy.loc[loads.bus]
        self._add({
            "type": "scatter", "mode": "markers", "name": "loads",
            "x": xy.x.tolist(), "y": xy.y.tolist(),
            "marker": {"symbol": "circle-open", "size": 6, "color": "#2c3e50"},
            "text": [f"load {n} at bus {b}" for n, b in zip(loads.index, loads.bus, strict=True)],
            "hovertemplate": "%{text}<extra></extra>", "visible": "legendonly",
        })  # fmt: skip

    def _voltage_trace(self, voltages: pd.DataFrame) -> dict:
        xy = self.xy.loc[voltages.columns]
        values = voltages.to_numpy(float)
        spread = max(float(np.nanmax(np.abs(values - 1.0), initial=0.0)), 0.05)
        self.v_range = (1.0 - spread, 1.0 + spread)
        return {
            "type": "scatter", "mode": "markers", "name": "bus voltage",
            "x": xy.x.tolist(), "y": xy.y.tolist(),
            "text": [f"bus {b}" for b in voltages.columns],
            "marker": {
                "size": 7, "color": [1.0] * len(xy), "colorscale": VOLTAGE_SCALE,
                "cmin": self.v_range[0], "cmax": self.v_range[1],
                "line": {"width": 0.5, "color": "#333333"},
                "colorbar": {"title": {"text": "voltage, p.u."}, "len": 0.45, "y": 0.25},
            },
            "hovertemplate": "%{text}<br>voltage %{customdata:.4f} p.u.<extra></extra>",
        }  # fmt: skip

    def _controller_ends(self) -> dict[int, list[tuple[int, float]]]:
        """Per key-node bus at an end of a limited line: ``(limited line, sign)`` of each line
        its controller measures (+1 at the parent end, where a positive flow leaves)."""
        rows = self.reduced.lines.loc[self.problem.lines]
        ends: dict[int, list[tuple[int, float]]] = {}
        for k, (a, b) in enumerate(zip(rows.from_bus, rows.to_bus, strict=True)):
            ends.setdefault(int(a), []).append((k, 1.0))
            ends.setdefault(int(b), []).append((k, -1.0))
        return ends

    def _controllers(self) -> dict:
        self.ends = self._controller_ends()
        xy = self.xy.loc[list(self.ends)]
        return {
            "type": "scatter", "mode": "markers", "name": "node controllers",
            "x": xy.x.tolist(), "y": xy.y.tolist(),
            "text": [f"node controller at bus {bus}" for bus in self.ends],
            "marker": {"symbol": "square", "size": 13, "color": ["#ffffff"] * len(xy),
                       "line": {"width": 2, "color": "#000000"}},
            "hovertemplate": "%{text}<br>%{customdata}<extra></extra>",
        }  # fmt: skip

    def _generators(self) -> dict:
        gens = self.reduced.generators
        xy = self.xy.loc[gens.bus]
        text = [
            f"{name} at bus {int(row.bus)}<br>limits {row.pmin_kw:g}-{row.pmax_kw:g} kW"
            for name, row in gens.iterrows()
        ]
        return {
            "type": "scatter", "mode": "markers+text", "name": "generators (size: set point)",
            "x": xy.x.tolist(), "y": xy.y.tolist(), "text": text,
            "texttemplate": list(gens.index), "textposition": "top center",
            "marker": {"symbol": "triangle-up", "size": [10.0] * len(gens),
                       "color": generator_colors(gens.index),
                       "line": {"width": 1, "color": "#000000"}},
            "hovertemplate": "%{text}<br>set point %{customdata[0]:.3f} kW<br>DC-OPF "
            "%{customdata[1]:.3f} kW<br>%{customdata[2]}<extra></extra>",
        }  # fmt: skip

    # -- per-step state -----------------------------------------------------------------------

    def updates(self, row: int) -> dict[int, dict]:
        """Trace index -> the attributes that change at step row ``row``."""
        flows = self.steps.flows_kw[row]
        magnitude = np.abs(flows) / self.flow_max
        out: dict[int, dict] = {}
        if self.per_line:
            colors = _sample(FLOW_SCALE, magnitude)
            for k, trace in enumerate(self.dynamic["lines"]):
                width = round(1.0 + 7.0 * float(magnitude[k]), 1)
                out[trace] = {"line": {"color": colors[k], "width": width}}
        out[self.dynamic["midpoints"][0]] = {
            "customdata": _rounded(flows, 2),
            "marker": {"color": _rounded(np.abs(flows), 2)},
        }
        out[self.dynamic["controllers"][0]] = self._controller_update(row)
        out[self.dynamic["generators"][0]] = self._generator_update(row)
        if "voltages" in self.dynamic:
            out[self.dynamic["voltages"][0]] = self._voltage_update(row)
        return out

    def _controller_update(self, row: int) -> dict:
        """Each controller's colour (the worst state of the lines it measures) and, per line,
        the flow it measures (+ leaving its bus), loading, state, the eq.-8 signal it sends
        and the DC-OPF's line price."""
        steps, rows = self.steps, self.reduced.lines.loc[self.problem.lines]
        flow, loading, states = self.limited_kw[row], self.loading[row], self.states[row]
        signal, price = steps.signal[row], steps.opf_price[row]
        color, data = [], []
        for measured in self.ends.values():
            color.append(STATE_COLORS[max(int(states[k]) for k, _ in measured)])
            data.append("<br>".join(
                f"line {int(rows.from_bus.iloc[k])}-{int(rows.to_bus.iloc[k])} "
                f"(limit {rows.limit_kw.iloc[k]:g} kW): {sign * flow[k]:+.3f} kW, "
                f"{loading[k]:.1f} %, {STATE_NAMES[int(states[k])]}; eq.-8 signal "
                f"{sign * signal[k]:+.2f}, DC-OPF price {_price(price[k])} EUR/MWh"
                for k, sign in measured
            ))  # fmt: skip
        return {"marker": {"color": color}, "customdata": data}

    def _generator_update(self, row: int) -> dict:
        steps = self.steps
        pmax = float(self.problem.pmax.max()) * KW_PER_MW
        p, opf, online = steps.setpoints_kw[row], steps.opf_kw[row], steps.online[row]
        size = 10.0 + 26.0 * np.clip(p / max(pmax, 1e-9), 0.0, 1.5)
        colors = generator_colors(self.problem.generators)
        return {
            "marker": {"size": _rounded(size, 1),
                       "color": [c if on else OFFLINE_COLOR for c, on in zip(colors, online,
                                                                              strict=True)]},
            "customdata": [[round(float(a), 3), _finite(b, 3), "online" if on else "offline"]
                           for a, b, on in zip(p, opf, online, strict=True)],
        }  # fmt: skip

    def _voltage_update(self, row: int) -> dict:
        table = self.voltages
        step = int(self.steps.values[row])
        if step in table.index:
            values = table.loc[step].to_numpy(float)
        else:
            values = np.full(table.shape[1], np.nan)
        lo, hi = self.v_range
        colors = _sample(VOLTAGE_SCALE, (values - lo) / (hi - lo))
        return {"marker": {"color": colors}, "customdata": [_finite(v, 4) for v in values]}

    def _apply(self, row: int) -> None:
        """Write step row ``row``'s state into the traces (the figure's initial state)."""
        for index, update in self.updates(row).items():
            _merge(self.traces[index], update)


def frame_bytes(problem: DispatchProblem, steps: Steps) -> int:
    """About how many bytes of JSON one map frame takes (the first step's, plus its title)."""
    builder = MapBuilder(problem, steps)
    builder.build_traces(0)
    return len(json.dumps(list(builder.updates(0).values()))) + 200


def map_figure(problem: DispatchProblem, steps: Steps, rows: np.ndarray, titles: list[str]) -> dict:
    """The map as a plotly figure dict: traces in the state of the last kept step, one frame
    per kept step row (named by its step value, titled ``titles[j]``), a slider (its value
    called by the steps' :attr:`~Steps.step_name`) and play and pause buttons."""
    builder = MapBuilder(problem, steps)
    data = builder.build_traces(int(rows[-1]))
    frames = []
    for row, title in zip(rows, titles, strict=True):
        updates = builder.updates(int(row))
        frames.append({
            "name": str(int(steps.values[row])), "traces": list(updates),
            "data": list(updates.values()), "layout": {"title": {"text": title}},
        })  # fmt: skip
    layout = {
        "title": {"text": titles[-1], "x": 0.01, "font": {"size": 15}},
        "xaxis": {"visible": False},
        "yaxis": {"visible": False, "scaleanchor": "x", "scaleratio": 1},
        "plot_bgcolor": "#ffffff", "height": 720, "hovermode": "closest",
        "legend": {"orientation": "h", "y": -0.02, "x": 0.0, "yanchor": "top"},
        "margin": {"l": 10, "r": 10, "t": 50, "b": 150},
        "sliders": [_slider(frames, steps.step_name)], "updatemenus": [_play_buttons()],
    }  # fmt: skip
    return {"data": data, "layout": layout, "frames": frames}


def _slider(frames: list[dict], kind: str) -> dict:
    step_args = {"mode": "immediate", "frame": {"duration": 0, "redraw": True},
                 "transition": {"duration": 0}}  # fmt: skip
    return {
        "active": len(frames) - 1, "x": 0.16, "len": 0.84, "y": -0.1, "yanchor": "top",
        "currentvalue": {"prefix": f"{kind} ", "font": {"size": 13}},
        "pad": {"t": 10, "b": 10}, "ticklen": 3, "minorticklen": 0,
        "steps": [{"method": "animate", "label": f["name"],
                   "args": [[f["name"]], step_args]} for f in frames],
    }  # fmt: skip


def _play_buttons() -> dict:
    play = {"frame": {"duration": 250, "redraw": True}, "fromcurrent": True,
            "transition": {"duration": 0}, "mode": "immediate"}  # fmt: skip
    pause = {"frame": {"duration": 0, "redraw": False}, "mode": "immediate",
             "transition": {"duration": 0}}  # fmt: skip
    return {
        "type": "buttons", "direction": "left", "x": 0.0, "y": -0.1, "xanchor": "left",
        "yanchor": "top", "pad": {"t": 10, "r": 10}, "showactive": False,
        "buttons": [{"label": "\u25b6 play", "method": "animate", "args": [None, play]},
                    {"label": "\u275a\u275a pause", "method": "animate",
                     "args": [[None], pause]}],
    }  # fmt: skip


def _merge(target: dict, update: dict) -> None:
    for key, value in update.items():
        if isinstance(value, dict):
            _merge(target.setdefault(key, {}), value)
        else:
            target[key] = value


def _line_trace(xs: list, ys: list, color: str, width: float, name: str | None) -> dict:
    return {
        "type": "scatter", "mode": "lines", "x": xs, "y": ys, "hoverinfo": "skip",
        "line": {"color": color, "width": width}, "name": name or "",
        "showlegend": name is not None,
    }  # fmt: skip


@functools.cache
def _palette(scale: str | tuple) -> tuple[str, ...]:
    """256 hex colours along a plotly colour scale (sampled once per scale)."""
    from plotly.colors import sample_colorscale, unlabel_rgb

    scale = [list(stop) for stop in scale] if isinstance(scale, tuple) else scale
    sampled = sample_colorscale(scale, np.linspace(0.0, 1.0, 256).tolist())
    return tuple("#{:02x}{:02x}{:02x}".format(*(round(c) for c in unlabel_rgb(s))) for s in sampled)


def _sample(scale: str | list, values: np.ndarray) -> list[str]:
    """Colours of ``values`` (0..1, NaN -> grey) on a plotly colour scale, as hex strings."""
    values = np.asarray(values, dtype=float)
    key = scale if isinstance(scale, str) else tuple(tuple(stop) for stop in scale)
    palette = np.array(_palette(key) + (OFFLINE_COLOR,))
    index = np.where(np.isfinite(values), np.rint(np.clip(values, 0.0, 1.0) * 255), 256)
    return palette[index.astype(np.int64)].tolist()


def _rounded(values: np.ndarray, digits: int) -> list[float]:
    return np.round(np.asarray(values, dtype=float), digits).tolist()


def _price(value: float) -> str:
    return f"{value:+.2f}" if np.isfinite(value) else "n/a"


def _finite(value: float, digits: int) -> float | None:
    return round(float(value), digits) if np.isfinite(value) else None
