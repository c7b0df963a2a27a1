"""Distributed dispatch: every DG and node controller an agent exchanging messages (mango).

The same rules as the mean-dynamics engine, run from local information and messages only
(docs/agents.md): generator agents (:mod:`~popdispatch.agents.generator`), node-controller
agents (:mod:`~popdispatch.agents.controller`) and the plant
(:mod:`~popdispatch.agents.plant`), in rounds (:mod:`~popdispatch.agents.schedule`), over
mango's simulated world with seeded loss, delay and duplication
(:mod:`~popdispatch.agents.network`); :func:`run_agents` runs one minute
(:mod:`~popdispatch.agents.system`) of an algorithm (:mod:`~popdispatch.agents.algorithms`:
:mod:`~popdispatch.agents.population`, :mod:`~popdispatch.agents.dual_decomposition`) in the
generic world
(:mod:`~popdispatch.agents.world`). Needs the ``agents`` extra (mango-agents):
``pip install "popdispatch[agents]"``.
"""

from __future__ import annotations

#: ``pip`` command that installs the agents' runtime.
AGENTS_EXTRA = 'pip install "popdispatch[agents]"'


def require_mango() -> None:
    """Raise a one-line :class:`ImportError` naming the extra if mango-agents is missing."""
    try:
        import mango  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(f"the agents need mango-agents: {AGENTS_EXTRA} ({exc})") from exc


def __getattr__(name: str):
    """Lazy access to the run API, so importing this package does not import mango."""
    if name in ("AgentRun", "AgentSettings", "run_agents"):
        require_mango()
        from popdispatch.agents import system

        return getattr(system, name)
    if name == "build_agents":
        require_mango()
        from popdispatch.agents import population

        return population.build_agents
    if name == "Faults":
        require_mango()
        from popdispatch.agents.network import Faults

        return Faults
    raise AttributeError(f"module 'popdispatch.agents' has no attribute {name!r}")


__all__ = ["AGENTS_EXTRA", "AgentRun", "AgentSettings", "Faults", "build_agents",
           "require_mango", "run_agents"]  # fmt: skip
