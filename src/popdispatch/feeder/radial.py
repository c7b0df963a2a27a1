"""What the readers do to a network before it is a radial :class:`~popdispatch.feeder.Feeder`:
parallel branches merged into one, and several separate feeders joined into one tree.

**Parallel branches.** Branches between the same two buses (parallel conductors, and lines of
different phases between the same buses: both are a radial feeder's normal content, not a
mesh) become one branch named ``a+b+...``: impedance the parallel combination of theirs
(``1 / sum(1 / z_k)``, ohm, on the first one's ``kv_base``; 0 if one of them has none),
limit the sum of their limits (``inf`` if one is unlimited), length the first one's, ``kind``
theirs where they agree, else ``parallel``.

**Several feeders.** A network of separate radial feeders, each with its own source (MATPOWER
``case16ci``: three feeders with their ties open), is dispatched as one run: a *virtual bus*
(:data:`VIRTUAL_BUS_NAME`; id 0, or one above the largest id if 0 is taken) is joined to each
feeder's source by a *balance line* named ``balance:<source>`` with zero impedance and a
limit of 0 kW. No power can cross a balance line, so each feeder is balanced by its own
generators, exactly; the DC-OPF and exact mode see them as limited lines like any other (their
prices are the differences between the feeders' marginal prices).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

#: Name of the virtual bus joining several feeders (``name`` column, where there is one).
VIRTUAL_BUS_NAME = "(feeders)"
#: Prefix of the balance lines from the virtual bus to each feeder's source.
BALANCE_PREFIX = "balance:"
#: ``kind`` of the balance lines.
BALANCE_KIND = "balance"


def merge_parallel(lines: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """``(lines, members)``: ``lines`` (index name; ``from_bus``, ``to_bus``, ``length_km``,
    ``r_ohm``, ``x_ohm``, ``limit_kw``, optional ``kv_base`` and ``kind``) with parallel
    branches merged (see the module docstring; the first of each group keeps its place), and
    each merged branch's name -> the names it merges."""
    low = np.minimum(lines.from_bus.to_numpy(), lines.to_bus.to_numpy())
    high = np.maximum(lines.from_bus.to_numpy(), lines.to_bus.to_numpy())
    pair = pd.Series(list(zip(low.tolist(), high.tolist(), strict=True)), index=lines.index)
    repeated = pair.duplicated(keep=False).to_numpy()
    if not repeated.any():
        return lines, {}
    keep = ~pair.duplicated(keep="first").to_numpy()
    merged = lines.copy()
    names = list(lines.index)
    members: dict[str, list[str]] = {}
    groups = pd.Series(np.arange(len(lines)))[repeated].groupby(
        pd.Series(pair[repeated].to_numpy()).to_numpy()
    )
    for _, group in groups:
        rows = group.to_numpy()
        first = rows[0]
        merged.iloc[first, merged.columns.get_indexer(["r_ohm", "x_ohm", "limit_kw"])] = _parallel(
            lines.iloc[rows]
        )
        if "kind" in lines.columns:
            kinds = set(lines["kind"].iloc[rows])
            merged.iloc[first, merged.columns.get_loc("kind")] = (
                kinds.pop() if len(kinds) == 1 else "parallel"
            )
        names[first] = "+".join(str(n) for n in lines.index[rows])
        members[names[first]] = [str(n) for n in lines.index[rows]]
    merged.index = pd.Index(names, name=lines.index.name)
    return merged[keep], members


def _parallel(group: pd.DataFrame) -> tuple[float, float, float]:
    """``(r_ohm, x_ohm, limit_kw)`` of parallel branches (see the module docstring)."""
    z = group["r_ohm"].to_numpy(float) + 1j * group["x_ohm"].to_numpy(float)
    if "kv_base" in group.columns:
        kv = group["kv_base"].to_numpy(float)
        z = z * np.where(kv > 0, (kv[0] / np.where(kv > 0, kv, 1.0)) ** 2, 1.0)
    total = 0j if (z == 0).any() else 1.0 / np.sum(1.0 / z)
    return float(total.real), float(total.imag), float(group["limit_kw"].to_numpy(float).sum())


def join_feeders(
    buses: pd.DataFrame, lines: pd.DataFrame, sources: list[int]
) -> tuple[pd.DataFrame, pd.DataFrame, int]:
    """``(buses, lines, virtual bus id)``: the separate feeders of ``sources`` (bus ids, one
    per feeder) joined at a virtual bus by balance lines (see the module docstring). The
    virtual bus sits above the sources' mean position; it takes the first source's ``vn_kv``
    and, where buses have names, the name :data:`VIRTUAL_BUS_NAME`."""
    taken = buses.index
    virtual = 0 if 0 not in taken else int(taken.max()) + 1
    source_rows = buses.loc[sources]
    row = {"x": float(source_rows["x"].mean()), "y": float(buses["y"].max()) + _spacing(buses)}
    for column in buses.columns.difference(["x", "y"]):
        row[column] = source_rows[column].iloc[0]
    if "name" in buses.columns:
        row["name"] = VIRTUAL_BUS_NAME
    extra = pd.DataFrame([row], index=pd.Index([virtual], name=buses.index.name))
    joined_buses = pd.concat([extra.astype(buses.dtypes.to_dict()), buses])
    labels = (
        source_rows["name"].astype(str)
        if "name" in buses.columns
        else pd.Series([str(s) for s in sources], index=sources)
    )
    balance = pd.DataFrame(
        {
            "from_bus": virtual,
            "to_bus": np.asarray(sources, dtype=np.int64),
            "length_km": 0.0,
            "r_ohm": 0.0,
            "x_ohm": 0.0,
            "limit_kw": 0.0,
        },
        index=pd.Index([f"{BALANCE_PREFIX}{labels[s]}" for s in sources], name=lines.index.name),
    )
    if "kv_base" in lines.columns:
        balance["kv_base"] = (
            source_rows["vn_kv"].to_numpy(float) if "vn_kv" in buses.columns else np.nan
        )
    if "kind" in lines.columns:
        balance["kind"] = BALANCE_KIND
    joined_lines = pd.concat([balance, lines])
    joined_lines = joined_lines.astype({"from_bus": np.int64, "to_bus": np.int64})
    return joined_buses, joined_lines, virtual


def _spacing(buses: pd.DataFrame) -> float:
    """A tenth of the layout's height (1 for a flat one): how far above it the virtual bus."""
    span = float(buses["y"].max() - buses["y"].min())
    return 0.1 * span if span > 0 else 1.0


def balance_lines(lines: pd.DataFrame) -> pd.Index:
    """Names of the balance lines of a joined feeder (empty for a single feeder)."""
    return lines.index[lines.index.astype(str).str.startswith(BALANCE_PREFIX)]


__all__ = ["BALANCE_PREFIX", "VIRTUAL_BUS_NAME", "balance_lines", "join_feeders",
           "merge_parallel"]  # fmt: skip
