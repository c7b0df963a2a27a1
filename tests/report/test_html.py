"""The interactive HTML report (issue 17): its numbers against independent yardsticks, its
input checks, and the page itself in a real browser (playwright driving Debian's
chromium-headless-shell).

The browser tests skip with a reason where no browser (or playwright) is present, except under
CI (``CI`` set), where a missing browser fails. ``POPDISPATCH_REPORT_SCREENSHOT=docs/img/
report.png`` also writes the ELV screenshot shown in docs/report.md.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import networkx as nx
import numpy as np
import pandas as pd
import pytest

from helpers import find_official_folder

pytest.importorskip(
    "plotly", reason='the HTML report needs plotly: pip install "popdispatch[html]"'
)

from popdispatch.errors import FeederError  # noqa: E402
from popdispatch.feeder import Feeder, make_fleet, reduce_feeder  # noqa: E402
from popdispatch.feeder.profiles import LoadProfiles  # noqa: E402
from popdispatch.game.controllers import overflow_signal  # noqa: E402
from popdispatch.game.problem import build_problem_from_loads  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402
from popdispatch.report.interactive import (  # noqa: E402
    day_report_html,
    snapshot_report_html,
    write_day_html,
)
from popdispatch.report.interactive.feeder_map import (  # noqa: E402
    STATE_COLORS,
    MapBuilder,
    bus_coordinates,
    map_figure,
)
from popdispatch.report.interactive.steps import (  # noqa: E402
    BINDING,
    all_flows_kw,
    day_steps,
    eq8_signals,
    frame_rows,
)
from popdispatch.report.summaries import day_summary  # noqa: E402
from popdispatch.runs import FeederSource, load_run, run_day_vs_opf, run_snapshot_vs_opf  # noqa: E402
from popdispatch.scenarios import CONGESTION_PATH  # noqa: E402

MINUTES = 12  # the small day: minutes 1..12


# -- a small feeder whose line L34 (4 kW) binds at some minutes -------------------------------


def small_feeder() -> Feeder:
    """README's five-bus feeder: the cheap G4 sits behind line L34, limited to 4 kW."""
    buses = pd.DataFrame({"x": [0.0, 1, 2, 3, 3], "y": [0.0, 0, 0, 1, -1]},
                         index=pd.Index([1, 2, 3, 4, 5], name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": [1, 2, 3, 3], "to_bus": [2, 3, 4, 5], "length_km": 0.1, "r_ohm": 0.03,
         "x_ohm": 0.01, "limit_kw": [np.inf, np.inf, 4.0, np.inf]},
        index=["L12", "L23", "L34", "L35"],
    )  # fmt: skip
    loads = pd.DataFrame({"bus": [2, 3, 5, 4]}, index=["home", "shop", "farm", "barn"])
    fleet = make_fleet([(1, 0, 5.0, 0.02, 0, 30), (4, 0, 1.0, 0.01, 0, 10),
                        (5, 0, 2.0, 0.02, 0, 10)])  # fmt: skip
    return Feeder("small", buses, lines, loads, source_bus=1, generators=fleet)


def small_loads_kw() -> np.ndarray:
    """(1440, 4) kW: the barn's load beside G4 falls from 9 to 1 kW over the first minutes, so
    G4's export over L34 reaches its 4 kW limit part-way; the rest of the day repeats minute
    12."""
    day = np.tile([6.0, 5.0, 8.0, 1.0], (1440, 1))
    day[:MINUTES, 3] = np.linspace(9.0, 1.0, MINUTES)
    return day


@pytest.fixture(scope="module")
def small():
    """``(problem, profiles, comparison)`` of the small feeder's first minutes, exact mode."""
    loads = small_loads_kw()
    feeder = reduce_feeder(small_feeder())
    problem = build_problem_from_loads(feeder, loads, "test loads")
    table = pd.DataFrame(loads, columns=feeder.original.loads.index,
                         index=pd.RangeIndex(1, 1441, name="minute"))  # fmt: skip
    profiles = LoadProfiles(table, "test loads")
    minutes = np.arange(1, MINUTES + 1)
    comparison = run_day_vs_opf(problem, RunSettings(mode="exact"), minutes)
    return problem, profiles, comparison


@pytest.fixture(scope="module")
def elv_day():
    """A short ieee-elv day around the peak (minutes 556..580) with the paper's congestion
    limit, exact mode: official profiles when present, else the shipped default ones."""
    folder = find_official_folder()
    span = np.arange(556, 581)
    problem, profiles = load_run(FeederSource(), folder, None, [CONGESTION_PATH], minutes=span)
    comparison = run_day_vs_opf(problem, RunSettings(mode="exact"), span)
    return problem, profiles, comparison


# -- the numbers ---------------------------------------------------------------------------


def networkx_flows_kw(feeder: Feeder, injection_kw: pd.Series) -> pd.Series:
    """Yardstick: each original line's DC flow (kW, + away from the source) as the net demand of
    the buses below it, from networkx's BFS tree (independent of popdispatch's tree code)."""
    tree = nx.bfs_tree(feeder.graph(), feeder.source_bus)
    flows = {}
    for name, a, b in zip(feeder.lines.index, feeder.lines.from_bus, feeder.lines.to_bus,
                          strict=True):  # fmt: skip
        child = b if tree.has_edge(a, b) else a
        below = nx.descendants(tree, child) | {child}
        flows[name] = -sum(injection_kw.get(bus, 0.0) for bus in below)
    return pd.Series(flows)


def test_line_flows_match_a_networkx_yardstick_on_the_elv(elv_day) -> None:
    problem, profiles, comparison = elv_day
    steps = day_steps(comparison, problem, profiles)
    row = 10  # minute 566
    original = problem.feeder.original
    load = profiles.for_loads(original.loads.index).at(int(steps.values[row]))
    injection = -load.groupby(original.loads.bus).sum()
    gen_bus = original.generators.bus
    injection = injection.add(pd.Series(steps.setpoints_kw[row], index=gen_bus.to_numpy()),
                              fill_value=0.0)  # fmt: skip
    expected = networkx_flows_kw(original, injection)
    line_map = problem.feeder.line_map
    kept = line_map[line_map >= 0]
    got = steps.flows_kw[row][kept.to_numpy()]
    np.testing.assert_allclose(got, expected[kept.index].to_numpy(), atol=1e-9)


def test_limited_flows_match_the_dc_opf_model(small) -> None:
    """The flows the map shows on limited lines equal the DC-OPF's ``load_flow - D p``."""
    problem, profiles, comparison = small
    steps = day_steps(comparison, problem, profiles)
    for row, minute in enumerate(steps.values):
        p_mw = comparison.run.setpoints_kw[row] / 1000.0
        np.testing.assert_allclose(
            steps.limited_flows_kw(problem)[row],
            problem.flows(p_mw, int(minute)) * 1000.0,
            atol=1e-9,
        )


def test_eq8_signals_match_the_controllers_kernel(small) -> None:
    problem = small[0]
    flows = np.array([[-9.0], [-4.5], [-4.0], [0.0], [3.99], [4.0], [4.01], [7.5]])
    got = eq8_signals(problem, flows, 1000.0)
    expected = [[overflow_signal(f / 1000.0, problem.limit[0], 1000.0)] for f in flows[:, 0]]
    np.testing.assert_allclose(got, expected, atol=1e-12)
    assert got[-1, 0] == pytest.approx(-3.5)  # (7.5 - 4) kW = 0.0035 MW times C = 1000


def test_congestion_is_there_and_gets_its_own_frames(small) -> None:
    """The test day binds L34 (the DC-OPF's dual is nonzero) and each change of its state
    gets a map frame even when regular frames are sparse."""
    problem, profiles, comparison = small
    steps = day_steps(comparison, problem, profiles)
    states = steps.line_states(problem)[:, 0]
    price = np.array([o.line_price[0] for o in comparison.opf])
    assert (states == BINDING).any() and (states == 0).any()
    assert np.all((np.abs(price) > 1e-6) == (states == BINDING))
    rows = frame_rows(steps, problem, every=100)
    changes = np.flatnonzero(states[1:] != states[:-1]) + 1
    assert set(changes) <= set(rows) and {0, MINUTES - 1} <= set(rows)


def generator_trace(figure: dict) -> int:
    return next(i for i, t in enumerate(figure["data"]) if t["name"].startswith("generators"))


def test_frames_carry_the_days_setpoints_and_dc_opf(small) -> None:
    problem, profiles, comparison = small
    steps = day_steps(comparison, problem, profiles)
    rows = np.arange(MINUTES)
    figure = map_figure(problem, steps, rows, [str(m) for m in steps.values])
    index = generator_trace(figure)
    for row, frame in zip(rows, figure["frames"], strict=True):
        assert frame["name"] == str(row + 1)
        data = frame["data"][frame["traces"].index(index)]["customdata"]
        np.testing.assert_allclose([d[0] for d in data], comparison.run.setpoints_kw[row],
                                   atol=5e-4)  # fmt: skip
        np.testing.assert_allclose([d[1] for d in data], comparison.opf_kw[row], atol=5e-4)


def test_controllers_show_the_state_of_the_line_they_measure(small) -> None:
    """L34's two controllers (buses 3 and 4) turn orange exactly where the DC-OPF's dual of
    L34 is nonzero (the dynamics hold the line at its limit) and say what they measure."""
    problem, profiles, comparison = small
    steps = day_steps(comparison, problem, profiles)
    builder = MapBuilder(problem, steps)
    builder.build_traces(0)
    index = builder.dynamic["controllers"][0]
    assert list(builder.ends) == [3, 4]
    for row, opf in enumerate(comparison.opf):
        update = builder.updates(row)[index]
        binding = abs(opf.line_price[0]) > 1e-6
        expected = STATE_COLORS[BINDING] if binding else STATE_COLORS[0]
        assert update["marker"]["color"] == [expected, expected]
        flow = steps.limited_flows_kw(problem)[row, 0]
        assert f"{flow:+.3f} kW" in update["customdata"][0]  # parent end: + leaves bus 3
        assert f"{-flow:+.3f} kW" in update["customdata"][1]


def test_infeasible_minutes_are_shown_without_a_dc_opf(small) -> None:
    """G1 (the source's 30 kW) offline at minutes 4-7: no DC-OPF exists; the frames keep the
    dynamics' set points, carry no DC-OPF and their titles say so."""
    problem, profiles, _ = small
    outage = problem.with_outage("G1", 4, 8, check=False)
    comparison = run_day_vs_opf(outage, RunSettings(mode="exact"), np.arange(1, MINUTES + 1))
    assert comparison.infeasible_minutes == [4, 5, 6, 7]
    text = day_report_html(comparison, outage, profiles)
    figure = _figure_json(text, "popdispatch-map")
    index = generator_trace(figure)
    for frame in figure["frames"]:
        data = frame["data"][frame["traces"].index(index)]["customdata"]
        minute = int(frame["name"])
        infeasible = minute in comparison.infeasible_minutes
        assert ("n/a (no DC-OPF)" in frame["layout"]["title"]["text"]) == infeasible
        assert all((d[1] is None) == infeasible for d in data)
        assert data[0][2] == ("offline" if 4 <= minute <= 7 else "online")
        np.testing.assert_allclose(
            [d[0] for d in data], comparison.run.setpoints_kw[minute - 1], atol=5e-4
        )


def test_a_large_feeder_draws_its_lines_once_and_colours_their_middles(small, monkeypatch):
    """Above MAX_LINE_TRACES reduced lines the map keeps one grey trace for all lines and shows
    the flows by the colour of the lines' middle markers (here forced on the small feeder)."""
    from popdispatch.report.interactive import feeder_map

    problem, profiles, comparison = small
    monkeypatch.setattr(feeder_map, "MAX_LINE_TRACES", 2)
    steps = day_steps(comparison, problem, profiles)
    builder = MapBuilder(problem, steps)
    traces = builder.build_traces(0)
    assert "lines" not in builder.dynamic
    assert sum(t["mode"] == "lines" for t in traces) == 3  # pruned, limited band, all lines
    middle = builder.dynamic["midpoints"][0]
    first, last = builder.updates(0)[middle], builder.updates(MINUTES - 1)[middle]
    np.testing.assert_allclose(first["marker"]["color"], np.abs(steps.flows_kw[0]), atol=5e-3)
    assert first["marker"]["color"] != last["marker"]["color"]


def test_a_dated_series_is_labelled_by_its_times(small, monkeypatch) -> None:
    """Steps of a dated 15-minute series are called steps and labelled by their start times;
    a series longer than the panels' MAX_POINTS draws fewer steps, the map's frames among
    them."""
    from popdispatch.feeder.profiles import Timeline
    from popdispatch.report.interactive import panels

    problem, profiles, comparison = small
    times = pd.date_range("2016-03-01 00:00", periods=1440, freq="15min")
    dated = LoadProfiles(profiles.kw, "dated", Timeline.from_times(times))
    monkeypatch.setattr(panels, "MAX_POINTS", 4)
    text = day_report_html(comparison, problem, dated, every_minutes=5)
    figure = _figure_json(text, "popdispatch-map")
    titles = {f["name"]: f["layout"]["title"]["text"] for f in figure["frames"]}
    for name, title in titles.items():
        assert title.startswith(f"step {name} ({times[int(name) - 1]:%Y-%m-%d %H:%M}): ")
    panel = _figure_json(text, "popdispatch-panels")
    drawn = panel["data"][0]["x"]
    assert len(drawn) < MINUTES and {int(n) for n in titles} <= set(drawn)
    labels = panel["data"][0]["customdata"]
    assert labels == [f"{times[step - 1]:%Y-%m-%d %H:%M}" for step in drawn]
    assert "of 12 steps, evenly spaced" in text
    # the slider and the header call a quarter hour a step, not a minute
    assert figure["layout"]["sliders"][0]["currentvalue"]["prefix"] == "step "
    info = {"case": "small", "first_minute": 1, "last_minute": 12, "step_minutes": 15.0}
    header = day_report_html(comparison, problem, dated, run_info=info).split("<script")[0]
    assert "<b>first step</b>1" in header and "<b>last step</b>12" in header
    assert "first minute" not in header


def test_panels_show_the_error_to_the_dc_opf_and_the_demand(small) -> None:
    """The error panel: the largest |set point - DC-OPF| per minute (down to 1e-9 kW on its
    log axis); the demand panel: the loads' sum."""
    problem, profiles, comparison = small
    panel = _figure_json(day_report_html(comparison, problem, profiles), "popdispatch-panels")
    traces = {t.get("name"): t for t in panel["data"]}
    error = np.abs(comparison.run.setpoints_kw - comparison.opf_kw).max(axis=1)
    np.testing.assert_allclose(traces["max error"]["y"], np.maximum(error, 1e-9), rtol=1e-3)
    demand = small_loads_kw()[:MINUTES].sum(axis=1)
    np.testing.assert_allclose(traces["demand"]["y"], demand, atol=5e-5)


def test_the_page_is_self_contained_and_names_the_run(small) -> None:
    problem, profiles, comparison = small
    info = {"case": "small", "mode": "exact", "limits": [{"from_bus": 3, "to_bus": 4,
            "limit_kw": 4.0}], "events": ["4:off@9"], "profile_source": "test loads"}  # fmt: skip
    text = day_report_html(comparison, problem, profiles, run_info=info)
    assert not re.search(r"<(script|link)[^>]+(src|href)=", text)  # nothing to fetch
    assert "plotly.js v" in text  # embedded (the browser test checks no request leaves)
    for shown in ("3-4 at 4 kW", "4:off@9", "test loads", "exact"):
        assert shown in text


def test_snapshot_frames_follow_the_trajectory(small) -> None:
    problem, profiles, _ = small
    comparison = run_snapshot_vs_opf(problem, MINUTES, RunSettings(mode="exact"))
    text = snapshot_report_html(comparison, problem, profiles)
    figure = _figure_json(text, "popdispatch-map")
    last = figure["frames"][-1]
    assert last["name"] == str(comparison.run.iterations)
    data = last["data"][last["traces"].index(generator_trace(figure))]["customdata"]
    np.testing.assert_allclose([d[0] for d in data], comparison.run.setpoints_kw, atol=5e-4)
    np.testing.assert_allclose([d[1] for d in data], comparison.opf.p_kw, atol=5e-4)


def _figure_json(text: str, div_id: str) -> dict:
    """The figure plotly.io.to_html wrote for ``div_id``: Plotly.newPlot's arguments."""
    start = re.search(rf'Plotly\.newPlot\(\s*"{div_id}",', text).end()
    body = text[start:]
    decoder = json.JSONDecoder()
    data, end = decoder.raw_decode(body.lstrip())
    rest = body.lstrip()[end:].lstrip(", \n")
    layout, end = decoder.raw_decode(rest)
    rest = rest[end:]
    frames_at = rest.index("Plotly.addFrames(") if "Plotly.addFrames(" in rest else -1
    frames = []
    if frames_at >= 0:
        after = rest[frames_at:].split(",", 1)[1].lstrip()
        frames, _ = decoder.raw_decode(after)
    return {"data": data, "layout": layout, "frames": frames}


# -- bad input and layouts ---------------------------------------------------------------------


def test_voltages_of_an_unknown_bus_are_refused_naming_it(small) -> None:
    problem, profiles, comparison = small
    voltages = pd.DataFrame({99: [1.0] * MINUTES}, index=np.arange(1, MINUTES + 1))
    with pytest.raises(FeederError, match="bus 99"):
        day_report_html(comparison, problem, profiles, voltages_pu=voltages)
    voltages = pd.DataFrame({2: [1.0]}, index=[700])
    with pytest.raises(FeederError, match="step 700"):
        day_report_html(comparison, problem, profiles, voltages_pu=voltages)
    voltages = pd.DataFrame({2: [230.0]}, index=[1])
    with pytest.raises(FeederError, match="230.0 p.u."):
        day_report_html(comparison, problem, profiles, voltages_pu=voltages)


def test_voltages_colour_the_buses(small) -> None:
    problem, profiles, comparison = small
    voltages = pd.DataFrame({2: np.linspace(0.95, 1.0, MINUTES), 5: 1.0},
                            index=np.arange(1, MINUTES + 1))  # fmt: skip
    steps = day_steps(comparison, problem, profiles, voltages)
    builder = MapBuilder(problem, steps)
    builder.build_traces(0)
    index = builder.dynamic["voltages"][0]
    first, last = builder.updates(0)[index], builder.updates(MINUTES - 1)[index]
    assert first["customdata"] == [0.95, 1.0] and last["customdata"] == [1.0, 1.0]
    assert first["marker"]["color"][0] != last["marker"]["color"][0]


def test_the_elv_map_is_drawn_on_its_own_coordinates() -> None:
    """As the static figures draw it: the ELV puts a few of its 906 buses on one spot, which
    must not turn the map into a tree layout (that one read upside down against them)."""
    from popdispatch.cases.builtin import ieee_elv

    feeder = ieee_elv()
    pd.testing.assert_frame_equal(bus_coordinates(feeder), feeder.buses[["x", "y"]].astype(float))


def test_a_feeder_without_coordinates_gets_a_layered_layout() -> None:
    feeder = small_feeder()
    flat = Feeder("flat", feeder.buses.assign(x=0.0, y=0.0), feeder.lines, feeder.loads, 1,
                  feeder.generators)  # fmt: skip
    xy = bus_coordinates(flat)
    assert xy.x.to_dict() == {1: 0, 2: 1, 3: 2, 4: 3, 5: 3}  # lines from the source
    assert len(np.unique(xy.to_numpy(), axis=0)) == 5
    assert xy.loc[3, "y"] == pytest.approx((xy.loc[4, "y"] + xy.loc[5, "y"]) / 2)
    pd.testing.assert_frame_equal(bus_coordinates(feeder), feeder.buses[["x", "y"]])


def test_all_flows_are_the_problems_own_flow_model(small) -> None:
    problem, profiles, comparison = small
    load = small_loads_kw()[:MINUTES]
    got = all_flows_kw(problem, comparison.run.setpoints_kw, load)
    for row in range(MINUTES):
        p_mw = comparison.run.setpoints_kw[row] / 1000.0
        expected = problem.all_line_flows_mw(p_mw, row + 1, load[row]) * 1000.0
        np.testing.assert_allclose(got[row], expected, atol=1e-9)


# -- in a real browser -----------------------------------------------------------------------


def browser_path() -> str:
    """chromium-headless-shell, or skip (outside CI) / fail (under CI) with the reason."""
    path = shutil.which("chromium-headless-shell") or "/usr/bin/chromium-headless-shell"
    reason = None
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        reason = "playwright is not installed (pip install -e '.[test]')"
    if reason is None and not Path(path).is_file():
        reason = "no chromium-headless-shell (apt-get install -y chromium-headless-shell)"
    if reason is not None:
        if os.environ.get("CI"):
            pytest.fail(f"CI must run the browser tests: {reason}")
        pytest.skip(reason)
    return path


@pytest.fixture(scope="module")
def browser():
    path = browser_path()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        chromium = playwright.chromium.launch(executable_path=path)
        yield chromium
        chromium.close()


def open_report(browser, path: Path):
    """A page showing the report; console errors and page errors collected in ``errors``."""
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.errors = []
    page.on(
        "request",
        lambda r: (
            r.url.startswith(("file:", "data:")) or page.errors.append(f"network request {r.url}")
        ),
    )
    page.on("console", lambda m: m.type == "error" and page.errors.append(m.text))
    page.on("pageerror", lambda e: page.errors.append(str(e)))
    page.goto(path.as_uri())
    page.wait_for_function(
        "() => { const m = document.getElementById('popdispatch-map');"
        " return m && m._transitionData && m._transitionData._frames.length > 0; }",
        timeout=60_000,
    )
    return page


MAP_STATE = """() => {
  const map = document.getElementById('popdispatch-map');
  const gens = map.data.findIndex(t => t.name.startsWith('generators'));
  const lines = map.data.map((t, i) => [t, i]).filter(([t]) => t.mode === 'lines'
      && t.showlegend === false).map(([t]) => t.line.color);
  return {active: map.layout.sliders[0].active, sizes: map.data[gens].marker.size,
          setpoints: map.data[gens].customdata.map(d => d[0]), lines: lines,
          cursor: document.getElementById('popdispatch-panels').layout.shapes[0].x0,
          title: map.layout.title.text};
}"""


def move_slider(page, fraction: float) -> None:
    """Click the map's slider rail at ``fraction`` of its length (a real mouse click)."""
    box = page.locator("#popdispatch-map .slider-rail-rect").bounding_box()
    page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)
    page.wait_for_timeout(300)


def test_the_report_renders_and_the_slider_moves_the_map(browser, elv_day, tmp_path) -> None:
    problem, profiles, comparison = elv_day
    path = write_day_html(tmp_path / "report.html", comparison, problem, profiles)
    page = open_report(browser, path)
    for div in ("popdispatch-map", "popdispatch-panels"):
        paths = page.locator(f"#{div} .main-svg .scatterlayer path").count()
        assert paths > 10, f"{div} drew {paths} paths"
    before = page.evaluate(MAP_STATE)
    assert before["active"] == len(page.evaluate("window.popdispatchReport.frames")) - 1
    move_slider(page, 0.0)
    after = page.evaluate(MAP_STATE)
    assert after["active"] == 0 and after["title"].startswith("minute 556 ")
    assert after["sizes"] != before["sizes"] and after["lines"] != before["lines"]
    np.testing.assert_allclose(after["setpoints"], comparison.run.setpoints_kw[0], atol=5e-4)
    assert after["cursor"] == 556  # the panels follow the map
    page.screenshot(path=str(tmp_path / "report.png"), full_page=True)
    assert (tmp_path / "report.png").stat().st_size > 50_000
    assert page.errors == []


def test_a_click_on_a_panel_moves_the_map(browser, small, tmp_path) -> None:
    problem, profiles, comparison = small
    path = write_day_html(tmp_path / "small.html", comparison, problem, profiles)
    page = open_report(browser, path)
    page.evaluate("document.getElementById('popdispatch-panels').emit('plotly_click',"
                  " {points: [{x: 3.2}]})")  # fmt: skip
    page.wait_for_timeout(300)
    state = page.evaluate(MAP_STATE)
    assert state["title"].startswith("minute 3 ")
    np.testing.assert_allclose(state["setpoints"], comparison.run.setpoints_kw[2], atol=5e-4)
    assert page.errors == []


def test_play_runs_through_the_frames(browser, small, tmp_path) -> None:
    problem, profiles, comparison = small
    path = write_day_html(tmp_path / "play.html", comparison, problem, profiles)
    page = open_report(browser, path)
    move_slider(page, 0.0)
    title = "document.getElementById('popdispatch-map').layout.title.text"
    page.wait_for_function(f"() => {title}.startsWith('minute 1 ')"
                           " && window.popdispatchReport.step === 1", timeout=60_000)  # fmt: skip
    page.get_by_text("\u25b6 play").click()
    # the frames the map draws (the step the link script follows), not the slider's active
    # step: under load plotly's slider can stay where it was clicked while the frames play
    page.wait_for_function("() => window.popdispatchReport.step >= 4", timeout=60_000)
    page.get_by_text("pause").click()
    page.wait_for_timeout(300)
    state = page.evaluate(MAP_STATE)
    assert state["cursor"] == float(state["title"].split()[1])  # the panels kept up
    assert page.errors == []


BUS_COLOURS = """() => {
  const map = document.getElementById('popdispatch-map');
  const i = map.data.findIndex(t => t.name === 'bus voltage');
  const node = [...map.querySelectorAll('.scatterlayer .trace')]
      .find(t => t.__data__ && t.__data__[0].trace.index === i);
  const bar = [...map.querySelectorAll('.colorbar')]
      .find(c => c.querySelector('.cbtitle').textContent.startsWith('voltage'));
  const gradient = document.getElementById(
      bar.querySelector('rect.cbfill').style.fill.match(/#([^"')]+)/)[1]);
  return {
    buses: map.data[i].text, fills: [...node.querySelectorAll('path.point')]
        .map(p => p.style.fill.match(/\\d+/g).map(Number)),
    cmin: map._fullData[i].marker.cmin, cmax: map._fullData[i].marker.cmax,
    from_bottom: gradient.getAttribute('y1') === '1' && gradient.getAttribute('y2') === '0',
    stops: [...gradient.querySelectorAll('stop')].map(s => [parseFloat(s.getAttribute('offset')),
        s.getAttribute('stop-color').match(/\\d+/g).map(Number)]),
  };
}"""


def colour_bar_at(stops: list, fraction: float) -> np.ndarray:
    """The colour bar's colour at ``fraction`` (0 = its cmin end) from its gradient's stops
    (offsets in percent, RGB), interpolated as the browser draws it."""
    offsets = np.array([offset for offset, _ in stops]) / 100.0
    rgb = np.array([colour for _, colour in stops], dtype=float)
    return np.array([np.interp(fraction, offsets, rgb[:, c]) for c in range(3)])


def test_a_bus_shows_the_colour_the_colour_bar_gives_its_voltage(browser, small, tmp_path):
    """Bus 2 at 0.93 p.u., bus 5 at 1.0 and bus 4 at 1.04: each marker as drawn has the colour
    the drawn colour bar shows at that voltage (the markers once ran red-low while the bar
    read red-high), the low bus blue and the high one red (docs/report.md)."""
    problem, profiles, comparison = small
    volts = {2: 0.93, 5: 1.0, 4: 1.04}
    voltages = pd.DataFrame(volts, index=np.arange(1, MINUTES + 1))
    path = write_day_html(tmp_path / "volts.html", comparison, problem, profiles,
                          voltages_pu=voltages)  # fmt: skip
    page = open_report(browser, path)
    drawn = page.evaluate(BUS_COLOURS)
    assert drawn["from_bottom"]  # offset 0 (cmin) at the bar's bottom
    assert drawn["cmin"] <= 0.93 and drawn["cmax"] >= 1.04
    for name, fill in zip(drawn["buses"], drawn["fills"], strict=True):
        volt = volts[int(name.split()[1])]
        fraction = (volt - drawn["cmin"]) / (drawn["cmax"] - drawn["cmin"])
        np.testing.assert_allclose(fill, colour_bar_at(drawn["stops"], fraction), atol=3.0,
                                   err_msg=name)  # fmt: skip
    low = drawn["fills"][drawn["buses"].index("bus 2")]
    high = drawn["fills"][drawn["buses"].index("bus 4")]
    assert low[2] > 2 * low[0] and high[0] > high[2]  # blue low, red high
    assert page.errors == []


def test_docs_screenshot(browser, elv_day, tmp_path) -> None:
    """docs/report.md's screenshot: the ELV around the peak with the map at minute 566. Written to
    ``$POPDISPATCH_REPORT_SCREENSHOT`` when set (docs/img/report.png), else to a tmp path."""
    problem, profiles, comparison = elv_day
    summary = day_summary(problem, comparison, [CONGESTION_PATH])
    path = write_day_html(tmp_path / "elv.html", comparison, problem, profiles, run_info=summary)
    page = open_report(browser, path)
    page.evaluate("Plotly.animate('popdispatch-map', ['566'], {mode: 'immediate',"
                  " frame: {duration: 0, redraw: true}, transition: {duration: 0}})")  # fmt: skip
    page.wait_for_timeout(500)
    assert page.evaluate(MAP_STATE)["cursor"] == 566
    target = Path(os.environ.get("POPDISPATCH_REPORT_SCREENSHOT") or tmp_path / "shot.png")
    page.set_viewport_size({"width": 1400, "height": 1500})
    page.screenshot(path=str(target))
    assert target.stat().st_size > 50_000
    assert page.errors == []
