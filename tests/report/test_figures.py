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
    from popdispatch.report.reproduce import peak_load_kw
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
