"""Radial feeders: the model, built-in cases, synthetic feeders, key-node reduction, DC flows."""

from popdispatch.feeder.cases import elv_snapshot_566_kw, ieee_elv, list_cases, load_case
from popdispatch.feeder.generators import make_fleet, paper_fleet, read_fleet
from popdispatch.feeder.model import Feeder
from popdispatch.feeder.reduction import ReducedFeeder, reduce_feeder
from popdispatch.feeder.synthetic import synthetic_feeder, synthetic_load_kw, synthetic_profiles
from popdispatch.feeder.tree import (
    Tree,
    build_tree,
    depths,
    downstream,
    line_flows,
    path_sums,
    subtree_sums,
)

__all__ = [
    "Feeder",
    "ReducedFeeder",
    "Tree",
    "build_tree",
    "depths",
    "downstream",
    "elv_snapshot_566_kw",
    "ieee_elv",
    "line_flows",
    "list_cases",
    "load_case",
    "make_fleet",
    "paper_fleet",
    "path_sums",
    "read_fleet",
    "reduce_feeder",
    "subtree_sums",
    "synthetic_feeder",
    "synthetic_load_kw",
    "synthetic_profiles",
]
