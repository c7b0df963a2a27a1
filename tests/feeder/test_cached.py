"""The cached ieee-elv problem (popdispatch.cases.cached, runs.load_run): a problem from the
cache equals one built afresh field by field and array by array; other profiles, limits or code,
a corrupt or foreign entry and a disabled cache all build afresh."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pandas as pd
import pytest

from popdispatch import cache, runs
from popdispatch.cases import cached
from popdispatch.cases.builtin import ieee_elv
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.readers import PROFILES_ENV, default_profiles
from popdispatch.runs import FeederSource, load_run
from popdispatch.scenarios import elv_problem

LIMITS = [(505, 666, 28.0)]


def assert_same(a, b, where: str = "problem") -> None:
    """Equal type and, recursively, equal fields: arrays and pandas objects exactly."""
    assert type(a) is type(b), where
    if dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            assert_same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, where
        np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, pd.DataFrame):
        pd.testing.assert_frame_equal(a, b, check_exact=True, obj=where)
    elif isinstance(a, pd.Series):
        pd.testing.assert_series_equal(a, b, check_exact=True, obj=where)
    elif isinstance(a, pd.Index):
        pd.testing.assert_index_equal(a, b, exact=True, obj=where)
    elif isinstance(a, float) and np.isnan(a):
        assert np.isnan(b), where
    else:
        assert a == b, where


def fresh(profiles: LoadProfiles, limits=()) -> object:
    """The problem built directly, no problem cache involved (the yardstick)."""
    feeder = ieee_elv()
    return elv_problem(profiles.for_loads(feeder.loads.index), limits, feeder, check=False)


@pytest.fixture
def no_entries(monkeypatch):
    """No problem entries in the test cache; the default profiles (no official data needed)."""
    monkeypatch.delenv(PROFILES_ENV, raising=False)
    folder = cache.cache_dir()
    for entry in folder.glob(f"{cached.PROBLEM_CACHE}-*.pickle") if folder.exists() else ():
        entry.unlink()
    return folder


@pytest.fixture
def refuse_build(monkeypatch):
    """Make building the feeder fail, so a problem can only come from the cache."""

    def arm() -> None:
        def refuse(*args, **kwargs):
            raise AssertionError("the feeder was built although the cache was warm")

        monkeypatch.setattr(runs, "load_feeder", refuse)

    return arm


@pytest.mark.parametrize("limits", [(), LIMITS])
def test_cached_problem_equals_fresh(no_entries, refuse_build, limits):
    built, series = load_run(FeederSource(), limits=limits)
    assert len(list(no_entries.glob("problem-*.pickle"))) == 1
    refuse_build()
    warm, warm_series = load_run(FeederSource(), limits=limits)
    yardstick = fresh(default_profiles(), limits)
    assert_same(warm, yardstick)
    assert_same(built, yardstick)
    assert_same(warm_series, series, "profiles")
    # the numbers that matter, against the profiles themselves (kW -> MW)
    np.testing.assert_allclose(warm.demand, series.kw.sum(axis=1).to_numpy() / 1000, rtol=1e-12)
    if limits:
        np.testing.assert_array_equal(warm.limit, np.full(len(warm.limit), 0.028))


def test_other_profiles_or_limits_build_afresh(no_entries):
    base = default_profiles()
    doubled = LoadProfiles(base.kw * 2.0, base.source)
    problems = [
        cached.cached_build(p, lim, lambda p=p, lim=lim: fresh(p, lim))
        for p, lim in ((base, ()), (doubled, ()), (base, LIMITS))
    ]
    assert [hit for _, hit in problems] == [False, False, False]
    np.testing.assert_allclose(problems[1][0].demand, 2 * problems[0][0].demand, rtol=1e-15)
    assert len(problems[2][0].limit) > 0 == len(problems[0][0].limit)
    again = cached.cached_build(doubled, (), lambda: pytest.fail("not from the cache"))
    assert again[1] and np.array_equal(again[0].demand, problems[1][0].demand)


def test_changed_code_builds_afresh(no_entries, monkeypatch):
    base = default_profiles()
    cached.cached_build(base, (), lambda: fresh(base))
    monkeypatch.setattr(cached, "code_hash", lambda *modules: "other code")
    _, hit = cached.cached_build(base, (), lambda: fresh(base))
    assert not hit


@pytest.mark.parametrize("damage", ["garbage", "truncated", "foreign key", "not a problem"])
def test_bad_entry_is_rebuilt(no_entries, damage):
    base = default_profiles()
    key = cached.problem_key(base, ())
    problem, _ = cached.cached_build(base, (), lambda: fresh(base))
    path = cached.entry_path(key)
    if damage == "garbage":
        path.write_bytes(b"\x80\x05 not a pickle")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[:1000])
    elif damage == "foreign key":
        path.write_bytes(pickle.dumps({"key": "{}", "problem": problem}))
    else:
        path.write_bytes(pickle.dumps({"key": cache.key_text(key), "problem": "x"}))
    assert cached.load(key) is None
    again, hit = cached.cached_build(base, (), lambda: fresh(base))
    assert not hit
    assert_same(again, problem)
    assert_same(cached.load(key), problem)  # rewritten whole


def test_disabled_cache_writes_nothing(no_entries, monkeypatch):
    base = default_profiles()
    problem = fresh(base)  # before disabling: the ieee-elv tables come from the test cache
    monkeypatch.setenv(cache.CACHE_ENV, "off")
    got, hit = cached.cached_build(base, (), lambda: problem)
    assert got is problem and not hit
    assert cached.load(cached.problem_key(base, ())) is None


def test_old_entries_are_pruned(no_entries, monkeypatch):
    monkeypatch.setattr(cached, "KEEP", 2)
    base = default_profiles()
    problem = fresh(base)
    for scale in (1.0, 1.5, 2.0):
        cached.cached_build(LoadProfiles(base.kw * scale, base.source), (), lambda: problem)
    assert len(list(no_entries.glob("problem-*.pickle"))) == 2
    newest = LoadProfiles(base.kw * 2.0, base.source)
    assert cached.load(cached.problem_key(newest, ())) is not None
