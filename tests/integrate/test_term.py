"""The ODE term on its own: one evaluation of the field into a Stage equals the plain-numpy
reference's game, weights and pairwise flows."""

from __future__ import annotations

import numpy as np
import pytest

from popdispatch.game.parameters import GameWork, MinuteInputs
from popdispatch.integrate import Stage
from popdispatch.integrate.term import evaluate
from popdispatch.online import Engine, RunSettings
from popdispatch.reference import ReferenceMinute
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem


@pytest.fixture(scope="module")
def problem():
    return elv_problem(limits=[CONGESTION_PATH])


@pytest.mark.parametrize(
    ("mode", "dynamics", "graph"),
    [("paper", "smith", "complete"), ("exact", "distributed-smith", "ring"),
     ("paper", "local-replicator", "path")],
)  # fmt: skip
def test_one_evaluation_equals_the_reference(problem, mode, dynamics, graph):
    settings = RunSettings(mode=mode, dynamics=dynamics, graph=graph)
    engine = Engine(problem, settings)
    minute = MinuteInputs.of(problem, PEAK_MINUTE)
    rng = np.random.default_rng(3)
    x = rng.dirichlet(np.ones(problem.n_generators))
    z = rng.uniform(0.0, 20.0, len(engine.z))
    stage = Stage.empty(len(x), len(z))
    work = GameWork.empty(len(problem.limit), n_generators=problem.n_generators)
    evaluate(x, z, stage.p, stage.f, stage.w, stage.v, stage.room, stage.mass, stage.inflow,
             stage.outflow, stage.z_rate, stage.order, engine.term, engine.params, minute,
             work)  # fmt: skip
    reference = ReferenceMinute(problem, settings, PEAK_MINUTE)
    (f, w, v, room, mass, inflow, outflow, z_rate), _, _ = reference.evaluate(x, z)
    np.testing.assert_array_equal(stage.p, x * minute.demand)
    np.testing.assert_allclose(stage.f, f, rtol=1e-12)
    for got, expected in ((stage.w, w), (stage.v, v), (stage.room, room), (stage.mass, mass)):
        np.testing.assert_allclose(got, expected, rtol=1e-15, atol=0)
    np.testing.assert_allclose(stage.inflow, inflow, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(stage.outflow, outflow, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(stage.z_rate, z_rate, rtol=1e-12)
    assert list(np.argsort(stage.f, kind="stable")) == list(np.argsort(f, kind="stable")) or (
        not engine.term.complete
    )
