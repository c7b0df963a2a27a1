"""The distance certificate (popdispatch.online.certificate) against an exact DC-OPF found by
enumerating active sets (tests/qp_exact.py): whatever the end state and the prices, the bound
it proves is at least the true distance; at an exact optimum with its own prices it proves the
optimum to round-off."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from qp_exact import exact_dc_opf

from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem
from popdispatch.online.certificate import Batch, certify_minutes


def random_fleet_problem(seed: int, n_gens: int, n_limits: int, linear_share: float = 0.2):
    """A random radial feeder (12 buses) with ``n_gens`` generators whose curvatures are
    log-uniform over five decades (0.02-2000 EUR/MW^2h; linear one time in five), marginal
    costs 5-55 EUR/MWh, capacities 5-40 kW, Pmin > 0 one time in four, ``n_limits`` lines
    above generators limited between their least reachable and their unconstrained flow."""
    rng = np.random.default_rng(seed)
    n_buses = 12
    parents = [int(rng.integers(0, i)) for i in range(1, n_buses)]
    buses = pd.DataFrame({"x": rng.random(n_buses), "y": rng.random(n_buses)},
                         index=pd.Index(np.arange(1, n_buses + 1), name="bus"))  # fmt: skip
    lines = pd.DataFrame(
        {"from_bus": np.array(parents) + 1, "to_bus": np.arange(2, n_buses + 1),
         "length_km": 0.01, "r_ohm": 0.01, "x_ohm": 0.001, "limit_kw": np.inf},
        index=pd.Index([f"L{i}" for i in range(2, n_buses + 1)], name="line"),
    )  # fmt: skip
    load_buses = rng.choice(np.arange(2, n_buses + 1), size=5, replace=False)
    loads = pd.DataFrame({"bus": load_buses},
                         index=pd.Index([f"LD{b}" for b in load_buses], name="load"))  # fmt: skip
    gen_buses = [1, *rng.choice(np.arange(2, n_buses + 1), size=n_gens - 1, replace=False)]
    rows = []
    for k, bus in enumerate(gen_buses):
        c = 0.0 if rng.random() < linear_share else float(10 ** rng.uniform(np.log10(0.02), 3.3))
        pmax = 200.0 if k == 0 else float(rng.uniform(5, 40))
        pmin = float(rng.uniform(0, 0.5) * pmax) if k and rng.random() < 0.25 else 0.0
        rows.append((int(bus), 0.0, float(rng.uniform(5, 55)), c, pmin, pmax))
    feeder = Feeder("random", buses, lines, loads, 1, make_fleet(rows))
    demand = float(rng.uniform(0.3, 0.9)) * sum(r[5] for r in rows[1:]) + 10.0
    load = pd.Series(rng.dirichlet(np.ones(len(loads))) * demand, index=loads.index)
    if n_limits:
        chosen = rng.choice(np.arange(1, len(gen_buses)), size=min(n_limits, n_gens - 1),
                            replace=False)  # fmt: skip
        tree = feeder.bus_tree()
        limits = {}
        for k in chosen:
            node = feeder.buses.index.get_loc(gen_buses[k])
            line = feeder.lines.index[int(tree.parent_line[node])]
            limits[line] = float(rng.uniform(0.5, 20.0))
        feeder = feeder.with_line_limits(pd.Series(limits))
    profiles = single_minute_profiles(1, load, "random")
    return build_problem(reduce_feeder(feeder), profiles)


def _certify(problem, p, mu, accuracy=1e-6):
    return certify_minutes(problem, np.array([1]), p[None], mu[None], np.array([accuracy]))[0]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(2, 5), st.integers(0, 2),
       st.floats(1e-9, 0.5), st.floats(0.0, 1.0))  # fmt: skip
def test_the_bound_is_never_below_the_true_distance(seed, n_gens, n_limits, scale, price_scale):
    problem = random_fleet_problem(seed, n_gens, n_limits)
    optimum = exact_dc_opf(problem)
    assume(optimum is not None)
    rng = np.random.default_rng(seed + 1)
    batch = Batch.of(problem, np.array([1]))
    lo, hi = batch.lo[0], batch.hi[0]
    # an end state: the optimum with mass moved between random pairs (balance kept)
    p = optimum.copy()
    for _ in range(3):
        i, j = rng.choice(len(p), 2, replace=False)
        move = min(scale * float(rng.random()) * max(hi.max(), 1e-3), p[j] - lo[j], hi[i] - p[i])
        p[i] += move
        p[j] -= move
    mu = rng.exponential(1.0, batch.A.shape[0]) * price_scale * 50.0
    mu[rng.random(len(mu)) < 0.5] = 0.0
    certificate = _certify(problem, p, mu)
    distance = np.abs(p - optimum)
    assert (certificate.bound_mw >= distance - 1e-9 * max(1.0, hi.max())).all(), (
        certificate, p, optimum)  # fmt: skip


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.integers(2, 5), st.integers(0, 2))
def test_the_exact_optimum_proves_itself_to_round_off(seed, n_gens, n_limits):
    """At the optimum, with the controllers' prices near the optimal line duals (here: none,
    the polish finds them), every generator is proved within 1e-9 of the demand."""
    problem = random_fleet_problem(seed, n_gens, n_limits)
    optimum = exact_dc_opf(problem)
    assume(optimum is not None)
    batch = Batch.of(problem, np.array([1]))
    excess = batch.e0[0] + batch.A @ optimum
    mu = np.where(excess > -1e-9, 1.0, 0.0)  # a price on each line at its limit
    demand = float(problem.demand[0])
    certificate = _certify(problem, optimum, mu, accuracy=1e-12 * demand)
    assert certificate.reason is None
    assert certificate.distance_mw <= 1e-7 * demand


def test_an_end_state_beyond_a_limit_without_a_kkt_point_near_it_proves_nothing():
    problem = random_fleet_problem(3, 4, 1)
    optimum = exact_dc_opf(problem)
    assert optimum is not None
    batch = Batch.of(problem, np.array([1]))
    line = int(np.argmax(np.abs(problem.down).sum(axis=1)))
    below = np.flatnonzero(problem.down[line])
    p = optimum.copy()
    p[below] = batch.lo[0][below]  # the generators below the limited line at their minimum
    p[0] += optimum[below].sum() - p[below].sum()  # the source makes up for them
    excess = batch.e0[0] + batch.A @ p
    if excess.max() <= 1e-6:
        return  # that line was not binding: nothing beyond a limit to show
    certificate = _certify(problem, p, np.zeros(batch.A.shape[0]), accuracy=1e-9)
    assert certificate.distance_mw >= np.abs(p - optimum).max() - 1e-12
