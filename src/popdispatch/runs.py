"""Runs as the ``popdispatch`` commands make them, with the same checks for Python users.

:func:`load_profiles` and :func:`load_problem` build a run's problem (profiles, the built-in
ieee-elv feeder or one read from OpenDSS files, path limits checked against the feeder's buses,
generator events); :func:`run_snapshot_vs_opf` and :func:`run_day_vs_opf` check the initial
shares against the problem's fleet and the generators online, then run against the DC-OPF.
Bad usage raises :class:`~popdispatch.errors.OptionError` naming the option (the CLI exits 2).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch.cases.builtin import PEAK_MINUTE
from popdispatch.cases.sources import (  # noqa: F401  (re-exported: the runs' feeders)
    FLEET_RANGES,
    NETWORK_READERS,
    FeederSource,
    check_fleet_ranges,
    load_feeder,
    load_network,
    read_network,
    require_fleet,
)
from popdispatch.compare import (
    DayComparison,
    SnapshotComparison,
    check_voltage,
    day_vs_opf,
    elv_problem,
    peak_profiles,
    snapshot_vs_opf,
)
from popdispatch.errors import OptionError
from popdispatch.events import Event, apply_events
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import (
    DispatchProblem,
    check_net_demand,
    check_online,
    feeder_shortfalls,
)
from popdispatch.online import RunSettings
from popdispatch.progress import Progress

#: A path limit: every line between original buses A and B (as the source format names them)
#: limited to KW kW.
Limit = tuple[int | str, int | str, float]


def load_profiles(
    folder: Path | None = None, minute: int | None = None, progress: Progress | None = None
) -> LoadProfiles:
    """Profiles for a run: ``folder``, else minute 566's official loads (when ``minute`` is
    566), else ``$POPDISPATCH_PROFILES`` or the offline default (a note says which)."""
    from popdispatch.readers import PROFILES_ENV, read_profiles, resolve_profiles

    progress = progress or Progress(quiet=True)
    if folder is not None:
        with progress.step("reading load profiles"):
            return read_profiles(folder)
    if minute == PEAK_MINUTE:
        return peak_profiles()
    profiles = resolve_profiles(None)
    if not os.environ.get(PROFILES_ENV, "").strip():
        progress.note(f"no --profiles given: using the offline default, {profiles.source}")
    return profiles


def network_profiles(feeder: Feeder) -> LoadProfiles:
    """A network without profiles runs on its own loads (column ``p_kw``, kW): one time step."""
    from popdispatch.errors import ProfileError

    if "p_kw" not in feeder.loads.columns:
        raise ProfileError(f"feeder {feeder.name} has no load values (p_kw) to run on")
    kw = feeder.loads["p_kw"].astype(float).to_frame().T
    kw.index = pd.RangeIndex(1, 2, name="minute")
    return LoadProfiles(kw, f"{feeder.name} loads")


def known_steps(
    source: FeederSource, profiles: Path | None = None, loads: Path | None = None
) -> int | None:
    """How many steps a run's series has when that is known before any data is read: the
    ELV day (1440 minutes) or a network on its own loads (1); ``None`` for a load table, a
    SimBench year or an OpenDSS circuit (its load shapes, :mod:`popdispatch.feeder.shapes`)."""
    from popdispatch.cases.builtin import SIMBENCH_PREFIX
    from popdispatch.constants import MINUTES_PER_DAY

    if loads is not None:
        return None
    if source.net is not None and source.net.suffix.lower() == ".dss":
        return None
    if source.case is not None and source.case.startswith("opendss:"):
        return None
    if profiles is not None or not source.own_loads:
        return MINUTES_PER_DAY
    if source.case is not None and source.case.startswith(SIMBENCH_PREFIX):
        return None
    return 1


def series_for(
    source: FeederSource,
    feeder: Feeder,
    profiles: Path | None = None,
    loads: Path | None = None,
    minute: int | None = None,
    progress: Progress | None = None,
    series_kind: str | None = None,
) -> LoadProfiles:
    """The load time series of a run on ``feeder``: the table ``loads`` (CSV or Parquet, see
    :mod:`popdispatch.readers.series`), else the ELV profile folder ``profiles`` (also for a
    network read from the ELV's own files: loads match by name, case ignored), else the
    network's own: a SimBench case's bundled year, an OpenDSS circuit's load shapes of kind
    ``series_kind`` (``daily``, ``yearly``, ``duty``; default the one its loads use,
    :func:`popdispatch.feeder.shapes.shape_series`), a network's or case's own loads (one
    step), or ieee-elv's official or default profiles (:func:`load_profiles`)."""
    progress = progress or Progress(quiet=True)
    if loads is not None and profiles is not None:
        raise OptionError("give --loads or --profiles, not both", "--loads")
    if series_kind is not None and (loads is not None or profiles is not None):
        given = "--loads" if loads is not None else "--profiles"
        raise OptionError(f"--series runs the network's own load shapes; {given} replaces "
                          "them: give one", "--series")  # fmt: skip
    if loads is not None:
        from popdispatch.readers.series import read_load_table

        with progress.step(f"reading load table {loads}"):
            return read_load_table(loads, feeder)
    if profiles is not None or not source.own_loads:
        return load_profiles(profiles, minute, progress).for_loads(feeder.loads.index)
    from popdispatch.cases.builtin import SIMBENCH_PREFIX

    if source.case is not None and source.case.startswith(SIMBENCH_PREFIX):
        from popdispatch.cases.builtin import simbench_profiles

        with progress.step("reading SimBench's year profiles"):
            return simbench_profiles(source.case[len(SIMBENCH_PREFIX) :], feeder)
    from popdispatch.feeder.shapes import shape_series

    shaped = shape_series(feeder, series_kind)
    return shaped if shaped is not None else network_profiles(feeder)


def select_steps(
    profiles: LoadProfiles,
    steps: tuple[int, int] | None = None,
    start: str | None = None,
    end: str | None = None,
) -> np.ndarray | None:
    """The 1-based steps a day run simulates: ``steps`` (first, last; the CLI's ``--steps``
    or ``--minutes``) or the steps whose intervals hold ``start`` .. ``end`` (ISO 8601 times,
    ``HH:MM`` for the undated ELV day); ``None`` for every step. :class:`OptionError` for a
    range outside the series."""
    if steps is not None and (start is not None or end is not None):
        raise OptionError("give --steps (or --minutes) or --start/--end, not both", "--steps")
    if steps is None and start is None and end is None:
        return None
    timeline = profiles.timeline
    if steps is None:
        first = timeline.step_at(start, "--start") if start is not None else 1
        last = timeline.step_at(end, "--end") if end is not None else profiles.steps
        if last < first:
            raise OptionError(f"--end {end} comes before --start {start}", "--end")
        steps = (first, last)
    first, last = steps
    if not 1 <= first <= last <= profiles.steps:
        raise OptionError(
            f"steps {first}-{last} are outside the series' 1-{profiles.steps} ({profiles.source})",
            "--steps",
        )
    return np.arange(first, last + 1)


@dataclass(frozen=True)
class Span:
    """The steps a day run simulates, as the CLI gives them: ``steps`` (first, last; 1-based,
    ``--steps``/``--minutes``) or the times ``start``/``end`` (``--start``/``--end``); all
    ``None``: every step."""

    steps: tuple[int, int] | None = None
    start: str | None = None
    end: str | None = None

    def of(self, profiles: LoadProfiles) -> np.ndarray | None:
        """The 1-based steps of ``profiles`` (:func:`select_steps`)."""
        return select_steps(profiles, self.steps, self.start, self.end)


def check_step(minute: int | None, profiles: LoadProfiles) -> None:
    """:class:`OptionError` (``--minute``) for a step outside the series."""
    if minute is not None and not 1 <= minute <= profiles.steps:
        one = " (a network without profiles is one time step)" if profiles.steps == 1 else ""
        raise OptionError(
            f"step {minute} is outside the series' 1-{profiles.steps}{one} ({profiles.source})",
            "--minute",
        )


def check_limits(limits: Sequence[Limit], feeder: Feeder | DcNetwork) -> None:
    """:class:`OptionError` (``--limit``) for a limit naming a bus ``feeder`` lacks (buses as
    the source format names them: numbers, or OpenDSS names), or, on a meshed network, two
    buses no line joins."""
    from popdispatch.errors import FeederError

    buses = feeder.buses.index
    for a, b, kw in limits:
        for bus in (a, b):
            try:
                feeder.bus_id(bus)
            except FeederError:
                named = "name" in feeder.buses.columns
                known = (
                    f"buses named e.g. {', '.join(feeder.bus_labels(buses[:3]))}"
                    if named
                    else f"buses {buses.min()}..{buses.max()}"
                )
                raise OptionError(
                    f"unknown bus {bus} in {a}:{b}={kw:g} (feeder {feeder.name} has {known})",
                    "--limit",
                ) from None
        if isinstance(feeder, DcNetwork):
            try:
                feeder.path_lines(a, b)
            except FeederError as exc:
                raise OptionError(f"{a}:{b}={kw:g}: {exc}", "--limit") from None


def load_problem(
    profiles: LoadProfiles | None,
    limits: Sequence[Limit] = (),
    source: FeederSource | Path | None = None,
    events: Sequence[Event] = (),
    minutes=None,
) -> DispatchProblem:
    """The dispatch problem of a run: the feeder (:func:`load_feeder`) with path ``limits``
    (checked, :func:`check_limits`) and ``events`` applied (:func:`popdispatch.events.
    apply_events`, which checks a generator is online at each of ``minutes``, default all).
    ``profiles``: ``None`` runs a network on its own loads (:func:`network_profiles`).

    Demand is not checked against the fleet here: a run checks only the minutes it runs.
    """
    feeder = load_feeder(source)
    check_limits(limits, feeder)
    profiles = profiles or network_profiles(feeder)
    problem = elv_problem(profiles, limits, feeder, check=False)
    return apply_events(problem, events, minutes) if events else problem


def load_run(
    source: FeederSource,
    profiles: Path | None = None,
    minute: int | None = None,
    limits: Sequence[Limit] = (),
    progress: Progress | None = None,
    events: Sequence[Event] = (),
    minutes=None,
    loads: Path | None = None,
    series_kind: str | None = None,
) -> tuple[DispatchProblem, LoadProfiles]:
    """``(problem, profiles)`` of a run as the commands make it: the feeder of ``source`` with
    the time series :func:`series_for` picks (``profiles``: an ELV profile folder; ``loads``:
    a load table), ``minute`` (a snapshot's step) checked against the series; ``minutes``
    (the steps a day runs: an array or a :class:`Span`) for the events' check."""
    progress = progress or Progress(quiet=True)
    if loads is not None and profiles is not None:
        raise OptionError("give --loads or --profiles, not both", "--loads")
    if source.own_loads or loads is not None:
        with progress.step(f"loading {source.label}"):
            feeder, note = load_network(source)
            feeder = require_fleet(feeder)
        if note:
            progress.note(note)
        if isinstance(feeder, DcNetwork) and series_kind is not None:
            raise OptionError(f"load shapes are not run on a meshed network ({feeder.name}: one "
                              "step, or a --loads table)", "--series")  # fmt: skip
        series = series_for(source, feeder, profiles, loads, minute, progress, series_kind)
    else:  # ieee-elv: the profiles (and their note) first, as before
        if series_kind is not None:
            raise OptionError("--series runs a network's own load shapes (an OpenDSS circuit "
                              "given with --net)", "--series")  # fmt: skip
        series = load_profiles(profiles, minute, progress)
        problem = _elv_run_problem(source, series, limits, progress)
        series = series.for_loads(problem.feeder.original.loads.index)
        check_step(minute, series)
        if isinstance(minutes, Span):
            minutes = minutes.of(series)
        problem = apply_events(problem, events, minutes) if events else problem
        return problem, series
    check_step(minute, series)
    if isinstance(minutes, Span):
        minutes = minutes.of(series)
    check_limits(limits, feeder)
    problem = elv_problem(series, limits, feeder, check=False)
    problem = apply_events(problem, events, minutes) if events else problem
    for shortfall in feeder_shortfalls(problem, [minute] if minute else minutes):
        progress.note(f"note: {shortfall}")
    return problem, series


def _elv_run_problem(
    source: FeederSource, series: LoadProfiles, limits: Sequence[Limit], progress: Progress
) -> DispatchProblem:
    """The problem of the ieee-elv feeder (built in, or from OpenDSS files) with ``series``
    and path ``limits``, from the on-disk cache where the built-in case was built before
    (:mod:`popdispatch.cases.cached`: skips reading and reducing the feeder)."""

    def build() -> DispatchProblem:
        with progress.step(f"loading {source.label}"):
            feeder = load_feeder(source)
        check_limits(limits, feeder)
        return elv_problem(series.for_loads(feeder.loads.index), limits, feeder, check=False)

    builtin = source.opendss is None and source.case in (None, "ieee-elv")
    if not builtin or source.fleet is not None:  # files the key does not follow: no cache
        return build()
    from popdispatch.cases.cached import cached_build

    described = {"case": "ieee-elv", "root": source.root, "ratings": source.ratings}
    return cached_build(series, limits, build, described)[0]


def fleet_names(source: FeederSource | None = None) -> list[str] | None:
    """Names of the generators of the feeder ``source`` gives, where they are known before any
    network is read (the paper's fleet, Table I, on the built-in case and its OpenDSS folder;
    a ``--fleet`` file's names); ``None`` for a network's own generators."""
    from popdispatch.feeder.generators import paper_fleet, read_fleet

    if source is not None and source.fleet is not None:
        return list(read_fleet(source.fleet).index)
    if source is not None and source.own_loads:
        return None
    return list(paper_fleet().index)


def check_x0(x0: str | dict[str, float], names: Sequence[str] | None) -> list[str]:
    """:class:`OptionError` (``--x0``) for initial shares naming a generator not in ``names``;
    returns the generators the shares leave out (they start at zero share)."""
    if not isinstance(x0, dict) or names is None:
        return []
    unknown = [name for name in x0 if name not in names]
    if unknown:
        shares = ",".join(f"{name}={share:g}" for name, share in x0.items())
        raise OptionError(
            f"unknown generator {unknown[0]!r} in {shares} (known: {', '.join(names)})", "--x0"
        )
    return [name for name in names if not x0.get(name)]


def with_voltage(
    problem: DispatchProblem,
    profiles: LoadProfiles,
    settings: RunSettings,
    vn_kv: float | None = None,
) -> DispatchProblem:
    """``problem`` with the voltage rows of ``settings``' limits (``vmin_pu``/``vmax_pu``;
    unchanged without them), from the per-load demand of ``profiles`` (the run's series):
    :func:`popdispatch.ac.lindistflow.with_voltage_limits`. ``vn_kv``: the nominal voltage
    where the network does not say (kV)."""
    if not settings.voltage_limited:
        return problem
    from popdispatch.ac.lindistflow import with_voltage_limits

    loads = profiles.for_loads(problem.feeder.original.loads.index).kw.to_numpy(float)
    return with_voltage_limits(problem, loads, settings.vmin_pu, settings.vmax_pu, vn_kv=vn_kv)


def run_snapshot_vs_opf(
    problem: DispatchProblem, minute: int, settings: RunSettings | None = None
) -> SnapshotComparison:
    """One minute of dynamics and its DC-OPF (the LinDistFlow OPF with voltage limits), once
    the initial shares are checked against the problem's fleet, the voltage limits against the
    problem's (:func:`check_voltage`) and some generator is online at ``minute``."""
    settings = settings or RunSettings()
    check_voltage(problem, settings)
    check_x0(settings.x0, problem.generators)
    check_online(problem, [minute])
    check_net_demand(problem, [minute])
    return snapshot_vs_opf(problem, minute, settings)


def run_day_vs_opf(
    problem: DispatchProblem,
    settings: RunSettings | None = None,
    minutes=None,
    progress: Progress | None = None,
) -> DayComparison:
    """The online day over ``minutes`` (default all) and each minute's DC-OPF (LinDistFlow
    OPF with voltage limits), once the initial shares are checked against the problem's fleet,
    the voltage limits against the problem's and some generator is online at every minute."""
    settings = settings or RunSettings()
    check_voltage(problem, settings)
    check_x0(settings.x0, problem.generators)
    check_online(problem, minutes)
    check_net_demand(problem, minutes)
    return day_vs_opf(problem, settings, minutes, progress)
