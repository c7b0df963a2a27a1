"""Figures a person can read (issue 10): lines on top of each other stay visible, legends and
labels do not cover data or each other, the signal values are explained, the day figure names
its loads and marks outages."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon, Rectangle
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from popdispatch.online import RunSettings
from popdispatch.report import figures

NAMES = pd.Index(["G1", "G114", "G578", "G739", "G817", "G835"])


def _render(fig):
    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


def _points(line: Line2D, per_segment: int = 40) -> np.ndarray:
    """Display coordinates along a drawn line (segments densified: axhline has two points)."""
    xy = line.get_transform().transform(np.asarray(line.get_xydata(), float))
    xy = xy[np.isfinite(xy).all(axis=1)]
    if len(xy) < 2:
        return xy
    t = np.linspace(0.0, 1.0, per_segment)[None, :, None]
    return (xy[:-1, None, :] * (1 - t) + xy[1:, None, :] * t).reshape(-1, 2)


def _covered(bbox, ax, lines=None) -> list[str]:
    """Labels of the data lines of ``ax`` with a point inside ``bbox`` (display units)."""
    hit = []
    for line in lines if lines is not None else ax.get_lines():
        xs = np.asarray(line.get_xdata(), float)
        if len(xs) == 2 and xs[0] == xs[1]:
            continue  # a vertical marker line: the one a label belongs to
        if bbox.count_contains(_points(line)):
            hit.append(line.get_label())
    return hit


def _marker_box(collection, dpi: float) -> Bbox:
    """Display box of a one-point scatter's marker (its edge line included)."""
    (x, y) = collection.get_offset_transform().transform(collection.get_offsets())[0]
    half = (np.sqrt(collection.get_sizes()[0]) / 2 + collection.get_linewidths()[0]) * dpi / 72
    return Bbox.from_extents(x - half, y - half, x + half, y + half)


def _snapshot(trajectory: np.ndarray, opf_kw: np.ndarray, first=1, converged=49):
    run = SimpleNamespace(
        minute=566,
        generators=NAMES,
        trajectory_kw=trajectory,
        iterations=len(trajectory) - 1,
        first_congestion=first,
        converged_at=converged,
    )
    return SimpleNamespace(run=run, opf=SimpleNamespace(p_kw=opf_kw, status="optimal"))


@pytest.fixture
def congested():
    """The congestion scenario's shape: G114 and G835 both at 10 kW all along."""
    t = np.arange(70)[:, None]
    start = np.full(6, 9.56)
    end = np.array([8.49, 10.0, 5.0, 3.87, 20.0, 10.0])
    trajectory = end + (start - end) * np.exp(-t / 8.0)
    trajectory[:, [1, 5]] = 10.0
    return _snapshot(trajectory, np.array([9.22, 10.0, 5.0, 3.14, 20.0, 10.0]))


# -- set points per iteration ----------------------------------------------------------------


def test_infeasible_snapshot_title_claims_no_dc_opf(congested):
    congested.opf.status = "infeasible"
    assert (
        figures.congestion_figure(congested).axes[0].get_title().endswith("no DC-OPF (infeasible)")
    )
    congested.opf.status = "optimal"
    assert figures.congestion_figure(congested).axes[0].get_title().endswith("DC-OPF (dashed)")


def test_overlapping_set_point_lines_stay_distinguishable(congested):
    fig = figures.congestion_figure(congested)
    _render(fig)
    ax = fig.axes[0]
    solid = {ln.get_label(): ln for ln in ax.get_lines() if ln.get_label() in NAMES}
    assert set(solid) == set(NAMES)
    assert len({ln.get_marker() for ln in solid.values()}) == len(NAMES)
    assert solid["G114"].get_markevery() != solid["G835"].get_markevery()
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    at_10 = [ln for ln in dashed if np.allclose(ln.get_ydata(), 10.0)]
    assert len(at_10) == 2  # the two DC-OPF lines at 10 kW take turns
    assert at_10[0]._dash_pattern[0] != at_10[1]._dash_pattern[0]


def test_end_labels_name_every_generator_without_overprinting(congested):
    fig = figures.congestion_figure(congested)
    renderer = _render(fig)
    ax = fig.axes[0]
    labels = {t.get_text(): t for t in ax.texts if t.get_text() in NAMES}
    assert set(labels) == set(NAMES)
    boxes = [Text.get_window_extent(t, renderer) for t in labels.values()]  # text, no leader
    for i, a in enumerate(boxes):
        assert not any(a.overlaps(b) for b in boxes[i + 1 :])


def test_detection_and_convergence_labels_cover_no_curve(congested):
    fig = figures.congestion_figure(congested)
    renderer = _render(fig)
    ax = fig.axes[0]
    notes = [t for t in ax.texts if "iteration" in t.get_text()]
    assert len(notes) == 2
    boxes = [t.get_window_extent(renderer) for t in notes]
    assert not boxes[0].overlaps(boxes[1])
    for box in boxes:
        assert _covered(box, ax) == []


def test_extinction_lines_at_the_same_value_stay_distinguishable(congested):
    runs = {k: congested.run for k in ("replicator", "smith")}
    result = SimpleNamespace(generator="G114", opf=congested.opf, **runs)
    fig = figures.extinction_figure(result)
    _render(fig)
    for ax in fig.axes:
        markers = {ln.get_marker() for ln in ax.get_lines() if ln.get_label() in NAMES}
        assert len(markers) == len(NAMES)


# -- figure 1 ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def peak_problem():
    from popdispatch.scenarios import elv_problem, peak_profiles

    return elv_problem(peak_profiles())


def test_fitness_legend_covers_no_curve(peak_problem):
    fig = figures.fitness_figure(peak_problem, "G739", 6.9, RunSettings().fitness)
    renderer = _render(fig)
    ax = fig.axes[0]
    legend = fig.legends[0] if fig.legends else ax.get_legend()
    curves = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
    assert len(curves) == 3
    assert _covered(legend.get_window_extent(renderer), ax, curves) == []


# -- figure 2 ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def detection_figure(peak_problem):
    from popdispatch.opf import solve_opf
    from popdispatch.reproduce import peak_load_kw
    from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem, peak_profiles

    problem = elv_problem(peak_profiles(), [CONGESTION_PATH])
    free = solve_opf(peak_problem, PEAK_MINUTE)
    fig = figures.congestion_detection_figure(
        problem, free.p_kw, PEAK_MINUTE, peak_load_kw(problem), 1000.0, "test"
    )
    return fig, _render(fig)


def test_detection_figure_explains_the_signal_values(detection_figure):
    fig, _ = detection_figure
    text = " ".join(t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text")))
    assert "EUR/MW" in text and "penalty" in text and "incentive" in text
    assert "fitness" in text  # what the number does
    assert "(34.9 \u2212 28) kW = 0.0069 MW" in text  # the worked value of the controllers
    assert "\u22136.9 EUR/MW" in text


def test_detection_figure_labels_leave_the_controllers_visible(detection_figure):
    fig, renderer = detection_figure
    zoom = next(ax for ax in fig.axes if ax.get_title().startswith("Most overloaded"))
    squares = [c for c in zoom.collections if c.get_label().startswith("controller at bus")]
    assert len(squares) == 2
    boxes = [_marker_box(c, fig.dpi) for c in squares]
    labels = [t for t in zoom.texts if t.get_visible() and t.get_text()]
    inside = [t for t in labels if zoom.bbox.overlaps(t.get_window_extent(renderer))]
    assert inside  # the zoom does label its generators
    for text in inside:
        extent = text.get_window_extent(renderer)
        assert not any(extent.overlaps(b) for b in boxes), text.get_text()


def _labels_inside(ax, renderer) -> list[str]:
    """Generator labels of a map whose marker is in view but whose text runs over the frame."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    out = []
    for text in ax.texts:
        x, y = text.xy
        if x0 <= x <= x1 and y0 <= y <= y1:
            box = text.get_window_extent(renderer)
            frame = ax.get_window_extent(renderer)
            if not (frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0
                    and box.y1 <= frame.y1):  # fmt: skip
                out.append(text.get_text())
    return out


def test_detection_figure_labels_stay_inside_their_maps(detection_figure):
    fig, renderer = detection_figure
    maps = [ax for ax in fig.axes if ax.axison and ax.texts]
    assert len(maps) == 2
    for ax in maps:
        assert _labels_inside(ax, renderer) == [], ax.get_title()


def test_detection_figure_has_no_empty_band_above_its_legend(detection_figure):
    """The square maps fill their row: the legend starts right under them (at most 0.25 in
    of white between the lower map frame and the legend)."""
    fig, renderer = detection_figure
    maps = [ax.get_window_extent(renderer) for ax in fig.axes if ax.axison]
    legend = next(lg for ax in fig.axes if (lg := ax.get_legend())).get_window_extent(renderer)
    gap = min(box.y0 for box in maps) - legend.y1
    assert 0 <= gap <= 0.25 * fig.dpi


@pytest.fixture(scope="module")
def flow_figure(peak_problem):
    from popdispatch.opf import solve_opf
    from popdispatch.reproduce import peak_load_kw
    from popdispatch.scenarios import PEAK_MINUTE

    opf = solve_opf(peak_problem, PEAK_MINUTE)
    fig = figures.feeder_flow_figure(peak_problem, opf.p_kw, PEAK_MINUTE,
                                     peak_load_kw(peak_problem))  # fmt: skip
    return fig, _render(fig)


def test_flow_figure_labels_stay_inside_the_map(flow_figure):
    fig, renderer = flow_figure
    assert _labels_inside(fig.axes[0], renderer) == []
    assert any(t.get_text().startswith("G1 ") for t in fig.axes[0].texts)


def test_wide_flow_lines_are_drawn_without_gaps_at_their_joints(flow_figure):
    """Each original line is its own segment: with butt ends a wide line shows a white notch
    at every joint of a bend; round ends and joins close them."""
    from matplotlib.collections import LineCollection

    fig, _ = flow_figure
    wide = [c for c in fig.axes[0].collections
            if isinstance(c, LineCollection) and max(c.get_linewidths()) > 2]  # fmt: skip
    assert wide
    for collection in wide:
        assert collection.get_capstyle() == "round" and collection.get_joinstyle() == "round"


def test_detection_figure_text_blocks_do_not_overlap(detection_figure):
    fig, renderer = detection_figure
    blocks = [lg.get_window_extent(renderer) for ax in fig.axes if (lg := ax.get_legend())]
    blocks += [ax.get_window_extent(renderer) for ax in fig.axes if ax.axison]
    caption = [t for ax in fig.axes for t in ax.texts if t.get_text().startswith("Numbers")]
    assert len(caption) == 1
    blocks.append(caption[0].get_window_extent(renderer))
    for i, a in enumerate(blocks):
        assert not any(a.overlaps(b) for b in blocks[i + 1 :])
        assert fig.bbox.contains(a.x0, a.y0) and fig.bbox.contains(a.x1, a.y1)


# -- figure 4 ---------------------------------------------------------------------------------


def _day(online: np.ndarray, source: str):
    minutes = np.arange(1, len(online) + 1)
    setpoints = np.where(online, 5.0, 0.0)
    run = SimpleNamespace(
        minutes=minutes,
        generators=NAMES,
        setpoints_kw=setpoints,
        online=online,
        settings=RunSettings(),
        profile_source=source,
    )
    return SimpleNamespace(run=run, opf_kw=setpoints)


@pytest.mark.parametrize("source", ["official profiles: /data/ieee-elv", "synthetic (seed 3)"])
def test_day_figure_names_its_loads(source):
    fig = figures.base_day_figure(_day(np.ones((120, 6), bool), source), list(range(6)))
    assert source in fig.get_suptitle()
    other = figures.base_day_figure(_day(np.ones((120, 6), bool), "x"), list(range(6)), source)
    assert source in other.get_suptitle()


def test_day_figure_marks_outages():
    online = np.ones((1440, 6), bool)
    online[599:719, 4] = False  # G817 off at minute 600, back at 720
    fig = figures.base_day_figure(_day(online, "synthetic"), list(range(6)))
    _render(fig)
    spans = {
        ax.get_title(): [p for p in ax.patches if isinstance(p, Polygon | Rectangle)]
        for ax in fig.axes
    }
    marked = {title for title, patches in spans.items() if patches}
    assert marked == {"G817 (bus 4), outage"}
    (span,) = spans["G817 (bus 4), outage"]
    if isinstance(span, Polygon):
        xs = span.get_xy()[:, 0]
    else:
        xs = [span.get_x(), span.get_x() + span.get_width()]
    assert min(xs) == pytest.approx(599 / 60) and max(xs) == pytest.approx(719 / 60)
    legend = " ".join(t.get_text() for t in fig.legends[0].get_texts())
    assert "offline" in legend
    quiet = figures.base_day_figure(_day(np.ones((1440, 6), bool), "synthetic"), list(range(6)))
    assert "offline" not in " ".join(t.get_text() for t in quiet.legends[0].get_texts())


def test_day_figure_fits_a_short_span_and_keeps_plain_kw_ticks():
    day = _day(np.ones((241, 6), bool), "synthetic")
    day.run.minutes = np.arange(540, 781)
    day.run.setpoints_kw[:, 1] = 10.0 + 0.005 * np.sin(np.arange(241))  # watts of chatter
    fig = figures.base_day_figure(day, list(range(6)))
    _render(fig)
    assert fig.axes[0].get_xlim() == pytest.approx((539 / 60, 780 / 60))
    g114 = fig.axes[1]
    low, high = g114.get_ylim()
    assert high - low >= 1.0 - 1e-9
    assert g114.yaxis.get_offset_text().get_text() == ""  # no "+1e1" above the panel


def test_day_figure_uses_the_series_step_length():
    """A day of 15-minute steps (SimBench) spans 24 h, not 96 minutes; an outage of steps
    41-48 is shaded over 10:00-12:00 (the timeline's own times: the yardstick)."""
    from popdispatch.feeder.profiles import Timeline

    times = pd.date_range("2016-01-01", periods=96, freq="15min")
    timeline = Timeline.from_times(times)
    online = np.ones((96, 6), bool)
    online[40:48, 2] = False
    fig = figures.base_day_figure(_day(online, "simbench"), list(range(6)), timeline=timeline)
    _render(fig)
    line = fig.axes[0].get_lines()[0]
    assert line.get_xdata()[0] == pytest.approx(0.25) and line.get_xdata()[-1] == pytest.approx(24)
    assert fig.axes[0].get_xlim() == pytest.approx((0, 24))
    assert "15-minute steps" in fig.axes[-1].get_xlabel()
    (span,) = [p for p in fig.axes[2].patches if isinstance(p, Polygon | Rectangle)]
    xs = (
        span.get_xy()[:, 0]
        if isinstance(span, Polygon)
        else [span.get_x(), span.get_x() + span.get_width()]
    )
    assert min(xs) == pytest.approx(10.0) and max(xs) == pytest.approx(12.0)
    # a week of such steps: hours since the first day's midnight
    week = Timeline.from_times(pd.date_range("2016-01-04", periods=672, freq="15min"))
    fig = figures.base_day_figure(_day(np.ones((672, 6), bool), "x"), list(range(6)),
                                  timeline=week)  # fmt: skip
    assert fig.axes[0].get_lines()[0].get_xdata()[-1] == pytest.approx(168)
    assert fig.axes[-1].get_xlabel().startswith("time since 2016-01-04 00:00, h")


@pytest.mark.parametrize("n", [1, 2, 4, 5])
def test_day_figure_has_one_panel_per_generator_and_no_empty_one(n):
    """A fleet of four draws four panels (2 x 2), five draws five: no panel left empty on its
    default 0-1 axes; each column's lowest panel carries the time axis."""
    online = np.ones((120, n), bool)
    day = _day(np.ones((120, 6), bool), "x")
    day.run.generators = NAMES[:n]
    day.run.setpoints_kw = day.run.setpoints_kw[:, :n]
    day.run.online = online
    day.opf_kw = day.run.setpoints_kw
    fig = figures.base_day_figure(day, list(range(n)))
    _render(fig)
    assert len(fig.axes) == n
    for ax in fig.axes:
        assert ax.get_lines() and ax.get_ylim() != (0.0, 1.0)
    labelled = [ax for ax in fig.axes if ax.get_xlabel()]
    columns = {round(ax.get_position().x0, 3) for ax in fig.axes}
    assert len(labelled) == len(columns)
    for ax in labelled:
        assert any(t.get_text() for t in ax.get_xticklabels())


# -- figure 7 ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def voltage_figure():
    """Figure 7's shape: case33bw's buses, four dispatches, the source and four DGs (one with
    a rounding residue below zero)."""
    buses = np.arange(1, 34, dtype=float)
    profile = pd.DataFrame(
        {
            name: 1.0 - 0.002 * k * buses
            for k, name in enumerate(
                ["DC exact", "voltage-aware", "AC OPF", "AC-corrected"], start=1
            )
        },
        index=buses,
    )
    points = pd.DataFrame(
        {
            "DC exact": [3715.0, 0, 0, 0, 0],
            "voltage-aware": [2727.7, 392.1, 595.2, 0, 0],
            "AC OPF": [2786.7, 408.6, 600.0, 0, 31.2],
            "AC-corrected": [2786.7, 408.5, 600.0, -0.02, 31.1],
        },
        index=["source", "DG18", "DG33", "DG25", "DG30"],
    )
    costs = dict(zip(points.columns, [86.0, 104.4, 105.7, 105.7], strict=True))
    from popdispatch.reproduce import branch_label

    label = branch_label(list(range(1, 34)), [19, 23, 26], {19: 2, 23: 3, 26: 6})
    fig = figures.voltage_profile_figure(profile, points, costs, 0.95, "case33bw", label)
    return fig, _render(fig)  # fmt: skip


def test_voltage_figure_legend_covers_no_data(voltage_figure):
    fig, renderer = voltage_figure
    (legend,) = fig.legends
    box = legend.get_window_extent(renderer)
    for ax in fig.axes:
        assert not box.overlaps(ax.get_window_extent(renderer))
    assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1)
    names = [t.get_text() for t in legend.get_texts()]
    assert "DC exact: 86.000 EUR/h" in names and "vmin 0.95 p.u." in names


def test_voltage_figure_bars_read_in_plain_kw(voltage_figure):
    """A linear axis (a symlog one read 0, 10^2, 10^3) and each bar's value written on it,
    never "-0"."""
    fig, renderer = voltage_figure
    bars = fig.axes[1]
    assert bars.get_yscale() == "linear"
    values = [t.get_text() for t in bars.texts]
    assert "3715" in values and "31" in values and "-0" not in values


def test_voltage_figure_x_label_says_which_buses_are_which_branch(voltage_figure):
    fig, renderer = voltage_figure
    label = fig.axes[0].get_xlabel()
    assert "main feeder 1-18" in label
    assert "laterals 19-22 (from bus 2), 23-25 (from bus 3), 26-33 (from bus 6)" in label
    box = fig.axes[0].xaxis.label.get_window_extent(renderer)
    assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1)
