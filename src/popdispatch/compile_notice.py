"""Whether the engine's compiled kernels must be compiled now (numba's disk cache is cold).

The engine's kernels are compiled by numba on first use and cached on disk (``cache=True``):
the first run after installing or updating popdispatch (or with an empty ``NUMBA_CACHE_DIR``)
spends about 30-40 s compiling (2026-12-01, 2-core machine: 29 s of CPU for ``popdispatch
day --mode exact``; 72 s before issue 13), later processes load them in under half a second.
The CLI calls :func:`kernels_cached` before the engine runs so that it can say so on stderr
instead of staying silent.

The check asks numba's own cache object of each entry point (:data:`ENTRY_POINTS`) for its
index, as numba itself would when the kernel is first called: wherever the cache lives
(``__pycache__`` next to the sources, ``NUMBA_CACHE_DIR``, the user-wide fallback), missing,
written by another numba version or older than the source file all read as empty.
"""

from __future__ import annotations

import importlib

#: The kernels every engine run compiles (``module:function``): the day loop (a single minute
#: runs as a day of one row) and the game and field it calls; their callees are compiled and
#: cached with them.
ENTRY_POINTS = (
    "popdispatch.integrate.steppers:evaluate_stage",
    "popdispatch.online.day:integrate_day",
    "popdispatch.game.flows:limited_ancestors",
)

COMPILE_NOTICE = (
    "compiling the engine's kernels (first run after installing or updating popdispatch, or "
    "an empty numba cache): about 30-60 s, once; later runs load them from numba's disk cache"
)


def kernels_cached() -> bool | None:
    """True if numba's disk cache holds an up-to-date entry for every entry point, False if
    one must be compiled, None if that cannot be told (then say nothing)."""
    try:
        for entry in ENTRY_POINTS:
            module, _, name = entry.partition(":")
            dispatcher = getattr(importlib.import_module(module), name)
            if not dispatcher._cache._cache_file._load_index():
                return False
    except Exception:  # numba internals differ: no notice rather than a wrong one
        return None
    return True
