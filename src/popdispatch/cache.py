"""A small on-disk cache of derived arrays, so a second process skips slow builds.

What is cached: tables that take seconds to derive but never change for a given installation,
e.g. the ieee-elv feeder's buses, lines, loads and minute-566 snapshot, which otherwise need
``import pandapower`` and its JSON network in every process.

Where: ``$POPDISPATCH_CACHE_DIR`` if set and not empty, else ``$XDG_CACHE_HOME/popdispatch``,
else ``~/.cache/popdispatch``. ``POPDISPATCH_CACHE_DIR=off`` disables the cache (nothing is
read or written). The folder may be deleted at any time.

How: one ``.npz`` file (numpy arrays, no pickles) per entry and key, named
``<name>-<hash of the key>.npz``; the key (a JSON object: a format version, the versions of
what the data comes from, ...) is also stored inside the file and compared on every read.
A file is written under a temporary name in the cache folder and renamed into place, so a
reader never sees a partial file. Reading is defensive: a missing, unreadable, truncated,
corrupt (zip CRC) or foreign file, or one whose key differs, counts as a miss and the caller
rebuilds; a cache that cannot be written (read-only home, full disk) is skipped silently.
The cache can make a command faster, never make it fail.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

#: Environment variable naming the cache folder (``off`` disables the cache).
CACHE_ENV = "POPDISPATCH_CACHE_DIR"
DISABLED = ("off", "none", "0", "false", "no")
_KEY = "__key__"


def cache_dir() -> Path | None:
    """The cache folder (not necessarily existing yet), or None when the cache is disabled."""
    env = os.environ.get(CACHE_ENV, "").strip()
    if env:
        return None if env.lower() in DISABLED else Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "popdispatch"


def key_text(key: dict) -> str:
    """The canonical JSON text of a key (sorted keys, no spaces)."""
    return json.dumps(key, sort_keys=True, separators=(",", ":"))


def entry_path(name: str, key: dict) -> Path | None:
    """The file of entry ``name`` under ``key`` (None when the cache is disabled)."""
    folder = cache_dir()
    if folder is None:
        return None
    digest = hashlib.sha256(key_text(key).encode()).hexdigest()[:16]
    return folder / f"{name}-{digest}.npz"


def load_arrays(name: str, key: dict) -> dict[str, np.ndarray] | None:
    """The arrays stored for ``name`` under exactly ``key``; None on any miss or bad file."""
    path = entry_path(name, key)
    if path is None:
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}  # reads and CRC-checks every member
    except Exception:  # missing, truncated, not a zip, bad CRC, pickled object...: a miss
        return None
    stored = arrays.pop(_KEY, None)
    if stored is None or stored.shape != () or str(stored) != key_text(key):
        return None
    return arrays


def save_arrays(name: str, key: dict, arrays: dict[str, np.ndarray]) -> Path | None:
    """Store ``arrays`` for ``name`` under ``key`` atomically; returns the file, or None if the
    cache is disabled or cannot be written (never raises for an I/O problem)."""
    path = entry_path(name, key)
    if path is None:
        return None
    if _KEY in arrays:
        raise ValueError(f"array name {_KEY!r} is reserved")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, lambda handle: np.savez(handle, **arrays, **{_KEY: key_text(key)}))
    except OSError:
        return None
    return path


def write_atomic(path: Path, write) -> None:
    """Call ``write(handle)`` on a temporary binary file next to ``path``, then rename it to
    ``path``. On any error (or interruption) the temporary file is removed and ``path`` is left
    as it was."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
