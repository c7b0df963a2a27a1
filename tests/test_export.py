"""MATPOWER and pandapower exports reproduce our DC-OPF when solved by other means (issue 4)."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from scipy.optimize import minimize

from popdispatch.export import matpower_text, pandapower_net, write_case
from popdispatch.opf import solve_opf
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem, peak_profiles


def loads_566(problem) -> np.ndarray:
    return peak_profiles().for_loads(problem.feeder.original.loads.index).at(566).to_numpy()


@pytest.fixture(scope="module", params=[(), (CONGESTION_PATH,)], ids=["free", "congested"])
def problem(request):
    return elv_problem(None, list(request.param))


def parse_matrix(text: str, name: str) -> np.ndarray:
    body = re.search(rf"mpc\.{name} = \[\n(.*?)\n\];", text, re.S).group(1)
    return np.array([[float(v) for v in row.strip(" \t;").split("\t")] for row in body.split("\n")])


def dc_opf_from_matpower(text: str) -> np.ndarray:
    """Solve the DC-OPF of a parsed MATPOWER case independently (SLSQP on flows of the tree)."""
    bus, gen = parse_matrix(text, "bus"), parse_matrix(text, "gen")
    branch, cost = parse_matrix(text, "branch"), parse_matrix(text, "gencost")
    index = {int(b): k for k, b in enumerate(bus[:, 0])}
    root = int(bus[bus[:, 1] == 3, 0][0])
    children: dict[int, list[int]] = {}
    for f, t in branch[:, :2].astype(int):
        children.setdefault(f, []).append(t)
    below = {}  # bus -> buses in its subtree (branches are listed parent -> child)

    def subtree(b: int) -> list[int]:
        if b not in below:
            below[b] = [b] + [x for c in children.get(b, []) for x in subtree(c)]
        return below[b]

    subtree(root)
    limited = branch[branch[:, 5] > 0]
    gen_bus = gen[:, 0].astype(int)

    def flow(p, t):  # MW from parent to child: subtree load minus subtree generation
        sub = set(subtree(int(t)))
        return sum(bus[index[b], 2] for b in sub) - p[np.isin(gen_bus, list(sub))].sum()

    constraints = [{"type": "eq", "fun": lambda p: p.sum() - bus[:, 2].sum()}]
    for row in limited:
        constraints.append({"type": "ineq", "fun": lambda p, r=row: r[5] - abs(flow(p, r[1]))})
    objective = lambda p: float(np.sum(cost[:, 4] * p**2 + cost[:, 5] * p + cost[:, 6]))  # noqa: E731
    bounds = list(zip(gen[:, 9], gen[:, 8], strict=True))
    x0 = gen[:, 8] * bus[:, 2].sum() / gen[:, 8].sum()
    result = minimize(objective, x0, bounds=bounds, constraints=constraints, method="SLSQP",
                      options={"ftol": 1e-14, "maxiter": 500})  # fmt: skip
    assert result.success, result.message
    return result.x * 1000.0


def test_matpower_case_solves_to_our_dc_opf(problem):
    text = matpower_text(problem, PEAK_MINUTE, loads_566(problem), "case566")
    bus = parse_matrix(text, "bus")
    assert bus.shape == (110, 13)
    assert bus[:, 2].sum() * 1000 == pytest.approx(57.358, abs=1e-6)  # loads in MW
    assert parse_matrix(text, "branch").shape == (109, 13)
    ours = solve_opf(problem, PEAK_MINUTE)
    np.testing.assert_allclose(dc_opf_from_matpower(text), ours.p_kw, atol=2e-3)


def test_pandapower_net_solves_to_our_dc_opf(problem):
    import pandapower as pp

    net = pandapower_net(problem, PEAK_MINUTE, loads_566(problem))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pp.rundcopp(net)
    assert net.OPF_converged
    ours = solve_opf(problem, PEAK_MINUTE)
    np.testing.assert_allclose(net.res_gen.p_mw.to_numpy() * 1000, ours.p_kw, atol=1e-4)
    assert net.res_cost == pytest.approx(ours.cost, rel=1e-6)
    assert len(net.bus) == 110 and len(net.line) == 109 and len(net.load) == 55


def test_offline_generator_is_exported_out_of_service(tmp_path):
    problem = elv_problem().with_outage("G578", 500, 600)
    text = matpower_text(problem, 566, loads_566(problem), "c")
    gen = parse_matrix(text, "gen")
    assert gen[gen[:, 0] == 578, 7].tolist() == [0.0]
    net = pandapower_net(problem, 566, loads_566(problem))
    assert not net.gen.set_index("name").in_service["G578"]


def test_write_case_is_atomic_on_error(tmp_path):
    problem = elv_problem()
    with pytest.raises(ValueError, match="unknown export format 'csv'"):
        write_case(tmp_path / "x.csv", "csv", problem, 566, loads_566(problem))
    target = tmp_path / "1 case.m"
    write_case(target, "matpower", problem, 566, loads_566(problem))
    assert target.read_text().startswith("function mpc = case_1_case")
    assert [p.name for p in tmp_path.iterdir()] == ["1 case.m"]
