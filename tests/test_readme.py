"""The README's Python examples run as printed and say what they claim.

Each ```python block of README.md runs in a fresh interpreter (as a reader would paste it);
the "your own feeder" example must print set points equal to the DC-OPF's (Clarabel) within
the engine's convergence tolerance.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from popdispatch.modes import get_mode

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.DOTALL)


def run_block(code: str, tmp_path: Path) -> str:
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=600
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def own_feeder_block() -> str:
    blocks = [b for b in BLOCKS if "Feeder(" in b]
    assert len(blocks) == 1, "the README shows one 'your own feeder' example"
    return blocks[0]


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_blocks_run(index: int, tmp_path: Path) -> None:
    run_block(BLOCKS[index], tmp_path)


def test_readme_flow_example_prints_what_its_comment_says(tmp_path: Path) -> None:
    block = next(b for b in BLOCKS if "line_flows" in b)
    claimed = re.search(r"#\s*(\d+ \d+ [\d.]+)\s*$", block, flags=re.MULTILINE)[1]
    assert run_block(block, tmp_path).split() == claimed.split()


def test_own_feeder_example_lands_on_the_dc_opf(tmp_path: Path) -> None:
    out = run_block(own_feeder_block(), tmp_path)
    assert out.splitlines()[0].startswith("converged")
    rows = [line.split() for line in out.splitlines() if re.match(r"^G\d+\s", line)]
    assert len(rows) == 3
    # The run stops when set points move less than tol_kw; the table is rounded to 0.001 kW.
    tol_kw = get_mode("exact").integrator.tol_kw
    for name, setpoint, opf in rows:
        assert abs(float(setpoint) - float(opf)) <= 0.001 + tol_kw, name
