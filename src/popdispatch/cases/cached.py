"""The built ieee-elv dispatch problem of a run, kept in the on-disk cache.

Building the problem of the built-in feeder (its tables, the key-node reduction, the engine
arrays) needs scipy's graph code (``scipy.sparse.csgraph``, which imports ``scipy.linalg``)
and pandas work in every process, a noticeable share of a command's start-up, for a result
that only changes with its inputs. :func:`cached_build` stores the problem as a pickle in the cache
folder of :mod:`popdispatch.cache` (``$POPDISPATCH_CACHE_DIR``, ``$XDG_CACHE_HOME/popdispatch``
or ``~/.cache/popdispatch``; ``POPDISPATCH_CACHE_DIR=off`` disables it) under a key of
everything the build depends on:

- the load profiles themselves: a SHA-256 of their kW values, load names and source (the
  profile folder's own cache entry is checked against its files' sizes and modification
  times, :mod:`popdispatch.readers.manifest`, so a changed file changes this digest);
- the path limits; the ieee-elv tables' key (pandapower and popdispatch versions, ...);
- the source code of every module the build runs (a changed module is a miss).

Pickles are read from the cache folder (the user's own by default, as numba does for its
compiled kernels; a folder others can write to, given by ``POPDISPATCH_CACHE_DIR``, is as
trusted as code, since unpickling runs it) and used only for a key that matches exactly and
only if they hold a dispatch problem;
an unreadable, truncated, foreign or corrupt file is a miss and is rebuilt. Files are written
under a temporary name and renamed into place (:func:`popdispatch.cache.write_atomic`); at
most :data:`KEEP` problem entries are kept (the least recently written go first).
"""

from __future__ import annotations

import hashlib
import json
import pickle
from collections.abc import Callable, Sequence
from pathlib import Path

from popdispatch import cache
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import DispatchProblem
from popdispatch.readers.manifest import code_hash

#: Cache entry name prefix and layout version of the built problems.
PROBLEM_CACHE, PROBLEM_FORMAT = "problem", 1
#: Problem entries kept in the cache folder (each about 1-2 MB for a day of profiles).
KEEP = 16
#: The modules whose code a built problem depends on (relative to the package).
BUILD_MODULES = (
    "cases/builtin.py", "cases/cached.py", "feeder/generators.py", "feeder/model.py",
    "feeder/profiles.py", "feeder/reduction.py", "feeder/tree.py", "game/problem.py",
    "game/flows.py", "compare.py", "runs.py", "constants.py", "readers/pandapower.py",
    "cases/sources.py",
)  # fmt: skip


def profiles_digest(profiles: LoadProfiles) -> str:
    """SHA-256 of a series' kW values, shape, load names, index and source."""
    digest = hashlib.sha256()
    values = profiles.kw.to_numpy(dtype=float)
    digest.update(json.dumps([list(values.shape), [str(c) for c in profiles.kw.columns],
                              profiles.source]).encode())  # fmt: skip
    digest.update(profiles.kw.index.to_numpy().tobytes())
    digest.update(values.tobytes())
    return digest.hexdigest()


def problem_key(
    profiles: LoadProfiles, limits: Sequence[tuple[int, int, float]], source: dict | None = None
) -> dict:
    """What the built ieee-elv problem of ``profiles`` and path ``limits`` depends on
    (``source``: the feeder's description, e.g. the run's feeder options)."""
    from popdispatch import __version__
    from popdispatch.cases.builtin import elv_cache_key

    return {
        "source": source,
        "what": "ieee-elv dispatch problem",
        "format": PROBLEM_FORMAT,
        "popdispatch": __version__,
        "code": code_hash(*BUILD_MODULES),
        "elv": elv_cache_key(),
        "profiles": profiles_digest(profiles),
        "limits": [[int(a), int(b), float(kw)] for a, b, kw in limits],
    }


def entry_path(key: dict) -> Path | None:
    """The pickle of ``key`` (None when the cache is disabled)."""
    folder = cache.cache_dir()
    if folder is None:
        return None
    digest = hashlib.sha256(cache.key_text(key).encode()).hexdigest()[:16]
    return folder / f"{PROBLEM_CACHE}-{digest}.pickle"


def load(key: dict) -> DispatchProblem | None:
    """The problem stored under exactly ``key``; None on any miss."""
    path = entry_path(key)
    if path is None:
        return None
    try:
        with open(path, "rb") as handle:
            stored = pickle.load(handle)
        text, problem = stored["key"], stored["problem"]
    except Exception:  # missing, truncated, not a pickle, another layout: a miss
        return None
    if text != cache.key_text(key) or not isinstance(problem, DispatchProblem):
        return None
    return problem


def save(key: dict, problem: DispatchProblem) -> Path | None:
    """Store ``problem`` under ``key`` atomically; None if the cache is disabled or cannot be
    written (never raises for an I/O problem)."""
    path = entry_path(key)
    if path is None:
        return None
    payload = {"key": cache.key_text(key), "problem": problem}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        cache.write_atomic(path, lambda handle: pickle.dump(payload, handle, protocol=5))
    except (OSError, pickle.PicklingError):
        return None
    _prune(path.parent)
    return path


def _prune(folder: Path) -> None:
    """Delete all but the :data:`KEEP` most recently written problem entries."""
    try:
        entries = sorted(folder.glob(f"{PROBLEM_CACHE}-*.pickle"), key=lambda p: p.stat().st_mtime)
        for old in entries[:-KEEP]:
            old.unlink(missing_ok=True)
    except OSError:
        pass


def cached_build(
    profiles: LoadProfiles,
    limits: Sequence[tuple[int, int, float]],
    build: Callable[[], DispatchProblem],
    source: dict | None = None,
) -> tuple[DispatchProblem, bool]:
    """``(problem, hit)``: the stored problem of ``profiles``, ``limits`` and ``source``, else
    ``build()`` (stored for the next process; an error it raises is not stored)."""
    key = problem_key(profiles, limits, source)
    found = load(key)
    if found is not None:
        return found, True
    problem = build()
    save(key, problem)
    return problem, False
