"""Input-file manifests for the on-disk cache (:mod:`popdispatch.cache`) of tables read from
files, so a second process skips re-reading and re-parsing them.

A cached table is stored under a key naming what was read (e.g. the absolute profile folder)
and the code that read it; beside the arrays, the entry keeps the *manifest* of the inputs:
every file and folder the read looked at, with its size (bytes) and modification time (ns).
A cached entry is used only when every input still has the same size and modification time
(re-checked on every use, one ``stat`` per input); any change, removal or unreadable input is a
miss, and the caller reads the files afresh and replaces the entry. Folders are in the manifest
because a file added next to the ones read (e.g. a second ``loads.txt`` that makes a name
ambiguous) changes the folder's modification time.

An entry is stored only when every input was last modified at least :data:`SETTLE_NS` before
(:meth:`Inputs.settled`): a file rewritten with the same size within one tick of the
filesystem's clock keeps its modification time, so an input modified just before it was read
could change again unseen (git's "racily clean" files). A folder written a moment ago is read
afresh until it has settled.
"""

from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import numpy as np

_PATHS, _SIZES, _MTIMES = "__manifest_paths__", "__manifest_sizes__", "__manifest_mtimes_ns__"
#: How long before the store every input must have been last modified, ns (2 s: coarser than
#: any common filesystem's timestamps, FAT's 2 s included).
SETTLE_NS = 2_000_000_000


def code_hash(*modules: str) -> str | None:
    """A short hash of the source files of ``modules`` (paths relative to the ``popdispatch``
    package, e.g. ``"readers/profiles.py"``): a cached entry made by other code is not used."""
    root = Path(__file__).resolve().parents[1]
    digest = hashlib.sha256()
    try:
        for module in modules:
            digest.update((root / module).read_bytes())
    except OSError:
        return None
    return digest.hexdigest()[:16]


class Inputs:
    """The files and folders a read looks at, each stat-ed when first added (before it is
    read, so a file changed during the read leaves a manifest that no longer matches it)."""

    def __init__(self) -> None:
        self._stats: dict[str, tuple[int, int]] = {}

    def add(self, path: Path | None, root: Path | None = None) -> Path | None:
        """Record ``path`` (a file or folder; None is passed through unrecorded) and, with
        ``root``, every folder from ``root`` down to it; returns ``path``."""
        if path is None:
            return None
        chain = [Path(path)]
        if root is not None:
            chain = [*reversed(Path(path).parents), Path(path)]
            chain = [p for p in chain if p == Path(root) or Path(root) in p.parents]
        for item in chain:
            key = str(item)
            if key not in self._stats:
                stat = os.stat(item)
                self._stats[key] = (stat.st_size, stat.st_mtime_ns)
        return path

    def settled(self, now_ns: int | None = None) -> bool:
        """Was every input last modified at least :data:`SETTLE_NS` before ``now_ns`` (ns since
        the epoch; default: now)? Only then may the manifest vouch for the contents."""
        now_ns = time.time_ns() if now_ns is None else now_ns
        return all(mtime <= now_ns - SETTLE_NS for _, mtime in self._stats.values())

    def arrays(self) -> dict[str, np.ndarray]:
        """The manifest arrays to store beside a cached entry."""
        paths = list(self._stats)
        return {
            _PATHS: np.array(paths, dtype=str),
            _SIZES: np.array([self._stats[p][0] for p in paths], dtype=np.int64),
            _MTIMES: np.array([self._stats[p][1] for p in paths], dtype=np.int64),
        }


def split_current(arrays: dict[str, np.ndarray] | None) -> dict[str, np.ndarray] | None:
    """The stored arrays without their manifest if every input listed in it is unchanged
    (same size and modification time), else None (also for an entry without a manifest)."""
    if arrays is None or not {_PATHS, _SIZES, _MTIMES} <= arrays.keys():
        return None
    paths, sizes, mtimes = arrays[_PATHS], arrays[_SIZES], arrays[_MTIMES]
    if not (paths.ndim == sizes.ndim == mtimes.ndim == 1 and len(paths) == len(sizes) > 0):
        return None
    if len(mtimes) != len(paths):
        return None
    try:
        stats = [os.stat(path) for path in paths.tolist()]
    except OSError:  # an input was removed or became unreadable
        return None
    now = [(s.st_size, s.st_mtime_ns) for s in stats]
    if now != list(zip(sizes.tolist(), mtimes.tolist(), strict=True)):
        return None
    return {k: v for k, v in arrays.items() if k not in (_PATHS, _SIZES, _MTIMES)}
