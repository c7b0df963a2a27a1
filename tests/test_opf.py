"""The DC-OPF yardstick against a QP written from scratch here and solved with scipy.

The reference builds its own constraints from the reduced feeder's tables: which loads and
generators sit below each limited line comes from networkx on ``lines.from_node -> to_node``
(not from ``problem.down``), and the costs from the fleet table. Feasibility is decided
independently with ``scipy.optimize.linprog``.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog, minimize

from popdispatch.cases.builtin import elv_snapshot_566_kw
from popdispatch.errors import InfeasibleError
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import ReducedFeeder, reduce_feeder
from popdispatch.game.problem import build_problem
from popdispatch.opf import solve_opf
from popdispatch.scenarios import apply_path_limits, elv_problem

from helpers import random_feeder

# Table I, in the fleet's order G1, G114, G578, G739, G817, G835 (EUR, EUR/MW, EUR/MW^2).
TABLE_A = np.zeros(6)
TABLE_B = np.array([5.0, 1.0, 3.0, 4.0, 2.5, 2.0])
TABLE_C = np.array([0.02, 0.01, 0.025, 0.01, 0.015, 0.02])
ELV_GENERATORS = ["G1", "G114", "G578", "G739", "G817", "G835"]


@dataclass
class ReferenceQP:
    """``min sum b p/1000 + c (p/1000)^2`` (p in kW) with balance, bounds and line limits."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    pmin: np.ndarray  # kW
    pmax: np.ndarray  # kW
    demand: float  # kW
    below: np.ndarray  # (limited lines, generators) 1.0 if the generator is below the line
    load_below: np.ndarray  # kW of load below each limited line
    limit: np.ndarray  # kW

    def flows(self, p_kw: np.ndarray) -> np.ndarray:
        return self.load_below - self.below @ p_kw

    def cost(self, p_kw: np.ndarray) -> float:
        """EUR, with p in MW (offline generators have pmax = 0 and contribute nothing)."""
        p_mw = np.asarray(p_kw) / 1000.0
        online = self.pmax > 0
        return float(np.sum(np.where(online, self.a + self.b * p_mw + self.c * p_mw**2, 0.0)))

    def feasibility_margin(self) -> float:
        """Largest t with a point satisfying every constraint with limits U - t (linprog).

        Negative: infeasible (the limits must be relaxed by -t). Capped at 1 kW.
        """
        n, m = len(self.b), len(self.limit)
        # Variables (p, t); maximise t.
        objective = np.zeros(n + 1)
        objective[-1] = -1.0
        # |load_below - below p| <= U - t  <=>  -below p + t <= U - load_below
        #                                        below p + t <= U + load_below
        a_ub = np.vstack(
            [
                np.hstack([-self.below, np.ones((m, 1))]),
                np.hstack([self.below, np.ones((m, 1))]),
            ]
        ).reshape(2 * m, n + 1)
        b_ub = np.concatenate([self.limit - self.load_below, self.limit + self.load_below])
        a_eq = np.hstack([np.ones((1, n)), np.zeros((1, 1))])
        bounds = [(lo, hi) for lo, hi in zip(self.pmin, self.pmax, strict=True)] + [(None, 1.0)]
        result = linprog(
            objective,
            A_ub=a_ub if m else None,
            b_ub=b_ub if m else None,
            A_eq=a_eq,
            b_eq=[self.demand],
            bounds=bounds,
            method="highs",
        )
        assert result.status == 0, result.message
        return float(-result.fun)

    def solve(self):
        """SLSQP on the objective scaled by 1e6 (EUR -> micro-EUR, same minimiser)."""
        n = len(self.b)
        scale = 1e3
        b_kw = self.b / 1000.0 * scale
        c_kw = self.c / 1e6 * scale

        def fun(p):
            return float(np.sum(b_kw * p + c_kw * p**2))

        def jac(p):
            return b_kw + 2.0 * c_kw * p

        constraints = [
            {
                "type": "eq",
                "fun": lambda p: np.array([p.sum() - self.demand]),
                "jac": lambda p: np.ones((1, n)),
            }
        ]
        if len(self.limit):
            constraints.append(
                {
                    "type": "ineq",
                    "fun": lambda p: np.concatenate(
                        [self.limit - self.flows(p), self.limit + self.flows(p)]
                    ),
                    "jac": lambda p: np.vstack([self.below, -self.below]),
                }
            )
        capacity = self.pmax.sum()
        p0 = self.pmax * (self.demand / capacity) if capacity > 0 else np.zeros(n)
        result = minimize(
            fun,
            p0,
            jac=jac,
            method="SLSQP",
            bounds=list(zip(self.pmin, self.pmax, strict=True)),
            constraints=constraints,
            options={"ftol": 1e-12, "maxiter": 2000},
        )
        if result.success:
            result.x = self.polish(result.x, 2.0 * c_kw, b_kw)
        return result

    def polish(self, x: np.ndarray, hess: np.ndarray, grad: np.ndarray) -> np.ndarray:
        """Solve the KKT system of the constraints SLSQP left active (it stops ~1e-7 kW short).

        Keeps SLSQP's point unless the polished one is feasible and next to it.
        """
        n, tol = len(x), 1e-6
        rows, rhs = [np.ones(n)], [self.demand]
        eye = np.eye(n)
        for i in range(n):
            if x[i] - self.pmin[i] < tol:
                rows.append(eye[i])
                rhs.append(self.pmin[i])
            elif self.pmax[i] - x[i] < tol:
                rows.append(eye[i])
                rhs.append(self.pmax[i])
        flows = self.flows(x)
        for k in range(len(self.limit)):
            if self.limit[k] - flows[k] < tol:  # load_below - below p = U
                rows.append(self.below[k])
                rhs.append(self.load_below[k] - self.limit[k])
            elif self.limit[k] + flows[k] < tol:  # load_below - below p = -U
                rows.append(self.below[k])
                rhs.append(self.load_below[k] + self.limit[k])
        a = np.array(rows)
        kkt = np.block([[np.diag(hess), a.T], [a, np.zeros((len(a), len(a)))]])
        solution = np.linalg.lstsq(kkt, np.concatenate([-grad, rhs]), rcond=None)[0]
        polished = solution[:n]
        try:
            assert_feasible(self, polished, tol=1e-9)
        except AssertionError:
            return x
        return polished if np.max(np.abs(polished - x)) < 1e-4 else x


def reference_qp(
    reduced: ReducedFeeder, load_kw: pd.Series, online: np.ndarray | None = None
) -> ReferenceQP:
    """The QP of one minute from the reduced feeder's tables, built without ``DispatchProblem``."""
    gens = reduced.generators
    online = np.ones(len(gens), bool) if online is None else np.asarray(online, bool)
    graph = nx.DiGraph()
    graph.add_nodes_from(reduced.nodes.index)
    graph.add_edges_from(zip(reduced.lines.from_node, reduced.lines.to_node, strict=True))
    assert nx.is_arborescence(graph)
    limited = reduced.lines[np.isfinite(reduced.lines.limit_kw.to_numpy(float))]
    load_node = reduced.loads["node"]
    load_values = load_kw[reduced.loads.index].to_numpy(float)
    below = np.zeros((len(limited), len(gens)))
    load_below = np.zeros(len(limited))
    for k, child in enumerate(limited.to_node):
        subtree = nx.descendants(graph, child) | {child}
        below[k] = gens["node"].isin(subtree).to_numpy(float)
        load_below[k] = load_values[load_node.isin(subtree).to_numpy()].sum()
    return ReferenceQP(
        a=gens.a.to_numpy(float),
        b=gens.b.to_numpy(float),
        c=gens.c.to_numpy(float),
        pmin=np.where(online, gens.pmin_kw.to_numpy(float), 0.0),
        pmax=np.where(online, gens.pmax_kw.to_numpy(float), 0.0),
        demand=float(load_values.sum()),
        below=below,
        load_below=load_below,
        limit=limited.limit_kw.to_numpy(float),
    )


def assert_feasible(qp: ReferenceQP, p_kw: np.ndarray, tol: float = 1e-6) -> None:
    assert np.all(p_kw >= qp.pmin - tol) and np.all(p_kw <= qp.pmax + tol)
    assert abs(p_kw.sum() - qp.demand) <= tol
    assert np.all(np.abs(qp.flows(p_kw)) <= qp.limit + tol)


def check_against_reference(result, qp: ReferenceQP) -> str:
    """Compare one ``solve_opf`` result with the reference; return the kind of case checked."""
    margin = qp.feasibility_margin()
    if margin < -1e-6:
        assert result.status == "infeasible"
        assert np.isnan(result.p_kw).all() and len(result.p_kw) == len(qp.b)
        assert np.isnan(result.cost)
        return "infeasible"
    if margin < 1e-6:
        return "borderline"  # feasible set (nearly) a single point: no solver agrees reliably
    assert result.status == "optimal"
    assert_feasible(qp, result.p_kw)
    assert result.cost == pytest.approx(qp.cost(result.p_kw), rel=1e-12, abs=1e-15)
    reference = qp.solve()
    if not reference.success:
        return "scipy failed"
    assert_feasible(qp, reference.x)
    np.testing.assert_allclose(result.p_kw, reference.x, rtol=0, atol=1e-3)
    reference_cost = qp.cost(reference.x)
    assert result.cost == pytest.approx(reference_cost, rel=1e-9, abs=1e-13)
    binding = np.abs(np.abs(qp.flows(result.p_kw)) - qp.limit) < 1e-6
    return "binding" if binding.any() else "optimal"


# --- random small feeders ----------------------------------------------------------------------


def random_case(seed: int, n_buses: int, n_gens: int, n_paths: int):
    rng = np.random.default_rng(seed)
    feeder = random_feeder(rng, n_buses, n_gens)
    capacity = feeder.generators.pmax_kw.sum()
    share = rng.random(len(feeder.loads)) + 0.05
    total = rng.uniform(0.05, 0.95) * capacity
    load_kw = pd.Series(share / share.sum() * total, index=feeder.loads.index)
    limits = []
    for _ in range(n_paths):
        bus_a, bus_b = rng.choice(feeder.buses.index.to_numpy(), size=2, replace=False)
        limits.append((int(bus_a), int(bus_b), float(rng.uniform(0.0, 1.2) * total)))
    feeder = apply_path_limits(feeder, limits)
    reduced = reduce_feeder(feeder)
    problem = build_problem(reduced, single_minute_profiles(1, load_kw, "random"))
    return problem, reduced, load_kw


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_buses=st.integers(2, 14),
    n_gens=st.integers(1, 5),
    n_paths=st.integers(0, 3),
)
def test_random_problems_match_scipy_reference(seed, n_buses, n_gens, n_paths):
    n_gens = min(n_gens, n_buses)
    problem, reduced, load_kw = random_case(seed, n_buses, n_gens, n_paths)
    qp = reference_qp(reduced, load_kw)
    result = solve_opf(problem, 1)
    assert result.minute == 1
    assert result.demand_kw == pytest.approx(qp.demand, rel=1e-12)
    check_against_reference(result, qp)


def test_random_problems_cover_every_kind_of_case():
    """A fixed sweep: the comparison really meets free, binding and infeasible problems."""
    kinds = []
    for seed in range(60):
        rng = np.random.default_rng(1000 + seed)
        n_buses = int(rng.integers(3, 14))
        n_gens = int(rng.integers(1, min(5, n_buses) + 1))
        problem, reduced, load_kw = random_case(seed, n_buses, n_gens, 1 + seed % 3)
        kinds.append(check_against_reference(solve_opf(problem, 1), reference_qp(reduced, load_kw)))
    for kind in ("optimal", "binding", "infeasible"):
        assert kind in kinds, kinds
    assert kinds.count("scipy failed") <= 3, kinds


# --- ieee-elv ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def peak():
    return elv_problem()


@pytest.fixture(scope="module")
def peak_opf(peak):
    return solve_opf(peak, 566)


def table_cost(p_kw: np.ndarray) -> float:
    p_mw = np.asarray(p_kw) / 1000.0
    return float(np.sum(TABLE_A + TABLE_B * p_mw + TABLE_C * p_mw**2))


def test_elv_fleet_is_table_one(peak):
    assert list(peak.generators) == ELV_GENERATORS
    np.testing.assert_array_equal(peak.b, TABLE_B)
    np.testing.assert_array_equal(peak.c, TABLE_C)


def test_elv_peak_is_merit_order(peak, peak_opf):
    result = peak_opf
    assert result.status == "optimal"
    demand = elv_snapshot_566_kw().sum()
    assert result.demand_kw == pytest.approx(demand, rel=1e-12)
    assert demand == pytest.approx(57.358, abs=1e-5)
    # Cheapest first (b = 1, 2, 2.5, 3, 4 EUR/MW at full output), G1 (b = 5) takes the rest.
    np.testing.assert_allclose(result.p_kw, [2.358, 10, 5, 10, 20, 10], rtol=0, atol=1e-4)
    assert result.p_kw.sum() == pytest.approx(demand, abs=1e-6)
    assert result.cost == pytest.approx(table_cost(result.p_kw), rel=1e-12)
    expected_p = np.array([demand - 55.0, 10, 5, 10, 20, 10])
    assert result.cost == pytest.approx(table_cost(expected_p), rel=1e-8)
    assert result.cost == pytest.approx(0.146800738, rel=1e-6)
    # The marginal unit is G1: price = b + 2 c p in EUR/MW.
    assert result.marginal_price == pytest.approx(5.0 + 2 * 0.02 * (demand - 55.0) / 1000, abs=1e-6)
    check_against_reference(result, reference_qp(peak.feeder, elv_snapshot_566_kw()))


def test_elv_congested_path(peak_opf):
    problem = elv_problem(limits=[(505, 666, 28.0)])
    assert len(problem.lines) > 0
    np.testing.assert_array_equal(problem.limit, 0.028)
    result = solve_opf(problem, 566)
    assert result.status == "optimal"
    flows_kw = problem.flows(result.p_kw / 1000.0, 566) * 1000.0
    assert np.all(np.abs(flows_kw) <= 28.0 + 1e-6)
    assert np.any(np.abs(flows_kw) >= 28.0 - 1e-5)
    assert result.p_kw.sum() == pytest.approx(result.demand_kw, abs=1e-6)
    assert result.cost > peak_opf.cost + 1e-4
    assert result.cost == pytest.approx(table_cost(result.p_kw), rel=1e-12)
    # The path's line flows, recomputed over every reduced line from nodal injections.
    all_flows = (
        problem.all_line_flows_mw(result.p_kw / 1000.0, 566, elv_snapshot_566_kw().to_numpy())
        * 1000.0
    )
    np.testing.assert_allclose(all_flows[problem.lines], flows_kw, atol=1e-9)
    kind = check_against_reference(result, reference_qp(problem.feeder, elv_snapshot_566_kw()))
    assert kind == "binding"


def test_elv_zero_limit_to_bus_34_is_infeasible():
    problem = elv_problem(limits=[(1, 34, 0.0)])
    result = solve_opf(problem, 566)
    assert result.status == "infeasible"
    assert np.isnan(result.p_kw).all() and result.p_kw.shape == (6,)
    assert np.isnan(result.cost)
    qp = reference_qp(problem.feeder, elv_snapshot_566_kw())
    assert qp.feasibility_margin() < -1e-3
    assert check_against_reference(result, qp) == "infeasible"


# --- outages -----------------------------------------------------------------------------------


def test_outage_at_peak_exceeds_capacity(peak):
    # 57.358 kW of load against 55 kW without G114: rejected when the outage is declared.
    with pytest.raises(InfeasibleError, match="exceeds the available generation capacity"):
        peak.with_outage("G114", 566, 567)


def test_capacity_checks_name_the_minute_its_capacity_and_who_is_off(peak):
    from popdispatch.game.problem import check_capacity, check_online

    short = peak.with_outage("G114", 566, 567, check=False)  # kept; the DC-OPF says infeasible
    assert solve_opf(short, 566).status == "infeasible"
    with pytest.raises(InfeasibleError, match=r"minute 566 .* 55\.000 kW at that minute") as exc:
        check_capacity(short, [566])
    assert "offline: G114" in str(exc.value)
    dark = short
    for name in short.generators:
        dark = dark.with_outage(name, 566, check=False)
    with pytest.raises(InfeasibleError, match=r"no generator is online at minute 566"):
        check_online(dark, [566])
    check_online(short, [566])  # some generator is online: the minute can run


def test_offline_generator_is_held_at_zero():
    load_kw = 0.8 * elv_snapshot_566_kw()
    demand = load_kw.sum()
    problem = elv_problem(single_minute_profiles(566, load_kw, "80 % of minute 566"))
    outage = problem.with_outage("G114", 566, 567)
    g114 = ELV_GENERATORS.index("G114")

    result = solve_opf(outage, 566)
    assert result.status == "optimal"
    assert result.p_kw[g114] == 0.0
    assert result.p_kw.sum() == pytest.approx(demand, abs=1e-6)
    # The others in merit order: G835, G817, G578, G739 full, G1 the remaining 0.886 kW.
    np.testing.assert_allclose(result.p_kw, [demand - 45.0, 0, 5, 10, 20, 10], rtol=0, atol=1e-4)
    online = np.ones(6, bool)
    online[g114] = False
    assert result.cost == pytest.approx(table_cost(result.p_kw), rel=1e-12)
    qp = reference_qp(outage.feeder, load_kw, online)
    check_against_reference(result, qp)

    # Back online the minute after (on_minute is exclusive), and online before.
    for minute in (565, 567):
        again = solve_opf(outage, minute)
        np.testing.assert_allclose(again.p_kw, [0, 10, 5, demand - 45.0, 20, 10], atol=1e-4)


def test_day_solver_with_data_updates_equals_fresh_solves():
    """One solver updated minute after minute gives what a fresh solver gives each minute."""
    from popdispatch.opf import solve_opf_day
    from popdispatch.readers import read_profiles

    from helpers import official_folder

    profiles = read_profiles(official_folder())
    problem = elv_problem(profiles, [(505, 666, 28.0)]).with_outage("G114", 700, 705)
    minutes = np.array([1, 565, 566, 567, 699, 700, 704, 705, 1440])
    day = solve_opf_day(problem, minutes)
    for minute, updated in zip(minutes, day, strict=True):
        fresh = solve_opf(problem, int(minute))
        assert updated.status == fresh.status == "optimal"
        np.testing.assert_allclose(updated.p_kw, fresh.p_kw, atol=1e-6)
        assert updated.cost == pytest.approx(fresh.cost, rel=1e-9)
    assert day[minutes.tolist().index(566)].line_price[0] != 0.0
