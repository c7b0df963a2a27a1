"""The algorithm seam: the registry refuses, before any work, a mode or an agent option the
chosen algorithm cannot use, naming it in one line."""

from __future__ import annotations

import sys
import types

import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

from popdispatch.agents import algorithms  # noqa: E402
from popdispatch.agents.network import Faults  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents  # noqa: E402
from popdispatch.errors import OptionError  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402


@pytest.fixture
def lean(monkeypatch):
    """A registered algorithm that runs exact mode and reads only the world's options; its
    ``run`` records that it was reached."""
    module = types.ModuleType("lean_algorithm")
    module.NAME, module.MODES = "lean", ("exact",)
    module.OPTIONS = frozenset({"max_rounds", "window", "tol_kw", "drain_rounds"})
    module.reached = []
    module.refuse = lambda settings, opts, faults: None
    module.run = lambda *args: module.reached.append(args)
    monkeypatch.setitem(sys.modules, "lean_algorithm", module)
    monkeypatch.setitem(algorithms.ALGORITHMS, "lean", "lean_algorithm")
    return module


@pytest.mark.parametrize(
    ("settings", "opts", "named"),
    [(RunSettings(mode="paper"), AgentSettings(), "--mode"),
     (RunSettings(mode="exact"), AgentSettings(step_s=1e-3), "step_s"),
     (RunSettings(mode="exact"), AgentSettings(decision_copies=2), "decision_copies")],
)  # fmt: skip
def test_what_an_algorithm_cannot_use_is_refused_before_any_work(lean, settings, opts, named):
    with pytest.raises(OptionError) as error:
        run_agents(None, 1, settings, Faults(), opts, algorithm="lean")  # no problem needed
    assert error.value.option == named and "\n" not in str(error.value)
    assert lean.reached == []


def test_an_unknown_algorithm_is_named():
    with pytest.raises(OptionError, match="no agent algorithm 'nope'.*population"):
        algorithms.get_algorithm("nope")
