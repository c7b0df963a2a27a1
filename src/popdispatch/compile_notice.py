"""Whether the engine's compiled kernels must be compiled now (numba's disk cache is cold).

The engine's kernels are compiled by numba on first use and cached on disk (``cache=True``):
the first run after installing or updating popdispatch (or with an empty ``NUMBA_CACHE_DIR``)
compiles the kernels of its own run configuration (mode, dynamic, graph, stepper:
:mod:`popdispatch.integrate.term`); a run of another configuration later compiles its own
once more, and later processes load them from the cache (``benchmarks/bench_first_run.py``
measures both; docs/performance.md).
The CLI calls :func:`kernels_cached` before the engine runs so that it can say so on stderr
instead of staying silent.

The check asks numba's own cache object of each entry point (:data:`ENTRY_POINTS`) for its
index, as numba itself would when the kernel is first called: wherever the cache lives
(``__pycache__`` next to the sources, ``NUMBA_CACHE_DIR``, the user-wide fallback), missing,
written by another numba version or older than the source file all read as empty.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from popdispatch.online.settings import RunSettings

#: The kernels every engine run compiles (``module:function``): the day loop (a single minute
#: runs as a day of one row) and the game and field it calls; their callees are compiled and
#: cached with them. (Not the problem's build, ``game.flows.limited_ancestors``: a run whose
#: built problem comes from the problem cache, cases/cached.py, never calls it, and the
#: notice then showed on every run.)
ENTRY_POINTS = (
    "popdispatch.integrate.steppers:evaluate_stage",
    "popdispatch.online.day:integrate_day",
)

#: The day loop: compiled once per run configuration (see :func:`kernels_cached`).
DAY_LOOP = "popdispatch.online.day:integrate_day"

COMPILE_NOTICE = (
    "compiling the engine's kernels (first run after installing or updating popdispatch, or "
    "an empty numba cache, or a mode, dynamic or graph not run before): this run takes longer, "
    "once per configuration; later runs load them from numba's disk cache"
)


def kernels_cached(settings: RunSettings | None = None) -> bool | None:
    """True if numba's disk cache holds an up-to-date entry for every entry point, False if
    one must be compiled, None if that cannot be told (then say nothing).

    The engine compiles its day loop once per run configuration (the record classes of the
    mode, field, graph and stepper, :func:`run_classes`): with ``settings``, the
    day loop's entry must be one compiled for that configuration, with or without limited
    lines (exact mode's kernel differs; the feeder is read after the notice, so either
    counts, and a run of the other kind compiles without a notice); without, any entry will
    do.
    """
    try:
        for entry in ENTRY_POINTS:
            index = _dispatcher(entry)._cache._cache_file._load_index()
            if not index:
                return False
        if settings is not None:  # the feeder, not read yet, may or may not limit lines
            wanted = [run_classes(settings, limited) for limited in (True, False)]
            if wanted[0] is None:
                return None
            index = _dispatcher(DAY_LOOP)._cache._cache_file._load_index()
            return any(w <= _classes(key[0]) for w in wanted for key in index)
    except Exception:  # numba internals differ: no notice rather than a wrong one
        return None
    return True


def run_classes(settings: RunSettings, limited: bool = True) -> set[type] | None:
    """The record classes that select the compiled kernels of a run with ``settings`` (as
    :class:`~popdispatch.online.engine.Engine` builds them) on a radial feeder with
    (``limited``) or without limited lines, None for settings that cannot run."""
    from popdispatch.dynamics.fields import law_of
    from popdispatch.dynamics.pairwise import CompleteGraph, SparseGraph
    from popdispatch.integrate.steppers import method_tag
    from popdispatch.modes import get_mode, mode_tag

    mode = get_mode(settings.mode)
    field = settings.field
    if field is None:
        return None
    return {
        law_of(field).tag,
        type(mode_tag(mode.code, settings.exact.price_law,
                      pinned=limited and settings.hastens_pinned_lines)),
        CompleteGraph if settings.complete_graph else SparseGraph,
        type(method_tag(settings.stepping.method_code)),
    }  # fmt: skip


def _dispatcher(entry: str):
    module, _, name = entry.partition(":")
    return getattr(importlib.import_module(module), name)


def _classes(types: tuple) -> set[type]:
    """The Python classes of every named record in a compiled signature, nested ones too."""
    found: set[type] = set()
    stack = list(types)
    while stack:
        item = stack.pop()
        cls = getattr(item, "instance_class", None)
        if cls is not None:
            found.add(cls)
        stack.extend(getattr(item, "types", ()) if cls is not None else ())
    return found
