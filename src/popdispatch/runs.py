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
from pathlib import Path

from popdispatch.errors import OptionError
from popdispatch.events import Event, apply_events
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles
from popdispatch.game.problem import DispatchProblem, check_online
from popdispatch.online import RunSettings
from popdispatch.report.progress import Progress
from popdispatch.scenarios import (
    PEAK_MINUTE,
    DayComparison,
    SnapshotComparison,
    day_vs_opf,
    elv_problem,
    peak_profiles,
    snapshot_vs_opf,
)

#: A path limit: every line between original buses A and B limited to KW kW.
Limit = tuple[int, int, float]


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


def load_feeder(opendss: Path | None = None) -> Feeder:
    """The built-in ieee-elv feeder, or the one in the OpenDSS files of folder ``opendss``."""
    if opendss is not None:
        from popdispatch.readers import read_opendss_feeder

        return read_opendss_feeder(opendss)
    from popdispatch.feeder.cases import ieee_elv

    return ieee_elv()


def check_limits(limits: Sequence[Limit], feeder: Feeder) -> None:
    """:class:`OptionError` (``--limit``) for a limit naming a bus ``feeder`` lacks."""
    buses = feeder.buses.index
    for a, b, kw in limits:
        for bus in (a, b):
            if bus not in buses:
                raise OptionError(
                    f"unknown bus {bus} in {a}:{b}={kw:g} (feeder {feeder.name} has buses "
                    f"{buses.min()}..{buses.max()})",
                    "--limit",
                )


def load_problem(
    profiles: LoadProfiles,
    limits: Sequence[Limit] = (),
    opendss: Path | None = None,
    events: Sequence[Event] = (),
    minutes=None,
) -> DispatchProblem:
    """The dispatch problem of a run: the feeder (:func:`load_feeder`) with path ``limits``
    (checked, :func:`check_limits`) and ``events`` applied (:func:`popdispatch.events.
    apply_events`, which checks a generator is online at each of ``minutes``, default all).

    Demand is not checked against the fleet here: a run checks only the minutes it runs.
    """
    feeder = load_feeder(opendss)
    check_limits(limits, feeder)
    problem = elv_problem(profiles, limits, feeder, check=False)
    return apply_events(problem, events, minutes) if events else problem


def fleet_names() -> list[str]:
    """Names of the generators of every feeder :func:`load_feeder` returns (the paper's fleet,
    Table I, on the built-in case and on a feeder read from OpenDSS files): initial shares can
    be checked against them before any data is read."""
    from popdispatch.feeder.generators import paper_fleet

    return list(paper_fleet().index)


def check_x0(x0: str | dict[str, float], names: Sequence[str]) -> list[str]:
    """:class:`OptionError` (``--x0``) for initial shares naming a generator not in ``names``;
    returns the generators the shares leave out (they start at zero share)."""
    if not isinstance(x0, dict):
        return []
    unknown = [name for name in x0 if name not in names]
    if unknown:
        shares = ",".join(f"{name}={share:g}" for name, share in x0.items())
        raise OptionError(
            f"unknown generator {unknown[0]!r} in {shares} (known: {', '.join(names)})", "--x0"
        )
    return [name for name in names if not x0.get(name)]


def run_snapshot_vs_opf(
    problem: DispatchProblem, minute: int, settings: RunSettings | None = None
) -> SnapshotComparison:
    """One minute of dynamics and its DC-OPF, once the initial shares are checked against the
    problem's fleet and some generator is online at ``minute``."""
    settings = settings or RunSettings()
    check_x0(settings.x0, problem.generators)
    check_online(problem, [minute])
    return snapshot_vs_opf(problem, minute, settings)


def run_day_vs_opf(
    problem: DispatchProblem,
    settings: RunSettings | None = None,
    minutes=None,
    progress: Progress | None = None,
) -> DayComparison:
    """The online day over ``minutes`` (default all) and each minute's DC-OPF, once the
    initial shares are checked against the problem's fleet and some generator is online at
    every minute."""
    settings = settings or RunSettings()
    check_x0(settings.x0, problem.generators)
    check_online(problem, minutes)
    return day_vs_opf(problem, settings, minutes, progress)
