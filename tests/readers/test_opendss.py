"""The strict OpenDSS reader of the IEEE European LV Test Feeder (popdispatch.readers.opendss)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch.cases.builtin import ieee_elv
from popdispatch.errors import FeederError
from popdispatch.feeder.generators import paper_fleet
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.readers import read_opendss_feeder

from helpers import MISSING_OFFICIAL, find_official_folder

OFFICIAL = find_official_folder()
needs_official = pytest.mark.skipif(OFFICIAL is None, reason=MISSING_OFFICIAL)


@pytest.fixture(scope="module")
def dss_feeder():
    return read_opendss_feeder(OFFICIAL)


@pytest.fixture(scope="module")
def pp_feeder():
    return ieee_elv()


@needs_official
def test_same_feeder_as_pandapower(dss_feeder, pp_feeder):
    a, b = dss_feeder, pp_feeder
    assert a.name == "ieee-elv"
    assert a.source_bus == b.source_bus == 1
    assert (len(a.buses), len(a.lines), len(a.loads)) == (906, 905, 55)
    assert a.buses.index.name == "bus" and list(a.buses.index) == list(range(1, 907))
    pd.testing.assert_index_equal(a.buses.index, b.buses.index)
    np.testing.assert_allclose(a.buses[["x", "y"]], b.buses[["x", "y"]], rtol=1e-12)
    pd.testing.assert_index_equal(a.lines.index, b.lines.index)
    assert a.lines.index[0] == "LINE1"
    pd.testing.assert_frame_equal(
        a.lines[["from_bus", "to_bus"]], b.lines[["from_bus", "to_bus"]], check_dtype=False
    )
    assert np.isinf(a.lines.limit_kw).all()
    pd.testing.assert_frame_equal(a.loads, b.loads, check_dtype=False)
    assert list(a.loads.index[:2]) == ["LOAD1", "LOAD2"]
    assert a.loads.loc["LOAD1", "bus"] == 34
    pd.testing.assert_frame_equal(a.generators, paper_fleet())


@needs_official
def test_first_line_numbers(dss_feeder):
    # LINE1: 1 -> 2, 4c_70 (R1 = 0.446, X1 = 0.071 ohm/km), 1.098 m
    line = dss_feeder.lines.loc["LINE1"]
    assert line.length_km == pytest.approx(1.098e-3, rel=1e-15)
    assert line.r_ohm == pytest.approx(0.446 * 1.098e-3, rel=1e-15)
    assert line.x_ohm == pytest.approx(0.071 * 1.098e-3, rel=1e-15)


@needs_official
def test_pandapower_holds_the_opendss_values_in_single_precision(dss_feeder):
    """pandapower stores length_km and r/x per km as float32-rounded copies of the OpenDSS data."""
    from popdispatch.cases.builtin import _elv_net

    line = _elv_net().line
    ours = dss_feeder.lines
    length = ours.length_km.to_numpy()
    # pandapower's JSON keeps the float32 values rounded to 15 decimals
    np.testing.assert_allclose(
        np.float32(length).astype(float), line.length_km.to_numpy(), rtol=0, atol=5.1e-16
    )
    for ohm, per_km in (("r_ohm", "r_ohm_per_km"), ("x_ohm", "x_ohm_per_km")):
        exact = ours[ohm].to_numpy() / length
        np.testing.assert_allclose(
            np.float32(exact).astype(float), line[per_km].to_numpy(), rtol=1e-12
        )
    # so the two sources differ by float32 rounding only: at most 2 x 2**-24 relative
    for column in ("length_km", "r_ohm", "x_ohm"):
        rel = np.abs(ours[column] / ieee_elv().lines[column] - 1)
        assert 1e-9 < rel.max() < 2.0**-23


def _float32_like_pandapower(feeder):
    lines = feeder.lines.copy()
    length = np.float32(lines.length_km.to_numpy()).astype(float)
    for column in ("r_ohm", "x_ohm"):
        per_km = np.float32(lines[column].to_numpy() / lines.length_km.to_numpy()).astype(float)
        lines[column] = per_km * length
    lines["length_km"] = length
    return feeder.__class__(
        feeder.name, feeder.buses, lines, feeder.loads, feeder.source_bus, feeder.generators
    )


@needs_official
def test_reduced_feeders_identical(dss_feeder, pp_feeder):
    ra, rb = reduce_feeder(dss_feeder), reduce_feeder(pp_feeder)
    assert (ra.n_nodes, ra.n_lines) == (110, 109)
    assert (rb.n_nodes, rb.n_lines) == (110, 109)
    np.testing.assert_array_equal(ra.nodes.bus, rb.nodes.bus)
    topo = ["from_node", "to_node", "from_bus", "to_bus", "n_original"]
    np.testing.assert_array_equal(ra.lines[topo], rb.lines[topo])
    np.testing.assert_array_equal(ra.loads.node, rb.loads.node)
    for column in ("length_km", "r_ohm", "x_ohm"):
        # raw: the float32 rounding of pandapower's data shows (< 1.2e-7 relative)
        np.testing.assert_allclose(ra.lines[column], rb.lines[column], rtol=1.2e-7)
    # with the OpenDSS numbers rounded the way pandapower stores them: identical within 1e-9
    rc = reduce_feeder(_float32_like_pandapower(dss_feeder))
    for column in ("length_km", "r_ohm", "x_ohm"):
        np.testing.assert_allclose(rc.lines[column], rb.lines[column], rtol=1e-9, atol=0)


@needs_official
def test_cross_check_with_opendssdirect(dss_feeder, tmp_path):
    """OpenDSSDirect cannot load the distribution as is (backslash, capital L) but, with the load
    shapes redefined, agrees with the strict reader on every line and load."""
    dss = pytest.importorskip("opendssdirect")
    folder = OFFICIAL.resolve()
    dss.Text.Command("clear")
    dss.Text.Command("new circuit.LVTest")
    with pytest.raises(Exception, match="could not be opened"):
        dss.Text.Command(f"redirect {folder / 'LoadShapes.txt'}")
    dss.Text.Command("clear")
    dss.Text.Command("new circuit.LVTest")
    dss.Text.Command(f"redirect {folder / 'LineCode.txt'}")
    for n in range(1, 56):
        dss.Text.Command(
            f"New Loadshape.Shape_{n} npts=1440 minterval=1 "
            f"mult=(file={folder / 'Daily_1min_100profiles' / f'load_profile_{n}.txt'})"
        )
    for name in ("Lines.txt", "Transformers.txt", "Loads.txt"):
        dss.Text.Command(f"redirect {folder / name}")
    assert dss.Lines.Count() == 905 and dss.Loads.Count() == 55
    rows = []
    index = dss.Lines.First()
    while index:
        assert dss.Lines.Units() == 4  # metres; R1, X1 in ohm per metre
        rows.append(
            (dss.Lines.Name(), int(dss.Lines.Bus1()), int(dss.Lines.Bus2()),
             dss.Lines.Length() / 1000, dss.Lines.R1() * dss.Lines.Length(),
             dss.Lines.X1() * dss.Lines.Length())
        )  # fmt: skip
        index = dss.Lines.Next()
    theirs = pd.DataFrame(rows, columns=["name", "from_bus", "to_bus", "length_km", "r", "x"])
    ours = dss_feeder.lines.loc[theirs.name.str.upper()]
    np.testing.assert_array_equal(theirs.from_bus, ours.from_bus)
    np.testing.assert_array_equal(theirs.to_bus, ours.to_bus)
    np.testing.assert_allclose(theirs.length_km, ours.length_km, rtol=1e-12)
    np.testing.assert_allclose(theirs.r, ours.r_ohm, rtol=1e-12)
    np.testing.assert_allclose(theirs.x, ours.x_ohm, rtol=1e-12)
    loads = {}
    index = dss.Loads.First()
    while index:
        loads[dss.Loads.Name().upper()] = int(dss.CktElement.BusNames()[0].split(".")[0])
        index = dss.Loads.Next()
    assert loads == dss_feeder.loads.bus.to_dict()


# -- strict reader on small synthetic folders ----------------------------------------------------

GOOD = {
    "LineCode.txt": "New LineCode.lc nphases=3 R1=0.5 X1=0.1 R0=1 X0=0.2 C1=0 C0=0 Units=km\r\n",
    "Lines.txt": (
        "New Line.LINE1 Bus1=1 Bus2=2 phases=3 Linecode=lc Length=10 Units=m\r\n"
        "! a comment\r\n"
        "New Line.LINE2 Bus1=2 Bus2=3 phases=3 Linecode=LC Length=0.02 Units=km\r\n"
    ),
    "Loads.txt": "New Load.LOAD1 Phases=1 Bus1=3.2 kV=0.23 kW=1 PF=0.95 Yearly=Shape_1\r\n",
    "Buscoords.txt": "1\t0\t0\r\n2 10 0\r\n3,10,20\r\n",
}


def _folder(tmp_path: Path, **changes: str | None) -> Path:
    files = {**GOOD, **changes}
    for name, text in files.items():
        if text is not None:
            (tmp_path / name).write_text(text, newline="")
    return tmp_path


def test_small_feeder(tmp_path):
    feeder = read_opendss_feeder(_folder(tmp_path), generators=_fleet())
    assert feeder.source_bus == 1
    assert feeder.lines.length_km.tolist() == pytest.approx([0.01, 0.02], rel=1e-15)
    assert feeder.lines.r_ohm.tolist() == pytest.approx([0.005, 0.01], rel=1e-15)
    assert feeder.lines.x_ohm.tolist() == pytest.approx([0.001, 0.002], rel=1e-15)
    assert feeder.loads.bus.to_dict() == {"LOAD1": 3}
    assert feeder.buses.loc[3].tolist() == [10.0, 20.0]


def test_lower_case_file_names_and_transformer(tmp_path):
    folder = _folder(tmp_path, **{"Buscoords.txt": None})
    (folder / "buscoords.txt").write_text(GOOD["Buscoords.txt"])
    (folder / "Transformers.txt").write_text(
        "New Transformer.TR1 Buses=[2 3] Conns=[Delta Wye] kVs=[11 0.416] kVAs=[800 800] XHL=4\n"
    )
    assert read_opendss_feeder(folder, generators=_fleet()).source_bus == 3


def _fleet():
    from popdispatch.feeder.generators import make_fleet

    return make_fleet([(2, 0.0, 1.0, 0.01, 0.0, 10.0)])


BAD = [
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=2 Linecode=lc Length=10 Units=m Switch=y\n",
     "Lines.txt:1", "Switch=y"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=x Linecode=lc Length=10 Units=m\n", "Lines.txt:1",
     "Bus2=x"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=9 Linecode=lc Length=10 Units=m\n", "Lines.txt:1",
     "Bus2=9"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=2 Linecode=nope Length=10 Units=m\n", "Lines.txt:1",
     "Linecode=nope"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=2 Linecode=lc Length=ten Units=m\n", "Lines.txt:1",
     "length=ten"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=2 Linecode=lc Length=10 Units=furlong\n",
     "Lines.txt:1", "units=furlong"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=2 Linecode=lc Length=10\n", "Lines.txt:1",
     "New Line.L1"),
    ("Lines.txt", "\nEdit Line.L1 Length=3\n", "Lines.txt:2", "Edit"),
    ("Lines.txt", "New Load.L1 Bus1=1\n", "Lines.txt:1", "Load.L1"),
    ("Lines.txt", "New Line.L1 Bus1=1 Bus2=2 Linecode=lc Length=10 Units=m junk\n",
     "Lines.txt:1", "junk"),
    ("Lines.txt", GOOD["Lines.txt"] + "New Line.line1 Bus1=1 Bus2=3 Linecode=lc Length=1 Units=m\n",
     "Lines.txt:4", "line1"),
    ("LineCode.txt", "New LineCode.lc R1=abc X1=0.1 Units=km\n", "LineCode.txt:1", "r1=abc"),
    ("LineCode.txt", "New LineCode.lc R1=nan X1=0.1 Units=km\n", "LineCode.txt:1", "r1=nan"),
    ("Loads.txt", "New Load.LOAD1 Bus1=3.2 kW=1 Shape=x\n", "Loads.txt:1", "Shape=x"),
    ("Loads.txt", "New Load.LOAD1 Bus1=B3 kW=1\n", "Loads.txt:1", "bus1=B3"),
    ("Buscoords.txt", "1 0 0\n2 10\n3 10 20\n", "Buscoords.txt:2", "2 10"),
    ("Buscoords.txt", "1 0 0\n2 10 y\n3 10 20\n", "Buscoords.txt:2", "y"),
    ("Buscoords.txt", "1 0 0\nbus2 10 0\n3 10 20\n", "Buscoords.txt:2", "bus2"),
    ("Buscoords.txt", "1 0 0\n1 10 0\n3 10 20\n", "Buscoords.txt:2", "1"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "text", "where", "token"), BAD)
def test_strict_errors_name_file_line_and_token(tmp_path, name, text, where, token):
    folder = _folder(tmp_path, **{name: text})
    with pytest.raises(FeederError) as info:
        read_opendss_feeder(folder, generators=_fleet())
    message = str(info.value)
    assert "\n" not in message
    assert where in message
    assert re.search(re.escape(token), message, flags=re.IGNORECASE), message


@pytest.mark.parametrize("missing", ["Lines.txt", "LineCode.txt", "Loads.txt", "Buscoords.txt"])
def test_missing_file(tmp_path, missing):
    folder = _folder(tmp_path, **{missing: None})
    with pytest.raises(FeederError, match=re.escape(missing)):
        read_opendss_feeder(folder, generators=_fleet())


def test_missing_folder(tmp_path):
    with pytest.raises(FeederError, match="does not exist"):
        read_opendss_feeder(tmp_path / "nowhere")


def test_meshed_feeder_is_rejected(tmp_path):
    lines = GOOD["Lines.txt"] + "New Line.LINE3 Bus1=3 Bus2=1 Linecode=lc Length=1 Units=m\n"
    with pytest.raises(FeederError, match="meshed"):
        read_opendss_feeder(_folder(tmp_path, **{"Lines.txt": lines}), generators=_fleet())
