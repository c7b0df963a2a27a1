"""Reader benchmark: loading and reducing a ~10,000-bus radial pandapower network (issue 12).

Usage: python benchmarks/bench_readers.py [--buses 10000] [--repeat 5] [--json]

Builds a pandapower net from the seeded synthetic feeder (popdispatch.feeder.synthetic, seed 1):
an ext_grid on a 20 kV bus, a 20/0.4 kV substation transformer to the feeder's source bus, one
line per feeder line (``max_i_ka`` from its limit where it has one), a closed line switch on
every line and a closed bus-bus switch on every 50th lateral leaf (a merged twin bus), one load
per feeder load, the fleet as ``gen`` + ``poly_cost`` and GeoJSON bus coordinates. Times
``read_pandapower(net)`` and ``reduce_feeder`` (median of ``--repeat`` runs; target under 1 s
together) and, with ``--json``, ``pandapower.from_json`` of the same net written to a file
(pandapower's own loading time, reported apart).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.feeder.synthetic import synthetic_feeder, synthetic_load_kw
from popdispatch.readers.pandapower import read_pandapower


def synthetic_net(n_buses: int):
    """A pandapower net of ``synthetic_feeder(n_buses, 10, seed=1, limited_lines=1.0)``."""
    import pandapower as pp

    feeder = synthetic_feeder(n_buses, 10, seed=1, limited_lines=1.0)
    load_kw = synthetic_load_kw(feeder).loc[feeder.loads.index]
    net = pp.create_empty_network(name=f"synthetic {n_buses}")
    pp.create_bus(net, 20.0, index=0, name="HV")
    ids = feeder.buses.index.to_numpy()
    geo = [
        json.dumps({"coordinates": [float(x), float(y)], "type": "Point"})
        for x, y in feeder.buses[["x", "y"]].to_numpy()
    ]
    pp.create_buses(net, len(ids), 0.4, index=ids, geodata=None)
    net.bus.loc[ids, "geo"] = geo
    pp.create_ext_grid(net, 0)
    pp.create_transformer(net, 0, feeder.source_bus, "0.63 MVA 20/0.4 kV")
    lines = feeder.lines
    length = np.maximum(lines.length_km.to_numpy(float), 1e-6)
    limit = lines.limit_kw.to_numpy(float)
    max_i_ka = np.where(np.isfinite(limit), limit / 1000.0 / (math.sqrt(3) * 0.4), 99999.0)
    line_ids = pp.create_lines_from_parameters(
        net,
        lines.from_bus.to_numpy(),
        lines.to_bus.to_numpy(),
        length,
        r_ohm_per_km=lines.r_ohm.to_numpy(float) / length,
        x_ohm_per_km=lines.x_ohm.to_numpy(float) / length,
        c_nf_per_km=0.0,
        max_i_ka=max_i_ka,
    )
    pp.create_switches(net, lines.from_bus.to_numpy(), line_ids, et="l", closed=True)
    leaves = np.setdiff1d(lines.to_bus.to_numpy(), lines.from_bus.to_numpy())[::50]
    twins = np.arange(len(leaves)) + ids.max() + 1
    pp.create_buses(net, len(twins), 0.4, index=twins)
    net.bus.loc[twins, "geo"] = [geo[int(np.flatnonzero(ids == b)[0])] for b in leaves]
    pp.create_switches(net, leaves, twins, et="b", closed=True)
    pp.create_loads(net, feeder.loads.bus.to_numpy(), load_kw.to_numpy() / 1000.0)
    gens = feeder.generators
    gen_ids = pp.create_gens(
        net,
        gens.bus.to_numpy(),
        p_mw=0.0,
        vm_pu=1.0,
        min_p_mw=gens.pmin_kw.to_numpy() / 1000,
        max_p_mw=gens.pmax_kw.to_numpy() / 1000,
        controllable=True,
    )
    pp.create_poly_costs(net, gen_ids, "gen", cp1_eur_per_mw=gens.b.to_numpy(),
                         cp2_eur_per_mw2=gens.c.to_numpy(), cp0_eur=gens.a.to_numpy())  # fmt: skip
    return net, feeder


def median_seconds(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--buses", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true", help="also time pandapower.from_json")
    args = parser.parse_args()
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        net, source = synthetic_net(args.buses)
    build = time.perf_counter() - start
    feeder = read_pandapower(net)  # warm-up (imports)
    reduced = reduce_feeder(feeder)
    assert len(feeder.buses) == len(source.buses) and len(feeder.lines) == len(source.lines)
    assert np.isclose(feeder.loads.p_kw.sum(), synthetic_load_kw(source).sum())
    assert np.isclose(
        np.isfinite(feeder.lines.limit_kw).sum(), np.isfinite(source.lines.limit_kw).sum()
    )
    read = median_seconds(lambda: read_pandapower(net), args.repeat)
    reduce = median_seconds(lambda: reduce_feeder(feeder), args.repeat)
    both = median_seconds(lambda: reduce_feeder(read_pandapower(net)), args.repeat)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores")
    print(
        f"pandapower net: {len(net.bus)} buses, {len(net.line)} lines, {len(net.switch)} "
        f"switches, {len(net.load)} loads, {len(net.gen)} gens (built in {build:.1f} s)"
    )
    print(f"feeder: {len(feeder.buses)} buses, {len(feeder.lines)} lines, {len(feeder.loads)} "
          f"loads, {np.isfinite(feeder.lines.limit_kw).sum()} limited lines; reduced to "
          f"{reduced.n_nodes} nodes, {reduced.n_lines} lines")  # fmt: skip
    print(f"median of {args.repeat}: read_pandapower {read:.3f} s, reduce_feeder {reduce:.3f} s, "
          f"both {both:.3f} s (target < 1 s: {'met' if both < 1 else 'MISSED'})")  # fmt: skip
    if args.json:
        import pandapower as pp

        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "net.json"
            pp.to_json(net, str(path))
            size = path.stat().st_size
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load = median_seconds(lambda: pp.from_json(str(path)), args.repeat)
                whole = median_seconds(lambda: reduce_feeder(read_pandapower(path)), args.repeat)
        print(f"JSON file ({size / 1e6:.1f} MB): pandapower.from_json {load:.3f} s; "
              f"read_pandapower(path) + reduce_feeder {whole:.3f} s")  # fmt: skip


if __name__ == "__main__":
    main()
