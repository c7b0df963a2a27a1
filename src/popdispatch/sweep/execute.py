"""Running a sweep's scenarios on Dask distributed (``pip install "popdispatch[sweep]"``).

A :class:`distributed.LocalCluster` by default: one worker process per core, one thread each
(the engine's kernels are single-threaded numba code; processes sidestep the GIL). Each worker
loads the compiled kernels from numba's disk cache once (:func:`warm_up`, run on every worker
before the scenarios) and then runs scenario after scenario; ``scheduler`` connects to an
existing cluster instead (``dask scheduler`` / ``dask worker ADDRESS``; workers need the same
popdispatch and a shared file system for ``out`` and the profiles).

Workers write their scenario's results themselves (:func:`popdispatch.sweep.scenario.
run_and_store`); the driver only receives a few fields per scenario and keeps at most
:data:`WINDOW` scenarios per worker in flight, so its memory does not grow with the count.
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from popdispatch.sweep.scenario import Context, run_and_store
from popdispatch.sweep.spec import Scenario
from popdispatch.sweep.store import FAILED, finished_ids

#: Scenarios in flight per worker thread (enough to keep workers busy between results).
WINDOW = 4


@dataclass
class SweepResult:
    """What a sweep did: scenarios expanded, skipped (already in ``out``), run, failed (their
    ids and messages), the time the scenarios took (s; cluster start and warm-up excluded) and
    each worker's :func:`warm_up` (its seconds, numba cache hits and misses)."""

    total: int
    skipped: int
    ran: int = 0
    failed: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    workers: int = 0
    warm_up: dict[str, dict] = field(default_factory=dict)


def _require_dask():
    try:
        import distributed
    except ImportError:  # pragma: no cover - the extra is part of .[test]
        from popdispatch.errors import OptionError

        raise OptionError(
            'sweeps need Dask and pyarrow: pip install "popdispatch[sweep]"', "sweep"
        ) from None
    return distributed


def warm_up() -> dict:
    """Import the engine and run one two-minute ELV scenario (exact mode, DC-OPF, tables,
    Parquet write into a temporary folder) in this process, so the kernels are loaded (from
    numba's disk cache when it is warm) and every lazy import done before any scenario is
    timed. Returns the seconds it took and numba's cache hits and misses of the entry points."""
    import tempfile

    start = time.perf_counter()
    from popdispatch.compile_notice import ENTRY_POINTS, kernels_cached
    from popdispatch.sweep.spec import parse_spec

    cached = kernels_cached()
    (scenario,) = parse_spec({"steps": "566-567", "mode": "exact"}).scenarios
    with tempfile.TemporaryDirectory(prefix="popdispatch-warm-up-") as folder:
        run_and_store(scenario, Context(folder))
    return {"seconds": time.perf_counter() - start, "cached_before": cached} | cache_stats(
        ENTRY_POINTS
    )


def cache_stats(entries: Sequence[str]) -> dict:
    """numba's disk-cache hits and misses (compilations) of ``entries`` in this process."""
    import importlib

    hits = misses = 0
    for entry in entries:
        module, _, name = entry.partition(":")
        stats = getattr(importlib.import_module(module), name).stats
        hits += sum(stats.cache_hits.values())
        misses += sum(stats.cache_misses.values())
    return {"cache_hits": hits, "cache_misses": misses}


@contextlib.contextmanager
def client_for(scheduler: str | None = None, workers: int | None = None, processes: bool = True):
    """A :class:`distributed.Client`: on ``scheduler`` (an address) or on a new LocalCluster
    of ``workers`` single-threaded workers (default: one per core)."""
    distributed = _require_dask()
    if scheduler is not None:
        with distributed.Client(scheduler) as client:
            yield client
        return
    n = workers or os.cpu_count() or 1
    cluster = distributed.LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=processes,
        dashboard_address=":0",  # any free port (8787 may be taken)
        silence_logs=logging.ERROR,
    )
    with cluster, distributed.Client(cluster) as client:
        yield client


def pending(scenarios: Sequence[Scenario], out: Path, retry_failed: bool = True) -> list[Scenario]:
    """The scenarios not yet written in ``out`` (resume); duplicates run once."""
    done = finished_ids(out, retry_failed)
    seen: set[str] = set()
    todo = []
    for s in scenarios:
        if s.id not in done and s.id not in seen:
            todo.append(s)
            seen.add(s.id)
    return todo


def submit_all(
    client, todo: Sequence[Scenario], context: Context, on_done: Callable[[dict], None]
) -> None:
    """Run ``todo`` on ``client``, at most :data:`WINDOW` per worker thread in flight; call
    ``on_done`` with each scenario's outcome as it finishes (a lost worker's scenario, after
    Dask's own retries, reads as failed)."""
    from distributed import as_completed

    threads = max(1, sum(client.nthreads().values()))
    queue = iter(todo)
    by_key = {}

    def submit(s: Scenario):
        future = client.submit(run_and_store, s, context, key=f"scenario-{s.id}", pure=False)
        by_key[future.key] = s
        return future

    running = as_completed([submit(s) for s in _take(queue, WINDOW * threads)])
    for future in running:
        scenario = by_key.pop(future.key)
        try:
            outcome = future.result()
        except Exception as exc:  # worker lost or results unwritable: record, carry on
            outcome = _lost(scenario, context, exc)
        future.release()
        on_done(outcome)
        for s in _take(queue, 1):
            running.add(submit(s))


def _lost(scenario: Scenario, context: Context, exc: Exception) -> dict:
    """Record a scenario whose task itself failed (not its run) as failed, from the driver,
    unless an earlier attempt of the task wrote its results before its worker was lost."""
    from popdispatch.sweep.scenario import parameters
    from popdispatch.sweep.store import status_of, write_scenario

    message = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    status = status_of(Path(context.out), scenario.id)
    if status not in (None, FAILED):
        return {"id": scenario.id, "status": status, "error": None, "scenario_seconds": None}
    with contextlib.suppress(OSError):
        row = {"status": FAILED, "error": message} | parameters(scenario)
        write_scenario(Path(context.out), scenario.id, row)
    return {"id": scenario.id, "status": FAILED, "error": message, "scenario_seconds": None}


def _take(iterator: Iterator, n: int) -> list:
    return [item for _, item in zip(range(n), iterator, strict=False)]


def check_profiles(scenarios: Sequence[Scenario], profiles) -> None:
    """:class:`OptionError` (``--profiles``) before any work when random profile assignments
    have no official profile folder to draw from."""
    from popdispatch.errors import OptionError

    if profiles is None and any(s.assignment.seed is not None for s in scenarios):
        raise OptionError(
            "random profile assignments need the official profiles: give --profiles DIR or "
            "set POPDISPATCH_PROFILES",
            "--profiles",
        )


def run_sweep(
    scenarios: Sequence[Scenario],
    out: str | Path,
    profiles: str | Path | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    quiet: bool = False,
    processes: bool = True,
    retry_failed: bool = True,
) -> SweepResult:
    """Run the scenarios not yet in ``out`` on Dask and write their results there.

    ``profiles``: the official profile folder (else ``$POPDISPATCH_PROFILES``); ``workers``:
    LocalCluster size (default: cores); ``processes=False`` runs the workers as threads of
    this process (for tests; the GIL then serialises them). A progress bar on stderr shows
    scenarios done, failures, rate and ETA unless ``quiet``.
    """
    profiles = profiles or os.environ.get("POPDISPATCH_PROFILES", "").strip() or None
    check_profiles(scenarios, profiles)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    context = Context(str(out.resolve()), str(Path(profiles).resolve()) if profiles else None)
    todo = pending(scenarios, out, retry_failed)
    result = SweepResult(total=len(scenarios), skipped=len(scenarios) - len(todo))
    if not todo:
        return result
    with client_for(scheduler, workers, processes) as client:
        result.workers = len(client.nthreads())
        result.warm_up = client.run(warm_up)
        start = time.perf_counter()
        with _bar(result, quiet) as advance:
            submit_all(client, todo, context, advance)
        result.seconds = time.perf_counter() - start
    return result


@contextlib.contextmanager
def _bar(result: SweepResult, quiet: bool):
    """tqdm bar over every scenario (skipped ones counted as done), failures as postfix."""
    import sys

    from tqdm import tqdm

    bar = tqdm(
        total=result.total,
        initial=result.skipped,
        desc="sweep",
        unit="scenario",
        disable=quiet,
        file=sys.stderr,
        dynamic_ncols=True,
        mininterval=0.5 if sys.stderr.isatty() else 10.0,
    )
    bar.set_postfix(failed=0)

    def advance(outcome: dict) -> None:
        result.ran += 1
        if outcome["status"] == FAILED:
            result.failed[outcome["id"]] = outcome["error"]
        bar.set_postfix(failed=len(result.failed), refresh=False)
        bar.update(1)

    try:
        yield advance
    finally:
        bar.close()
