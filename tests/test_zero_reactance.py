"""Zero-reactance branches of a meshed network: ideal connections in the DC model.

The buses they join share one angle and their flows follow Kirchhoff's current law; a
reactance below 1e-6 of the network's median nonzero ``|x|`` counts as zero. Yardsticks
written here in plain numpy, nothing of popdispatch's model used: the same network with every
zero reactance replaced by 1e-9 p.u., solved by a dense ``numpy.linalg.solve`` of the full
``B`` (its flows, distribution factors and angles); the exact limit ``x = 0``, the buses merged
by hand and the ideal connections' flows by least squares on Kirchhoff's current law; and a
DC-OPF written with the dense factors and solved by Clarabel. On EPRI ckt24 as shipped (its
busbars have ``X1 0``, ``Line.Other_Feeders`` ``X1`` 1e-9 ohm; skipped without the data) the
``feeder`` command describes the network, the base case meets Kirchhoff's current law at every
bus, and an exact-mode snapshot with a limit on a busbar lands on the DC-OPF and on the optimum
worked out from the topology by hand.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import clarabel
import numpy as np
import pandas as pd
import pytest
from scipy import sparse

from popdispatch.cases.sources import FeederSource, load_network
from popdispatch.errors import FeederError
from popdispatch.feeder.dcnet import DcNetwork
from popdispatch.feeder.fusion import zero_reactance, zero_reactance_threshold
from popdispatch.feeder.generators import make_fleet
from popdispatch.game.mesh import build_mesh_problem
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import OpfSolver

from helpers import FEEDERS_REASON, feeders_folder

BASE_MVA = 100.0
#: The stand-in reactance of the dense yardstick (p.u.).
TINY_X = 1e-9

#: (name, from, to, x p.u., tap, shift deg). Zero reactance: ``a`` joins the slack bus 1 to bus
#: 6 (``p`` is a branch with reactance parallel to it), ``e`` lies in the loop 2-3-4, ``e`` and
#: ``g`` make the path 3-4-5 that ``h`` (a phase shifter) parallels, ``j`` is a bridge to bus 8.
LINES = [
    ("a", 1, 6, 0.0, 0.0, 0.0),
    ("p", 1, 6, 0.05, 0.0, 0.0),
    ("b", 6, 2, 0.1, 0.0, 0.0),
    ("c", 1, 3, 0.2, 0.0, 0.0),
    ("d", 2, 3, 0.15, 0.0, 0.0),
    ("e", 3, 4, 0.0, 0.0, 0.0),
    ("f", 4, 2, 0.25, 0.0, 0.0),
    ("g", 4, 5, 0.0, 0.0, 0.0),
    ("h", 3, 5, 0.3, 0.0, 3.0),
    ("i", 5, 7, 0.2, 0.0, 0.0),
    ("j", 7, 8, 0.0, 0.0, 0.0),
    ("k", 6, 7, 0.12, 0.95, 0.0),
    ("l", 7, 9, 0.1, 0.0, 4.0),
    ("m", 9, 5, 0.2, 0.0, 0.0),
    ("n", 2, 9, 0.3, 0.0, 0.0),
]
PD_MW = [0.0, 40.0, 20.0, 15.0, 10.0, 5.0, 10.0, 25.0, 30.0]
GS_MW = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
#: (bus, a, b EUR/MWh, c EUR/MW^2h, pmin kW, pmax kW): G6 in the slack's group, G4 in the group
#: {3, 4, 5}, G8 behind the zero-reactance bridge.
FLEET = [(1, 0, 50, 0.01, 0, 300e3), (6, 0, 40, 0.02, 0, 40e3), (4, 0, 20, 0.02, 0, 60e3),
         (8, 0, 10, 0.02, 0, 100e3), (9, 0, 30, 0.01, 0, 50e3)]  # fmt: skip


def network(lines=LINES, limits: dict[str, float] | None = None) -> DcNetwork:
    """The test network (``limits``: kW per line name)."""
    buses = pd.DataFrame({"pd_mw": PD_MW, "gs_mw": GS_MW},
                         index=pd.Index(np.arange(1, 10), name="bus"))  # fmt: skip
    table = pd.DataFrame(lines, columns=["name", "from_bus", "to_bus", "x_pu", "tap",
                                         "shift_deg"]).set_index("name")  # fmt: skip
    table["limit_kw"] = pd.Series(limits or {}, dtype=float).reindex(table.index).fillna(np.inf)
    fleet = make_fleet(FLEET, [f"G{row[0]}" for row in FLEET])
    return DcNetwork("zero-x", BASE_MVA, buses, table, fleet, 1)


# -- the dense yardstick: zero reactances replaced by TINY_X ---------------------------------


def dense_model(net: DcNetwork):
    """``(Bf, shift_flows, B, C)`` of ``net`` with TINY_X for a zero reactance, dense."""
    index = net.buses.index
    f, t = index.get_indexer(net.lines.from_bus), index.get_indexer(net.lines.to_bus)
    m, n = len(f), len(index)
    x = net.lines.x_pu.to_numpy(float)
    tap = net.lines.tap.to_numpy(float)
    b = 1.0 / (np.where(x == 0, TINY_X, x) * np.where(tap == 0, 1.0, tap))
    C = np.zeros((m, n))
    C[np.arange(m), f], C[np.arange(m), t] = 1.0, -1.0
    shift_flows = -BASE_MVA * b * np.deg2rad(net.lines.shift_deg.to_numpy(float))
    return b[:, None] * C, shift_flows, C.T @ (b[:, None] * C), C


def dense_flows(net: DcNetwork, injection: np.ndarray, shifted: bool = True):
    """Flows (MW, every line) and angles (rad) of ``injection`` (MW per bus, the slack's
    entry ignored: it balances), by a dense solve with the slack's angle 0."""
    Bf, shift_flows, B, C = dense_model(net)
    shift_flows = shift_flows if shifted else np.zeros_like(shift_flows)
    rest = np.arange(1, len(injection))  # the slack is bus 1, position 0
    theta = np.zeros(len(injection))
    rhs = (injection - C.T @ shift_flows)[rest] / BASE_MVA
    theta[rest] = np.linalg.solve(B[np.ix_(rest, rest)], rhs)
    return BASE_MVA * Bf @ theta + shift_flows, theta


def injections() -> np.ndarray:
    """Per bus, the loads and shunts withdrawn and some generation (MW)."""
    out = -(np.array(PD_MW) + np.array(GS_MW))
    out[[3, 7, 8]] += [30.0, 60.0, 20.0]
    return out


def test_flows_angles_and_factors_equal_a_dense_solve_with_tiny_reactances():
    net = network()
    model = net.model
    lines = np.arange(len(LINES))
    injection = injections()
    ours = model.flows_mw(injection, lines)[:, 0]
    theirs, theta = dense_flows(net, injection)
    scale = np.abs(theirs).max()
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-6 * scale)
    angles = model.angles(injection)[:, 0]
    np.testing.assert_allclose(angles, theta, atol=1e-6 * np.abs(theta).max())
    # by hand: the bridge carries bus 8's withdrawal; the branch with reactance parallel to
    # the ideal connection 1-6 carries nothing, the phase shifter parallel to 3-4-5 its shift
    flow = pd.Series(ours, index=net.lines.index)
    assert flow["j"] == pytest.approx(-injection[7], rel=1e-12)
    assert flow["p"] == 0.0
    assert flow["h"] == pytest.approx(-BASE_MVA / 0.3 * np.deg2rad(3.0), rel=1e-12)
    # Kirchhoff's current law at every bus but the slack, which balances the rest
    balance = net.model.incidence.T @ ours
    np.testing.assert_allclose(balance[1:], injection[1:], atol=1e-9 * scale)
    # one angle per group
    angles = pd.Series(angles, index=net.buses.index)
    assert angles[1] == angles[6] == 0.0 and angles[3] == angles[4] == angles[5]
    assert angles[7] == angles[8]
    # several columns at once
    two = model.flows_mw(np.c_[injection, 2 * injection], lines)
    np.testing.assert_allclose(two[:, 0], ours)
    shift = model.flows_mw(np.zeros(9), lines)[:, 0]
    np.testing.assert_allclose(two[:, 1], 2 * ours - shift, atol=1e-9 * scale)


def test_distribution_factors_equal_a_dense_solve_with_tiny_reactances():
    net = network()
    lines, buses = np.arange(len(LINES)), np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 7, 3])
    ours = net.model.ptdf(lines, buses)
    theirs = np.column_stack([
        dense_flows(net, np.eye(9)[bus], shifted=False)[0] for bus in buses
    ])  # fmt: skip
    np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-6)
    assert np.all(ours[:, 0] == 0.0)  # the slack's column
    # the slack's group: an injection at bus 6 is an injection at the slack, but for the ideal
    # connection 1-6 that carries it there
    at6 = pd.Series(ours[:, 5], index=net.lines.index)
    assert at6["a"] == pytest.approx(-1.0, abs=1e-12)
    assert np.abs(at6.drop("a")).max() <= 1e-12
    assert ours[net.lines.index.get_loc("j"), 7] == pytest.approx(-1.0, abs=1e-12)


def test_a_network_without_zero_reactance_is_unchanged():
    """Lines with reactance only: every bus is its own group, the model is makeBdc's."""
    lines = [row if row[3] else (*row[:3], 0.07, *row[4:]) for row in LINES]
    net = network(lines)
    assert net.model.zero is None and np.array_equal(net.model.group, np.arange(9))
    injection = injections()
    ours = net.model.flows_mw(injection, np.arange(len(lines)))[:, 0]
    np.testing.assert_allclose(ours, dense_flows(net, injection)[0], rtol=1e-10, atol=1e-10)


# -- near-zero reactance: below 1e-6 of the median nonzero |x| is zero --------------------------

#: The zero-reactance lines of LINES.
ZERO_LINES = ("a", "e", "g", "j")
#: A reactance (p.u.) far below the threshold, 5e-12 of the lines' median: ckt24's
#: Other_Feeders is 2.7e-11 of its network's.
NEAR_X = 1e-12


def with_x(x_by_name: dict[str, float], lines=LINES) -> list[tuple]:
    """``lines`` with the reactances (p.u.) of the lines named in ``x_by_name`` replaced."""
    return [(*row[:3], x_by_name.get(row[0], row[3]), *row[4:]) for row in lines]


def threshold_by_hand(lines) -> float:
    """1e-6 times the median nonzero |x| (p.u.) of ``lines``, written out here."""
    x = np.abs([row[3] for row in lines])
    return 1e-6 * float(np.median(x[x != 0]))


def merged_flows(net: DcNetwork, injection: np.ndarray, ideal: tuple[str, ...]) -> np.ndarray:
    """Flows (MW, every line) of ``injection`` (MW per bus, the slack's entry its balance) in
    the exact limit of the lines ``ideal`` at ``x = 0``: their buses merged by hand into one
    bus each set, a dense ``B`` of the merged buses from every other line (phase shifts
    included), and the ideal lines' flows the least-squares solution of Kirchhoff's current law
    at every bus (exact: the ideal lines form a forest, so the law fixes them)."""
    index = net.buses.index
    f, t = index.get_indexer(net.lines.from_bus), index.get_indexer(net.lines.to_bus)
    n = len(index)
    is_ideal = net.lines.index.isin(ideal)
    label = np.arange(n)  # each bus labelled by the smallest bus of its merged set
    for _ in range(n):
        for k in np.flatnonzero(is_ideal):
            low = min(label[f[k]], label[t[k]])
            label[(label == label[f[k]]) | (label == label[t[k]])] = low
    _, merged = np.unique(label, return_inverse=True)
    m = merged.max() + 1
    injection = injection.copy()
    injection[0] = -injection[1:].sum()  # the slack (bus 1, position 0) balances
    rest = np.flatnonzero(~is_ideal)
    x = net.lines.x_pu.to_numpy(float)[rest]
    tap = net.lines.tap.to_numpy(float)[rest]
    b = 1.0 / (x * np.where(tap == 0, 1.0, tap))
    C = np.zeros((len(rest), m))
    np.add.at(C, (np.arange(len(rest)), merged[f[rest]]), 1.0)
    np.add.at(C, (np.arange(len(rest)), merged[t[rest]]), -1.0)
    shift_flows = -BASE_MVA * b * np.deg2rad(net.lines.shift_deg.to_numpy(float)[rest])
    group_injection = np.bincount(merged, injection, minlength=m) - C.T @ shift_flows
    B = C.T @ (b[:, None] * C)
    keep = np.flatnonzero(np.arange(m) != merged[0])
    theta = np.zeros(m)
    theta[keep] = np.linalg.solve(B[np.ix_(keep, keep)], group_injection[keep] / BASE_MVA)
    flows = np.zeros(len(net.lines))
    flows[rest] = BASE_MVA * b * (C @ theta) + shift_flows
    full = np.zeros((len(net.lines), n))
    full[np.arange(len(f)), f], full[np.arange(len(t)), t] = 1.0, -1.0
    others = full[rest].T @ flows[rest]
    lines = np.flatnonzero(is_ideal)
    flows[lines] = np.linalg.lstsq(full[lines].T, injection - others, rcond=None)[0]
    return flows


def test_near_zero_reactances_are_ideal_connections_equal_to_the_exact_limit():
    """Every zero reactance of LINES at 1e-12 p.u.: the same groups, and flows and angles equal
    to the limit x = 0 worked out by hand, to round-off."""
    lines = with_x(dict.fromkeys(ZERO_LINES, NEAR_X))
    assert threshold_by_hand(lines) > 1e4 * NEAR_X
    near, exact = network(lines), network()
    assert net_zero_names(near) == list(ZERO_LINES)
    np.testing.assert_array_equal(near.model.group, exact.model.group)
    injection = injections()
    every = np.arange(len(LINES))
    ours = near.model.flows_mw(injection, every)[:, 0]
    theirs = merged_flows(near, injection, ZERO_LINES)
    scale = np.abs(theirs).max()
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(ours, exact.model.flows_mw(injection, every)[:, 0], rtol=0,
                               atol=1e-12 * scale)  # fmt: skip
    np.testing.assert_array_equal(near.model.angles(injection), exact.model.angles(injection))
    # Kirchhoff's current law at every bus, the slack's injection the balance
    balanced = injection.copy()
    balanced[0] = -injection[1:].sum()
    np.testing.assert_allclose(near.model.incidence.T @ ours, balanced, rtol=0,
                               atol=1e-12 * scale)  # fmt: skip


def net_zero_names(net: DcNetwork) -> list[str]:
    """The names of the lines the DC model of ``net`` takes as ideal connections."""
    zero = net.model.zero
    return [] if zero is None else net.lines.index[zero.lines].tolist()


def test_a_reactance_just_above_the_threshold_is_a_branch_and_just_below_it_is_fused():
    """Line ``a`` (1-6, parallel to ``p``) at 0.99 and 1.01 times the threshold: below it, an
    ideal connection (the exact limit by hand); above it, a branch of ``B`` whose flows equal
    the merged yardstick with ``a`` kept (well conditioned: 1e-6 of the median); the two differ
    by the share ``x_a / (x_a + x_th)`` of a's flow that its reactance pushes onto ``p``, about
    4e-6 (``x_th`` about 0.04 p.u.)."""
    threshold = threshold_by_hand(with_x({"a": NEAR_X}))  # a, the least, leaves the median
    assert threshold == pytest.approx(1.75e-7, rel=1e-12)  # 1e-6 x (0.15 + 0.2) / 2
    below = network(with_x({"a": 0.99 * threshold}))
    above = network(with_x({"a": 1.01 * threshold}))
    assert net_zero_names(below) == list(ZERO_LINES)
    assert net_zero_names(above) == ["e", "g", "j"]
    group = pd.Series(above.model.group, index=above.buses.index)
    assert group[1] != group[6] and group[3] == group[4] == group[5] and group[7] == group[8]
    assert below.model.group[0] == below.model.group[5]  # buses 1 and 6 at one angle
    injection = injections()
    every = np.arange(len(LINES))
    flows_below = below.model.flows_mw(injection, every)[:, 0]
    flows_above = above.model.flows_mw(injection, every)[:, 0]
    scale = np.abs(flows_below).max()
    np.testing.assert_allclose(flows_below, merged_flows(below, injection, ZERO_LINES), rtol=0,
                               atol=1e-12 * scale)  # fmt: skip
    np.testing.assert_allclose(flows_above, merged_flows(above, injection, ("e", "g", "j")),
                               rtol=0, atol=1e-9 * scale)  # fmt: skip
    jump = np.abs(flows_above - flows_below).max()
    a = above.lines.index.get_loc("a")
    assert 1e-6 * abs(flows_below[a]) < jump < 1e-5 * abs(flows_below[a])


def test_no_line_with_reactance_leaves_only_exact_zeros_zero():
    """Where no line has reactance there is no typical one: only x = 0 is zero (a path of
    ideal connections from the slack)."""
    table = pd.DataFrame({"x_pu": [0.0, 0.0, -0.0]})
    assert zero_reactance_threshold(table) == 0.0
    assert zero_reactance(table).all()
    table = pd.DataFrame({"x_pu": [0.0, 1e-300, -0.5, 0.5, 1.0]})  # |x|: the sign is no matter
    assert zero_reactance_threshold(table) == pytest.approx(0.5e-6, rel=1e-12)
    np.testing.assert_array_equal(zero_reactance(table), [True, True, False, False, False])


# -- the DC-OPF ----------------------------------------------------------------------------


def dense_opf(net: DcNetwork) -> np.ndarray:
    """The DC-OPF (kW per generator) of ``net`` on the dense yardstick: flows ``F0 + PTDF_g p``
    with ``F0`` the loads' flows (the slack supplying them, phase shifts included), Clarabel
    on the variables ``p`` (MW)."""
    demand = np.array(PD_MW) + np.array(GS_MW)
    base, _ = dense_flows(net, -demand)
    gen_bus = net.buses.index.get_indexer(net.generators.bus)
    ptdf = np.column_stack([dense_flows(net, np.eye(9)[k], shifted=False)[0] for k in gen_bus])
    limit = net.lines.limit_kw.to_numpy(float) / 1e3
    rows = np.flatnonzero(np.isfinite(limit))
    gens = net.generators
    n = len(gens)
    A = np.vstack([np.ones((1, n)), -np.eye(n), np.eye(n), ptdf[rows], -ptdf[rows]])
    b = np.r_[demand.sum(), -gens.pmin_kw / 1e3, gens.pmax_kw / 1e3,
              limit[rows] - base[rows], limit[rows] + base[rows]]  # fmt: skip
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    cones = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(len(b) - 1)]
    P = sparse.csc_matrix(np.diag(2 * gens.c.to_numpy(float)))
    solution = clarabel.DefaultSolver(P, gens.b.to_numpy(float), sparse.csc_matrix(A), b, cones,
                                      settings).solve()  # fmt: skip
    assert str(solution.status) == "Solved"
    return np.asarray(solution.x) * 1e3


#: Line limits (kW), each below its unconstrained flow and each binding at the optimum: the
#: zero-reactance bridge j, the zero-reactance line e inside the loop 2-3-4 and the line k (with
#: reactance and a tap) in the loop 6-7-5-3-1.
LIMITS = {"j": 20e3, "e": 3e3, "k": 5e3}


def test_the_dc_opf_with_limits_on_ideal_connections_equals_a_dense_one():
    free = dense_opf(network())
    net = network(limits=LIMITS)
    problem = build_mesh_problem(net)
    theirs = dense_opf(net)
    assert np.abs(theirs - free).max() > 1e3  # the limits move the optimum
    tol = 1e-6 * float(problem.demand[0]) * 1e3
    for formulation in ("angles", "factors"):
        opf = OpfSolver(problem, formulation).solve(1)
        assert opf.status == "optimal"
        assert np.abs(opf.p_kw - theirs).max() <= tol, formulation
        binding = pd.Series(np.abs(opf.line_price) > 1e-3, index=net.lines.index[problem.lines])
        assert binding.all(), (formulation, binding)
    run = run_snapshot(problem, 1, RunSettings(mode="exact"))
    assert run.status == "converged"
    assert np.abs(run.setpoints_kw - theirs).max() <= max(1e-3, tol)


# -- what the DC model cannot take ------------------------------------------------------------


def refusal(lines) -> str:
    """The message of the :class:`FeederError` that building the network of ``lines`` raises,
    asserted to be one line."""
    with pytest.raises(FeederError) as exc:
        network(lines)
    message = str(exc.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize(
    "extra, named",
    [([("e2", 3, 4, 0.0, 0.0, 0.0)], "e2"),  # parallel to e
     ([("q", 3, 5, 0.0, 0.0, 0.0)], "q")],  # with e and g, a triangle
)  # fmt: skip
def test_a_loop_of_zero_reactance_lines_is_refused_in_one_line(extra, named):
    message = refusal(LINES + extra)
    assert f"line {named!r} closes a loop of zero-reactance branches" in message


def test_a_zero_reactance_phase_shifter_is_refused_in_one_line():
    lines = [(*row[:5], 2.0) if row[0] == "j" else row for row in LINES]
    message = refusal(lines)
    assert "line 'j' has zero reactance and a phase shift of 2 deg" in message


def test_a_near_zero_line_closing_a_loop_of_ideal_connections_is_refused_in_one_line():
    """``q`` (3-5, 1e-12 p.u.) with the exact zeros ``e`` and ``g``: a triangle of ideal
    connections, refused as for x = 0; the message says what zero is."""
    lines = LINES + [("q", 3, 5, NEAR_X, 0.0, 0.0)]
    message = refusal(lines)
    below = f"{threshold_by_hand(lines):.3g}"
    assert below == "1.75e-07"
    assert (f"line 'q' closes a loop of zero-reactance branches (reactance below {below} p.u.; "
            "the DC model cannot split") in message  # fmt: skip
    # at the threshold's other side q is a branch of B, in a group: it carries no flow
    net = network(LINES + [("q", 3, 5, 1.01 * threshold_by_hand(lines), 0.0, 0.0)])
    assert net_zero_names(net) == list(ZERO_LINES)
    q = net.lines.index.get_loc("q")
    assert net.model.flows_mw(injections(), np.array([q]))[0, 0] == 0.0


def test_a_near_zero_phase_shifter_is_refused_in_one_line():
    lines = [(*row[:3], NEAR_X, row[4], 2.0) if row[0] == "j" else row for row in LINES]
    message = refusal(lines)
    below = f"{threshold_by_hand(lines):.3g}"
    assert below == "1.75e-07"
    assert (f"line 'j' has zero reactance (1e-12 p.u., below {below} p.u.) and a phase shift of "
            "2 deg") in message  # fmt: skip


def test_what_is_wrong_otherwise_is_still_refused():
    net = network()
    with pytest.raises(FeederError, match="several parts"):
        replace(net, lines=net.lines.drop(index="j"))
    with pytest.raises(FeederError, match="is not a bus"):
        replace(net, lines=net.lines.assign(to_bus=net.lines.to_bus.replace(8, 99)))


# -- the command line ----------------------------------------------------------------------


def popdispatch(*args: str) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, "-m", "popdispatch.cli", *args], capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return done


def matpower_text(lines=LINES) -> str:
    """The test network as a MATPOWER case file (no ``baseKV``: read as a mesh)."""
    bus = "".join(f"{k} {3 if k == 1 else 1} {PD_MW[k - 1]} 0 {GS_MW[k - 1]} 0 1 1 0 0 1 1.1 0.9;\n"
                  for k in range(1, 10))  # fmt: skip
    gen = "".join(f"{g[0]} 0 0 0 0 1 100 1 {g[5] / 1e3} {g[4] / 1e3};\n" for g in FLEET)
    cost = "".join(f"2 0 0 3 {g[3]} {g[2]} {g[1]};\n" for g in FLEET)
    branch = "".join(f"{f} {t} 0.01 {x} 0 0 0 0 {tap} {shift} 1 -360 360;\n"
                     for _, f, t, x, tap, shift in lines)  # fmt: skip
    return (f"function mpc = zerox\nmpc.version = '2';\nmpc.baseMVA = {BASE_MVA};\n"
            f"mpc.bus = [\n{bus}];\nmpc.gen = [\n{gen}];\nmpc.gencost = [\n{cost}];\n"
            f"mpc.branch = [\n{branch}];\n")  # fmt: skip


def test_the_commands_say_how_many_lines_they_join(tmp_path):
    case = tmp_path / "zerox.m"
    case.write_text(matpower_text())
    described = popdispatch("feeder", "--net", str(case))
    assert ("ideal connections: 4 zero-reactance line(s) (reactance below 2e-07 p.u.) join 7 "
            "buses into 3 group(s), each at one angle") in described.stdout  # fmt: skip
    assert ("4 zero-reactance line(s) (reactance below 2e-07 p.u.) joined as ideal "
            "connections") in described.stderr  # fmt: skip
    summary = json.loads(popdispatch("feeder", "--net", str(case), "--json", "-q").stdout)
    assert (summary["zero_reactance_lines"], summary["fused_buses"], summary["fused_groups"]) == (
        4, 7, 3)  # fmt: skip
    limits = ["--limit", "7:8=20000", "--limit", "3:4=3000", "--limit", "6:7=5000"]
    opf = json.loads(popdispatch("opf", "--net", str(case), "--minute", "1", *limits, "--json",
                                 "-q").stdout)  # fmt: skip
    theirs = dense_opf(network(limits=LIMITS))
    ours = np.array([g["p_kw"] for g in opf["generators"]])
    assert np.abs(ours - theirs).max() <= 1e-6 * opf["demand_kw"]


def test_the_commands_count_near_zero_lines_and_say_the_threshold(tmp_path):
    """The zero lines at 1e-12 p.u. in a MATPOWER case: the same four ideal connections, the
    threshold 1e-6 x 0.12 p.u. (the median of the 15 nonzero reactances) in the text and the
    JSON, the DC-OPF the exact limit's."""
    lines = with_x(dict.fromkeys(ZERO_LINES, NEAR_X))
    case = tmp_path / "nearx.m"
    case.write_text(matpower_text(lines))
    described = popdispatch("feeder", "--net", str(case))
    assert ("ideal connections: 4 zero-reactance line(s) (reactance below 1.2e-07 p.u.) join 7 "
            "buses into 3 group(s)") in described.stdout  # fmt: skip
    summary = json.loads(popdispatch("feeder", "--net", str(case), "--json", "-q").stdout)
    assert (summary["zero_reactance_lines"], summary["fused_buses"], summary["fused_groups"]) == (
        4, 7, 3)  # fmt: skip
    assert summary["zero_reactance_threshold_pu"] == pytest.approx(threshold_by_hand(lines),
                                                                   rel=1e-12)  # fmt: skip
    limits = ["--limit", "7:8=20000", "--limit", "3:4=3000", "--limit", "6:7=5000"]
    opf = json.loads(popdispatch("opf", "--net", str(case), "--minute", "1", *limits, "--json",
                                 "-q").stdout)  # fmt: skip
    theirs = dense_opf(network(limits=LIMITS))
    ours = np.array([g["p_kw"] for g in opf["generators"]])
    assert np.abs(ours - theirs).max() <= 1e-6 * opf["demand_kw"]


# -- EPRI ckt24 as shipped -------------------------------------------------------------------

CKT24 = feeders_folder() / "opendss" / "ckt24" / "master_ckt24.dss"
needs_ckt24 = pytest.mark.skipif(not CKT24.is_file(), reason=FEEDERS_REASON)
#: A priced source and three DGs: G1 behind the busbar n274498-n274501 (zero reactance, a
#: bridge), G2 on a busbar group of the substation's bay (n292679), G3 elsewhere.
CKT24_FLEET = ("bus,name,a,b,c,pmin_kw,pmax_kw\nsourcebus,G0,0,60,0.002,0,80000\n"
               "n274501,G1,0,10,0.01,0,900\nn292679,G2,0,15,0.01,0,900\n"
               "n283927,G3,0,20,0.01,0,900\n")  # fmt: skip
BUSBAR, BUSBAR_KW = ("n274498", "n274501"), 300.0


@pytest.fixture(scope="module")
def ckt24_summary() -> dict:
    return json.loads(popdispatch("feeder", "--net", str(CKT24), "--json", "-q").stdout)


@needs_ckt24
def test_ckt24_as_shipped_is_described_with_its_busbars_joined():
    done = popdispatch("feeder", "--net", str(CKT24))
    below = "(reactance below 3.08e-08 p.u.)"  # 1e-6 of the median, 0.0308 p.u. on 1 MVA
    assert (f"ideal connections: 65 zero-reactance line(s) {below} join 77 buses into 12 "
            "group(s)") in done.stdout  # fmt: skip
    assert f"65 zero-reactance line(s) {below} joined as ideal connections" in done.stderr


@needs_ckt24
def test_ckt24_base_case_meets_kirchhoffs_current_law_at_every_bus():
    """``Line.Other_Feeders`` (``X1`` 1e-9 ohm: 8.4e-13 p.u., 2.7e-11 of the median) is an ideal
    connection, so ``B`` holds only real branches and the base case (the loads withdrawn, the
    slack balancing) meets Kirchhoff's current law at every bus to round-off: within 1e-9 of the
    demand (51 mW; the branch left in ``B`` misses it by 12 W at bus ``feeders``, 13 W in the
    slack's balance). The balance is summed here from the line table, not the model's
    incidence."""
    net, _ = load_network(FeederSource(net=CKT24))
    index = net.buses.index
    injection = -(net.buses.pd_mw + net.buses.gs_mw).to_numpy(float)  # MW
    slack = index.get_loc(net.slack_bus)
    injection[slack] -= injection.sum()  # the slack's balance
    flows = net.model.flows_mw(injection, np.arange(len(net.lines)))[:, 0]
    f, t = index.get_indexer(net.lines.from_bus), index.get_indexer(net.lines.to_bus)
    out = np.bincount(f, flows, len(index)) - np.bincount(t, flows, len(index))
    residual = np.abs(out - injection)
    worst = net.bus_labels([index[residual.argmax()]])[0]
    assert residual.max() <= 1e-9 * net.demand_mw, (worst, residual.max())
    assert "other_feeders" in net_zero_names(net)


@needs_ckt24
def test_ckt24_exact_mode_with_a_busbar_limited_lands_on_the_dc_opf(tmp_path, ckt24_summary):
    """The busbar n274498-n274501 is a bridge: its flow is the net demand beyond it less G1's
    output (networkx on the described lines), so the optimum is G1 at the limit plus that
    demand, G2 and G3 at their maximum (cheaper than the source) and the source the rest."""
    nx = pytest.importorskip("networkx")
    s = ckt24_summary
    assert s["zero_reactance_lines"] == 65
    graph = nx.MultiGraph([(r["from_bus"], r["to_bus"]) for r in s["line_table"]])
    graph.remove_edge(*BUSBAR)
    beyond = nx.node_connected_component(graph, BUSBAR[1])
    assert BUSBAR[0] not in beyond  # a bridge
    load = sum(r["p_kw"] for r in s["load_table"] if r["bus"] in beyond)
    fleet = tmp_path / "fleet.csv"
    fleet.write_text(CKT24_FLEET)
    out = popdispatch("snapshot", "--net", str(CKT24), "--fleet", str(fleet), "--minute", "1",
                      "--mode", "exact", "--no-ratings", "--limit",
                      f"{BUSBAR[0]}:{BUSBAR[1]}={BUSBAR_KW}", "--json", "-q")  # fmt: skip
    run = json.loads(out.stdout)
    expected = np.array([0.0, BUSBAR_KW + load, 900.0, 900.0])
    expected[0] = run["demand_kw"] - expected[1:].sum()
    assert 0 < BUSBAR_KW + load < 900.0
    setpoints = np.array([g["setpoint_kw"] for g in run["generators"]])
    opf_kw = np.array([g["opf_kw"] for g in run["generators"]])
    assert run["status"] == "converged"
    assert run["distance_bound_kw"] <= run["accuracy_kw"] <= max(1e-3, 1e-6 * run["demand_kw"])
    assert np.abs(setpoints - opf_kw).max() <= run["accuracy_kw"]
    assert np.abs(opf_kw - expected).max() <= run["accuracy_kw"]
    assert any(abs(row["price_eur_per_mwh"]) > 1e-3 for row in run["line_prices"])
