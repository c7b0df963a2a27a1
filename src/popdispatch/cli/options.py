"""The CLI's option types and shared options: forms are checked here, at parse time (exit 2);
names are checked against the problem by the library (:mod:`popdispatch.runs`)."""

from __future__ import annotations

import functools
import importlib
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import click

from popdispatch.notation import (  # re-exported: the option types of the commands
    LimitType,
    MinutesType,
    number_or_none,
)
from popdispatch.report.output import check_writable, missing_folder


class X0Type(click.ParamType):
    """``uniform``, ``capacity`` or ``NAME=SHARE,...`` (names ``G114`` or buses ``114``).

    Only the form is checked here; the names are checked against the problem's own fleet once
    it is built (:func:`popdispatch.runs.check_x0`), still a usage error.
    """

    name = "uniform|capacity|G=SHARE,..."

    def convert(self, value, param, ctx) -> str | dict[str, float]:
        if isinstance(value, dict) or value in ("uniform", "capacity"):
            return value
        shares: dict[str, float] = {}
        for item in str(value).split(","):
            key, sep, share = item.partition("=")
            key, number = key.strip(), number_or_none(share)
            name = f"G{key}" if key.isdigit() else key
            if not sep or not key or number is None or number < 0:
                self.fail(
                    f"{item!r} is not NAME=SHARE with a share >= 0 (in {value!r})", param, ctx
                )
            shares[name] = number
        if sum(shares.values()) <= 0:
            self.fail(f"{value!r}: the shares sum to zero", param, ctx)
        return shares


class ConstantsType(click.ParamType):
    """``NAME=VALUE,...``: the game's constants, read by
    :meth:`popdispatch.game.fitness.FitnessParameters.parse` (``B``, ``m``, ``C``, ``gain``,
    ``price_rate``, each finite and >= 0; the others at their defaults)."""

    name = "NAME=VALUE,..."

    def convert(self, value, param, ctx):
        from popdispatch.errors import OptionError
        from popdispatch.game.fitness import FitnessParameters

        if isinstance(value, FitnessParameters):
            return value
        try:
            return FitnessParameters.parse(value)
        except OptionError as exc:
            self.fail(str(exc), param, ctx)


FOLDER = click.Path(exists=True, file_okay=False, dir_okay=True, readable=True, path_type=Path)


class EngineChoice(click.Choice):
    """A choice among names the engine defines (``"module:ATTRIBUTE"``), looked up only when
    click parses a value: importing the CLI must not import the engine (numba).

    ``shown``: the names the help lists without importing the engine (numba and pandas would
    be imported for three lists of names); parsing always
    checks against the engine's own names, and tests/cli/test_startup.py checks the two agree.
    """

    def __init__(
        self, source: str, case_sensitive: bool = True, shown: tuple[str, ...] = ()
    ) -> None:
        self.source = source
        self.case_sensitive = case_sensitive
        self.shown = shown

    @property
    def choices(self) -> tuple[str, ...]:
        module, _, attribute = self.source.partition(":")
        return tuple(getattr(importlib.import_module(module), attribute))

    def get_metavar(self, param, ctx) -> str | None:
        if not self.shown:
            return super().get_metavar(param, ctx)
        names = "|".join(self.shown)
        return f"[{names}]" if param.param_type_name == "option" else f"{{{names}}}"


DYNAMICS_CHOICE = EngineChoice(
    "popdispatch.dynamics:DYNAMICS",
    shown=("smith", "distributed-smith", "replicator", "local-replicator", "bnn", "logit"),
)
MODE_CHOICE = EngineChoice("popdispatch.modes:MODES", shown=("paper", "exact", "voltage"))
GRAPH_CHOICE = EngineChoice(
    "popdispatch.dynamics.graph:GRAPHS", shown=("complete", "ring", "path", "star", "circulant")
)
WARM_START_CHOICE = EngineChoice(
    "popdispatch.warm_start:WARM_STARTS", shown=("shares", "setpoints", "merit")
)


option = click.option


json_option = option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
quiet_option = option("-q", "--quiet", is_flag=True, help="No progress bars or notes on stderr.")
minute_option = option(
    "--minute",
    "--step",
    "minute",
    type=click.IntRange(1),
    required=True,
    help="1-based minute of the day (566 = the peak), or step of a --loads/SimBench series "
    "(a network on its own loads has one step: 1).",
)
limit_option = option(
    "--limit",
    "limits",
    type=LimitType(),
    multiple=True,
    help="Limit every line on the path between original buses A and B to KW kilowatts "
    "(repeatable), e.g. 505:666=28; on a meshed network, the lines joining A and B.",
)
#: The message faults every message-passing command simulates.
loss_option = option(
    "--loss", type=click.FloatRange(0.0, 1.0, max_open=True), default=0.0, show_default=True,
    help="Probability that a message is lost (0-1).",
)  # fmt: skip
duplicate_option = option(
    "--duplicate", type=click.FloatRange(0.0, 1.0, max_open=True), default=0.0,
    show_default=True, help="Probability that a message is delivered twice.",
)  # fmt: skip
profiles_option = option(
    "--profiles",
    type=FOLDER,
    help="Folder with the official load profiles (else $POPDISPATCH_PROFILES, else the shipped "
    "synthetic default; minute 566 alone uses the official loads shipped by pandapower).",
)
LOADS_FILE = click.Path(exists=True, dir_okay=False, path_type=Path)


class Series(NamedTuple):
    """Where a run's load time series comes from: an ELV profile ``folder`` (``--profiles``)
    or a load ``table`` (``--loads``, CSV or Parquet); both ``None``: the feeder's own, its
    load shapes of kind ``kind`` (``--series``) where it has them."""

    folder: Path | None = None
    table: Path | None = None
    kind: str | None = None


def series_options(func):
    """``--profiles``, ``--loads`` and ``--series``, handed to the command as one ``profiles``
    (:class:`Series`)."""

    @functools.wraps(func)
    def command(*args, profiles, loads, series, **kwargs):
        return func(*args, profiles=Series(profiles, loads, series), **kwargs)

    command = option(
        "--series",
        type=click.Choice(["daily", "yearly", "duty"]),
        help="The network's own load shapes as the run's loads (OpenDSS daily=, yearly=, "
        "duty=); default the kind its loads use.",
    )(command)
    command = option(
        "--loads",
        type=LOADS_FILE,
        help="Load time series of any resolution and length: CSV or Parquet, a time column "
        "(ISO 8601) and one column per load name or bus id, kW.",
    )(command)
    return profiles_option(command)


def steps_options(func):
    """``--steps``/``--minutes``, ``--start`` and ``--end``, handed to the command as one
    ``minutes`` (:class:`popdispatch.runs.Span`)."""

    @functools.wraps(func)
    def command(*args, minutes, start, end, **kwargs):
        from popdispatch.runs import Span

        return func(*args, minutes=Span(minutes, start, end), **kwargs)

    decorators = [
        option(
            "--steps",
            "--minutes",
            "minutes",
            type=MinutesType(None),
            help="Simulate only steps START-END (1-based; minutes of the ELV day, default all).",
        ),
        option("--start", metavar="TIME", help="First step: the one holding TIME (ISO 8601; "
               "HH:MM on the undated ELV day)."),
        option("--end", metavar="TIME", help="Last step: the one holding TIME."),
    ]  # fmt: skip
    for decorate in reversed(decorators):
        command = decorate(command)
    return command


def build(source, profiles: Series, minute, limits, progress, events=(), minutes=None):
    """``(problem, profiles)`` of a run (:func:`popdispatch.runs.load_run`); a bad ``--limit``
    reads as click's own usage errors."""
    from popdispatch.errors import OptionError
    from popdispatch.runs import known_steps, load_run

    steps = known_steps(source, profiles.folder, profiles.table)
    if steps is not None and minute is not None and minute > steps:  # before any data is read
        raise click.BadParameter(f"{minute} is outside 1..{steps}", param_hint="'--minute'")
    span = getattr(minutes, "steps", None)
    if steps is not None and span is not None and span[1] > steps:
        raise click.BadParameter(
            f"{span[0]}-{span[1]}: need 1 <= START <= END <= {steps}", param_hint="'--steps'"
        )
    try:
        return load_run(
            source, profiles.folder, minute, limits, progress, events, minutes, profiles.table,
            profiles.kind,
        )
    except OptionError as exc:
        if exc.option != "--limit":
            raise
        raise click.BadParameter(str(exc), param_hint="'--limit'") from None


out_option = option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Also write time series (CSV, units in column names), summary.json and a figure here.",
)


def run_options(func):
    """``--dynamics``, ``--eta``, ``--mode``, ``--x0``, ``--graph``, ``--constants`` and
    ``--price-law``."""
    decorators = [
        option(
            "--dynamics",
            type=DYNAMICS_CHOICE,
            default="smith",
            show_default=True,
            help="Population dynamics: the paper's (eqs. 9-14), Brown-von Neumann-Nash (bnn; "
            "paper mode) or logit (needs --eta); docs/dynamics.md.",
        ),
        option(
            "--eta",
            type=click.FloatRange(min=0.0, min_open=True),
            help="Logit dynamics' noise level, EUR/MWh (> 0; smaller: closer to the best "
            "response); logit only.",
        ),
        option(
            "--mode",
            type=MODE_CHOICE,
            default="paper",
            show_default=True,
            help="How node controllers turn flows into fitness signals.",
        ),
        option(
            "--x0",
            type=X0Type(),
            default="uniform",
            show_default=True,
            help="Initial shares: uniform, capacity or e.g. G114=0,G1=1,G578=1 (generators "
            "not named start at zero; a note on stderr names them).",
        ),
        option(
            "--graph",
            type=GRAPH_CHOICE,
            default="complete",
            show_default=True,
            help="Communication graph (local-replicator and distributed-smith only).",
        ),
        option(
            "--constants",
            type=ConstantsType(),
            help="Paper mode's constants, e.g. B=1000,m=400,C=1000 (on MW: B EUR/MW, m and C "
            "EUR/MW^2; also gain and price_rate); others keep their defaults. Exact mode's are "
            "dimensionless (Python: RunSettings(exact=ExactConstants(...))).",
        ),
        option(
            "--price-law",
            type=click.Choice(["plain", "tree", "scaled"], case_sensitive=False),
            default="plain",
            show_default=True,
            help="Exact mode's line-price law: plain (each controller integrates its own "
            "line's overflow), tree (preconditioned by the tree of active limited lines: far "
            "fewer iterations where limits nest) or scaled (each line's price rate times N/N_k, "
            "the fleet's tradable generators over those below it: feeders with many generators "
            "and limited lines); the same optimum, docs/exact-mode.md.",
        ),
    ]
    for decorate in reversed(decorators):
        func = decorate(func)
    return func


def accuracy_options(func):
    """``--accuracy-kw`` and ``--accuracy-rel``, handed to the command as one ``accuracy``
    (``(kW, relative)``): what a mode that claims the DC-OPF must prove to call a minute
    converged."""

    @functools.wraps(func)
    def command(*args, accuracy_kw, accuracy_rel, **kwargs):
        return func(*args, accuracy=(accuracy_kw, accuracy_rel), **kwargs)

    decorators = [
        option(
            "--accuracy-kw",
            type=click.FloatRange(min=0.0, min_open=True),
            default=1e-3,
            show_default=True,
            help="Exact and voltage mode: a minute is converged only when every set point is "
            "proved within max(this, --accuracy-rel x demand) kW of the DC-OPF (the distance "
            "certificate, docs/exact-mode.md).",
        ),
        option(
            "--accuracy-rel",
            type=click.FloatRange(min=0.0, max=1.0, max_open=True),
            default=1e-6,
            show_default=True,
            help="The accuracy relative to the minute's demand (see --accuracy-kw).",
        ),
    ]
    for decorate in reversed(decorators):
        command = decorate(command)
    return command


def feeder_options(func):
    """``--opendss``, ``--net``, ``--case``, ``--fleet``, ``--root`` and ``--no-ratings``,
    handed to the command as one ``source`` (:class:`popdispatch.runs.FeederSource`), checked
    before any data is read."""

    @functools.wraps(func)
    def command(*args, opendss, net, case, fleet, root, no_ratings, **kwargs):
        from popdispatch.cases.sources import FeederSource

        source = FeederSource(opendss, net, fleet, root, not no_ratings, case)
        return func(*args, source=source, **kwargs)

    decorators = [
        option(
            "--opendss",
            type=FOLDER,
            help="Read the ieee-elv feeder from its OpenDSS files in this folder instead of "
            "the built-in case (the paper's six generators on the same buses).",
        ),
        option(
            "--net",
            type=click.Path(exists=True, dir_okay=False, path_type=Path),
            help="Any network: MATPOWER case (.m), pandapower JSON (.json) or OpenDSS master "
            "(.dss); runs on its own loads, generators and costs. A network with loops runs "
            "on MATPOWER's DC model (docs/meshed.md).",
        ),
        option(
            "--case",
            metavar="NAME",
            help="A built-in case (popdispatch cases lists them); default ieee-elv.",
        ),
        option(
            "--fleet",
            type=click.Path(exists=True, dir_okay=False, path_type=Path),
            help="Generators (CSV or TOML: bus,name,a,b,c,pmin_kw,pmax_kw) replacing the "
            "network's own.",
        ),
        option(
            "--root",
            metavar="BUS",
            help="Source bus of a --net network (as the network names it: a MATPOWER number, a "
            "pandapower index, an OpenDSS name such as sourcebus); default its own source(s).",
        ),
        option("--no-ratings", is_flag=True, help="Ignore a --net network's line ratings."),
    ]
    for decorate in reversed(decorators):
        command = decorate(command)
    return command


def settings_from(
    dynamics: str, mode: str, x0, graph: str, warm_start: str | None = None, constants=None,
    price_law: str = "plain", accuracy: tuple[float, float] = (1e-3, 1e-6),
    eta: float | None = None,
):  # fmt: skip
    """The run's :class:`~popdispatch.online.RunSettings`; ``constants`` (``--constants``, a
    :class:`~popdispatch.game.fitness.FitnessParameters`) replace the default ones;
    ``price_law`` (``--price-law``) is exact mode's
    (:class:`~popdispatch.game.parameters.PriceLaw`); ``accuracy`` (``--accuracy-kw``,
    ``--accuracy-rel``) what a converged minute must prove; ``eta`` (``--eta``, EUR/MWh) the
    logit dynamics' noise level."""
    from popdispatch.errors import OptionError
    from popdispatch.modes.exact import ExactConstants
    from popdispatch.online import RunSettings

    settings = RunSettings(dynamics=dynamics, mode=mode, graph=graph, x0=x0, warm_start=warm_start,
                           exact=ExactConstants(price_law=price_law), accuracy_kw=accuracy[0],
                           accuracy_rel=accuracy[1], eta=eta)  # fmt: skip
    if constants is not None and mode != "paper":
        raise OptionError(  # exact mode reads settings.exact: the constants would be ignored
            f"--constants sets paper mode's constants (EUR/MW); {mode} mode's are dimensionless "
            "(Python: RunSettings(exact=ExactConstants(gain=, C=, price_rate=)))",
            "--constants",
        )
    return settings if constants is None else replace(settings, fitness=constants)


def check_out(out: Path | None) -> None:
    """Usage error (exit 2) before any work if ``--out`` cannot be created where it is asked
    (its folder missing, or a part of its path a file)."""
    if out is None:
        return
    missing = missing_folder(out)
    if missing is not None:
        raise click.BadParameter(f"cannot write {out}: {missing}", param_hint="'--out'")
    check_writable(out)  # read-only, forbidden or refused: one line, exit 1, before any work


def refuse_opendss(ctx: click.Context, param: click.Parameter, value) -> None:
    """``reproduce --opendss``: a usage error saying which commands read OpenDSS files."""
    if value is not None:
        raise click.BadParameter(
            "reproduce runs the paper's experiments on the built-in ieee-elv case; --opendss "
            "is accepted by feeder, opf, snapshot, day and export",
            ctx,
            param,
        )


def check_shares(x0, progress, source=None) -> None:
    """``--x0`` names checked before any data is read (where the fleet is known then); a note
    names the generators left out."""
    from popdispatch.runs import check_x0, fleet_names

    zeroed = check_x0(x0, fleet_names(source))
    if zeroed:
        progress.note(
            f"--x0 gives no share to {', '.join(zeroed)}: they start at 0 kW (imitative "
            "dynamics such as replicator then keep them there)"
        )
