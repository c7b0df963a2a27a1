"""Fast dual decomposition as agents: :mod:`popdispatch.agents.dual_decomposition`'s agents
with Nesterov's momentum and the joint gradient restart (``DualParams.accelerated``, the
comparison's ``fast-dual-decomposition`` and its default steps)."""

from __future__ import annotations

from popdispatch.agents.dual_decomposition import MODES, OPTIONS, RUN_OPTIONS, make_run
from popdispatch.agents.dual_decomposition import refuse as _refuse

#: The name the registry (:mod:`popdispatch.agents.algorithms`) knows this algorithm by.
NAME = "fast-dual-decomposition"
__all__ = ["MODES", "NAME", "OPTIONS", "RUN_OPTIONS", "refuse", "run"]


def refuse(settings, opts, faults) -> None:
    """As dual decomposition's (:func:`popdispatch.agents.dual_decomposition.refuse`)."""
    _refuse(settings, opts, faults, NAME)


run = make_run(NAME)
