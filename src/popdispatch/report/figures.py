"""The paper's figures (section III), drawn from popdispatch results with matplotlib.

Every function returns a :class:`matplotlib.figure.Figure` (object API, no pyplot state, no
display needed); :func:`save_figure` writes it as PNG (screen) and PDF (paper). Powers are shown
in kW, fitness in EUR/MW (the engine's units: Table I's coefficients apply to MW).
"""

from __future__ import annotations

import functools
import textwrap
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from popdispatch.compare import DayComparison, SnapshotComparison
from popdispatch.feeder.profiles import Timeline
from popdispatch.feeder.reduction import ReducedFeeder
from popdispatch.game.controllers import broadcast_signals, overflow_signal
from popdispatch.game.fitness import FitnessParameters, barrier
from popdispatch.game.problem import KW_PER_MW, DispatchProblem

if TYPE_CHECKING:  # drawn here, run by the paper's scenarios above this package
    from popdispatch.scenarios import ExtinctionResult

SINGLE = 3.5  # inches: one column of a two-column paper
DOUBLE = 7.16  # inches: full page width
STYLE = {
    "font.size": 8,
    "axes.titlesize": 9,
    "axes.labelsize": 8,
    "legend.fontsize": 7,
    "xtick.labelsize": 7,
    "ytick.labelsize": 7,
    "lines.linewidth": 1.2,
    "axes.grid": True,
    "grid.alpha": 0.3,
}
PENALTY, INCENTIVE = "#c0392b", "#1e8449"
LABEL_BOX = {"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8}


def styled(draw):
    """Decorator: draw the figure under the paper style (rcParams are read when drawing)."""

    @functools.wraps(draw)
    def wrapper(*args, **kwargs):
        import matplotlib

        with matplotlib.rc_context(STYLE):
            return draw(*args, **kwargs)

    return wrapper


def new_figure(width: float, height: float, **subplots) -> tuple[Figure, np.ndarray]:
    """A figure with a grid of axes (``subplots`` as for ``Figure.subplots``)."""
    fig = Figure(figsize=(width, height), layout="constrained")
    return fig, fig.subplots(squeeze=False, **subplots)


def save_figure(fig: Figure, stem) -> list:
    """Write ``stem.png`` (200 dpi) and ``stem.pdf``; returns the two paths."""
    import matplotlib

    paths = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    with matplotlib.rc_context(STYLE):
        fig.savefig(paths[0], dpi=200)
        fig.savefig(paths[1])
    return paths


def generator_colors(names) -> dict[str, str]:
    """One fixed colour per generator (tab10), the same in every figure."""
    palette = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"]
    return {name: palette[k % len(palette)] for k, name in enumerate(names)}


# -- figure 1: fitness of a generator node ------------------------------------------------------


@styled
def fitness_figure(
    problem: DispatchProblem, generator: str, shift: float, params: FitnessParameters
) -> Figure:
    """Fitness of ``generator`` against its output (eqs. 5-7), and shifted by ``shift`` EUR/MW.

    ``shift`` is the magnitude of a congestion signal (eq. 8); the penalty curve is ``-shift``
    below, the incentive curve ``+shift`` above. Plotted as ``f - B`` so the axis reads in
    EUR/MW around the marginal cost.
    """
    k = problem.generators.get_loc(generator)
    pmin, pmax = problem.pmin[k], problem.pmax[k]
    p = np.linspace(pmin - 0.3 * pmax, 1.4 * pmax, 801)
    base = -(problem.b[k] + 2 * problem.c[k] * p)
    bar = barrier(p, np.full_like(p, pmin), np.full_like(p, pmax), float(params.m))
    fitness = base + bar
    fig, axes = new_figure(SINGLE, 2.7)
    ax = axes[0, 0]
    p_kw = p * KW_PER_MW
    ax.plot(p_kw, fitness, color="black", label="fitness $f_i - B$")
    ax.plot(p_kw, fitness - shift, color=PENALTY, ls="--", label=f"penalised ($-${shift:.1f})")
    ax.plot(p_kw, fitness + shift, color=INCENTIVE, ls=":", label=f"incentivised (+{shift:.1f})")
    for limit, name in ((pmin, "$P_{min}$"), (pmax, "$P_{max}$")):
        ax.axvline(limit * KW_PER_MW, color="grey", lw=0.8, ls="-.")
        ax.annotate(
            name,
            (limit * KW_PER_MW, 0.0),
            xycoords=("data", "axes fraction"),
            xytext=(2, 4),
            textcoords="offset points",
            fontsize=7,
        )
    ax.set_xlabel(f"output of {generator} (bus {problem.feeder.generators.bus[generator]}), kW")
    ax.set_ylabel("fitness $-$ B, EUR/MW")
    ax.set_title(f"Fitness of generator node {generator}")
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncols=2)
    return fig


# -- feeder drawings (figures 2 and 3) ----------------------------------------------------------


def _segments(reduced: ReducedFeeder):
    """Original line segments (x, y pairs) and the reduced line each belongs to (-1: pruned)."""
    original = reduced.original
    xy = original.buses[["x", "y"]]
    start = xy.loc[original.lines.from_bus].to_numpy()
    end = xy.loc[original.lines.to_bus].to_numpy()
    return np.stack([start, end], axis=1), reduced.line_map.to_numpy()


def _draw_network(ax, reduced: ReducedFeeder, widths: np.ndarray, colors) -> None:
    """Draw every original line; ``widths``/``colors`` per reduced line (pruned ones thin grey)."""
    segments, which = _segments(reduced)
    kept = which >= 0
    ax.add_collection(LineCollection(segments[~kept], colors="#cccccc", linewidths=0.4))
    colors = np.asarray(colors, dtype=object)
    ax.add_collection(
        LineCollection(
            segments[kept], colors=list(colors[which[kept]]), linewidths=widths[which[kept]],
            capstyle="round", joinstyle="round",  # wide lines join without gaps
        )
    )  # fmt: skip
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.04)
    ax.grid(False)
    ax.set_xticks([])
    ax.set_yticks([])


def _draw_loads_and_generators(
    ax, reduced: ReducedFeeder, labels: dict[str, str], offset: float = 5.0
) -> None:
    """Loads, the source and the generators, each labelled ``offset`` points from its marker
    towards the middle of the axes' current view (so no label runs over the frame)."""
    original = reduced.original
    load_xy = original.buses.loc[original.loads.bus, ["x", "y"]].to_numpy()
    ax.scatter(
        *load_xy.T, s=14, facecolors="none", edgecolors="#2c3e50", lw=0.7, zorder=3, label="load"
    )
    source = original.buses.loc[original.source_bus]
    ax.scatter(source.x, source.y, marker="s", s=40, color="black", zorder=4, label="source")
    gens = reduced.generators
    gen_xy = original.buses.loc[gens.bus, ["x", "y"]].to_numpy()
    ax.scatter(
        *gen_xy.T,
        marker="^",
        s=60,
        color="#f39c12",
        edgecolors="black",
        lw=0.6,
        zorder=5,
        label="generator",
    )
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    for name, (x, y) in zip(gens.index, gen_xy, strict=True):
        right, up = x <= (x0 + x1) / 2, y <= (y0 + y1) / 2
        ax.annotate(
            labels.get(name, name),
            (x, y),
            xytext=(offset if right else -offset, offset if up else -offset),
            textcoords="offset points",
            ha="left" if right else "right",
            va="bottom" if up else "top",
            fontsize=7,
            zorder=6,
            bbox=LABEL_BOX,
        )


def all_flows_kw(problem: DispatchProblem, setpoints_kw: np.ndarray, minute: int, load_kw):
    """Flow (kW, + away from the source) on every reduced line for set points in kW."""
    p_mw = np.asarray(setpoints_kw) / KW_PER_MW
    return problem.all_line_flows_mw(p_mw, minute, np.asarray(load_kw)) * KW_PER_MW


@styled
def feeder_flow_figure(
    problem: DispatchProblem, setpoints_kw: np.ndarray, minute: int, load_kw: np.ndarray
) -> Figure:
    """The reduced feeder on its coordinates; line widths proportional to |flow| at ``minute``."""
    reduced = problem.feeder
    flows = np.abs(all_flows_kw(problem, setpoints_kw, minute, load_kw))
    scale = 6.0 / max(flows.max(), 1e-9)
    fig, axes = new_figure(SINGLE, 3.6)
    ax = axes[0, 0]
    _draw_network(ax, reduced, 0.3 + flows * scale, ["#2471a3"] * len(flows))
    labels = {n: f"{n} {p:.1f} kW" for n, p in zip(problem.generators, setpoints_kw, strict=True)}
    _draw_loads_and_generators(ax, reduced, labels)
    for kw in (5, 20):
        ax.plot([], [], color="#2471a3", lw=0.3 + kw * scale, label=f"{kw} kW flow")
    ax.legend(loc="lower right", frameon=True)
    ax.set_title(
        f"Reduced feeder ({reduced.n_nodes} key nodes)\nline widths: flows at minute {minute}"
    )
    return fig


@styled
def congestion_detection_figure(
    problem: DispatchProblem,
    setpoints_kw: np.ndarray,
    minute: int,
    load_kw: np.ndarray,
    C: float,
    situation: str,
) -> Figure:
    """Node controllers at a congested limited path: the penalty side and the incentive side.

    ``setpoints_kw`` is the dispatch whose flows are measured (``situation`` says which).
    Lines are coloured by their side of the most overloaded limited line; the controllers at its
    two ends are marked with their eq.-8 values, and every generator with the sum of the signals
    it receives (EUR/MW). A caption under the panels says what the numbers are.
    """
    reduced = problem.feeder
    flows = all_flows_kw(problem, setpoints_kw, minute, load_kw)
    limited = flows[problem.lines]
    k = int(np.argmax(np.abs(limited) - problem.limit * KW_PER_MW))
    line = int(problem.lines[k])
    down = np.ascontiguousarray(problem.down)
    signal = broadcast_signals(limited / KW_PER_MW, problem.limit, down, float(C))
    child_sends = limited[k] < 0  # flow towards the source: the child side sends it
    is_limited = np.isin(np.arange(reduced.n_lines), problem.lines)
    colors = np.where(_subtree_lines(reduced, line) == child_sends, PENALTY, INCENTIVE)
    colors = np.where(is_limited, "black", colors)
    # square maps side by side: the map row as tall as a column is wide, the legend and the
    # caption right under it (a taller row leaves a band of white around square maps)
    fig = Figure(figsize=(DOUBLE, 5.0), layout="constrained")
    grid = fig.add_gridspec(2, 2, height_ratios=[3.6, 1.25])
    overview, zoom, foot = (fig.add_subplot(g) for g in (grid[0, 0], grid[0, 1], grid[1, :]))
    labels = {n: f"{n} {s:+.1f}" for n, s in zip(problem.generators, signal, strict=True)}
    for ax in (overview, zoom):
        _draw_network(ax, reduced, np.where(is_limited, 3.0, 0.9), colors)
    _zoom_to(zoom, problem.feeder.original.buses, _path_buses(problem))
    for ax, offset in ((overview, 6.0), (zoom, 10.0)):  # the zoom's clear of its controllers
        _draw_loads_and_generators(ax, reduced, labels, offset)
    controllers = _draw_controllers(zoom, problem, line, limited[k], C)
    limit_kw = problem.limit[k] * KW_PER_MW
    overview.plot([], [], color="black", lw=3, label=f"limited path (U = {limit_kw:g} kW)")
    overview.plot([], [], color=PENALTY, lw=1.5, label="penalty side (sends the overflow)")
    overview.plot([], [], color=INCENTIVE, lw=1.5, label="incentive side")
    handles = overview.get_legend_handles_labels()[0] + controllers
    foot.axis("off")
    foot.legend(handles=handles, loc="upper center", ncols=3)
    foot.text(
        0.5,
        0.0,
        signal_caption(abs(limited[k]), limit_kw, C),
        transform=foot.transAxes,
        ha="center",
        va="bottom",
        fontsize=7,
    )
    row = reduced.lines.loc[line]
    overview.set_title("Signal each generator receives, EUR/MW")
    zoom.set_title(
        f"Most overloaded line {int(row.from_bus)}-{int(row.to_bus)}: "
        f"{abs(limited[k]):.1f} kW, limit {limit_kw:g} kW"
    )
    fig.suptitle(f"Congestion detection ({situation})", fontsize=9)
    return fig


def signal_caption(flow_kw: float, limit_kw: float, C: float) -> str:
    """What the numbers of the congestion-detection figure are: quantity, unit and sign."""
    mw = (flow_kw - limit_kw) / KW_PER_MW
    value = mw * C
    text = (
        "Numbers: congestion signals s (eq. 8) in EUR/MW, added to a generator's fitness. "
        "Negative = penalty (the generator is pushed to produce less), positive = incentive "
        "(pushed to produce more).\nThe two ends of an overloaded line send \u2212(|flow| \u2212 U)"
        "\u00b7C to the side the flow comes from (penalty) and +(|flow| \u2212 U)\u00b7C to the "
        f"other side (incentive): ({flow_kw:.1f} \u2212 {limit_kw:g}) kW = {mw:.4f} MW, times "
        f"C = {C:g} EUR/MW\u00b2, gives \u2213{value:.1f} EUR/MW. A generator receives the "
        "sum over all overloaded limited lines of the path."
    )
    return "\n".join(textwrap.fill(part, 125) for part in text.split("\n"))


def _path_buses(problem: DispatchProblem) -> list[int]:
    """Original buses at the ends of the limited reduced lines."""
    rows = problem.feeder.lines.loc[problem.lines]
    return sorted(set(rows.from_bus.astype(int)) | set(rows.to_bus.astype(int)))


def _zoom_to(ax, buses, around: list[int], margin_m: float = 20.0) -> None:
    xy = buses.loc[around, ["x", "y"]].to_numpy()
    (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
    half = max(x1 - x0, y1 - y0) / 2 + margin_m
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    ax.set_xlim(cx - half, cx + half)
    ax.set_ylim(cy - half, cy + half)


def _draw_controllers(ax, problem: DispatchProblem, line: int, flow_kw: float, C: float) -> list:
    """Mark the node controllers at both ends of ``line`` (squares coloured by their eq.-8
    signal); returns legend handles naming each with its value (EUR/MW)."""
    row = problem.feeder.lines.loc[line]
    limit = problem.limit[list(problem.lines).index(line)] * KW_PER_MW
    buses = problem.feeder.original.buses
    handles = []
    for bus, measured in ((int(row.from_bus), flow_kw), (int(row.to_bus), -flow_kw)):
        value = overflow_signal(measured / KW_PER_MW, limit / KW_PER_MW, float(C))
        kind = "penalty" if value < 0 else "incentive"
        x, y = buses.loc[bus, ["x", "y"]]
        handles.append(
            ax.scatter(
                x,
                y,
                marker="s",
                s=90,
                facecolors="none",
                lw=1.8,
                zorder=7,
                edgecolors=PENALTY if value < 0 else INCENTIVE,
                label=f"controller at bus {bus}: sends {value:+.1f} EUR/MW ({kind})",
            )
        )
    return handles


def _subtree_lines(reduced: ReducedFeeder, line: int) -> np.ndarray:
    """Boolean per reduced line: is it below ``line`` (in the subtree of its child node)?"""
    tree = reduced.tree
    child = tree.line_child[line]
    first, size = tree.start[child], tree.size[child]
    position = tree.start[tree.line_child]
    return (position >= first) & (position < first + size)


# -- figures 4-6: set points against the DC-OPF -------------------------------------------------


def step_spans_h(steps: np.ndarray, timeline: Timeline | None = None) -> tuple[np.ndarray, ...]:
    """``(start, end)`` of each 1-based step, hours from midnight of the series' first day:
    from ``timeline`` (its step times and lengths: minutes of the ELV day, quarter hours of a
    SimBench year, ...), else one-minute steps from midnight."""
    steps = np.asarray(steps, dtype=np.int64)
    if timeline is None:
        return (steps - 1) / 60.0, steps / 60.0
    times = timeline.times
    if not isinstance(times, pd.TimedeltaIndex):  # dated: from the first day's midnight
        times = times - times[0].normalize()
    start = np.asarray(times[steps - 1].total_seconds(), dtype=float) / 3600.0
    return start, start + np.asarray(timeline.hours, dtype=float)[steps - 1]


def _time_label(start_h: np.ndarray, timeline: Timeline | None) -> str:
    """The x label: time of day (a series past its first day: since that day's midnight),
    naming a step length other than one minute."""
    label = "time of day, h"
    if len(start_h) and start_h.max() >= 24.0:
        dated = timeline is not None and isinstance(timeline.times, pd.DatetimeIndex)
        label = f"time since {timeline.times[0]:%Y-%m-%d} 00:00, h" if dated else "time, h"
    step = 1.0 if timeline is None else timeline.step_minutes
    if step is None:
        return f"{label} (steps of varying length)"
    return label if step == 1.0 else f"{label} ({step:g}-minute steps)"


@styled
def base_day_figure(
    result: DayComparison,
    buses: list[int],
    profile_source: str | None = None,
    timeline: Timeline | None = None,
) -> Figure:
    """Generator outputs over the day: dynamics solid, DC-OPF dashed, one panel per generator.

    ``buses``: the original bus of each generator (for the panel titles). Steps a generator
    is offline (``result.run.online``, e.g. ``--event``) are shaded. ``profile_source`` (default
    the run's) is named in the title: official or synthetic loads. ``timeline``: the series'
    step times and lengths (:class:`~popdispatch.feeder.profiles.Timeline`; default one-minute
    steps from midnight): each step's value is drawn at its end, in hours.
    """
    run = result.run
    starts, hours = step_spans_h(run.minutes, timeline)
    colors = generator_colors(run.generators)
    n = len(run.generators)
    ncols = 2 if n == 4 else min(n, 3)  # four as 2 x 2, not 3 + 1
    nrows = -(-n // ncols)
    fig, axes = new_figure(DOUBLE, 0.7 + 1.85 * nrows, nrows=nrows, ncols=ncols, sharex=True)
    bottoms = _panels_for(axes, n)
    opf = result.opf_kw
    online = np.asarray(run.online, dtype=bool).reshape(len(hours), -1)
    for k, (ax, name) in enumerate(zip(axes.flat, run.generators, strict=False)):
        _shade_offline(ax, (starts, hours), online[:, k])
        ax.plot(hours, run.setpoints_kw[:, k], color=colors[name], label="dynamics")
        ax.plot(hours, opf[:, k], color="black", ls="--", lw=0.7, alpha=0.8, label="DC-OPF")
        _readable_y(ax)
        ax.set_title(f"{name} (bus {buses[k]})" + ("" if online[:, k].all() else ", outage"))
        ax.set_ylabel("output, kW")
    _hours_axis(axes[0, 0], starts, hours)
    for ax in bottoms:
        ax.set_xlabel(_time_label(starts, timeline))
    handles = [
        Line2D([], [], color="grey", label="dynamics (colour per generator)"),
        Line2D([], [], color="black", ls="--", lw=0.7, label="DC-OPF"),
    ]
    if not online.all():
        handles.append(Patch(**OFFLINE, label="generator offline (event)"))
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles))
    source = profile_source or run.profile_source
    fig.suptitle(
        f"Generator output over the day: {run.settings.dynamics} dynamics (solid), "
        f"DC-OPF (dashed)\nloads: {source}",
        fontsize=9,
    )
    return fig


def _panels_for(axes: np.ndarray, n: int) -> list:
    """Keep the first ``n`` panels of a grid (row by row), remove the others; returns the
    lowest kept panel of each column, which shows the shared time axis."""
    nrows, ncols = axes.shape
    for ax in axes.flat[n:]:
        ax.remove()
    bottoms = []
    for col in range(ncols):
        rows = [r for r in range(nrows) if r * ncols + col < n]
        ax = axes[rows[-1], col]
        ax.tick_params(labelbottom=True)
        bottoms.append(ax)
    return bottoms


def _hours_axis(ax, starts: np.ndarray, ends: np.ndarray) -> None:
    """The whole day with ticks every 6 h; a shorter span (or a longer series) fills the
    (shared) axis. ``starts``/``ends``: the steps' spans, h."""
    first, last = (float(starts.min()), float(ends.max())) if len(ends) else (0, 24)
    if last - first >= 12.0 and last <= 24.0 + 1e-9:
        ax.set_xlim(0, 24)
        ax.set_xticks(range(0, 25, 6))
    else:
        ax.set_xlim(first, last)


def _readable_y(ax, min_span_kw: float = 1.0) -> None:
    """No offset notation, and at least ``min_span_kw`` of y range so that a generator
    chattering by watts around a limit does not fill the panel."""
    ax.ticklabel_format(axis="y", useOffset=False)
    lo, hi = ax.get_ylim()
    if hi - lo < min_span_kw:
        middle = (lo + hi) / 2
        ax.set_ylim(middle - min_span_kw / 2, middle + min_span_kw / 2)


OFFLINE = {"facecolor": "#bbbbbb", "alpha": 0.5, "hatch": "///", "edgecolor": "#777777", "lw": 0}


def _shade_offline(ax, spans: tuple[np.ndarray, np.ndarray], online: np.ndarray) -> None:
    """Shade the spans of consecutive simulated steps where the generator is offline
    (``spans``: each step's start and end, h)."""
    begin, end = spans
    off = np.concatenate([[False], ~online, [False]]).astype(int)
    starts, stops = np.flatnonzero(np.diff(off) == 1), np.flatnonzero(np.diff(off) == -1)
    for a, b in zip(starts, stops, strict=True):
        ax.axvspan(begin[a], end[b - 1], zorder=0, **OFFLINE)


def _iteration_axes(ax, run, opf_kw, colors) -> None:
    """Set points per iteration (solid, one marker shape per generator, markers staggered so
    lines on top of each other stay visible), the DC-OPF (dashed; coinciding values get
    interleaved dashes) and the generator names at the right end, spread apart."""
    iterations = np.arange(run.iterations + 1)
    n = len(run.generators)
    every = max(run.iterations // 8, 1)
    for k, name in enumerate(run.generators):
        ax.plot(
            iterations,
            run.trajectory_kw[:, k],
            color=colors[name],
            marker=MARKERS[k % len(MARKERS)],
            markersize=3.5,
            markevery=(k * every // n, every),
            label=name,
        )
    for k, dashes in _interleaved_dashes(opf_kw).items():
        ax.axhline(opf_kw[k], color=colors[run.generators[k]], ls=dashes, lw=0.9)
    _end_labels(ax, run.trajectory_kw[-1], run.generators, colors)
    ax.set_xlabel("iteration (0.01 s each)")
    ax.set_ylabel("set point, kW")
    ax.set_xlim(0, run.iterations)


MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*"]


def _interleaved_dashes(values_kw: np.ndarray, tol_kw: float = 0.05) -> dict[int, tuple]:
    """A dash pattern per finite value; values within ``tol_kw`` of each other take turns
    (dash 4 pt, gap 2 pt, each member offset by 6 pt), so every colour shows."""
    finite = [k for k in range(len(values_kw)) if np.isfinite(values_kw[k])]
    dashes: dict[int, tuple] = {}
    for k in sorted(finite, key=lambda i: values_kw[i]):
        group = [j for j in finite if abs(values_kw[j] - values_kw[k]) <= tol_kw]
        member = group.index(k)
        dashes[k] = (6.0 * member, (4.0, 6.0 * len(group) - 4.0))
    return dashes


def _end_labels(ax, values_kw: np.ndarray, names, colors, gap: float = 0.075) -> None:
    """Names at the right end of the lines, at their final values, pushed apart vertically
    (at least ``gap`` of the axes height) so that equal values do not overprint."""
    lo, hi = ax.get_ylim()
    span = max(hi - lo, 1e-9)
    order = np.argsort(values_kw, kind="stable")
    positions = (np.asarray(values_kw, dtype=float)[order] - lo) / span
    for i in range(1, len(positions)):
        positions[i] = max(positions[i], positions[i - 1] + gap)
    positions -= max(positions[-1] - 1.0, 0.0) if len(positions) else 0.0
    for slot, k in zip(positions, order, strict=True):
        ax.annotate(
            names[k],
            (1.0, values_kw[k]),
            xycoords=("axes fraction", "data"),
            xytext=(8.0, slot),
            textcoords=("offset points", "axes fraction"),
            fontsize=6.5,
            color=colors[names[k]],
            va="center",
            annotation_clip=False,
            arrowprops={
                "arrowstyle": "-",
                "color": colors[names[k]],
                "lw": 0.5,
                "relpos": (0.0, 0.5),
                "shrinkA": 1,
                "shrinkB": 0,
            },
        )


@styled
def congestion_figure(result: SnapshotComparison, title: str | None = None) -> Figure:
    """Set points per iteration (solid) and the DC-OPF (dashed); detection and convergence
    marked by vertical lines labelled in a band above the curves."""
    run = result.run
    fig, axes = new_figure(SINGLE, 3.2)
    ax = axes[0, 0]
    _headroom(ax, run.trajectory_kw, result.opf.p_kw)
    _iteration_axes(ax, run, result.opf.p_kw, generator_colors(run.generators))
    marks = (
        (run.first_congestion, "congestion detected", ":"),
        (run.converged_at, "converged", "-."),
    )
    for row, (it, label, style) in enumerate(m for m in marks if m[0] is not None):
        _mark_iteration(ax, it, f"{label} (iteration {it})", style, row, run.iterations)
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncols=3)
    reference = "DC-OPF (dashed)" if result.opf.status == "optimal" else "no DC-OPF (infeasible)"
    ax.set_title(title or f"Minute {run.minute}: set points (solid), {reference}")
    return fig


def _mark_iteration(ax, it: int, text: str, style: str, row: int, last: int) -> None:
    """A vertical line at iteration ``it``, labelled in row ``row`` of the band above the
    curves, on the side of the line with room."""
    right = it > 0.6 * last
    ax.axvline(it, color="grey", ls=style, lw=1.0)
    ax.annotate(
        text,
        (it, 0.985 - 0.075 * row),
        xycoords=("data", "axes fraction"),
        xytext=(-3 if right else 3, 0),
        textcoords="offset points",
        ha="right" if right else "left",
        va="top",
        fontsize=6.5,
    )


def _headroom(ax, trajectory_kw: np.ndarray, opf_kw: np.ndarray, band: float = 0.17) -> None:
    """y limits with a free band of ``band`` (axes fraction) above every curve, for labels."""
    values = np.concatenate([np.ravel(trajectory_kw), np.ravel(opf_kw)])
    values = values[np.isfinite(values)]
    lo, hi = float(values.min()), float(values.max())
    pad = 0.05 * max(hi - lo, 1.0)
    lo, hi = lo - pad, hi + pad
    ax.set_ylim(lo, hi + band / (1 - band) * (hi - lo))


@styled
def extinction_figure(result: ExtinctionResult) -> Figure:
    """Replicator against Smith dynamics from the same state with one generator at zero share."""
    colors = generator_colors(result.smith.generators)
    fig, axes = new_figure(DOUBLE, 2.8, ncols=2, sharey=True)
    runs = [result.replicator.trajectory_kw, result.smith.trajectory_kw]
    _headroom(axes[0, 0], np.concatenate(runs), result.opf.p_kw, band=0.0)
    for ax, run, title in (
        (axes[0, 0], result.replicator, "replicator"),
        (axes[0, 1], result.smith, "Smith"),
    ):
        _iteration_axes(ax, run, result.opf.p_kw, colors)
        ax.set_title(f"{title} dynamics, {result.generator} starts at zero")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncols=6)
    fig.suptitle("Extinction: set points (solid), DC-OPF (dashed)", fontsize=9)
    return fig


@styled
def voltage_profile_figure(
    profile_pu, setpoints_kw, costs: dict[str, float], vmin_pu: float, title: str,
    branches: str = "bus",
) -> Figure:  # fmt: skip
    """The ``voltage`` scenario: the AC voltage of every bus (``profile_pu``: index bus number,
    one column per dispatch, p.u.; a NaN row breaks the line between two branches) with the
    lower limit, and each dispatch's set points (``setpoints_kw``: index generator, same
    columns, kW; linear axis, each bar labelled with its value). One legend under both panels
    names each dispatch (one colour in both) with its cost (``costs``, EUR/h). ``branches``:
    the profile's x axis label."""
    fig, axes = new_figure(DOUBLE, 3.1, ncols=2, width_ratios=[1.6, 1.0])
    ax, bars = axes[0]
    styles = ["-o", "-s", "--^", ":x"]
    colors = [f"C{k}" for k in range(len(profile_pu.columns))]
    for k, column in enumerate(profile_pu.columns):
        ax.plot(profile_pu.index, profile_pu[column], styles[k % 4], color=colors[k], ms=2.5,
                label=f"{column}: {costs[column]:.3f} EUR/h")  # fmt: skip
    ax.axhline(vmin_pu, color="black", lw=0.8, ls=(0, (6, 3)), label=f"vmin {vmin_pu:g} p.u.")
    ax.set_xlabel(branches)
    ax.set_ylabel("AC voltage (p.u.)")
    ax.set_title(title)
    width = 0.8 / max(len(setpoints_kw.columns), 1)
    positions = np.arange(len(setpoints_kw.index))
    for k, column in enumerate(setpoints_kw.columns):
        offset = (k - (len(setpoints_kw.columns) - 1) / 2) * width
        values = [v if abs(v) >= 0.5 else 0.0 for v in setpoints_kw[column]]  # no "-0"
        drawn = bars.bar(positions + offset, values, width, color=colors[k])
        bars.bar_label(drawn, labels=[f"{v:.0f}" for v in values], rotation=90, padding=2,
                       fontsize=5.5)  # fmt: skip
    bars.set_xticks(positions, setpoints_kw.index)
    bars.set_ylabel("set point (kW)")
    bars.set_ylim(0, 1.18 * float(np.nanmax(setpoints_kw.to_numpy())))  # room for the labels
    bars.set_title("set points of each dispatch")
    fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncols=3,
               title="each dispatch and its cost with the AC losses")  # fmt: skip
    return fig
