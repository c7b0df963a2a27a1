"""The on-disk cache (issue 6): where it lives, that a cached feeder is the fresh feeder, that
bad or outdated files are rebuilt and that a write never leaves a partial file."""

from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch import cache
from popdispatch.cases import builtin as cases


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    """An empty cache folder for this test, and no in-process copy of the ieee-elv tables."""
    folder = tmp_path / "cache"
    monkeypatch.setenv(cache.CACHE_ENV, str(folder))
    cases._elv_arrays.cache_clear()
    yield folder
    cases._elv_arrays.cache_clear()


@pytest.fixture(scope="module")
def fresh():
    """The ieee-elv arrays derived from pandapower right now, and the feeder made of them."""
    arrays = cases.elv_arrays_from_pandapower()
    return arrays, cases._feeder(arrays)


def elv_file(folder: Path) -> Path:
    path = cache.entry_path(cases.ELV_CACHE, cases.elv_cache_key())
    assert path is not None and path.parent == folder
    return path


def assert_same_feeder(feeder, expected) -> None:
    for table in ("buses", "lines", "loads"):
        pd.testing.assert_frame_equal(getattr(feeder, table), getattr(expected, table))
    assert feeder.source_bus == expected.source_bus
    assert feeder.name == expected.name


def assert_same_arrays(arrays: dict, expected: dict) -> None:
    assert arrays.keys() == expected.keys()
    for name, value in expected.items():
        assert arrays[name].dtype == value.dtype, name
        np.testing.assert_array_equal(arrays[name], value, err_msg=name)


def files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


# -- location -----------------------------------------------------------------------------------


def test_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv(cache.CACHE_ENV, str(tmp_path / "mine"))
    assert cache.cache_dir() == tmp_path / "mine"
    monkeypatch.setenv(cache.CACHE_ENV, "off")
    assert cache.cache_dir() is None
    assert cache.entry_path("x", {}) is None
    monkeypatch.setenv(cache.CACHE_ENV, "")  # empty counts as unset
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache.cache_dir() == tmp_path / "xdg" / "popdispatch"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache.cache_dir() == tmp_path / "home" / ".cache" / "popdispatch"


def test_the_tests_do_not_use_the_user_cache():
    folder = cache.cache_dir()
    assert folder is not None
    assert Path.home() / ".cache" not in folder.parents


# -- arrays -------------------------------------------------------------------------------------


def test_arrays_round_trip_under_their_key_only(cache_dir):
    arrays = {"a": np.arange(3), "b": np.array(["x", "yz"]), "c": np.array(1.5)}
    path = cache.save_arrays("thing", {"v": 1}, arrays)
    assert path is not None and path.parent == cache_dir
    assert_same_arrays(cache.load_arrays("thing", {"v": 1}), arrays)
    assert cache.load_arrays("thing", {"v": 2}) is None  # another key: another file, a miss
    assert cache.load_arrays("other", {"v": 1}) is None


def test_a_file_whose_stored_key_differs_is_a_miss(cache_dir):
    path = cache.save_arrays("thing", {"v": 1}, {"a": np.arange(3)})
    os.replace(cache.save_arrays("thing", {"v": 2}, {"a": np.arange(3)}), path)
    assert cache.load_arrays("thing", {"v": 1}) is None


def test_a_disabled_cache_reads_and_writes_nothing(monkeypatch, tmp_path):
    monkeypatch.setenv(cache.CACHE_ENV, "off")
    assert cache.save_arrays("thing", {}, {"a": np.arange(3)}) is None
    assert cache.load_arrays("thing", {}) is None


def test_an_unwritable_cache_is_skipped(monkeypatch, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(cache.CACHE_ENV, str(blocker / "cache"))
    assert cache.save_arrays("thing", {}, {"a": np.arange(3)}) is None
    assert cache.load_arrays("thing", {}) is None


# -- atomic writes ------------------------------------------------------------------------------


@pytest.mark.parametrize("error", [OSError("disk full"), KeyboardInterrupt()])
def test_a_failed_write_leaves_no_partial_file(cache_dir, monkeypatch, error):
    key = {"v": 1}
    good = {"a": np.arange(3)}
    cache.save_arrays("thing", key, good)
    before = files(cache_dir)

    def half_then_fail(handle, **arrays):
        handle.write(b"PK\x03\x04 half a zip")
        raise error

    with monkeypatch.context() as patch:
        patch.setattr(cache.np, "savez", half_then_fail)
        if isinstance(error, OSError):
            assert cache.save_arrays("thing", key, {"a": np.arange(5)}) is None
            assert cache.save_arrays("new", key, {"a": np.arange(5)}) is None
        else:
            with pytest.raises(KeyboardInterrupt):
                cache.save_arrays("thing", key, {"a": np.arange(5)})
    assert files(cache_dir) == before  # no temporary file, no new entry
    assert_same_arrays(cache.load_arrays("thing", key), good)  # the old entry is intact


def test_write_atomic_replaces_only_when_complete(tmp_path):
    path = tmp_path / "f.bin"
    cache.write_atomic(path, lambda handle: handle.write(b"one"))

    def fail(handle):
        handle.write(b"tw")
        raise RuntimeError("stop")

    with pytest.raises(RuntimeError):
        cache.write_atomic(path, fail)
    assert path.read_bytes() == b"one"
    assert files(tmp_path) == ["f.bin"]


# -- the ieee-elv tables ------------------------------------------------------------------------


def test_cached_feeder_equals_the_fresh_build(cache_dir, fresh):
    arrays, feeder = fresh
    first = cases.ieee_elv()  # builds and stores
    assert files(cache_dir) == [elv_file(cache_dir).name]
    assert_same_feeder(first, feeder)
    cases._elv_arrays.cache_clear()
    assert_same_arrays(cache.load_arrays(cases.ELV_CACHE, cases.elv_cache_key()), arrays)
    second = cases.ieee_elv()  # read back from the file
    assert_same_feeder(second, feeder)
    snapshot = cases.elv_snapshot_566_kw()
    expected = pd.Series(
        arrays["load_p_kw"], index=pd.Index(arrays["load"].tolist(), name="load"), name="p_kw"
    )
    pd.testing.assert_series_equal(snapshot, expected)
    assert snapshot.sum() == pytest.approx(57.358, abs=1e-3)


def test_callers_get_their_own_tables(cache_dir):
    feeder = cases.ieee_elv()
    feeder.lines.loc[feeder.lines.index[0], "r_ohm"] = 99.0
    feeder.buses.loc[feeder.buses.index[0], "x"] = -1.0
    again = cases.ieee_elv()
    assert again.lines.r_ohm.iloc[0] != 99.0
    assert again.buses.x.iloc[0] != -1.0


def test_the_elv_key_names_what_the_tables_depend_on():
    key = cases.elv_cache_key()
    from importlib.metadata import version

    assert key["pandapower"] == version("pandapower")
    assert key["format"] == cases.ELV_FORMAT
    assert key["code"]  # a hash of cases.py: changing the derivation changes the key


def corrupt_truncated(path: Path, arrays: dict) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def corrupt_garbage(path: Path, arrays: dict) -> None:
    path.write_bytes(os.urandom(4096))


def corrupt_empty(path: Path, arrays: dict) -> None:
    path.write_bytes(b"")


def corrupt_flipped_byte(path: Path, arrays: dict) -> None:
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("r_ohm.npy")
    data[info.header_offset + 200] ^= 0xFF  # inside the stored data: the CRC no longer matches
    path.write_bytes(bytes(data))


def rewrite(path: Path, arrays: dict, key: dict | None = None) -> None:
    key = cases.elv_cache_key() if key is None else key
    with path.open("wb") as handle:
        np.savez(handle, **arrays, __key__=cache.key_text(key))


def corrupt_old_pandapower(path: Path, arrays: dict) -> None:
    rewrite(path, arrays, {**cases.elv_cache_key(), "pandapower": "0.0.1"})


def corrupt_old_format(path: Path, arrays: dict) -> None:
    rewrite(path, arrays, {**cases.elv_cache_key(), "format": cases.ELV_FORMAT - 1})


def corrupt_no_key(path: Path, arrays: dict) -> None:
    with path.open("wb") as handle:
        np.savez(handle, **arrays)


def corrupt_missing_array(path: Path, arrays: dict) -> None:
    rewrite(path, {k: v for k, v in arrays.items() if k != "x_ohm"})


def corrupt_wrong_dtype(path: Path, arrays: dict) -> None:
    rewrite(path, {**arrays, "from_bus": arrays["from_bus"].astype(float)})


def corrupt_short_column(path: Path, arrays: dict) -> None:
    rewrite(path, {**arrays, "r_ohm": arrays["r_ohm"][:-1]})


def corrupt_nan(path: Path, arrays: dict) -> None:
    r = arrays["r_ohm"].copy()
    r[3] = np.nan
    rewrite(path, {**arrays, "r_ohm": r})


def corrupt_not_a_tree(path: Path, arrays: dict) -> None:
    to_bus = arrays["to_bus"].copy()
    to_bus[5] = arrays["from_bus"][5]  # sound arrays, but a line from a bus to itself
    rewrite(path, {**arrays, "to_bus": to_bus})


def corrupt_pickled(path: Path, arrays: dict) -> None:
    rewrite(path, {**arrays, "line": arrays["line"].astype(object)})


@pytest.mark.parametrize(
    "damage",
    [
        corrupt_truncated, corrupt_garbage, corrupt_empty, corrupt_flipped_byte,
        corrupt_old_pandapower, corrupt_old_format, corrupt_no_key, corrupt_missing_array,
        corrupt_wrong_dtype, corrupt_short_column, corrupt_nan, corrupt_not_a_tree,
        corrupt_pickled,
    ],
)  # fmt: skip
def test_a_bad_or_outdated_cache_file_is_rebuilt(cache_dir, fresh, damage):
    arrays, feeder = fresh
    cases.ieee_elv()
    path = elv_file(cache_dir)
    damage(path, arrays)
    cases._elv_arrays.cache_clear()
    assert_same_feeder(cases.ieee_elv(), feeder)  # no crash, the right feeder
    assert_same_arrays(cache.load_arrays(cases.ELV_CACHE, cases.elv_cache_key()), arrays)
    assert files(cache_dir) == [path.name]  # rewritten in place, nothing else left


def test_a_changed_key_uses_another_file(cache_dir, fresh, monkeypatch):
    cases.ieee_elv()
    old = elv_file(cache_dir)
    monkeypatch.setattr(cases, "ELV_FORMAT", cases.ELV_FORMAT + 1)
    cases._elv_arrays.cache_clear()
    assert_same_feeder(cases.ieee_elv(), fresh[1])
    new = elv_file(cache_dir)
    assert new != old
    assert files(cache_dir) == sorted([old.name, new.name])


def test_a_warm_process_does_not_import_pandapower(cache_dir):
    cases.ieee_elv()  # fills the cache
    code = (
        "import sys\n"
        "from popdispatch.cases import ieee_elv, elv_snapshot_566_kw\n"
        "f = ieee_elv(); s = elv_snapshot_566_kw()\n"
        "print(len(f.buses), len(f.lines), len(f.loads), round(s.sum(), 3),\n"
        "      'pandapower' in sys.modules)\n"
    )
    env = {**os.environ, cache.CACHE_ENV: str(cache_dir)}
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["906", "905", "55", "57.358", "False"]
