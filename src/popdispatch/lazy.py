"""Namespaces whose submodules are imported when a name is first used (PEP 562)."""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module


def lazy_namespace(package: str, homes: dict[str, str]) -> tuple[Callable, Callable, list[str]]:
    """``(__getattr__, __dir__, __all__)`` for ``package``: each public name of ``homes``
    (name -> submodule under ``package``) is imported from its submodule on first use and kept
    in the package's namespace, so importing the package imports none of them."""

    def __getattr__(name: str):
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module = import_module(package)
        value = getattr(import_module(f"{package}.{home}"), name)
        setattr(module, name, value)
        return value

    names = sorted(homes)

    def __dir__() -> list[str]:
        return sorted({*vars(import_module(package)), *names})

    return __getattr__, __dir__, names
