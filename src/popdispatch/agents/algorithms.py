"""The registry of agent algorithms: a name, the module that implements it.

An algorithm module provides ``NAME``; ``MODES``, the modes (``--mode``) it runs; ``OPTIONS``,
the :class:`~popdispatch.agents.system.AgentSettings` fields it reads; optionally
``RUN_OPTIONS``, the names of ``popdispatch agents``' run options (``--dynamics``, ``--x0``,
...) it reads (absent: all; the command refuses any other given); ``refuse(settings, opts,
faults)``, which raises :class:`~popdispatch.errors.OptionError` for what else it cannot
honour; and ``run(problem, minute, settings, faults, opts, on_round) -> AgentRun``, which
builds its agents and runs them in the generic world (:func:`popdispatch.agents.world.
run_world`). Adding an algorithm is one new module and one line here (docs/architecture.md).
"""

from __future__ import annotations

import importlib
from dataclasses import fields
from types import ModuleType

from popdispatch.errors import OptionError

#: Algorithm name -> the module implementing it.
ALGORITHMS: dict[str, str] = {
    "population": "popdispatch.agents.population",
    "dual-decomposition": "popdispatch.agents.dual_decomposition",
    "fast-dual-decomposition": "popdispatch.agents.fast_dual_decomposition",
    "consensus-admm": "popdispatch.agents.consensus_admm",
}
#: The algorithm :func:`popdispatch.agents.system.run_agents` runs by default.
DEFAULT_ALGORITHM = "population"


def get_algorithm(name: str) -> ModuleType:
    """The module of algorithm ``name`` (one-line error naming the known ones)."""
    if name not in ALGORITHMS:
        raise OptionError(f"no agent algorithm {name!r} (known: {', '.join(ALGORITHMS)})",
                          "--algorithm")  # fmt: skip
    return importlib.import_module(ALGORITHMS[name])


def refuse_options(algorithm: ModuleType, settings, opts, faults) -> None:
    """Refuse, before any work, a mode the algorithm does not run and any agent option it
    does not read that differs from its default (one line naming the option), then whatever
    the algorithm itself refuses (its ``refuse``)."""
    refuse_mode(algorithm, settings.mode)
    defaults = type(opts)()
    for option in fields(opts):
        given = getattr(opts, option.name)
        if option.name not in algorithm.OPTIONS and given != getattr(defaults, option.name):
            raise OptionError(f"the {algorithm.NAME} agents do not use {option.name} "
                              f"(given {given!r})", option.name)  # fmt: skip
    algorithm.refuse(settings, opts, faults)


def refuse_mode(algorithm: ModuleType, mode: str) -> None:
    """One-line error if the algorithm does not run ``mode`` (``--mode``)."""
    if mode not in algorithm.MODES:
        raise OptionError(f"the {algorithm.NAME} agents run {' and '.join(algorithm.MODES)} "
                          f"mode, not {mode}", "--mode")  # fmt: skip
