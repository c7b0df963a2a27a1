"""Seeded synthetic radial feeders for scale tests (1,000 to 100,000 buses, 10 to 1,000 DGs).

:func:`synthetic_feeder` builds a :class:`~popdispatch.feeder.model.Feeder` that looks like a
distribution feeder rather than a uniform random tree:

- a few long **trunks** leave the source bus (bus 1), each a chain of about
  ``2 sqrt(n / trunks)`` buses (about 280 buses per trunk at 100,000 buses);
- every other bus is a **lateral** bus, created in order: it continues the lateral being drawn
  (probability 0.8), or starts a new branch, either from a random trunk bus or from a recent
  lateral bus (exponential look-back, mean 20 buses). The recency bias keeps branches local, so
  the tree is deep like a real feeder's: the deepest bus is 70 to 95 lines from the source at
  1,000 buses, 150 to 260 at 10,000 and 390 to 440 at 100,000 (seeds 0 to 4; IEEE European LV:
  157 at 906 buses); about one bus in six is a leaf;
- lines are 20 to 100 m (trunk) or 5 to 50 m (lateral) of a cable drawn from a small catalogue
  (trunk 0.125 to 0.206 ohm/km, lateral 0.32 to 1.15 ohm/km); coordinates (m) follow the lines'
  headings, trunks radiating from the source and branches leaving at about right angles;
- loads sit on distinct lateral buses (a third of the buses by default), each with a nominal
  peak ``peak_kw`` (an extra column of ``loads``); generators sit on distinct random buses with
  Table-I-like costs (``a`` 0, ``b`` 1 to 5 EUR/MW, ``c`` 0.005 to 0.03 EUR/MW^2, ``pmin_kw`` 0,
  ``pmax_kw`` 5 to 20 kW);
- the loads' peaks add up to ``demand_share`` (0.7) of the fleet's capacity, so capacity stays
  above demand at every minute of :func:`synthetic_profiles` (at most ``1 + DEVIATION`` times
  the nominal peak: 0.84 of capacity);
- ``limit_kw`` is ``inf`` unless ``limited_lines`` asks for flow limits (below) on some of the
  lines with a generator below them.

Line limits. Take the *proportional dispatch*: every generator at the same fraction of its
``pmax_kw``, together matching demand. At the nominal peak it puts
``F_k = L_k - G_k * demand_share`` kW on line ``k``, where ``L_k`` is the peak load and ``G_k``
the capacity below the line. A limited line gets
``limit_kw = limit_factor * |F_k| + DEVIATION * (L_k + G_k * demand_share)``. Each load of
:func:`synthetic_profiles` stays within ``DEVIATION`` (per unit of its own peak) of a common
daily shape that never exceeds 1, so the proportional dispatch meets every limit at every
minute of every synthetic day and at every :func:`synthetic_load_kw` snapshot: the dispatch
problem stays feasible (the proportional dispatch loads the limited lines to at most about
0.83 of their limits at the peak). The economic dispatch moves output to cheap generators, so
many limits bind: with the default ``limit_factor`` 1, the unconstrained economic dispatch at the
peak overloads about 15 to 60 % of the limited lines of 1,000- to 10,000-bus feeders.

Everything is drawn from ``numpy.random.Generator`` streams derived from ``seed`` (one stream
per part: topology, geometry, loads, generators, limits), so the same arguments give the same
tables and ``limited_lines`` changes nothing but ``limit_kw``. No Python loop runs per bus.
"""

from __future__ import annotations

import numbers

import numpy as np
import pandas as pd

from popdispatch.feeder.generators import FLEET_COLUMNS
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import MINUTES_PER_DAY, LoadProfiles
from popdispatch.feeder.tree import Tree, build_tree, path_sums, subtree_sums

#: Largest deviation of a load from the common daily shape, per unit of the load's peak.
DEVIATION = 0.2
#: Default total nominal peak demand as a share of the fleet's capacity.
DEMAND_SHARE = 0.7

_P_CONTINUE = 0.8  # a lateral bus continues the lateral drawn just before it
_P_FROM_TRUNK = 0.35  # a new branch leaves a trunk bus (else a recent lateral bus)
_LOOK_BACK = 20.0  # mean look-back (buses) when a branch leaves a recent lateral bus
_TRUNK_SCALE = 2.0  # trunk length ~ _TRUNK_SCALE * sqrt(buses per trunk)
#: Cable catalogue (r, x in ohm/km): trunk cables, then lateral cables and service cables.
_TRUNK_CABLES = np.array([[0.125, 0.080], [0.164, 0.080], [0.206, 0.082]])
_LATERAL_CABLES = np.array([[0.320, 0.083], [0.443, 0.085], [0.868, 0.090], [1.150, 0.088]])
_STREAMS = ("topology", "geometry", "loads", "generators", "limits")
_PROFILE_STREAM = 100


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream,)))


def synthetic_feeder(
    n_buses: int,
    n_generators: int,
    seed: int = 0,
    *,
    n_trunks: int | None = None,
    load_fraction: float = 1 / 3,
    demand_share: float = DEMAND_SHARE,
    limited_lines: float | int = 0,
    limit_factor: float = 1.0,
    name: str | None = None,
) -> Feeder:
    """A seeded synthetic radial feeder (see the module docstring for the model).

    Parameters
    ----------
    n_buses : number of buses (>= 2); bus ids ``1..n_buses``, bus 1 is the source.
    n_generators : number of generators (1..n_buses), on distinct buses, named ``G<bus>``.
    seed : seed of every random draw; the same arguments give identical tables.
    n_trunks : trunks leaving the source; default ``round(log10(n_buses))`` clipped to 1..8
        (3 at 1,000 buses, 5 at 100,000).
    load_fraction : share of the buses with a load (default a third); loads sit on distinct
        lateral buses, named ``LD<bus>``, with a nominal peak ``peak_kw`` (kW).
    demand_share : total nominal peak demand (kW) as a share of the total ``pmax_kw``; below
        ``1 / (1 + DEVIATION)`` so that every synthetic minute stays below capacity.
    limited_lines : how many lines get a finite ``limit_kw``: an ``int`` is a count, a ``float``
        a fraction, both of the lines with at least one generator below them (on any other
        line the flow is the load below it, whatever the dispatch, so a limit there could only
        be slack or infeasible). Chosen at random (seeded); 0 (default) limits no line.
    limit_factor : >= 1; scales the proportional dispatch's peak flow in the limit (see the
        module docstring); larger is looser. Limits are in kW, rounded up to 0.01 kW.
    name : case name; default ``synthetic-<n_buses>b-<n_generators>g-seed<seed>``.

    Raises ``ValueError`` for arguments out of range.
    """
    n_buses, n_generators = int(n_buses), int(n_generators)
    if n_buses < 2:
        raise ValueError(f"a synthetic feeder needs at least 2 buses, got {n_buses}")
    if not 1 <= n_generators <= n_buses:
        raise ValueError(f"n_generators must be in 1..{n_buses} (one per bus), got {n_generators}")
    if not 0 < load_fraction <= 1:
        raise ValueError(f"load_fraction must be in (0, 1], got {load_fraction}")
    if not 0 < demand_share < 1 / (1 + DEVIATION):
        raise ValueError(
            f"demand_share must be in (0, {1 / (1 + DEVIATION):.4f}) so that demand stays below "
            f"capacity, got {demand_share}"
        )
    if not limit_factor >= 1:
        raise ValueError(f"limit_factor must be >= 1, got {limit_factor}")
    streams = {part: _rng(seed, k) for k, part in enumerate(_STREAMS)}

    parent, n_trunk_buses = _topology(n_buses, n_trunks, streams["topology"])
    child = np.arange(1, n_buses)  # line k feeds position k + 1 from parent[k + 1]
    tree = build_tree(n_buses, parent[child], child, 0)
    bus_ids = np.arange(1, n_buses + 1)
    lines = _lines(parent, n_trunk_buses, streams["geometry"])
    x_m, y_m = _coordinates(tree, parent, lines.length_km.to_numpy(), streams["geometry"])
    buses = pd.DataFrame({"x": x_m, "y": y_m}, index=pd.Index(bus_ids, name="bus"))

    fleet = _fleet(n_buses, n_generators, streams["generators"])
    load_position = _load_positions(n_buses, n_trunk_buses, load_fraction, streams["loads"])
    shares = streams["loads"].lognormal(0.0, 0.5, size=len(load_position))
    peak_kw = shares / shares.sum() * demand_share * fleet.pmax_kw.sum()
    loads = pd.DataFrame(
        {"bus": bus_ids[load_position], "peak_kw": peak_kw},
        index=pd.Index([f"LD{b}" for b in bus_ids[load_position].tolist()], name="load"),
    )
    lines["limit_kw"] = _limits(
        tree,
        load_position,
        peak_kw,
        fleet,
        demand_share,
        limited_lines,
        limit_factor,
        streams["limits"],
    )
    lines.index = pd.Index([f"L{b}" for b in bus_ids[child].tolist()], name="line")
    lines.insert(0, "from_bus", bus_ids[parent[child]])
    lines.insert(1, "to_bus", bus_ids[child])
    name = name if name is not None else f"synthetic-{n_buses}b-{n_generators}g-seed{seed}"
    return Feeder(name, buses, lines, loads, 1, fleet)


def _topology(
    n_buses: int, n_trunks: int | None, rng: np.random.Generator
) -> tuple[np.ndarray, int]:
    """Parent position of every position (-1 at the source, 0); parents come first.

    Positions ``1..n_trunk_buses`` are the trunks, the rest the laterals.
    """
    n = n_buses
    if n_trunks is None:
        n_trunks = int(np.clip(round(np.log10(n)), 1, min(8, n - 1)))
    if not 1 <= n_trunks <= n - 1:
        raise ValueError(f"n_trunks must be in 1..{n - 1} (buses other than the source)")
    base = _TRUNK_SCALE * np.sqrt((n - 1) / n_trunks)
    lengths = np.maximum(1, np.round(base * rng.uniform(0.7, 1.3, n_trunks))).astype(np.int64)
    if lengths.sum() > n - 1:  # tiny feeders: share the buses out evenly
        lengths = np.diff(np.round(np.linspace(0, n - 1, n_trunks + 1))).astype(np.int64)
    n_trunk_buses = int(lengths.sum())
    parent = np.arange(-1, n - 1, dtype=np.int64)  # trunk buses: the bus before them
    parent[1 + np.concatenate([[0], np.cumsum(lengths)[:-1]])] = 0  # trunk heads: the source
    first = n_trunk_buses + 1
    lateral = np.arange(first, n)
    m = len(lateral)
    carry_on = rng.random(m) < _P_CONTINUE
    carry_on[:1] = False  # the first lateral bus branches off a trunk
    from_trunk = rng.random(m) < _P_FROM_TRUNK
    recent = lateral - 1 - np.floor(rng.exponential(_LOOK_BACK, m)).astype(np.int64)
    trunk_bus = rng.integers(1, n_trunk_buses + 1, m)
    branch_parent = np.where(from_trunk | (recent < first), trunk_bus, recent)
    parent[first:] = np.where(carry_on, lateral - 1, branch_parent)
    return parent, n_trunk_buses


def _lines(parent: np.ndarray, n_trunk_buses: int, rng: np.random.Generator) -> pd.DataFrame:
    """Lengths (km) and impedances (ohm) of the lines, in the order of their child position."""
    child = np.arange(1, len(parent))
    trunk = child <= n_trunk_buses
    length_km = np.where(
        trunk, rng.uniform(0.02, 0.10, len(child)), rng.uniform(0.005, 0.05, len(child))
    )
    cable = np.where(
        trunk[:, None],
        _TRUNK_CABLES[rng.integers(0, len(_TRUNK_CABLES), len(child))],
        _LATERAL_CABLES[rng.integers(0, len(_LATERAL_CABLES), len(child))],
    )
    return pd.DataFrame(
        {
            "length_km": length_km,
            "r_ohm": cable[:, 0] * length_km,
            "x_ohm": cable[:, 1] * length_km,
        }
    )


def _coordinates(
    tree: Tree, parent: np.ndarray, length_km: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Plot coordinates (m) of every bus, source at (0, 0).

    Each bus turns from its parent's heading: trunk heads spread around the source, a bus that
    starts a branch turns by about +-90 degrees, others wander a little. Headings and positions
    are sums along the path from the source (:func:`~popdispatch.feeder.tree.path_sums`).
    """
    n = len(parent)
    child = np.arange(1, n)
    heads = np.flatnonzero(parent[child] == 0) + 1
    branch = parent[child] != child - 1
    turn = np.zeros(n)
    turn[child] = np.where(
        branch,
        rng.choice([-np.pi / 2, np.pi / 2], len(child)) + rng.normal(0.0, 0.2, len(child)),
        rng.normal(0.0, 0.08, len(child)),
    )
    turn[heads] = (
        2 * np.pi * (np.arange(len(heads)) + rng.uniform(-0.2, 0.2, len(heads))) / len(heads)
    )
    heading = path_sums(tree, turn)
    step_m = np.zeros(n)
    step_m[child] = 1000.0 * length_km
    return (
        path_sums(tree, step_m * np.cos(heading)),
        path_sums(tree, step_m * np.sin(heading)),
    )


def _fleet(n_buses: int, n_generators: int, rng: np.random.Generator) -> pd.DataFrame:
    """Table-I-like generators on distinct random buses (sorted by bus)."""
    bus = np.sort(rng.choice(n_buses, size=n_generators, replace=False)) + 1
    fleet = pd.DataFrame(
        {
            "bus": bus,
            "a": 0.0,
            "b": np.round(rng.uniform(1.0, 5.0, n_generators), 2),
            "c": np.round(rng.uniform(0.005, 0.03, n_generators), 4),
            "pmin_kw": 0.0,
            "pmax_kw": np.round(rng.uniform(5.0, 20.0, n_generators), 1),
        },
        index=pd.Index([f"G{b}" for b in bus.tolist()], name="generator"),
    )
    return fleet[FLEET_COLUMNS]


def _load_positions(
    n_buses: int, n_trunk_buses: int, load_fraction: float, rng: np.random.Generator
) -> np.ndarray:
    """Distinct load positions (sorted): lateral buses, or any non-source bus if too few."""
    n_loads = max(1, round(load_fraction * n_buses))
    candidates = np.arange(n_trunk_buses + 1, n_buses)
    if n_loads > len(candidates):
        candidates = np.arange(1, n_buses)
    n_loads = min(n_loads, len(candidates))
    return np.sort(rng.choice(candidates, size=n_loads, replace=False))


def _limits(
    tree: Tree,
    load_position: np.ndarray,
    peak_kw: np.ndarray,
    fleet: pd.DataFrame,
    demand_share: float,
    limited_lines: float | int,
    limit_factor: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """``limit_kw`` per line: ``inf``, or for the chosen lines the bound of the module docstring."""
    n = tree.n_nodes
    load_kw = np.bincount(load_position, weights=peak_kw, minlength=n)
    capacity_kw = np.bincount(fleet.bus.to_numpy() - 1, weights=fleet.pmax_kw, minlength=n)
    below_load = subtree_sums(tree, load_kw)[tree.line_child]
    below_capacity = subtree_sums(tree, capacity_kw)[tree.line_child]
    candidates = np.flatnonzero(below_capacity > 0)
    count = _limited_count(limited_lines, len(candidates))
    limit_kw = np.full(tree.n_lines, np.inf)
    chosen = np.sort(rng.choice(candidates, size=count, replace=False))
    proportional = below_load[chosen] - demand_share * below_capacity[chosen]
    spread = DEVIATION * (below_load[chosen] + demand_share * below_capacity[chosen])
    limit_kw[chosen] = np.ceil((limit_factor * np.abs(proportional) + spread) * 100) / 100
    return limit_kw


def _limited_count(limited_lines: float | int, n_candidates: int) -> int:
    if isinstance(limited_lines, bool | np.bool_):
        raise TypeError("limited_lines must be a count (int) or a fraction (float), not a bool")
    if isinstance(limited_lines, numbers.Integral):
        count = int(limited_lines)
        if not 0 <= count <= n_candidates:
            raise ValueError(
                f"limited_lines = {count} is not in 0..{n_candidates} "
                "(the lines with a generator below them)"
            )
        return count
    fraction = float(limited_lines)
    if not 0 <= fraction <= 1:
        raise ValueError(f"limited_lines as a fraction must be in [0, 1], got {fraction}")
    return round(fraction * n_candidates)


def synthetic_load_kw(feeder: Feeder, level: float = 1.0) -> pd.Series:
    """Per-load demand (kW) of a snapshot: ``level`` (0..1) times each load's ``peak_kw``.

    Indexed by load name in the order of ``feeder.loads``. For feeders from
    :func:`synthetic_feeder`; any feeder whose loads carry a ``peak_kw`` column (kW) works.
    """
    if not 0 <= level <= 1:
        raise ValueError(f"level must be in [0, 1] (share of the peak), got {level}")
    return (level * _peak_kw(feeder)).rename("p_kw")


def synthetic_profiles(feeder: Feeder, seed: int = 0, *, max_loads: int = 5000) -> LoadProfiles:
    """A seeded day of 1-minute per-load demand (kW), 1440 x loads, for small feeders.

    Every load follows a smooth daily shape ``s(t)`` (night 0.3, morning and evening peaks,
    maximum 1 at about 19:30) shifted by up to 45 minutes, scaled by 0.85 to 1.15 and noisy;
    its deviation from ``s(t)`` is clipped to ``DEVIATION`` per unit, and the result to >= 0,
    then multiplied by the load's ``peak_kw``. The line limits of :func:`synthetic_feeder` hold
    for the proportional dispatch at every minute, whatever the seed.

    ``max_loads`` guards memory (8 bytes x 1440 x loads; 5000 loads: 58 MB); use
    :func:`synthetic_load_kw` for snapshots of big feeders.
    """
    peak_kw = _peak_kw(feeder)
    n_loads = len(peak_kw)
    if n_loads > max_loads:
        raise ValueError(
            f"{n_loads} loads > max_loads = {max_loads}: a day of profiles would take "
            f"{8 * MINUTES_PER_DAY * n_loads / 1e6:.0f} MB; use synthetic_load_kw for snapshots"
        )
    rng = _rng(seed, _PROFILE_STREAM)
    shape = daily_shape()[:, None]
    minute = np.arange(MINUTES_PER_DAY)[:, None]
    shift = rng.integers(-45, 46, n_loads)[None, :]
    scale = rng.uniform(0.85, 1.15, n_loads)[None, :]
    # In place, three (1440, loads) arrays at most: deviation from the common shape, ...
    deviation = scale * daily_shape()[(minute - shift) % MINUTES_PER_DAY]
    deviation -= shape
    # ... white noise (appliances switching) and a 30-minute moving average (slow drift).
    deviation += rng.normal(0.0, 0.05, (MINUTES_PER_DAY, n_loads))
    cumulative = np.cumsum(rng.normal(0.0, 0.1 * np.sqrt(30), (MINUTES_PER_DAY + 29, n_loads)), 0)
    drift = cumulative[29:].copy()
    drift[1:] -= cumulative[:-30]
    deviation += drift / 30
    del cumulative, drift
    np.clip(deviation, -DEVIATION, DEVIATION, out=deviation)
    deviation += shape
    per_unit = np.maximum(deviation, 0.0, out=deviation)
    kw = pd.DataFrame(
        per_unit * peak_kw.to_numpy()[None, :],
        index=pd.RangeIndex(1, MINUTES_PER_DAY + 1, name="minute"),
        columns=peak_kw.index,
    )
    return LoadProfiles(kw, f"synthetic profiles (seed {seed}) for {feeder.name}")


def daily_shape() -> np.ndarray:
    """The common daily shape (per unit, maximum 1) at minutes 1..1440, periodic over the day.

    A household-like curve: 0.3 at night, a morning bump near 07:30, a small midday bump and
    the evening peak near 19:30.
    """
    hour = (np.arange(MINUTES_PER_DAY) + 0.5) / 60
    shape = np.full(MINUTES_PER_DAY, 0.3)
    for centre, width, height in ((7.5, 1.2, 0.35), (13.0, 2.0, 0.15), (19.5, 1.8, 0.7)):
        distance = (hour - centre + 12) % 24 - 12
        shape += height * np.exp(-0.5 * (distance / width) ** 2)
    return shape / shape.max()


def _peak_kw(feeder: Feeder) -> pd.Series:
    if "peak_kw" not in feeder.loads.columns:
        raise ValueError(
            f"loads of feeder {feeder.name!r} have no peak_kw column (not a synthetic feeder)"
        )
    peak_kw = feeder.loads["peak_kw"].astype(float)
    if not (np.isfinite(peak_kw) & (peak_kw >= 0)).all():
        raise ValueError(f"feeder {feeder.name!r} has a negative or non-finite peak_kw")
    return peak_kw
