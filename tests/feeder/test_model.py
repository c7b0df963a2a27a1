"""Bad feeders and fleets are rejected with one-line messages naming the offending element."""

import numpy as np
import pandas as pd
import pytest

from popdispatch.errors import FeederError, FleetError, PopdispatchError
from popdispatch.feeder import Feeder, make_fleet, paper_fleet, read_fleet
from popdispatch.feeder.generators import FLEET_COLUMNS, TABLE_I

LINE_COLUMNS = ["from_bus", "to_bus", "length_km", "r_ohm", "x_ohm", "limit_kw"]

#    1 (source) -- 2 -- 3 -- 4
#                  |
#                  5
BASE_LINES = [
    ("L12", 1, 2, 0.10, 0.03, 0.01, np.inf),
    ("L23", 2, 3, 0.20, 0.06, 0.02, 30.0),
    ("L34", 3, 4, 0.05, 0.02, 0.01, np.inf),
    ("L25", 2, 5, 0.30, 0.09, 0.03, np.inf),
]


def parts(lines=None, extra_buses=(), loads=None, fleet=None, source=1):
    rows = BASE_LINES if lines is None else lines
    bus_ids = [1, 2, 3, 4, 5, *extra_buses]
    buses = pd.DataFrame(
        {"x": np.arange(len(bus_ids), dtype=float), "y": np.zeros(len(bus_ids))},
        index=pd.Index(bus_ids, name="bus"),
    )
    lines_df = pd.DataFrame(
        [r[1:] for r in rows],
        columns=LINE_COLUMNS,
        index=pd.Index([r[0] for r in rows], name="line"),
    )
    load_rows = loads if loads is not None else [("HOUSE4", 4), ("HOUSE5", 5)]
    loads_df = pd.DataFrame(
        {"bus": [b for _, b in load_rows]},
        index=pd.Index([n for n, _ in load_rows], name="load"),
    )
    if fleet is None:
        fleet = make_fleet([(1, 0.0, 5.0, 0.02, 0.0, 10.0), (3, 0.0, 1.0, 0.01, 0.0, 10.0)])
    return ("small", buses, lines_df, loads_df, source, fleet)


def fleet_with(name, **changes):
    fleet = make_fleet(
        [(1, 0.0, 5.0, 0.02, 0.0, 10.0), (3, 0.0, 1.0, 0.01, 0.0, 10.0)],
        names=["GRID", name],
    )
    for column, value in changes.items():
        fleet.loc[name, column] = value
    return fleet


def test_valid_small_feeder():
    feeder = Feeder(*parts())
    assert feeder.path_lines(4, 5) == ["L34", "L23", "L25"]
    assert feeder.path_lines(1, 1) == []
    assert feeder.graph().number_of_edges() == 4


# --- topology --------------------------------------------------------------------------------


@pytest.mark.parametrize("ends", [(4, 5), (1, 4), (5, 1)])
def test_meshed_feeder_names_the_closing_line(ends):
    lines = [*BASE_LINES, ("LOOPER", *ends, 0.1, 0.01, 0.01, np.inf)]
    with pytest.raises(FeederError, match="meshed") as exc:
        Feeder(*parts(lines))
    message = str(exc.value)
    assert "'LOOPER'" in message
    assert "\n" not in message
    for bus in ends:
        assert str(bus) in message


def test_disconnected_feeder_names_the_lonely_bus():
    with pytest.raises(FeederError, match="disconnected") as exc:
        Feeder(*parts(extra_buses=[77]))
    assert "bus 77" in str(exc.value)
    assert "source bus 1" in str(exc.value)


def test_disconnected_subtree_names_a_lonely_bus():
    # Bus 5 and bus 6 are joined to each other but not to the rest.
    lines = [*BASE_LINES[:3], ("L56", 5, 6, 0.1, 0.01, 0.01, np.inf), ("L16", 6, 5, 1, 1, 1, 1)]
    with pytest.raises(FeederError, match="parallel") as exc:
        Feeder(*parts(lines, extra_buses=[6]))
    assert "'L16'" in str(exc.value)
    lines = [*BASE_LINES[:3], ("L56", 5, 6, 0.1, 0.01, 0.01, np.inf)]
    with pytest.raises(FeederError, match="disconnected") as exc:
        Feeder(*parts(lines, extra_buses=[6]))
    assert "bus 5" in str(exc.value)


def test_parallel_line():
    lines = [*BASE_LINES, ("TWIN", 3, 2, 0.2, 0.06, 0.02, np.inf)]
    with pytest.raises(FeederError, match="parallel") as exc:
        Feeder(*parts(lines))
    assert "'TWIN'" in str(exc.value)


def test_self_loop():
    lines = [*BASE_LINES, ("SELFIE", 3, 3, 0.2, 0.06, 0.02, np.inf)]
    with pytest.raises(FeederError, match="itself") as exc:
        Feeder(*parts(lines))
    assert "'SELFIE'" in str(exc.value)


@pytest.mark.parametrize("end", [0, 1])
def test_line_ending_at_unknown_bus(end):
    ends = [3, 6]
    ends[end] = 666
    lines = [*BASE_LINES, ("STRAY", *ends, 0.2, 0.06, 0.02, np.inf)]
    with pytest.raises(FeederError, match="unknown bus") as exc:
        Feeder(*parts(lines, extra_buses=[6]))
    assert "'STRAY'" in str(exc.value) and "666" in str(exc.value)


def test_unknown_or_duplicate_source_and_buses():
    with pytest.raises(FeederError, match="source bus 42"):
        Feeder(*parts(source=42))
    name, buses, lines, loads, source, fleet = parts()
    buses = pd.concat([buses, buses.loc[[3]]])
    with pytest.raises(FeederError, match="bus 3 is defined twice"):
        Feeder(name, buses, lines, loads, source, fleet)


# --- line data --------------------------------------------------------------------------------


@pytest.mark.parametrize("column", ["length_km", "r_ohm", "x_ohm", "limit_kw"])
@pytest.mark.parametrize("value", [-1.0, np.nan])
def test_bad_line_data(column, value):
    lines = [list(r) for r in BASE_LINES]
    lines[2][1 + LINE_COLUMNS.index(column)] = value
    with pytest.raises(FeederError, match=f"invalid {column}") as exc:
        Feeder(*parts([tuple(r) for r in lines]))
    assert "'L34'" in str(exc.value)


@pytest.mark.parametrize(
    ("table", "dropped"),
    [("lines", ["limit_kw"]), ("lines", ["r_ohm", "x_ohm"]), ("loads", ["bus"]), ("buses", ["y"])],
)
def test_missing_table_columns_are_named_on_one_line(table, dropped):
    name, buses, lines, loads, source, fleet = parts()
    tables = {"buses": buses, "lines": lines, "loads": loads}
    tables[table] = tables[table].drop(columns=dropped)
    with pytest.raises(FeederError) as exc:
        Feeder(name, tables["buses"], tables["lines"], tables["loads"], source, fleet)
    message = str(exc.value)
    assert f"{table} table" in message and "\n" not in message
    assert all(column in message for column in dropped)


def test_with_line_limits():
    feeder = Feeder(*parts())
    limited = feeder.with_line_limits(pd.Series({"L23": 50.0, "L25": 7.5}))
    # L23 already had 30 kW: the smaller one stays.
    assert limited.lines.limit_kw.to_dict() == {
        "L12": np.inf,
        "L23": 30.0,
        "L34": np.inf,
        "L25": 7.5,
    }
    assert np.isinf(feeder.lines.loc["L25", "limit_kw"])  # the original is untouched
    with pytest.raises(FeederError, match="'NOPE'"):
        feeder.with_line_limits(pd.Series({"NOPE": 1.0}))
    with pytest.raises(FeederError, match="invalid limit_kw") as exc:
        feeder.with_line_limits(pd.Series({"L25": -3.0}))
    assert "'L25'" in str(exc.value)
    with pytest.raises(FeederError, match="invalid limit_kw") as exc:
        feeder.with_line_limits(pd.Series({"L12": np.nan}))
    assert "'L12'" in str(exc.value)


# --- loads and generators ------------------------------------------------------------------------


def test_load_on_unknown_bus():
    with pytest.raises(FeederError, match="unknown bus 99") as exc:
        Feeder(*parts(loads=[("HOUSE4", 4), ("GHOST", 99)]))
    assert "'GHOST'" in str(exc.value)


def test_generator_on_unknown_bus():
    with pytest.raises(FleetError, match="unknown bus") as exc:
        Feeder(*parts(fleet=fleet_with("DRIFTER", bus=12)))
    assert "'DRIFTER'" in str(exc.value) and "12" in str(exc.value)


@pytest.mark.parametrize("column", ["a", "b", "c", "pmin_kw", "pmax_kw"])
def test_negative_cost_or_limit(column):
    fleet = fleet_with("SPENDY", **{column: -0.5})
    if column == "pmax_kw":
        fleet.loc["SPENDY", "pmin_kw"] = -1.0  # keep pmin <= pmax; pmin is reported first
    with pytest.raises(FleetError, match="negative") as exc:
        Feeder(*parts(fleet=fleet))
    assert "'SPENDY'" in str(exc.value)
    assert ("pmin_kw" if column == "pmax_kw" else column) in str(exc.value)


@pytest.mark.parametrize("column", ["a", "b", "c", "pmin_kw", "pmax_kw"])
@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_cost_or_limit(column, value):
    with pytest.raises(FleetError, match=f"non-finite {column}") as exc:
        Feeder(*parts(fleet=fleet_with("WEIRD", **{column: value})))
    assert "'WEIRD'" in str(exc.value)


def test_pmin_above_pmax():
    with pytest.raises(FleetError, match="pmin_kw = 8.0 > pmax_kw = 4.0") as exc:
        Feeder(*parts(fleet=fleet_with("BACKWARDS", pmin_kw=8.0, pmax_kw=4.0)))
    assert "'BACKWARDS'" in str(exc.value)
    # Equal limits are fine (a must-run unit).
    Feeder(*parts(fleet=fleet_with("FLAT", pmin_kw=4.0, pmax_kw=4.0)))


def test_duplicate_generator_names():
    fleet = make_fleet(
        [(1, 0.0, 5.0, 0.02, 0.0, 10.0), (3, 0.0, 1.0, 0.01, 0.0, 10.0), (5, 0, 1, 0, 0, 1)],
        names=["SOLO", "TWINGEN", "TWINGEN"],
    )
    with pytest.raises(FleetError, match="defined twice") as exc:
        Feeder(*parts(fleet=fleet))
    assert "'TWINGEN'" in str(exc.value)


def test_empty_fleet_is_a_described_network_and_a_missing_column_an_error():
    assert Feeder(*parts(fleet=make_fleet([]))).generators.empty
    with pytest.raises(FleetError, match="'pmax_kw'"):
        Feeder(*parts(fleet=paper_fleet().drop(columns="pmax_kw")))


def test_with_generators_validates(elv):
    bad = paper_fleet()
    bad.loc["G739", "bus"] = 5000
    with pytest.raises(FleetError, match="'G739'.*5000"):
        elv.with_generators(bad)
    moved = paper_fleet()
    moved.loc["G739", "bus"] = 740
    assert elv.with_generators(moved).generators.loc["G739", "bus"] == 740
    assert elv.generators.loc["G739", "bus"] == 739


def test_errors_share_the_base_class():
    assert issubclass(FeederError, PopdispatchError) and issubclass(FeederError, ValueError)
    assert issubclass(FleetError, PopdispatchError) and issubclass(FleetError, ValueError)


# --- reading fleets -----------------------------------------------------------------------------


def _toml(rows, names=True):
    out = []
    for bus, a, b, c, pmin, pmax in rows:
        out.append("[[generator]]")
        if names:
            out.append(f'name = "G{bus}"')
        # Integers where the value is whole: the reader must still give float columns.
        out += [f"bus = {bus}", f"a = {a:g}", f"b = {b:g}", f"c = {c!r}"]
        out += [f"pmin_kw = {pmin:g}", f"pmax_kw = {pmax:g}", ""]
    return "\n".join(out)


def test_csv_round_trip(tmp_path):
    path = tmp_path / "fleet.csv"
    paper_fleet().rename_axis("name").to_csv(path)
    pd.testing.assert_frame_equal(read_fleet(path), paper_fleet())
    # Spaces after commas, upper-case headers, whole numbers and no name column.
    lines = ["BUS, A, B, C, Pmin_kW, Pmax_kW"]
    lines += [", ".join(f"{v:g}" for v in row) for row in TABLE_I]
    loose = tmp_path / "loose.csv"
    loose.write_text("\n".join(lines) + "\n")
    pd.testing.assert_frame_equal(read_fleet(str(loose)), paper_fleet())


def test_toml_round_trip(tmp_path, elv):
    path = tmp_path / "fleet.toml"
    path.write_text(_toml(TABLE_I))
    fleet = read_fleet(path)
    pd.testing.assert_frame_equal(fleet, paper_fleet())
    unnamed = tmp_path / "unnamed.TOML"
    unnamed.write_text(_toml(TABLE_I, names=False))
    pd.testing.assert_frame_equal(read_fleet(unnamed), paper_fleet())
    pd.testing.assert_frame_equal(elv.with_generators(fleet).generators, elv.generators)


@pytest.mark.parametrize("suffix", ["csv", "toml"])
def test_missing_column(tmp_path, suffix):
    path = tmp_path / f"fleet.{suffix}"
    if suffix == "csv":
        paper_fleet().drop(columns="c").to_csv(path)
    else:
        path.write_text(_toml(TABLE_I).replace("c = ", "cost = "))
    with pytest.raises(FleetError, match="lacks column 'c_eur_per_mw2h'") as exc:
        read_fleet(path)
    assert str(path) in str(exc.value)


@pytest.mark.parametrize("suffix", ["csv", "toml"])
def test_non_numeric_value(tmp_path, suffix):
    path = tmp_path / f"fleet.{suffix}"
    if suffix == "csv":
        table = paper_fleet().astype({"b": object})
        table.loc["G578", "b"] = "cheap"
        table.to_csv(path)
    else:
        path.write_text(_toml(TABLE_I).replace("b = 3", 'b = "cheap"'))
    with pytest.raises(FleetError, match="row 3 has non-numeric b = 'cheap'") as exc:
        read_fleet(path)
    assert str(path) in str(exc.value)


def test_missing_toml_key_is_reported(tmp_path):
    path = tmp_path / "fleet.toml"
    text = _toml(TABLE_I)
    text = text.replace("pmax_kw = 20\n", "")  # G817, the fifth generator, lacks pmax_kw
    path.write_text(text)
    with pytest.raises(FleetError, match="row 5 has non-numeric pmax_kw"):
        read_fleet(path)


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("absent.csv", None),
        ("absent.toml", None),
        ("empty.csv", b""),
        ("binary.csv", b"\xff\xfe\x00\x81\x93garbage"),
        ("binary.toml", b"\xff\xfe\x00\x81\x93garbage"),
        ("broken.toml", b"[[generator]\nbus = = 3\n"),
        ("ragged.csv", b'bus,a,b,c,pmin_kw,pmax_kw\n1,0,5,0.02,0,10\n"2,0,1\n'),
    ],
)
def test_unreadable_file(tmp_path, name, content):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(FleetError, match="cannot read fleet file") as exc:
        read_fleet(path)
    assert str(path) in str(exc.value)
    assert "\n" not in str(exc.value).strip()


def test_toml_without_generators(tmp_path):
    path = tmp_path / "fleet.toml"
    path.write_text('[site]\nname = "nothing here"\n')
    with pytest.raises(FleetError, match=r"no \[\[generator\]\] tables") as exc:
        read_fleet(path)
    assert str(path) in str(exc.value)


def test_fleet_columns_are_the_documented_ones():
    assert FLEET_COLUMNS == ["bus", "a", "b", "c", "pmin_kw", "pmax_kw"]
    fleet = paper_fleet()
    assert list(fleet.columns) == FLEET_COLUMNS
    assert fleet.index.name == "generator"
    assert fleet.bus.tolist() == [1, 114, 578, 739, 817, 835]
    assert fleet.pmax_kw.sum() == 65.0
