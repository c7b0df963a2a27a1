"""docs/dynamics.md's results tables are what ``scripts/dynamics_experiments.py`` produces:
every cell to the digits the page shows (one unit of its last digit, and 1e-9 for the
round-off-sized numbers), statuses and counts exactly. The base day needs the official
profiles (skipped without them)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from helpers import MISSING_OFFICIAL, find_official_folder

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "dynamics.md"
ETAS = [0.01, 0.1, 1.0]


def _script():
    path = ROOT / "scripts" / "dynamics_experiments.py"
    spec = importlib.util.spec_from_file_location("dynamics_experiments", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


script = _script()


def documented(first_heading: str) -> list[list[str]]:
    """The body rows of the page's table whose header starts ``| run | first_heading |``."""
    lines = PAGE.read_text().splitlines()
    start = next(i for i, line in enumerate(lines)
                 if line.startswith(f"| run | {first_heading} |"))  # fmt: skip
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip("|").split("|")])
    return rows


def assert_cell(shown: str, value, where: str) -> None:
    if shown == "-":
        assert value is None, where
        return
    if isinstance(value, str):
        assert shown == value, where
        return
    match = re.fullmatch(r"-?\d+(?:\.(\d+))?(?:e([+-]\d+))?", shown)
    assert match, (shown, where)
    digits = len(match[1] or "")
    exponent = int(match[2] or 0)
    unit = 10.0 ** (exponent - digits)
    if digits == 0 and not match[2] and isinstance(value, int):
        assert int(shown) == value, where
        return
    assert abs(float(shown) - value) <= max(unit, 1e-9), (shown, value, where)


def compare(rows: list[dict], columns, heading: str) -> None:
    table = documented(heading)
    assert [row[0] for row in table] == [r["run"] for r in rows]
    for row, result in zip(table, rows, strict=True):
        for shown, (key, _, _) in zip(row, columns, strict=True):
            assert_cell(shown, result[key], f"{result['run']}: {key}")


def test_the_extinction_table_reproduces():
    compare(script.extinction_rows(ETAS), script.EXTINCTION_COLUMNS, "status")


@pytest.mark.slow
def test_the_base_day_table_reproduces():
    folder = find_official_folder()
    if folder is None:
        pytest.skip(MISSING_OFFICIAL)
    compare(script.day_rows(ETAS, folder), script.DAY_COLUMNS, "converged")
