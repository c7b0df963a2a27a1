"""popdispatch: online network-constrained dispatch of distributed generators with population
dynamics."""

__version__ = "0.1.0"
