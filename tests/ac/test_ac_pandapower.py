"""The AC check against pandapower's Newton-Raphson (``runpp``) on independently built nets.

- ieee-elv: a balanced positive-sequence pandapower net built here from the tables of
  ``pandapower.networks.ieee_european_lv_asymmetric`` (its LV buses, lines with their per-km
  impedances, the three phases of each load summed, an ideal ext_grid at the transformer's LV
  bus; the transformer and the MV side are not part of the feeder), never from our builder.
- case33bw: a pandapower net built here from the numbers of the MATPOWER file as written
  (ohm, kW, kvar, base kV), read with a regular expression independent of the reader.

Both sources are ideal voltage sources (pandapower's ext_grid; power-grid-model's source with
an internal impedance of 1e-17 p.u. on 1 kVA): agreement within 1e-6 p.u. of every bus
voltage and 1e-3 kW of the losses (the issue's tolerances).
"""

from __future__ import annotations

import functools
import math
import os
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("power_grid_model", reason='the AC check needs pip install "popdispatch[ac]"')
pp = pytest.importorskip("pandapower")

from popdispatch.ac import check_day, check_setpoints, check_snapshot  # noqa: E402
from popdispatch.feeder.generators import make_fleet  # noqa: E402
from popdispatch.readers import read_matpower, read_profiles  # noqa: E402
from popdispatch.scenarios import CONGESTION_PATH, elv_problem, peak_profiles  # noqa: E402

from helpers import MISSING_OFFICIAL, find_official_folder  # noqa: E402

V_TOL_PU = 1e-6
LOSS_TOL_KW = 1e-3
ELV_PF = 0.95  # the official Loads.txt: PF=0.95 for every load (checked below when present)
ELV_KV = 0.416
FEEDERS = Path(
    os.environ.get("POPDISPATCH_FEEDERS")
    or Path(__file__).resolve().parents[3] / "shared" / "feeders"
)
CASE33 = FEEDERS / "matpower" / "case33bw.m"
needs_case33 = pytest.mark.skipif(
    not CASE33.is_file(),
    reason=f"MATPOWER case33bw.m not found at {CASE33} (set POPDISPATCH_FEEDERS)",
)


def run_oracle(net) -> None:
    """Newton-Raphson to 1e-11 MVA (pandapower's numba kernels off: no compile per process)."""
    pp.runpp(net, algorithm="nr", init="flat", tolerance_mva=1e-11, max_iteration=50, numba=False)


# -- ieee-elv -----------------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def elv_tables():
    """pandapower's ieee-elv net (asymmetric, with its transformer and MV source)."""
    import pandapower.networks as pn

    return pn.ieee_european_lv_asymmetric("on_peak_566")


def elv_oracle(load_kw: pd.Series, gen_kw: pd.Series, limit_kw: pd.Series):
    """Balanced pandapower net of ieee-elv from pandapower's own tables, after ``runpp``.

    ``load_kw``: per load name (kW, q at power factor 0.95 lagging); ``gen_kw``: per IEEE bus
    number (kW, unity power factor); ``limit_kw``: per line name (finite: a rating)."""
    src = elv_tables()
    net = pp.create_empty_network()
    lv = src.bus[src.bus.index != src.trafo.hv_bus.iloc[0]]
    pp.create_buses(net, len(lv), lv.vn_kv.to_numpy(), name=lv["name"].astype(int), index=lv.index)
    limit = limit_kw.astype(float).reindex(src.line.name).fillna(math.inf).to_numpy()
    lines = src.line
    pp.create_lines_from_parameters(
        net, lines.from_bus.to_numpy(), lines.to_bus.to_numpy(), lines.length_km.to_numpy(),
        lines.r_ohm_per_km.to_numpy(), lines.x_ohm_per_km.to_numpy(), c_nf_per_km=0.0,
        max_i_ka=np.where(np.isfinite(limit), limit / (math.sqrt(3) * ELV_KV) / 1000, 1e6),
        name=lines.name.to_numpy(), parallel=lines.parallel.to_numpy(),
    )  # fmt: skip
    pp.create_ext_grid(net, src.trafo.lv_bus.iloc[0], vm_pu=1.0)
    loads = src.asymmetric_load
    p_mw = load_kw.loc[loads.name].to_numpy() / 1000
    q_mvar = p_mw * math.tan(math.acos(ELV_PF))
    pp.create_loads(net, loads.bus.to_numpy(), p_mw=p_mw, q_mvar=q_mvar)
    by_id = pd.Series(lv.index, index=lv["name"].astype(int))
    gen_buses = by_id.loc[gen_kw.index].to_numpy()
    pp.create_sgens(net, gen_buses, p_mw=gen_kw.to_numpy() / 1000, q_mvar=0.0)
    run_oracle(net)
    return net


def elv_voltages(net) -> pd.Series:
    return pd.Series(net.res_bus.vm_pu.to_numpy(), index=net.bus["name"].astype(int).to_numpy())


def setpoints_summing_to(problem, demand_kw: float) -> np.ndarray:
    """Set points (kW) in proportion to the generators' capacities, summing to the demand."""
    pmax = problem.pmax
    return pmax / pmax.sum() * demand_kw


def test_elv_minute_566_matches_pandapower_with_the_congestion_limits():
    problem = elv_problem(limits=[CONGESTION_PATH])
    profiles = peak_profiles()
    feeder = problem.feeder.original
    load_kw = profiles.at(566)
    setpoints = setpoints_summing_to(problem, float(load_kw.sum()))
    run = SimpleNamespace(minute=566, generators=problem.generators, setpoints_kw=setpoints)
    ac = check_snapshot(problem, profiles, SimpleNamespace(run=run))
    gens = feeder.generators
    net = elv_oracle(
        load_kw,
        pd.Series(setpoints, index=gens.loc[problem.generators, "bus"].to_numpy()),
        feeder.lines.limit_kw,
    )
    v_oracle = elv_voltages(net).loc[ac.buses.index]
    assert np.max(np.abs(ac.buses.v_pu - v_oracle)) < V_TOL_PU
    losses_oracle = net.res_line.pl_mw.sum() * 1000
    summary = ac.summary()
    assert abs(summary["losses_kw"] - losses_oracle) < LOSS_TOL_KW
    assert abs(summary["source_extra_kw"] - net.res_ext_grid.p_mw.iloc[0] * 1000) < LOSS_TOL_KW
    assert summary["v_min_bus"] == v_oracle.idxmin()
    assert summary["v_min_pu"] == pytest.approx(v_oracle.min(), abs=V_TOL_PU)
    # loading of the 28 kW lines: pandapower's current over the rating in amperes
    limited = feeder.lines.index[np.isfinite(feeder.lines.limit_kw)]
    oracle_loading = pd.Series(net.res_line.loading_percent.to_numpy(), index=net.line.name)
    np.testing.assert_allclose(
        ac.lines.loading_percent[limited], oracle_loading[limited], atol=1e-4, rtol=0
    )
    # lines in series carry almost the same current: the most loaded is the oracle's, or ties it
    worst = oracle_loading[summary["max_loading_line"]]
    assert worst == pytest.approx(oracle_loading[limited].max(), abs=1e-4)
    assert summary["max_loading_percent"] == pytest.approx(oracle_loading[limited].max(), abs=1e-4)
    assert ac.lines.loading_percent.drop(limited).isna().all()


def test_elv_day_batch_matches_pandapower_minute_by_minute():
    folder = find_official_folder()
    if folder is None:
        pytest.skip(MISSING_OFFICIAL)
    profiles = read_profiles(folder)
    problem = elv_problem(profiles)
    feeder = problem.feeder.original
    minutes = np.array([1, 566, 1210])
    load = profiles.for_loads(feeder.loads.index).kw.loc[minutes]
    setpoints = np.array([setpoints_summing_to(problem, d) for d in load.sum(axis=1)])
    run = SimpleNamespace(minutes=minutes, generators=problem.generators, setpoints_kw=setpoints)
    day = check_day(problem, profiles, run)
    buses = feeder.generators.loc[problem.generators, "bus"].to_numpy()
    for row, minute in enumerate(minutes):
        net = elv_oracle(
            load.loc[minute], pd.Series(setpoints[row], index=buses), pd.Series(dtype=float)
        )
        v_oracle = elv_voltages(net).loc[feeder.buses.index].to_numpy()
        assert np.max(np.abs(day.flows.v_pu[row] - v_oracle)) < V_TOL_PU
        step = day.steps.loc[minute]
        assert abs(step.losses_kw - net.res_line.pl_mw.sum() * 1000) < LOSS_TOL_KW


def test_elv_load_power_factor_is_the_official_one():
    folder = find_official_folder()
    if folder is None:
        pytest.skip(MISSING_OFFICIAL)
    text = (folder / "Loads.txt").read_text()
    pfs = {float(pf) for pf in re.findall(r"PF=([0-9.]+)", text, flags=re.I)}
    loads = len(re.findall(r"^New Load\.", text, flags=re.I | re.M))
    assert loads == 55 and pfs == {ELV_PF}
    from popdispatch.ac.network import KNOWN_LOAD_PF

    assert KNOWN_LOAD_PF["ieee-elv"] == ELV_PF


# -- case33bw -----------------------------------------------------------------------------------


def raw_matrix(path: Path, name: str) -> np.ndarray:
    """The numbers of ``mpc.<name> = [...]`` exactly as written (kW, ohm: before the file's
    own conversion statements)."""
    body = re.search(rf"mpc\.{name}\s*=\s*\[(.*?)\];", path.read_text(), re.S).group(1)
    rows = [line.split("%")[0].strip().rstrip(";") for line in body.splitlines()]
    return np.array([[float(v) for v in row.split()] for row in rows if row])


def case33_oracle(gen_kw: dict[int, float]):
    """pandapower net of case33bw from the raw numbers; returns the net (after runpp) and the
    base kV."""
    bus, branch = raw_matrix(CASE33, "bus"), raw_matrix(CASE33, "branch")
    kv = float(bus[0, 9])
    net = pp.create_empty_network()
    for row in bus:
        pp.create_bus(net, vn_kv=kv, index=int(row[0]))
        if row[2] or row[3]:
            pp.create_load(net, int(row[0]), p_mw=row[2] / 1000, q_mvar=row[3] / 1000)
    for row in branch:
        if row[10]:
            pp.create_line_from_parameters(
                net, int(row[0]), int(row[1]), 1.0, row[2], row[3], 0.0, max_i_ka=1e6
            )
    pp.create_ext_grid(net, int(bus[bus[:, 1] == 3, 0][0]), vm_pu=1.0)
    for b, kw in gen_kw.items():
        pp.create_sgen(net, b, p_mw=kw / 1000, q_mvar=0.0)
    run_oracle(net)
    return net, kv


@needs_case33
@pytest.mark.parametrize("dg_kw", [0.0, 300.0, 900.0])
def test_case33bw_matches_pandapower(dg_kw):
    dgs = {18: dg_kw, 33: dg_kw / 2, 25: dg_kw / 3}
    fleet = make_fleet([(1, 0, 5, 0.02, 0, 5000)] + [(b, 0, 1, 0.01, 0, 2000) for b in dgs])
    feeder = read_matpower(CASE33, fleet=fleet)
    net, kv = case33_oracle(dgs)
    load_kw = feeder.loads.p_kw.to_numpy()
    setpoints = [[load_kw.sum() - sum(dgs.values()), *dgs.values()]]
    day = check_setpoints(feeder, [load_kw], setpoints, vn_kv=kv)
    v_oracle = net.res_bus.vm_pu.loc[feeder.buses.index].to_numpy()
    assert np.max(np.abs(day.flows.v_pu[0] - v_oracle)) < V_TOL_PU
    step = day.steps.iloc[0]
    assert abs(step.losses_kw - net.res_line.pl_mw.sum() * 1000) < LOSS_TOL_KW
    # the ideal source supplies the losses beyond the balanced dispatch (the oracle's ext_grid
    # also supplies what our generator at the source bus, G1, is dispatched to)
    extra_oracle = net.res_ext_grid.p_mw.iloc[0] * 1000 - setpoints[0][0]
    assert abs(step.source_extra_kw - extra_oracle) < LOSS_TOL_KW
    assert abs(step.source_extra_kw - step.losses_kw) < LOSS_TOL_KW
    assert abs(step.source_kvar - net.res_ext_grid.q_mvar.iloc[0] * 1000) < LOSS_TOL_KW
    assert day.model.load_q_rule.startswith("each load's own q_kvar")
    if dg_kw == 0.0:
        # the published case: 202.7 kW of losses, minimum 0.9131 p.u. at bus 18 (Baran & Wu)
        assert step.v_min_bus == 18 and round(step.v_min_pu, 4) == 0.9131
        assert round(step.losses_kw, 1) == 202.7
