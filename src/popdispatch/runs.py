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


@dataclass(frozen=True)
class FeederSource:
    """Where a run's feeder comes from (the CLI's ``--opendss``, ``--net``, ``--fleet``,
    ``--root``, ``--no-ratings``).

    ``net``: a network file, read by its suffix (:data:`NETWORK_READERS`: ``.m`` MATPOWER,
    ``.json`` pandapower, ``.dss`` OpenDSS master); it runs on its own loads (one time step,
    repeated) with its own generators and costs, or ``fleet`` (a CSV or TOML fleet file, see
    :func:`popdispatch.feeder.generators.read_fleet`; buses as the network numbers them) in
    their place. ``case``: a built-in case by name (:func:`popdispatch.feeder.cases.
    list_cases`); other than ieee-elv it runs on its own loads like a network. ``root``: the
    source bus when the network has several. ``ratings``: line
    limits from the network's own ratings. Without ``net``: the built-in ieee-elv case, or its
    OpenDSS folder ``opendss``, with the paper's fleet (or ``fleet``) and the official or
    default profiles.
    """

    opendss: Path | None = None
    net: Path | None = None
    fleet: Path | None = None
    root: int | None = None
    ratings: bool = True
    case: str | None = None

    def __post_init__(self) -> None:
        given = [name for name, value in self._inputs() if value is not None]
        if len(given) > 1:
            raise OptionError(f"give one of {', '.join(given)}, not several", given[0])
        if self.case is not None:
            from popdispatch.feeder.cases import CASES, SIMBENCH_PREFIX

            if self.case not in CASES and not self.case.startswith(SIMBENCH_PREFIX):
                known = ", ".join(CASES)
                raise OptionError(f"unknown case {self.case!r} (known: {known})", "--case")
        if self.net is not None and self.net.suffix.lower() not in NETWORK_READERS:
            known = ", ".join(NETWORK_READERS)
            raise OptionError(f"{self.net}: unknown network format (known: {known})", "--net")
        if self.net is None and (self.root is not None or not self.ratings):
            raise OptionError("--root and --no-ratings apply to a --net network", "--root")

    def _inputs(self) -> list[tuple[str, object]]:
        return [("--opendss", self.opendss), ("--net", self.net), ("--case", self.case)]

    @property
    def own_loads(self) -> bool:
        """Whether the run uses the network's own loads (not the ieee-elv profiles)."""
        return self.net is not None or self.case not in (None, "ieee-elv")

    @property
    def label(self) -> str:
        """What is read, for progress lines."""
        where = self.net or self.opendss
        return f"the feeder in {where}" if where else f"the {self.case or 'ieee-elv'} feeder"


#: Network file suffix -> reader in :mod:`popdispatch.readers`.
NETWORK_READERS = {".m": "read_matpower", ".json": "read_pandapower", ".dss": "read_opendss_master"}


def read_network(path: Path, fleet=None, root: int | None = None, ratings: bool = True) -> Feeder:
    """A network file as a feeder, by its suffix (:data:`NETWORK_READERS`)."""
    import popdispatch.readers as readers

    suffix = path.suffix.lower()
    if suffix == ".dss" and root is not None:
        root = str(root)  # OpenDSS names its buses; numbered ones keep their number
    return getattr(readers, NETWORK_READERS[suffix])(path, fleet=fleet, root=root, ratings=ratings)


def load_feeder(source: FeederSource | Path | None = None) -> Feeder:
    """The feeder of ``source`` (a :class:`FeederSource`; a folder means its OpenDSS files;
    ``None`` the built-in ieee-elv case)."""
    if not isinstance(source, FeederSource):
        source = FeederSource(opendss=source)
    from popdispatch.feeder.generators import read_fleet

    fleet = read_fleet(source.fleet) if source.fleet is not None else None
    if source.net is not None:
        return read_network(source.net, fleet, source.root, source.ratings)
    if source.case is not None:
        from popdispatch.feeder.cases import load_case

        return load_case(source.case, fleet=fleet)
    if source.opendss is not None:
        from popdispatch.readers import read_opendss_feeder

        feeder = read_opendss_feeder(source.opendss)
    else:
        from popdispatch.feeder.cases import ieee_elv

        feeder = ieee_elv()
    return feeder if fleet is None else feeder.with_generators(fleet)


def network_profiles(feeder: Feeder) -> LoadProfiles:
    """A network without profiles runs on its own loads (column ``p_kw``, kW), the same at
    every minute."""
    from popdispatch.errors import ProfileError
    from popdispatch.feeder.profiles import single_minute_profiles

    if "p_kw" not in feeder.loads.columns:
        raise ProfileError(f"feeder {feeder.name} has no load values (p_kw) to run on")
    return single_minute_profiles(1, feeder.loads["p_kw"].astype(float), f"{feeder.name} loads")


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
) -> tuple[DispatchProblem, LoadProfiles]:
    """``(problem, profiles)`` of a run as the commands make it: ieee-elv with the profiles of
    folder ``profiles`` (:func:`load_profiles`), or a network or case on its own loads."""
    progress = progress or Progress(quiet=True)
    if source.own_loads and profiles is not None:
        raise OptionError(
            "a network or case runs on its own loads; --profiles is for ieee-elv", "--profiles"
        )
    day_profiles = None if source.own_loads else load_profiles(profiles, minute, progress)
    with progress.step(f"loading {source.label}"):
        problem = load_problem(day_profiles, limits, source, events, minutes)
    return problem, day_profiles or network_profiles(problem.feeder.original)


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
