"""The AC check on hand-checkable feeders: a 2-bus line in closed form, a 3-bus feeder against a
plain-numpy power flow (fixed-point iteration on the bus impedance matrix).

Yardsticks are computed here from the tables' numbers (ohm, kW, kV), never by the code under
test: the 2-bus receiving-end voltage solves the quartic of the two-bus power flow,
``V^4 + (2(PR + QX) - V0^2) V^2 + (P^2 + Q^2)(R^2 + X^2) = 0`` (p.u.), and its loss is
``R (P^2 + Q^2) / V^2``.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("power_grid_model", reason='the AC check needs pip install "popdispatch[ac]"')

from popdispatch.ac import check_setpoints  # noqa: E402
from popdispatch.feeder.generators import make_fleet  # noqa: E402
from popdispatch.feeder.model import Feeder  # noqa: E402

from helpers import random_feeder  # noqa: E402

VN_KV = 0.4
TIGHT_PU = 1e-12  # power-flow tolerance here: the model, not the default tolerance, is tested
S_BASE_KW = 1.0  # p.u. base of the yardsticks: 1 kW, 0.4 kV -> Z_base = 160 ohm


def z_base_ohm() -> float:
    return (VN_KV * 1e3) ** 2 / (S_BASE_KW * 1e3)


def chain_feeder(n_buses: int, r_ohm: float, x_ohm: float, gen_bus: int, limit_kw: float):
    """Buses 1..n in a chain from source bus 1; one load per non-source bus; a generator."""
    buses = pd.DataFrame(
        {"x": np.arange(n_buses, dtype=float), "y": 0.0},
        index=pd.Index(np.arange(1, n_buses + 1), name="bus"),
    )
    lines = pd.DataFrame(
        {
            "from_bus": np.arange(1, n_buses),
            "to_bus": np.arange(2, n_buses + 1),
            "length_km": 0.1,
            "r_ohm": r_ohm,
            "x_ohm": x_ohm,
            "limit_kw": limit_kw,
        },
        index=[f"L{k}" for k in range(1, n_buses)],
    )
    loads = pd.DataFrame(
        {"bus": np.arange(2, n_buses + 1)}, index=[f"D{b}" for b in range(2, n_buses + 1)]
    )
    fleet = make_fleet([(1, 0, 5.0, 0.02, 0, 100), (gen_bus, 0, 1.0, 0.01, 0, 100)])
    return Feeder("hand", buses, lines, loads, 1, fleet)


@pytest.mark.parametrize("source_pu", [1.0, 1.05])
def test_two_bus_line_matches_the_closed_form(source_pu):
    r, x = 0.05, 0.02  # ohm
    p_kw, pf = 30.0, 0.9
    q_kvar = p_kw * math.tan(math.acos(pf))
    feeder = chain_feeder(2, r, x, gen_bus=2, limit_kw=50.0)
    day = check_setpoints(
        feeder,
        [[p_kw]],
        [[0.0, 0.0]],
        vn_kv=VN_KV,
        load_pf=pf,
        source_pu=source_pu,
        tolerance_pu=TIGHT_PU,
    )
    # closed form, p.u. on 1 kW / 0.4 kV
    rr, xx = r / z_base_ohm(), x / z_base_ohm()
    pp, qq = p_kw / S_BASE_KW, q_kvar / S_BASE_KW
    b = source_pu**2 - 2 * (pp * rr + qq * xx)
    v2_sq = (b + math.sqrt(b**2 - 4 * (pp**2 + qq**2) * (rr**2 + xx**2))) / 2
    loss_kw = rr * (pp**2 + qq**2) / v2_sq * S_BASE_KW
    current_a = math.hypot(p_kw, q_kvar) / (math.sqrt(3) * VN_KV * math.sqrt(v2_sq))  # kVA/kV
    step = day.steps.iloc[0]
    assert step.v_min_pu == pytest.approx(math.sqrt(v2_sq), abs=1e-9)
    assert step.v_min_bus == 2 and step.v_max_bus == 1
    assert step.v_max_pu == pytest.approx(source_pu, abs=1e-12)
    assert step.losses_kw == pytest.approx(loss_kw, abs=1e-9)
    assert step.source_extra_kw == pytest.approx(p_kw + loss_kw, abs=1e-9)
    # rating: 50 kW at 0.4 kV and unity power factor is 50 / (sqrt(3) 0.4) A
    assert step.max_current_a == pytest.approx(current_a, rel=1e-9)
    rated_a = 50.0 / (math.sqrt(3) * VN_KV)
    assert step.max_loading_percent == pytest.approx(100 * current_a / rated_a, rel=1e-9)
    assert step.max_loading_line == "L1"


def numpy_power_flow(
    feeder: Feeder, s_net_kva: np.ndarray, source_pu: float
) -> tuple[np.ndarray, complex]:
    """Plain-numpy AC power flow of a feeder: ``V = V0 + Z (conj(S / V))`` on the bus
    impedance matrix of the non-source buses (p.u., 1 kW base), iterated to 1e-15.
    A line without impedance joins its two buses into one (same voltage).
    ``s_net_kva``: net complex injection per bus (generation minus load), kVA.
    Returns the bus voltages (p.u., complex) and the source's complex power (kVA)."""
    ids = feeder.buses.index
    group = list(range(len(ids)))  # each bus's representative (buses joined by shorts)
    for row in feeder.lines.itertuples():
        if row.r_ohm == 0 and row.x_ohm == 0:
            a, b = group[ids.get_loc(row.from_bus)], group[ids.get_loc(row.to_bus)]
            group = [a if g == b else g for g in group]
    reps = sorted(set(group))
    where = np.array([reps.index(g) for g in group])
    n = len(reps)
    y = np.zeros((n, n), dtype=complex)
    for row in feeder.lines.itertuples():
        if row.r_ohm == 0 and row.x_ohm == 0:
            continue
        a, b = where[ids.get_loc(row.from_bus)], where[ids.get_loc(row.to_bus)]
        yl = z_base_ohm() / complex(row.r_ohm, row.x_ohm)
        y[a, a] += yl
        y[b, b] += yl
        y[a, b] -= yl
        y[b, a] -= yl
    s = where[ids.get_loc(feeder.source_bus)]
    rest = [k for k in range(n) if k != s]
    z = np.linalg.inv(y[np.ix_(rest, rest)])
    v = np.full(n, source_pu, dtype=complex)
    w = -z @ y[np.ix_(rest, [s])][:, 0] * source_pu  # no-load voltages
    inj = np.zeros(n, dtype=complex)
    np.add.at(inj, where, s_net_kva / S_BASE_KW)
    for _ in range(200):
        new = w + z @ np.conj(inj[rest] / v[rest])
        done = np.max(np.abs(new - v[rest])) < 1e-15
        v[rest] = new
        if done:
            break
    s_source = v[s] * np.conj(y[s] @ v) * S_BASE_KW
    return v[where], s_source


@pytest.mark.parametrize("gen_kw", [0.0, 25.0, 60.0])
def test_three_bus_feeder_matches_a_numpy_power_flow(gen_kw):
    """Export beyond the local load (60 kW) raises the far end above the source."""
    feeder = chain_feeder(3, 0.08, 0.03, gen_bus=3, limit_kw=np.inf)
    load_kw = np.array([12.0, 18.0])
    gen_pf, load_pf = 0.9, 0.95
    day = check_setpoints(
        feeder,
        [load_kw],
        [[0.0, gen_kw]],
        vn_kv=VN_KV,
        load_pf=load_pf,
        generator_pf=gen_pf,
        tolerance_pu=TIGHT_PU,
    )
    s_net = np.zeros(3, dtype=complex)
    s_net[1:] -= load_kw * (1 + 1j * math.tan(math.acos(load_pf)))
    s_net[2] += gen_kw * (1 + 1j * math.tan(math.acos(gen_pf)))
    v, s_source = numpy_power_flow(feeder, s_net, 1.0)
    np.testing.assert_allclose(day.flows.v_pu[0], np.abs(v), atol=1e-9, rtol=0)
    np.testing.assert_allclose(day.flows.angle_deg[0], np.degrees(np.angle(v)), atol=1e-7, rtol=0)
    step = day.steps.iloc[0]
    losses = s_source.real + s_net.real[1:].sum()
    assert step.losses_kw == pytest.approx(losses, abs=1e-7)
    assert step.source_extra_kw == pytest.approx(s_source.real, abs=1e-7)
    assert step.source_kvar == pytest.approx(s_source.imag, abs=1e-7)
    assert math.isnan(step.max_loading_percent) and step.max_loading_line is None
    if gen_kw == 60.0:
        assert step.v_max_bus == 3 and step.v_max_pu > 1.0


def test_series_chain_buses_and_reversed_lines_match_a_numpy_power_flow():
    """Buses 2..5 carry nothing (one branch in power-grid-model, recovered by Ohm's law), one
    line is written against the flow (to_bus upstream) and one has no impedance."""
    feeder = chain_feeder(6, 0.02, 0.01, gen_bus=4, limit_kw=30.0)
    lines = feeder.lines.copy()
    lines.loc["L3", ["from_bus", "to_bus"]] = [4, 3]  # reversed
    lines.loc["L2", ["r_ohm", "x_ohm"]] = 0.0
    lines["r_ohm"] = lines["r_ohm"] * [1.0, 1.0, 2.0, 0.5, 3.0]
    loads = pd.DataFrame({"bus": [6]}, index=["D6"])
    feeder = Feeder("chain", feeder.buses, lines, loads, 1, make_fleet([(1, 0, 5, 0.02, 0, 99)]))
    day = check_setpoints(
        feeder, [[40.0]], [[0.0]], vn_kv=VN_KV, load_pf=0.9, tolerance_pu=TIGHT_PU
    )
    assert day.network.chains.kept.tolist() == [True, False, False, False, False, True]
    s_net = np.zeros(6, dtype=complex)
    s_net[5] = -40.0 * (1 + 1j * math.tan(math.acos(0.9)))
    v, s_source = numpy_power_flow(feeder, s_net, 1.0)
    np.testing.assert_allclose(day.flows.v_pu[0], np.abs(v), atol=1e-9, rtol=0)
    # every line carries the same current; the reversed line's from end is downstream
    z_pu = (lines.r_ohm + 1j * lines.x_ohm).to_numpy() / z_base_ohm()
    current = np.conj(s_source / S_BASE_KW / v[0])  # p.u.: kVA per p.u. of voltage
    amps = abs(current) / (math.sqrt(3) * VN_KV)
    np.testing.assert_allclose(day.flows.current_a[0], amps, rtol=1e-9)
    s_from_l3 = v[3] * np.conj(-current)  # L3 from bus 4 (downstream): power enters against
    assert day.flows.p_from_kw[0, 2] == pytest.approx(s_from_l3.real, abs=1e-9)
    assert day.flows.q_to_kvar[0, 2] == pytest.approx((v[2] * np.conj(current)).imag, abs=1e-9)
    np.testing.assert_allclose(
        day.flows.loss_kw[0], abs(current) ** 2 * z_pu.real, atol=1e-9, rtol=0
    )
    assert day.steps.losses_kw.iloc[0] == pytest.approx(s_source.real - 40.0, abs=1e-9)
    assert day.steps.max_loading_percent.iloc[0] == pytest.approx(
        100 * amps / (30.0 / (math.sqrt(3) * VN_KV)), rel=1e-9
    )


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_radial_feeders_match_a_numpy_power_flow(seed):
    """Random trees (tests/helpers.random_feeder) with half their lines written against the
    flow: every bus voltage, every line's current and the losses."""
    rng = np.random.default_rng(seed)
    feeder = random_feeder(rng, 40, 3)
    lines = feeder.lines.copy()
    flip = rng.random(len(lines)) < 0.5
    lines.loc[flip, ["from_bus", "to_bus"]] = lines.loc[flip, ["to_bus", "from_bus"]].to_numpy()
    feeder = Feeder("random", feeder.buses, lines, feeder.loads, 1, feeder.generators)
    load_kw = rng.uniform(0, 8, len(feeder.loads))
    gen_kw = rng.uniform(0, 10, len(feeder.generators))
    day = check_setpoints(
        feeder, [load_kw], [gen_kw], vn_kv=VN_KV, load_pf=0.95, tolerance_pu=TIGHT_PU
    )
    ids = feeder.buses.index
    s_net = np.zeros(len(ids), dtype=complex)
    np.add.at(
        s_net, ids.get_indexer(feeder.loads.bus), -load_kw * (1 + 1j * math.tan(math.acos(0.95)))
    )
    np.add.at(s_net, ids.get_indexer(feeder.generators.bus), gen_kw)
    v, s_source = numpy_power_flow(feeder, s_net, 1.0)
    np.testing.assert_allclose(day.flows.v_pu[0], np.abs(v), atol=1e-9, rtol=0)
    a, b = ids.get_indexer(lines.from_bus), ids.get_indexer(lines.to_bus)
    z = (lines.r_ohm + 1j * lines.x_ohm).to_numpy() / z_base_ohm()
    current = (v[a] - v[b]) / z  # p.u. from -> to
    np.testing.assert_allclose(
        day.flows.current_a[0], np.abs(current) / (math.sqrt(3) * VN_KV), rtol=1e-6, atol=1e-6
    )  # A; lines to leaves without load carry none
    np.testing.assert_allclose(
        day.flows.p_from_kw[0], (v[a] * np.conj(current)).real, atol=1e-7, rtol=0
    )
    assert day.steps.losses_kw.iloc[0] == pytest.approx(
        s_source.real + s_net.real.sum() - s_net.real[0], abs=1e-7
    )
