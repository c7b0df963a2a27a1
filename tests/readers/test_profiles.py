"""Official and default load profiles (popdispatch.readers.profiles)."""

from __future__ import annotations

import gzip
import os
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch.cases.builtin import elv_snapshot_566_kw
from popdispatch.errors import ProfileError
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.readers import PROFILES_ENV, default_profiles, read_profiles, resolve_profiles

from helpers import MISSING_OFFICIAL, find_official_folder

OFFICIAL = find_official_folder()
needs_official = pytest.mark.skipif(OFFICIAL is None, reason=MISSING_OFFICIAL)


@pytest.fixture(scope="module")
def official() -> LoadProfiles:
    return read_profiles(OFFICIAL)


# -- official data -------------------------------------------------------------------------------


@needs_official
def test_official_peak(official):
    assert official.kw.shape == (1440, 55)
    assert list(official.kw.columns) == [f"LOAD{n}" for n in range(1, 56)]
    assert official.kw.index[0] == 1 and official.kw.index[-1] == 1440
    assert official.source == f"official profiles: {OFFICIAL.resolve()}"
    total = official.total_kw()
    assert total.idxmax() == 566
    assert total.max() == pytest.approx(57.358, abs=1e-3)
    # LOAD1 follows load_profile_1.txt, whose first value is 0.036 kW (kW=1 multiplier)
    assert official.kw.loc[1, "LOAD1"] == pytest.approx(0.036, abs=1e-12)


@needs_official
def test_snapshot_566_matches_official_profiles(official):
    snapshot = elv_snapshot_566_kw()
    at = official.at(566)
    assert list(at.index) == list(snapshot.index)
    np.testing.assert_allclose(at.to_numpy(), snapshot.to_numpy(), rtol=0, atol=1e-6)
    assert snapshot.sum() == pytest.approx(57.358, abs=1e-3)


def _write_csv_form(src: Path, dst: Path) -> Path:
    """The IEEE CSV distribution layout, built from the OpenDSS form (only in tmp_path)."""
    rows = []
    for line in (src / "Loads.txt").read_text().splitlines():
        params = dict(t.split("=", 1) for t in line.split()[2:])
        bus, phase = params["Bus1"].split(".")
        name = line.split()[1].split(".", 1)[1]
        rows.append(
            f"{name},1,{bus},{'ABC'[int(phase) - 1]},{params['kV']},1,Y,{params['kW']},"
            f"{params['PF']},{params['Yearly']}"
        )
    (dst / "Load Profiles").mkdir(parents=True)
    (dst / "Loads.csv").write_text(
        "Load Data,,,,,,,,,\r\nUnits of kW and kV,,,,,,,,,\r\n,,,,,,,,,\r\n"
        "Name,numPhases,Bus,phases,kV,Model,Connection,kW,PF,Yearly\r\n"
        + "\r\n".join(rows)
        + "\r\n"
    )
    for n in range(1, 56):
        values = (src / "Daily_1min_100profiles" / f"load_profile_{n}.txt").read_text().split()
        times = [f"{m // 60:02d}:{m % 60:02d}:00" for m in range(1440)]
        body = "\r\n".join(f"{t},{v}" for t, v in zip(times, values, strict=True))
        (dst / "Load Profiles" / f"Load_profile_{n}.csv").write_text(f"time,mult\r\n{body}\r\n")
    return dst


@needs_official
def test_csv_form_equals_opendss_form(official, tmp_path):
    csv_form = read_profiles(_write_csv_form(OFFICIAL, tmp_path / "csv"))
    pd.testing.assert_frame_equal(csv_form.kw, official.kw)
    assert csv_form.source == f"official profiles: {(tmp_path / 'csv').resolve()}"
    assert csv_form.total_kw().idxmax() == 566


# -- synthetic OpenDSS-form folders ---------------------------------------------------------------


def _values(n: int = 1440, base: float = 0.5) -> list[str]:
    return [f"{base + 0.001 * (i % 7):.3f}" for i in range(n)]


def _dss_folder(tmp_path: Path, shapes: bool = True) -> Path:
    folder = tmp_path / "dss"
    (folder / "Daily_1min_100profiles").mkdir(parents=True)
    (folder / "Loads.txt").write_text(
        "New Load.LOAD1 Phases=1 Bus1=3.1 kV=0.23 kW=1 PF=0.95 Yearly=Shape_1\r\n"
        "New Load.LOAD2 Phases=1 Bus1=4.2 kV=0.23 kW=2 PF=0.95 Daily=Shape_2\r\n",
        newline="",
    )
    if shapes:
        (folder / "LoadShapes.txt").write_text(
            "".join(
                f"New Loadshape.Shape_{n} npts=1440 minterval=1 "
                f"mult=(file=Daily_1min_100profiles\\Load_profile_{n}.txt) useactual=true\r\n"
                for n in (1, 2)
            ),
            newline="",
        )
    for n, base in ((1, 0.5), (2, 1.0)):
        path = folder / "Daily_1min_100profiles" / f"load_profile_{n}.txt"
        path.write_text("\r\n".join(_values(base=base)) + "\r\n", newline="")
    return folder


@pytest.mark.parametrize("shapes", [True, False])
def test_small_opendss_form(tmp_path, shapes):
    profiles = read_profiles(_dss_folder(tmp_path, shapes))
    assert list(profiles.kw.columns) == ["LOAD1", "LOAD2"]
    assert profiles.kw.index.name == "minute"
    np.testing.assert_allclose(profiles.kw["LOAD1"], [float(v) for v in _values(base=0.5)])
    # kW=2 scales the multipliers
    np.testing.assert_allclose(profiles.kw["LOAD2"], [2 * float(v) for v in _values(base=1.0)])
    assert profiles.total_kw().loc[7] == pytest.approx(0.506 + 2 * 1.006)


def _profile_file(folder: Path, n: int) -> Path:
    return folder / "Daily_1min_100profiles" / f"load_profile_{n}.txt"


def _set_values(values: list[str]):
    def change(folder: Path) -> None:
        _profile_file(folder, 2).write_text("\n".join(values) + "\n")

    return change


BAD_DSS = {
    "missing file": (
        lambda f: _profile_file(f, 2).unlink(),
        r"missing profile file Daily_1min_100profiles\\Load_profile_2.txt for load 'LOAD2'",
    ),
    "short": (_set_values(_values(1439)), r"load_profile_2.txt: .*'LOAD2' has 1439 values"),
    "long": (_set_values(_values(1441)), r"load_profile_2.txt: .*'LOAD2' has 1441 values"),
    "nan": (_set_values(["nan"] + _values(1439)), r"load_profile_2.txt:1: load 'LOAD2'.*'nan'"),
    "text": (
        _set_values(_values(9) + ["x1"] + _values(1430)),
        r"load_profile_2.txt:10: load 'LOAD2'.*'x1'",
    ),
    "negative": (
        _set_values(_values(99) + ["-0.1"] + _values(1340)),
        r"load_profile_2.txt:100: load 'LOAD2': negative value '-0.1'",
    ),
    "blank inside": (
        _set_values(_values(5) + [""] + _values(1435)),
        r"load_profile_2.txt:6: load 'LOAD2'.*''",
    ),
    "unknown shape": (
        lambda f: (f / "Loads.txt").write_text("New Load.LOAD9 Bus1=3 kW=1 Yearly=Shape_9\n"),
        r"Loads.txt:1: load 'LOAD9': shape not defined",
    ),
    "no shape": (
        lambda f: (f / "Loads.txt").write_text("New Load.LOAD9 Bus1=3 kW=1\n"),
        r"Loads.txt:1: load 'LOAD9' has no Yearly= or Daily= shape",
    ),
    "bad kW": (
        lambda f: (f / "Loads.txt").write_text("New Load.LOAD9 Bus1=3 kW=abc Yearly=Shape_1\n"),
        r"Loads.txt:1: kw= is not a finite number: 'kw=abc'",
    ),
    "bad load key": (
        lambda f: (f / "Loads.txt").write_text("New Load.LOAD9 Bus1=3 kW=1 Foo=1 Yearly=S\n"),
        r"Loads.txt:1: unsupported Load property: 'Foo=1'",
    ),
    "bad npts": (
        lambda f: (f / "LoadShapes.txt").write_text(
            "New Loadshape.Shape_1 npts=24 minterval=1 mult=(file=a.txt)\n"
        ),
        r"LoadShapes.txt:1: only npts=1440 is supported: 'npts=24'",
    ),
    "inline mult": (
        lambda f: (f / "LoadShapes.txt").write_text(
            "New Loadshape.Shape_1 npts=1440 minterval=1 mult=(1 2 3)\n"
        ),
        r"LoadShapes.txt:1: only mult=\(file=NAME\) is supported",
    ),
}


@pytest.mark.parametrize("case", list(BAD_DSS))
def test_bad_opendss_form(tmp_path, case):
    change, pattern = BAD_DSS[case]
    folder = _dss_folder(tmp_path)
    change(folder)
    with pytest.raises(ProfileError) as info:
        read_profiles(folder)
    message = str(info.value)
    assert "\n" not in message
    assert re.search(pattern, message), message


def test_missing_folder(tmp_path):
    with pytest.raises(ProfileError, match=r"nowhere does not exist"):
        read_profiles(tmp_path / "nowhere")


def test_folder_without_loads(tmp_path):
    with pytest.raises(ProfileError, match=r"neither Loads.txt .* nor Loads.csv"):
        read_profiles(tmp_path)


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="needs file permissions")
def test_unreadable_folder(tmp_path):
    folder = _dss_folder(tmp_path)
    folder.chmod(0o000)
    try:
        with pytest.raises(ProfileError, match="unreadable"):
            read_profiles(folder)
    finally:
        folder.chmod(0o755)


# -- synthetic CSV-form folders -------------------------------------------------------------------


def _csv_folder(tmp_path: Path, profile: list[str] | None = None) -> Path:
    folder = tmp_path / "csv"
    (folder / "Load Profiles").mkdir(parents=True)
    (folder / "Loads.csv").write_text(
        "Load Data,,,,,,,,,\nUnits,,,,,,,,,\n,,,,,,,,,\n"
        "Name,numPhases,Bus,phases,kV,Model,Connection,kW,PF,Yearly\n"
        "LOAD1,1,3,A,0.23,1,Y,1,0.95,Shape_1\n"
        "LOAD2,1,4,B,0.23,1,Y,3,0.95,Shape_2\n"
    )
    for n in (1, 2):
        values = profile if (profile is not None and n == 2) else _values()
        body = "".join(f"{i},{v}\n" for i, v in enumerate(values))
        (folder / "Load Profiles" / f"Load_profile_{n}.csv").write_text("time,mult\n" + body)
    return folder


def test_small_csv_form(tmp_path):
    profiles = read_profiles(_csv_folder(tmp_path))
    assert list(profiles.kw.columns) == ["LOAD1", "LOAD2"]
    np.testing.assert_allclose(profiles.kw["LOAD2"], [3 * float(v) for v in _values()])


BAD_CSV = {
    "short": (_values(1000), r"Load_profile_2.csv: profile of load 'LOAD2' has 1000 values"),
    "nan": (_values(4) + ["NaN"] + _values(1435), r"Load_profile_2.csv:6: load 'LOAD2'.*'NaN'"),
    "negative": (["-1"] + _values(1439), r"Load_profile_2.csv:2: load 'LOAD2': negative"),
}


@pytest.mark.parametrize("case", list(BAD_CSV))
def test_bad_csv_profile(tmp_path, case):
    values, pattern = BAD_CSV[case]
    with pytest.raises(ProfileError, match=pattern):
        read_profiles(_csv_folder(tmp_path, values))


def test_bad_csv_tables(tmp_path):
    folder = _csv_folder(tmp_path)
    (folder / "Load Profiles" / "Load_profile_2.csv").unlink()
    with pytest.raises(ProfileError, match=r"missing profile file Load_profile_2.csv .*'LOAD2'"):
        read_profiles(folder)
    folder = _csv_folder(tmp_path / "b")
    loads = (
        (folder / "Loads.csv")
        .read_text()
        .replace("LOAD2,1,4,B,0.23,1,Y,3", "LOAD2,1,4,B,0.23,1,Y,x")
    )
    (folder / "Loads.csv").write_text(loads)
    with pytest.raises(ProfileError, match=r"Loads.csv:6: load 'LOAD2' has invalid kW 'x'"):
        read_profiles(folder)
    (folder / "Loads.csv").write_text("just a title\nLOAD1,1\n")
    with pytest.raises(ProfileError, match=r"Loads.csv: no header row starting with 'Name'"):
        read_profiles(folder)
    folder = _csv_folder(tmp_path / "c")
    (folder / "Load Profiles" / "Load_profile_1.csv").write_text("time,value\n0,1\n")
    with pytest.raises(ProfileError, match=r"Load_profile_1.csv: no header row with a 'mult'"):
        read_profiles(folder)


# -- default and resolution -----------------------------------------------------------------------


def test_default_profiles_valid_and_deterministic():
    a, b = default_profiles(), default_profiles()
    pd.testing.assert_frame_equal(a.kw, b.kw)
    assert a.source == b.source
    assert re.fullmatch(
        r"synthetic default \(richardsonpy CREST, seed \d+, scaled to a 57\.358 kW peak\)",
        a.source,
    )
    assert a.kw.shape == (1440, 55)
    assert list(a.kw.columns) == [f"LOAD{n}" for n in range(1, 56)]
    assert list(a.kw.index) == list(range(1, 1441))
    assert (a.kw.to_numpy() >= 0).all() and np.isfinite(a.kw.to_numpy()).all()
    # 3 decimals of kW (1 W)
    np.testing.assert_allclose(a.kw.to_numpy(), np.round(a.kw.to_numpy(), 3), atol=1e-12)
    total = a.total_kw()
    assert 20.0 < total.max() < 150.0  # tens of kW for 55 households
    assert 1.0 < total.min() < total.mean() < total.max()
    assert 200.0 < total.sum() / 60 < 1500.0  # kWh per day, 55 households
    # the shipped numbers themselves
    assert total.max() == pytest.approx(57.358, abs=1e-9)
    assert int(total.idxmax()) == 1161


#: Total capacity (kW) of the paper's fleet; a day on the default profiles must fit under it.
FLEET_CAPACITY_KW = 65.0


def test_default_peak_is_official_peak_below_fleet_capacity():
    """The default is scaled so its aggregate peak is the official feeder's 57.358 kW."""
    peak = default_profiles().total_kw().max()
    assert peak == pytest.approx(57.358, abs=1e-3)
    assert peak < FLEET_CAPACITY_KW


def test_default_file_is_small():
    resource = resources.files("popdispatch") / "data" / "default_profiles.csv.gz"
    with resources.as_file(resource) as path:
        assert path.stat().st_size < 500_000
        with gzip.open(path, "rt") as handle:
            assert handle.readline().startswith("# synthetic default (richardsonpy CREST, seed ")


def test_default_regenerates_identically(tmp_path):
    """The shipped file is what scripts/make_default_profiles.py makes (needs richardsonpy)."""
    pytest.importorskip("richardsonpy")
    import importlib.util

    script = Path(__file__).resolve().parents[2] / "scripts" / "make_default_profiles.py"
    spec = importlib.util.spec_from_file_location("make_default_profiles", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    out = tmp_path / "p.csv.gz"
    assert module.main(["--output", str(out)]) == 0
    resource = resources.files("popdispatch") / "data" / "default_profiles.csv.gz"
    assert out.read_bytes() == resource.read_bytes()


def test_resolve_order(tmp_path, monkeypatch):
    folder = _dss_folder(tmp_path)
    monkeypatch.delenv(PROFILES_ENV, raising=False)
    assert resolve_profiles(None).source.startswith("synthetic default")
    monkeypatch.setenv(PROFILES_ENV, "")
    assert resolve_profiles().source.startswith("synthetic default")
    monkeypatch.setenv(PROFILES_ENV, str(folder))
    assert resolve_profiles().source == f"official profiles: {folder.resolve()}"
    other = _csv_folder(tmp_path)
    assert resolve_profiles(other).source == f"official profiles: {other.resolve()}"
    monkeypatch.setenv(PROFILES_ENV, str(tmp_path / "gone"))
    with pytest.raises(ProfileError, match="gone does not exist"):
        resolve_profiles()
