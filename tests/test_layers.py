"""The package's import graph: no cycles among its modules, no private name (a leading
underscore; dunder names such as ``__version__`` are public) imported from another package,
and the layers of pyproject.toml ([tool.importlinter]) kept (CI also runs ``lint-imports``).
Imports under ``TYPE_CHECKING`` are annotations, not dependencies, and are left out."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import grimp
import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def graph():
    return grimp.build_graph("popdispatch", exclude_type_checking_imports=True)


def _edges(graph):
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            yield module, imported


def test_no_import_cycle(graph):
    directed = nx.DiGraph(list(_edges(graph)))
    cycles = [cycle for cycle in nx.simple_cycles(directed) if len(cycle) > 1]
    assert cycles == []


def _package(module: str) -> str:
    return ".".join(module.split(".")[:2])


def test_no_private_name_from_another_package(graph):
    private = []
    for module, imported in _edges(graph):
        if _package(module) == _package(imported):
            continue
        for detail in graph.get_import_details(importer=module, imported=imported):
            name = detail["line_contents"].split(" import ")[-1]
            names = [part.strip() for part in name.strip("()").split(",")]
            if any(n.startswith("_") and not n.startswith("__") for n in names):
                private.append(f"{module}:{detail['line_number']} {detail['line_contents']}")
    assert private == []


def test_the_layers_hold():
    done = subprocess.run([sys.executable, "-m", "importlinter.cli", "--config",
                           str(ROOT / "pyproject.toml")], capture_output=True, text=True,
                          cwd=ROOT)  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:]
