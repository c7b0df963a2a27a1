"""Radial feeders: the model, synthetic feeders, key-node reduction, DC flows (the built-in
cases and the networks a run reads: :mod:`popdispatch.cases`).

The submodules are imported when a name is first used (PEP 562), so that importing one of
them (``popdispatch.feeder.profiles``, say) does not import the synthetic feeders and the reduction
with it.
"""

from popdispatch.lazy import lazy_namespace

#: Where each public name lives (module under ``popdispatch.feeder``).
_HOMES = {
    "make_fleet": "generators",
    "paper_fleet": "generators",
    "read_fleet": "generators",
    "Feeder": "model",
    "ReducedFeeder": "reduction",
    "reduce_feeder": "reduction",
    "synthetic_feeder": "synthetic",
    "synthetic_load_kw": "synthetic",
    "synthetic_profiles": "synthetic",
    "Tree": "tree",
    "build_tree": "tree",
    "depths": "tree",
    "downstream": "tree",
    "line_flows": "tree",
    "path_sums": "tree",
    "subtree_sums": "tree",
}

__getattr__, __dir__, __all__ = lazy_namespace(__name__, _HOMES)
