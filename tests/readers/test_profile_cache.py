"""The on-disk cache of profile folders (popdispatch.readers.profiles + readers.manifest): a
cached table equals a fresh read value by value, and any changed, added or removed input, a
corrupt entry or a disabled cache falls back to reading the files."""

from __future__ import annotations

import os
import time
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from popdispatch import cache
from popdispatch.errors import ProfileError
from popdispatch.readers import manifest
from popdispatch.readers import profiles as reader
from popdispatch.readers.profiles import (
    DEFAULT_PROFILES_FILE,
    PROFILES_CACHE,
    default_profiles,
    profiles_cache_key,
    read_profiles,
)

from helpers import MISSING_OFFICIAL, find_official_folder

OFFICIAL = find_official_folder()
KW = {"L1": 2.0, "L2": 0.5}  # the loads' kW= scales of the small folder


def _write_folder(root: Path, seed: int = 0) -> Path:
    """A two-load OpenDSS-form folder (Loads.txt + two multiplier files) in ``root``."""
    rng = np.random.default_rng(seed)
    (root / "Daily_1min_100profiles").mkdir(parents=True)
    lines = [f"New Load.{name} Bus1=1.1 kW={kw} Yearly=Shape_{n}" for n, (name, kw) in
             enumerate(KW.items(), start=1)]  # fmt: skip
    (root / "Loads.txt").write_text("\n".join(lines) + "\n")
    for n in (1, 2):
        _write_profile(root, n, rng.uniform(0.0, 3.0, 1440).round(3))
    return _settle(root)


def _write_profile(root: Path, n: int, values: np.ndarray) -> Path:
    path = root / "Daily_1min_100profiles" / f"load_profile_{n}.txt"
    path.write_text("\n".join(f"{v:.3f}" for v in values) + "\n")
    return path


def _settle(root: Path, age_s: float = 60.0) -> Path:
    """Date every file and folder under ``root`` (and it) ``age_s`` seconds back, as a folder
    written a while ago (the cache stores only inputs older than ``SETTLE_NS``)."""
    then = time.time_ns() - int(age_s * 1e9)
    for path in [root, *root.rglob("*")]:
        os.utime(path, ns=(then, then))
    return root


def _expected(root: Path) -> np.ndarray:
    """Independent yardstick: numpy's own text reader times each load's kW= scale."""
    folder = root / "Daily_1min_100profiles"
    columns = [np.loadtxt(folder / f"load_profile_{n}.txt") * kw for n, kw in
               enumerate(KW.values(), start=1)]  # fmt: skip
    return np.column_stack(columns)


def _entry(root: Path) -> Path:
    return cache.entry_path(PROFILES_CACHE, profiles_cache_key(root.resolve()))


@pytest.fixture
def cache_dir(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv(cache.CACHE_ENV, str(folder))
    return folder


@pytest.fixture
def no_read(monkeypatch):
    """Make reading the files fail, so a result can only have come from the cache."""

    def refuse(*args, **kwargs):
        raise AssertionError("the files were read although the cache was warm")

    def arm() -> None:
        monkeypatch.setattr(reader, "_read_folder", refuse)

    return arm


def test_warm_read_equals_fresh_and_numpy(tmp_path, cache_dir, no_read):
    root = _write_folder(tmp_path / "elv")
    fresh = read_profiles(root)
    assert _entry(root).is_file()
    no_read()
    warm = read_profiles(root)
    pd.testing.assert_frame_equal(warm.kw, fresh.kw, check_exact=True)
    assert warm.source == fresh.source == f"official profiles: {root.resolve()}"
    np.testing.assert_array_equal(warm.kw.to_numpy(), _expected(root))
    assert list(warm.kw.columns) == list(KW)


@pytest.mark.parametrize("same_size", [False, True])
def test_changed_file_invalidates(tmp_path, cache_dir, same_size):
    root = _write_folder(tmp_path / "elv")
    before = read_profiles(root).kw.to_numpy()
    path = root / "Daily_1min_100profiles" / "load_profile_2.txt"
    stat = os.stat(path)
    values = np.loadtxt(path)
    values[565] = 9.5 if same_size else 12.25  # "9.500" keeps the byte count, "12.250" not
    _write_profile(root, 2, values)
    if same_size:  # only the modification time tells the change
        assert os.stat(path).st_size == stat.st_size
        os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    after = read_profiles(root).kw.to_numpy()
    np.testing.assert_array_equal(after, _expected(root))
    assert after[565, 1] == values[565] * KW["L2"] != before[565, 1]


def test_added_file_invalidates(tmp_path, cache_dir):
    """A second Loads file differing only in case makes the folder ambiguous: the cached
    table must not hide the error the files now give."""
    root = _write_folder(tmp_path / "elv")
    (root / "Loads.txt").rename(root / "loads.txt")  # found case-insensitively
    read_profiles(root)
    stat = os.stat(root)
    (root / "LOADS.TXT").write_text("")
    os.utime(root, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    with pytest.raises(ProfileError, match="matches several files"):
        read_profiles(root)


def test_removed_file_invalidates(tmp_path, cache_dir):
    root = _write_folder(tmp_path / "elv")
    read_profiles(root)
    (root / "Daily_1min_100profiles" / "load_profile_1.txt").unlink()
    with pytest.raises(ProfileError, match="missing profile file"):
        read_profiles(root)


@pytest.mark.parametrize("damage", ["garbage", "truncated", "other key"])
def test_corrupt_entry_is_rebuilt(tmp_path, cache_dir, damage):
    root = _write_folder(tmp_path / "elv")
    fresh = read_profiles(root)
    entry = _entry(root)
    if damage == "garbage":
        entry.write_bytes(b"not a zip file")
    elif damage == "truncated":
        entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 2])
    else:  # a sound file of another folder under this folder's name
        other = _write_folder(tmp_path / "other", seed=1)
        read_profiles(other)
        entry.write_bytes(_entry(other).read_bytes())
    again = read_profiles(root)
    pd.testing.assert_frame_equal(again.kw, fresh.kw, check_exact=True)
    arrays = cache.load_arrays(PROFILES_CACHE, profiles_cache_key(root.resolve()))
    assert arrays is not None  # rewritten whole
    np.testing.assert_array_equal(arrays["kw"], _expected(root))


def test_disabled_cache_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv(cache.CACHE_ENV, "off")
    root = _write_folder(tmp_path / "elv")
    first = read_profiles(root)
    np.testing.assert_array_equal(first.kw.to_numpy(), _expected(root))
    assert cache.entry_path(PROFILES_CACHE, profiles_cache_key(root.resolve())) is None


def test_xdg_cache_home(tmp_path, monkeypatch):
    monkeypatch.delenv(cache.CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    root = _write_folder(tmp_path / "elv")
    read_profiles(root)
    entry = _entry(root)
    assert entry.parent == tmp_path / "xdg" / "popdispatch" and entry.is_file()


@pytest.mark.skipif(OFFICIAL is None, reason=MISSING_OFFICIAL)
def test_official_folder_cached_equals_fresh(cache_dir, no_read):
    fresh = read_profiles(OFFICIAL, use_cache=False)
    read_profiles(OFFICIAL)  # writes the entry
    no_read()
    warm = read_profiles(OFFICIAL)
    pd.testing.assert_frame_equal(warm.kw, fresh.kw, check_exact=True)
    assert warm.source == fresh.source


def test_shipped_default_cached_equals_the_file(cache_dir, monkeypatch):
    resource = resources.files("popdispatch") / "data" / DEFAULT_PROFILES_FILE
    with resources.as_file(resource) as path:
        expected = np.loadtxt(path, delimiter=",", comments="#", skiprows=4)  # numpy reader
    first = default_profiles()
    monkeypatch.setattr(pd, "read_csv", None)  # a second read can only come from the cache
    warm = default_profiles()
    pd.testing.assert_frame_equal(warm.kw, first.kw, check_exact=True)
    assert warm.source == first.source and warm.source.startswith("synthetic default")
    np.testing.assert_array_equal(warm.kw.index.to_numpy(), expected[:, 0])
    np.testing.assert_array_equal(warm.kw.to_numpy(), expected[:, 1:])


def test_a_folder_written_a_moment_ago_is_read_but_not_cached(tmp_path, cache_dir):
    """A file rewritten with the same size within one tick of the filesystem's clock keeps
    its modification time: inputs modified less than SETTLE_NS ago are read, not stored."""
    root = _write_folder(tmp_path / "elv")
    _settle(root, age_s=0.0)  # modified now
    fresh = read_profiles(root)
    np.testing.assert_array_equal(fresh.kw.to_numpy(), _expected(root))
    assert not _entry(root).exists()
    _settle(root, age_s=manifest.SETTLE_NS / 1e9 + 1.0)
    read_profiles(root)
    assert _entry(root).is_file()
