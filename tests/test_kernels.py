"""The compiled engine against its plain-numpy reference (:mod:`popdispatch.reference`), and
the tree kernels against the dense matrix they replace."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from scipy import sparse

from popdispatch.dynamics import Kernel
from popdispatch.dynamics.pairwise import complete_graph_flows, graph_flows, sort_by_fitness
from popdispatch.dynamics.targets import target_flows
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.controllers import broadcast_signals, overflow_signal
from popdispatch.game.flows import broadcast, limited_line_flows
from popdispatch.game.problem import build_problem
from popdispatch.integrate import Integrator, Status
from popdispatch.modes.exact import ExactConstants
from popdispatch.online import Engine, RunSettings, initial_shares
from popdispatch.reference import ReferenceMinute, pair_flows
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

from helpers import random_feeder, random_fleet_problem


def limited_random_problem(seed: int, n_buses: int = 60, n_gens: int = 8, share: float = 0.5):
    """A random feeder with about ``share`` of its lines limited near their loads-only flow."""
    rng = np.random.default_rng(seed)
    feeder = random_feeder(rng, n_buses, n_gens)
    loads = feeder.loads.index
    load_kw = np.round(rng.uniform(0.5, 3.0, len(loads)), 3)
    profiles = single_minute_profiles(1, pd.Series(load_kw, index=loads), "random")
    chosen = feeder.lines.index[rng.random(len(feeder.lines)) < share]
    limits = pd.Series(rng.uniform(2.0, 15.0, len(chosen)), index=chosen)
    return build_problem(reduce_feeder(feeder.with_line_limits(limits)), profiles)


@pytest.mark.parametrize("seed", range(4))
def test_tree_flows_and_broadcast_equal_the_dense_matrix(seed):
    problem = limited_random_problem(seed)
    assert len(problem.limit) > 3
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 0.01, problem.n_generators)
    flow = np.empty(len(problem.limit))
    limited_line_flows(problem.load_flow[0], p, problem.generator_line, problem.line_up,
                       problem.line_preorder, flow)  # fmt: skip
    np.testing.assert_allclose(flow, problem.load_flow[0] - problem.down @ p, atol=1e-15)
    parent_side, child_side = rng.normal(size=(2, len(flow)))
    signal = np.empty(problem.n_generators)
    broadcast(parent_side, child_side, problem.generator_line, problem.line_up,
              problem.line_preorder, np.empty(len(flow)), signal)  # fmt: skip
    dense = (1 - problem.down).T @ parent_side + problem.down.T @ child_side
    np.testing.assert_allclose(signal, dense, atol=1e-12)
    limit = np.abs(flow) * rng.uniform(0.5, 1.5, len(flow))
    compiled = np.empty(problem.n_generators)
    par = np.array([overflow_signal(f, u, 1000.0) for f, u in zip(flow, limit, strict=True)])
    chi = np.array([overflow_signal(-f, u, 1000.0) if q else 0.0
                    for f, u, q in zip(flow, limit, par != 0, strict=True)])  # fmt: skip
    broadcast(par, chi, problem.generator_line, problem.line_up, problem.line_preorder,
              np.empty(len(flow)), compiled)  # fmt: skip
    np.testing.assert_allclose(
        compiled, broadcast_signals(flow, limit, problem.down, 1000.0), atol=1e-9
    )


@pytest.mark.parametrize("n", [1, 2, 7, 40, 300])
def test_sorted_prefix_sums_equal_all_pairs(n):
    rng = np.random.default_rng(n)
    f = rng.normal(size=n) * 100
    f[: n // 3] = f[0]  # ties give exactly zero flow between them
    w, v = rng.random(n), rng.random(n)
    order = rng.permutation(n).astype(np.int64)
    sort_by_fitness(f, order)
    assert (np.diff(f[order]) >= 0).all()
    inflow, outflow = np.empty(n), np.empty(n)
    complete_graph_flows(f, w, v, order, inflow, outflow)
    complete = np.ones((n, n)) - np.eye(n)
    ref_in, ref_out = pair_flows(f, w, v, complete)
    np.testing.assert_allclose(inflow, ref_in, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(outflow, ref_out, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(inflow.sum(), outflow.sum(), rtol=1e-12)
    ring = np.zeros((n, n))
    for i in range(n):
        ring[i, (i + 1) % n] = ring[(i + 1) % n, i] = 1.0 if n > 1 else 0.0
    csr = sparse.csr_matrix(ring)
    graph_flows(f, w, v, csr.indptr.astype(np.int64), csr.indices.astype(np.int64),
                inflow, outflow)  # fmt: skip
    ref_in, ref_out = pair_flows(f, w, v, ring)
    np.testing.assert_allclose(inflow, ref_in, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(outflow, ref_out, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 7, 40])
def test_target_sums_equal_all_pairs(n):
    """The sums of a target law (kernel 1, dynamics/targets.py) against the dense matrix."""
    rng = np.random.default_rng(n)
    w, v = rng.random(n), rng.random(n)
    w[: n // 3] = 0.0
    inflow, outflow = np.empty(n), np.empty(n)
    target_flows(w, v, inflow, outflow)
    ref_in, ref_out = pair_flows(np.zeros(n), w, v, np.ones((n, n)) - np.eye(n),
                                 kernel=Kernel.TARGET)  # fmt: skip
    np.testing.assert_allclose(inflow, ref_in, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(outflow, ref_out, rtol=1e-13, atol=1e-15)


def compare(problem, settings, minute, iterations, atol=1e-9, min_rows=11, stop_slack=0):
    """Compiled and reference set points (MW) agree within ``atol`` at every iteration, and
    both stop with the same status, within ``stop_slack`` iterations of each other."""
    engine = Engine(problem, settings)
    x0 = initial_shares(problem, settings.x0, minute)
    run = engine.run_minute(x0, minute, max_iterations=iterations)
    compiled = run.trajectory
    reference = ReferenceMinute(problem, settings, minute)
    x_ref = x0.copy()
    if get_bounded(settings):
        x_ref = compiled[0] / reference.demand  # both start from the projected shares
    ref, _, _, ref_status, ref_converged = reference.run(x_ref, max_iterations=iterations)
    rows = min(len(ref), len(compiled))
    assert rows >= min_rows
    np.testing.assert_allclose(compiled[:rows], ref[:rows], atol=atol, rtol=0)
    assert run.status == ref_status
    if run.converged_at is None or ref_converged is None:
        assert run.converged_at == ref_converged
    else:
        assert abs(run.converged_at - ref_converged) <= stop_slack, (run.converged_at,
                                                                     ref_converged)  # fmt: skip
    return compiled


def get_bounded(settings):
    return settings.mode == "exact"


@pytest.fixture(scope="module")
def congested():
    return elv_problem(limits=[CONGESTION_PATH])


@pytest.mark.parametrize(
    ("mode", "dynamics", "graph"),
    [
        ("paper", "smith", "complete"),
        ("paper", "replicator", "complete"),
        ("paper", "local-replicator", "ring"),
        ("paper", "distributed-smith", "star"),
        ("paper", "bnn", "complete"),
        ("paper", "logit", "complete"),
        ("exact", "smith", "complete"),
        ("exact", "distributed-smith", "ring"),
        ("exact", "logit", "complete"),
    ],
)
def test_compiled_trajectories_equal_the_numpy_reference(congested, mode, dynamics, graph):
    integrator = Integrator(substeps=20, max_iterations=120) if mode == "paper" else None
    eta = 0.5 if dynamics == "logit" else None  # EUR/MWh
    settings = RunSettings(dynamics=dynamics, mode=mode, graph=graph, integrator=integrator,
                           eta=eta)  # fmt: skip
    # the trajectories, not where they stop: the ring's exact run rests at iteration 1 on a
    # point that is not the DC-OPF (its neighbours are at their limits), which the fixed-point
    # stop ends at once (see test_fixed_point_stop_equal_in_the_reference)
    settings = replace(settings, integrator=replace(settings.stepping, fixed_point=False))
    # exact mode on this congestion (four series lines at one limit: degenerate line prices)
    # amplifies rounding differences about tenfold per 4 iterations (measured: 1e-18 MW at
    # iteration 10, 1e-9 at 38, 1e-7 at 45), so its comparison at 1e-9 MW stops at 35
    iterations = 120 if mode == "paper" else 35
    # the ring's relay (dynamics/pairwise.py relay_flows) sums its flows group by group, the
    # reference as a dense matrix: on this degenerate congestion the difference of summation
    # order grows about tenfold per iteration, to 1.9e-7 MW by iteration 35 (measured); exact
    # mode's curvature-scaled rates (up to 50 times Smith's) amplify the round-off of the
    # adaptive steps' error estimates too: 1.2e-9 MW by iteration 2 (measured)
    # exact logit (its revision rate is exact mode's gain) agrees to 1e-16 MW for six
    # iterations, then the same congestion amplifies round-off about tenfold per iteration, to
    # 1.7e-8 MW at iteration 15 where it comes to rest (measured)
    atol = {("exact", "ring"): 1e-6, ("exact", "complete"): 1e-8}.get((mode, graph), 1e-9)
    atol = 1e-7 if (mode, dynamics) == ("exact", "logit") else atol
    # where round-off grows tenfold an iteration the window rule may see the rest one
    # iteration apart (exact logit: 15 and 16, measured)
    slack = 1 if (mode, dynamics) == ("exact", "logit") else 0
    trajectory = compare(congested, settings, PEAK_MINUTE, iterations, atol=atol,
                         stop_slack=slack)  # fmt: skip
    assert np.ptp(trajectory, axis=0).max() > 1e-4  # things moved: the comparison is not vacuous


def test_fixed_point_stop_equal_in_the_reference():
    """Engine and reference end a run at the same iteration by the fixed-point stop: a run
    started where an exact run came to rest leaves its state unchanged within round-off
    and ends at once, converged; without the fixed-point stop the window rule runs on."""
    problem = elv_problem()
    settings = RunSettings(mode="exact")
    x0 = initial_shares(problem, "uniform", PEAK_MINUTE)
    rest = Engine(problem, settings).run_minute(x0, PEAK_MINUTE).x
    run = Engine(problem, settings).run_minute(rest.copy(), PEAK_MINUTE)
    assert run.status == Status.CONVERGED and run.iterations <= 3
    np.testing.assert_allclose(run.trajectory[-1], run.trajectory[0], rtol=0, atol=1e-12)
    reference = ReferenceMinute(problem, settings, PEAK_MINUTE)
    ref, _, _, status, converged_at = reference.run(run.trajectory[0] / reference.demand)
    assert (status, converged_at, len(ref)) == (run.status, run.converged_at, len(run.trajectory))
    np.testing.assert_allclose(ref, run.trajectory, rtol=0, atol=1e-12)
    without = replace(settings, integrator=replace(settings.stepping, fixed_point=False))
    assert Engine(problem, without).run_minute(rest.copy(), PEAK_MINUTE).iterations >= 15


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(("dynamics", "eta"), [("smith", None), ("logit", 0.3)])
def test_reference_agrees_on_random_limited_feeders(seed, dynamics, eta):
    problem = limited_random_problem(seed + 10, n_gens=12)
    # 12 generators and many prices: the adaptive steps see round-off of different summation
    # orders (prefix sums vs all pairs; the logit's box target by bisection vs Brent's
    # method); 1e-6 MW is 1 W. The fixed-point stop compares an iteration's movement with
    # round-off, which the two orders can reach at different iterations, and the window stop
    # dates convergence from the window's start (seed 2, logit: the engine at rest at
    # iteration 13, converged at 12; the reference's prices still moving by 2.4e-13 and
    # 2.9e-13 of their size at 13 and 14, over ROUND_OFF, so its window stops it at 15,
    # converged at 10). A pinned line's prices end seed 1's smith run in 3 iterations.
    settings = RunSettings(mode="exact", dynamics=dynamics, eta=eta)
    compare(problem, settings, 1, 200, atol=1e-6, min_rows=3, stop_slack=2)


def pinned_prices(seed: int, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """The line prices after ``iterations`` of exact mode on random fleet ``seed`` (5
    generators, 2 limits; tests/test_fleets.py), the engine's and the plain-numpy reference's
    from the engine's first state, after comparing their trajectories over those
    iterations."""
    problem = random_fleet_problem(seed, 5, 2)
    settings = RunSettings(mode="exact")
    compare(problem, settings, 1, iterations, atol=1e-6, min_rows=min(iterations + 1, 4),
            stop_slack=2)
    engine = Engine(problem, settings)
    run = engine.run_minute(initial_shares(problem, settings.x0, 1), 1,
                            max_iterations=iterations)  # fmt: skip
    reference = ReferenceMinute(problem, settings, 1)
    _, _, z_ref, _, _ = reference.run(run.trajectory[0] / reference.demand,
                                      max_iterations=iterations)  # fmt: skip
    return engine.z, z_ref


def test_a_pinned_lines_prices_equal_the_numpy_reference():
    """A line overflowed by 2.4 W with both generators below it at 0: its price climbs to
    21.8 EUR/MWh at the pinned lines' least speed within the first iteration (at its rate
    times the overflow: over 600), the same in both, through the engine's convergence (5
    iterations). A generator 2.35 W above its Pmin below the line at the optimum: with a
    switch at the limit instead of the gain's fade the reference's steps fell to 1e-8 s from
    the third iteration (1.2 million evaluations; docs/exact-mode.md, "Pinned lines")."""
    z, z_ref = pinned_prices(4195038496, 6)
    assert z[0] > 20.0
    np.testing.assert_allclose(z, z_ref, rtol=1e-6, atol=1e-6)


def test_a_pinned_lines_gain_fades_as_its_generator_leaves_its_limit():
    """The pinned line of fleet 4195038496 with every generator below it at its Pmin, then
    one of them moved 0.3 and 2 times ``PINNED_FADE`` of its range above it: the compiled
    rates equal the plain-numpy statement (``reference.pinned_rates``) at each, and the
    line's gain over its plain rate ``a`` is its full value ``a (min(PINNED_BOOST, v / |a|) -
    1)``, then 0.7 of it, then nothing."""
    from popdispatch.game.parameters import GameParameters, GameWork, MinuteInputs
    from popdispatch.modes.exact import PINNED_BOOST, PINNED_FADE, pinned_payoff
    from popdispatch.reference import pinned_rates

    problem = random_fleet_problem(4195038496, 5, 2)
    settings = RunSettings(mode="exact")
    speed = settings.engine_pinned_speed(problem)
    fp = settings.game_constants(problem)
    params = GameParameters.of(problem, fp, pinned_speed=speed)
    minute = MinuteInputs.of(problem, 1)
    low, high = minute.lo * minute.demand, minute.hi * minute.demand
    line = 0
    below = np.flatnonzero(problem.down[line] > 0)
    assert len(below) >= 1 and (high[below] > low[below]).all()
    n = len(problem.limit)
    work = GameWork.empty(n, n_generators=problem.n_generators)
    for fraction, weight in ((0.0, 1.0), (0.3, 0.7), (2.0, 0.0)):
        p = np.where(problem.down[line] > 0, low, 0.5 * (low + high))
        p[below[0]] += fraction * PINNED_FADE * (high - low)[below[0]]
        z = np.zeros(2 * n)
        fitness, z_rate = np.empty(len(p)), np.empty(2 * n)
        pinned_payoff(p, z, params, minute, work, fitness, z_rate)
        flow = problem.load_flow[0] - problem.down @ p
        excess = np.concatenate([flow - problem.limit, -flow - problem.limit])
        plain = fp.price_rate * excess
        expected = pinned_rates(problem, 1, p, z, excess, plain, fp.price_rate, speed)
        np.testing.assert_allclose(z_rate, expected, rtol=1e-12, atol=1e-12 * fp.price_rate)
        own = plain[line]
        assert 0.0 < abs(own) < speed  # slow: the full gain is not zero
        full = own * (min(PINNED_BOOST, speed / abs(own)) - 1.0)
        assert z_rate[line] - own == pytest.approx(weight * full, rel=1e-9, abs=1e-9 * speed)


def test_a_pinned_pairs_prices_equal_the_numpy_reference():
    """Two nested lines with the only generator between them at its Pmin: the generator below
    both answers the sum of their prices, so their difference moves at the pinned speed (at
    its rate times half the 0.46 W gap of the lines' excesses it took over 4000 iterations);
    the lower line's price reaches 0 and the upper one's 23.5 EUR/MWh, the same in both."""
    z, z_ref = pinned_prices(3376343775, 6)
    assert z[2] > 23.0 and z[3] < 1.0  # the lines' prices of the down direction
    np.testing.assert_allclose(z, z_ref, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("method", ["euler", "heun"])
def test_flux_limiter_keeps_every_step_inside_the_limits(congested, method):
    """Steps far longer than the dynamics' time scale (1 s, no error control) stay feasible:
    set points within their limits, total equal to the demand."""
    loose = Integrator(method=method, dt=1.0, substeps=1, rtol=1e6, atol=1e6, max_iterations=50)
    problem = congested
    # prices slow enough that 1 s steps do not carry them past their cap (infeasible) at once
    slow = ExactConstants(price_rate=0.01)
    engine = Engine(problem, RunSettings(mode="exact", integrator=loose, exact=slow))
    x0 = initial_shares(problem, "uniform", PEAK_MINUTE)
    trajectory = engine.run_minute(x0, PEAK_MINUTE).trajectory
    assert len(trajectory) > 5
    assert (trajectory >= problem.pmin - 1e-15).all()
    assert (trajectory <= problem.pmax + 1e-15).all()
    np.testing.assert_allclose(trajectory.sum(axis=1), problem.demand[PEAK_MINUTE - 1], rtol=1e-12)
    assert (trajectory == problem.pmax).any()  # the limiter put a generator exactly on Pmax
