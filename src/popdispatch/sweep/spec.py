"""A sweep spec (TOML) parsed, validated and expanded into scenarios with stable ids.

The spec is a product over its lists (cases or network files, steps, modes, dynamics, graphs,
line limits, events, profile assignments), optionally a seeded random ``sample`` of it::

    case = "ieee-elv"                      # or cases = [...]; or networks = ["feeder.m"]
    steps = "600-660"                      # minutes 600..660 (1-based); "day" = 1-1440
    modes = ["exact", "paper"]
    limits = [[], ["505:666=28"]]          # each entry: the path limits of one scenario, kW
    profile_assignments = { count = 5, seed = 1 }

Every value is checked before anything runs: a bad one raises a one-line
:class:`~popdispatch.errors.OptionError` naming the spec file and key (the CLI exits 2).
The step axis is a range of minutes of one day for now (:class:`StepRange`); the engine's
general time series will replace it without touching the rest of the sweep.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import tomllib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import click

from popdispatch.constants import MINUTES_PER_DAY
from popdispatch.errors import OptionError

#: Keys a spec may hold (singular forms take one value, plural forms a list).
LIST_KEYS = {
    "case": "cases",
    "network": "networks",
    "steps": "steps",
    "mode": "modes",
    "dynamics": "dynamics",
    "graph": "graphs",
    "x0": "x0",
}
OTHER_KEYS = {"limits", "events", "profile_assignments", "sample", "fleet", "warm_start"}
DEFAULTS = {"modes": ["exact"], "dynamics": ["smith"], "graphs": ["complete"], "x0": ["uniform"]}


@dataclass(frozen=True)
class StepRange:
    """Minutes ``first..last`` (1-based, both included) of one day: a scenario's steps."""

    first: int
    last: int

    @property
    def label(self) -> str:
        return f"{self.first}-{self.last}"

    @property
    def count(self) -> int:
        return self.last - self.first + 1

    def minutes(self):
        """The 1-based minutes as a numpy array (what the day loop takes)."""
        import numpy as np

        return np.arange(self.first, self.last + 1)


@dataclass(frozen=True)
class Assignment:
    """Which profile each load follows: ``seed`` and ``draw`` pick a random assignment of the
    official profiles to the loads (:mod:`popdispatch.sweep.assign`); ``None`` keeps the
    profiles the run would use anyway (the official ones or the offline default)."""

    seed: int | None = None
    draw: int | None = None

    @property
    def label(self) -> str:
        return "as-given" if self.seed is None else f"random:{self.seed}:{self.draw}"


@dataclass(frozen=True)
class Scenario:
    """One run of a sweep: an online day over ``steps`` against the DC-OPF.

    ``limits``: path limits ``(bus A, bus B, kW)``; ``events``: ``(bus, "off"|"on", minute)``.
    ``case`` or ``network`` (a path) names the feeder; ``fleet`` an optional fleet file.
    """

    index: int
    case: str | None
    network: str | None
    fleet: str | None
    steps: StepRange
    mode: str
    dynamics: str
    graph: str
    x0: str
    warm_start: str | None
    limits: tuple[tuple[int, int, float], ...]
    events: tuple[tuple[int, str, int], ...]
    assignment: Assignment = field(default_factory=Assignment)

    @property
    def feeder_label(self) -> str:
        return self.case or Path(self.network or "").name

    @property
    def limits_label(self) -> str:
        """``505:666=28`` (several joined by ``;``), or ``none``."""
        return ";".join(f"{a}:{b}={kw:g}" for a, b, kw in self.limits) or "none"

    @property
    def events_label(self) -> str:
        return ";".join(f"{b}:{s}@{m}" for b, s, m in self.events) or "none"

    @property
    def id(self) -> str:
        """Stable id: a hash of the parameters (not of the position in the spec), so a rerun
        of an extended spec recognises the scenarios it already ran."""
        params = asdict(self)
        params.pop("index")
        text = json.dumps(params, sort_keys=True, default=str)
        return "s" + hashlib.sha1(text.encode()).hexdigest()[:11]

    def settings(self):
        """The run's :class:`~popdispatch.online.RunSettings` (validated)."""
        from popdispatch.online import RunSettings

        return RunSettings(
            dynamics=self.dynamics, mode=self.mode, graph=self.graph, x0=self.x0,
            warm_start=self.warm_start,
        )  # fmt: skip

    def source(self):
        """The run's :class:`~popdispatch.runs.FeederSource`."""
        from popdispatch.runs import FeederSource

        net = Path(self.network) if self.network else None
        fleet = Path(self.fleet) if self.fleet else None
        return FeederSource(net=net, fleet=fleet, case=None if net else self.case)

    @property
    def own_loads(self) -> bool:
        return self.network is not None or self.case not in (None, "ieee-elv")


@dataclass(frozen=True)
class SweepSpec:
    """A parsed spec: the scenarios it expands to and where it came from."""

    path: Path | None
    scenarios: list[Scenario]
    product_size: int


def _fail(where: str, key: str, message: str) -> OptionError:
    return OptionError(f"{where}: {key}: {message}", "SPEC")


def _as_list(spec: dict, key: str, where: str) -> list | None:
    """The list under the plural ``key`` or one value under its singular form."""
    singular = next((s for s, p in LIST_KEYS.items() if p == key and s != p), None)
    if singular and singular in spec and key in spec:
        raise _fail(where, key, f"give {singular} or {key}, not both")
    if singular and singular in spec:
        return [spec[singular]]
    value = spec.get(key)
    if value is None:
        return None
    if isinstance(value, list):
        if not value:
            raise _fail(where, key, "an empty list gives no scenarios")
        return value
    return [value]


def parse_steps(value, where: str, key: str = "steps") -> StepRange:
    """``"START-END"`` (1-based minutes, both included), ``"day"`` (1-1440) or one minute."""
    from popdispatch.notation import MinutesType

    if value == "day":
        return StepRange(1, MINUTES_PER_DAY)
    if isinstance(value, int) and not isinstance(value, bool) or str(value).strip().isdigit():
        value = f"{str(value).strip()}-{str(value).strip()}"
    try:
        first, last = MinutesType().convert(str(value), None, None)
    except click.BadParameter as exc:
        raise _fail(where, key, exc.message) from None
    return StepRange(first, last)


def _parse_each(items, kind: click.ParamType, where: str, key: str) -> tuple:
    if not isinstance(items, list):
        raise _fail(where, key, f"{items!r} is not a list of {kind.name} strings")
    parsed = []
    for k, item in enumerate(items):
        try:
            parsed.append(kind.convert(str(item), None, None))
        except click.BadParameter as exc:
            raise _fail(where, f"{key}[{k}]", exc.message) from None
    return tuple(parsed)


def _assignments(value, where: str) -> list[Assignment]:
    """``{count = N, seed = S}``: N random assignments drawn from seed S (draws 0..N-1);
    ``"as-given"`` (or omitted): the profiles as the run reads them."""
    if value is None or value == "as-given":
        return [Assignment()]
    key = "profile_assignments"
    if not isinstance(value, dict) or set(value) - {"count", "seed"}:
        raise _fail(where, key, f"{value!r} is not {{count = N, seed = S}} or 'as-given'")
    count, seed = value.get("count"), value.get("seed", 0)
    for name, number in (("count", count), ("seed", seed)):
        if not isinstance(number, int) or isinstance(number, bool) or number < (name == "count"):
            raise _fail(
                where, f"{key}.{name}", f"{number!r} is not an integer >= {int(name == 'count')}"
            )
    return [Assignment(seed, draw) for draw in range(count)]


def _sample(scenarios: list[Scenario], value, where: str) -> list[Scenario]:
    """A seeded random sample (without replacement, in product order) of the product."""
    import numpy as np

    if not isinstance(value, dict) or set(value) - {"count", "seed"} or "count" not in value:
        raise _fail(where, "sample", f"{value!r} is not {{count = N, seed = S}}")
    count = value["count"]
    if not isinstance(count, int) or not 1 <= count <= len(scenarios):
        raise _fail(where, "sample.count", f"{count!r} is not in 1..{len(scenarios)} (the product)")
    picked = np.random.default_rng(value.get("seed", 0)).choice(
        len(scenarios), count, replace=False
    )
    return [scenarios[k] for k in sorted(picked)]


def _feeders(spec: dict, where: str, base: Path) -> list[tuple[str | None, str | None]]:
    """``(case, network path)`` pairs; networks are relative to the spec's folder."""
    from popdispatch.cases.builtin import CASES, SIMBENCH_PREFIX

    cases = _as_list(spec, "cases", where) or []
    networks = _as_list(spec, "networks", where) or []
    for k, name in enumerate(cases):
        if name not in CASES and not str(name).startswith(SIMBENCH_PREFIX):
            raise _fail(where, f"cases[{k}]", f"unknown case {name!r} (known: {', '.join(CASES)})")
    paths = []
    for k, name in enumerate(networks):
        path = (base / str(name)).resolve()
        if not path.is_file():
            raise _fail(where, f"networks[{k}]", f"no such file {path}")
        paths.append(str(path))
    pairs = [(c, None) for c in cases] + [(None, p) for p in paths]
    return pairs or [("ieee-elv", None)]


def parse_spec(spec: dict, where: str = "spec", base: Path | None = None) -> SweepSpec:
    """Every scenario of a spec (a TOML table as a dict), validated, in product order (or the
    ``sample`` of the product). ``base``: the folder relative paths start from."""
    base = base or Path.cwd()
    unknown = set(spec) - set(LIST_KEYS) - set(LIST_KEYS.values()) - OTHER_KEYS
    if unknown:
        known = ", ".join(sorted(set(LIST_KEYS.values()) | OTHER_KEYS))
        raise _fail(where, sorted(unknown)[0], f"unknown key (known: {known})")
    lists = {
        key: _as_list(spec, key, where) or DEFAULTS.get(key)
        for key in ("modes", "dynamics", "graphs", "x0")
    }
    steps = [
        parse_steps(v, where, f"steps[{k}]")
        for k, v in enumerate(_as_list(spec, "steps", where) or ["day"])
    ]
    from popdispatch.notation import EventType, LimitType

    limits = [
        _parse_each(v, LimitType(), where, f"limits[{k}]")
        for k, v in enumerate(spec.get("limits", [[]]))
    ]
    events = [
        _parse_each(v, EventType(), where, f"events[{k}]")
        for k, v in enumerate(spec.get("events", [[]]))
    ]
    assignments = _assignments(spec.get("profile_assignments"), where)
    fleet = str((base / spec["fleet"]).resolve()) if "fleet" in spec else None
    feeders = _feeders(spec, where, base)
    _check_assignments(feeders, assignments, where)
    product = itertools.product(
        feeders, steps, lists["modes"], lists["dynamics"], lists["graphs"], lists["x0"], limits,
        events, assignments,
    )  # fmt: skip
    scenarios = [
        Scenario(
            k,
            case,
            net,
            fleet,
            st,
            mode,
            dyn,
            graph,
            str(x0),
            spec.get("warm_start"),
            lim,
            ev,
            assign,
        )  # fmt: skip
        for k, ((case, net), st, mode, dyn, graph, x0, lim, ev, assign) in enumerate(product)
    ]
    _check_settings(scenarios, where)
    size = len(scenarios)
    if "sample" in spec:
        scenarios = _sample(scenarios, spec["sample"], where)
    return SweepSpec(None, scenarios, size)


def _check_assignments(feeders: Sequence, assignments: list[Assignment], where: str) -> None:
    random = assignments[0].seed is not None
    if random and any(case != "ieee-elv" for case, _ in feeders):
        raise _fail(where, "profile_assignments", "random assignments need the ieee-elv case")


def _check_settings(scenarios: list[Scenario], where: str) -> None:
    """Each distinct (mode, dynamics, graph, x0, warm start) validated once."""
    seen = set()
    for s in scenarios:
        combo = (s.mode, s.dynamics, s.graph, s.x0, s.warm_start)
        if combo in seen:
            continue
        seen.add(combo)
        try:
            s.settings()
        except OptionError as exc:
            raise _fail(where, (exc.option or "settings").lstrip("-"), str(exc)) from None


def load_spec(path: str | Path) -> SweepSpec:
    """Read and expand a TOML spec file (paths in it are relative to its folder)."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            table = tomllib.load(handle)
    except OSError as exc:
        raise OptionError(f"cannot read spec {path}: {exc.strerror}", "SPEC") from None
    except tomllib.TOMLDecodeError as exc:
        raise OptionError(f"{path}: not valid TOML: {exc}", "SPEC") from None
    parsed = parse_spec(table, str(path), path.resolve().parent)
    return SweepSpec(path, parsed.scenarios, parsed.product_size)
