"""Save the current code's outputs as a refactor guard (tests/test_reference_outputs.py).

Usage: python scripts/save_reference_outputs.py [PROFILE_FOLDER] [--out DIR]

Writes compressed ``.npz`` files and ``metadata.json`` under ``tests/data/reference/``:

- ``congestion_<mode>_<dynamics>.npz``: minute 566 with the 505-666 path limited to 28 kW
  (:data:`popdispatch.scenarios.CONGESTION_PATH`, official loads of pandapower's snapshot, no
  profile folder needed), complete graph: the full trajectory (kW, iterations x generators),
  converged and first-congestion iterations and the status; paper and exact mode x smith and
  distributed-smith, and replicator in paper mode.
- ``elv_day_<mode>.npz``: the online ELV day with the official profiles (PROFILE_FOLDER, else
  ``$POPDISPATCH_PROFILES``, else ``../shared/ieee-elv``): per-minute set points (kW),
  iterations and converged / stalled / infeasible flags. Only our outputs are stored, never
  the profiles. Skipped (and left as they are) when the official data is absent.
- ``synthetic_day_<mode>.npz``: the same for a small seeded synthetic feeder
  (:func:`popdispatch.feeder.synthetic.synthetic_feeder`), a guard that needs no data.

Regenerate only when a numerical change is intended, and say why in the commit message.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np

from popdispatch.feeder.synthetic import synthetic_feeder, synthetic_profiles
from popdispatch.online import RunSettings, run_day, run_snapshot
from popdispatch.scenarios import CONGESTION_PATH, PEAK_MINUTE, elv_problem

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "tests" / "data" / "reference"

#: (mode, dynamics) of the congestion snapshots.
CONGESTION_RUNS = (
    ("paper", "smith"),
    ("paper", "distributed-smith"),
    ("paper", "replicator"),
    ("exact", "smith"),
    ("exact", "distributed-smith"),
)
MODES = ("paper", "exact")

#: The synthetic feeder of the data-free guard: buses, generators, seeds, limited lines.
SYNTHETIC = {"n_buses": 300, "n_generators": 5, "seed": 3, "limited_lines": 0.3}
SYNTHETIC_PROFILE_SEED = 5


def _status_code(value: int | None) -> int:
    return -1 if value is None else int(value)


def congestion_outputs(mode: str, dynamics: str) -> dict[str, np.ndarray]:
    """The congestion snapshot's trajectory and counters."""
    problem = elv_problem(limits=[CONGESTION_PATH])
    run = run_snapshot(problem, PEAK_MINUTE, RunSettings(dynamics=dynamics, mode=mode))
    return {
        "trajectory_kw": np.asarray(run.trajectory_kw, dtype=np.float64),
        "iterations": np.int64(run.iterations),
        "converged_at": np.int64(_status_code(run.converged_at)),
        "first_congestion": np.int64(_status_code(run.first_congestion)),
        "status": np.str_(run.status),
    }


def day_outputs(problem, mode: str) -> dict[str, np.ndarray]:
    """An online day's per-minute set points, iterations and flags."""
    run = run_day(problem, RunSettings(mode=mode))
    none = np.zeros(len(run.minutes), dtype=bool)
    return {
        "minutes": np.asarray(run.minutes, dtype=np.int64),
        "setpoints_kw": np.asarray(run.setpoints_kw, dtype=np.float64),
        "iterations": np.asarray(run.iterations, dtype=np.int64),
        "converged": np.asarray(run.converged, dtype=bool),
        "stalled": np.asarray(run.stalled if run.stalled is not None else none, dtype=bool),
        "infeasible": np.asarray(
            run.infeasible if run.infeasible is not None else none, dtype=bool
        ),
        "status": np.str_(run.status),
    }


def synthetic_problem():
    feeder = synthetic_feeder(**SYNTHETIC)
    return elv_problem(synthetic_profiles(feeder, seed=SYNTHETIC_PROFILE_SEED), feeder=feeder)


def official_problem(folder: Path):
    from popdispatch.readers import read_profiles

    return elv_problem(read_profiles(folder))


def find_official(folder: str | None) -> Path | None:
    """``folder``, else ``$POPDISPATCH_PROFILES``, else ``../shared/ieee-elv`` (if complete)."""
    env = os.environ.get("POPDISPATCH_PROFILES", "").strip()
    for candidate in (folder, env, ROOT.parent / "shared" / "ieee-elv"):
        if candidate and all((Path(candidate) / f).is_file() for f in ("Loads.txt", "Lines.txt")):
            return Path(candidate)
    return None


def all_outputs(official: Path | None):
    """``(file stem, arrays)`` of every reference case (official ones only with ``official``)."""
    for mode, dynamics in CONGESTION_RUNS:
        yield f"congestion_{mode}_{dynamics}", congestion_outputs(mode, dynamics)
    problem = synthetic_problem()
    for mode in MODES:
        yield f"synthetic_day_{mode}", day_outputs(problem, mode)
    if official is not None:
        problem = official_problem(official)
        for mode in MODES:
            yield f"elv_day_{mode}", day_outputs(problem, mode)


def _git_commit() -> str:
    """HEAD of this checkout, flagged when ``src`` differs from it or is not what runs."""
    import popdispatch

    package = Path(popdispatch.__file__).resolve().parent
    if package != ROOT / "src" / "popdispatch":
        return f"unknown (popdispatch imported from {package}; pass --commit)"
    try:
        out = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True
        )
        dirty = subprocess.run(
            ["git", "-C", str(ROOT), "status", "--porcelain", "--", "src"],
            capture_output=True, text=True,
        )  # fmt: skip
    except OSError:
        return "unknown"
    return out.stdout.strip() + (" (src modified)" if dirty.stdout.strip() else "")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("profiles", nargs="?", help="official IEEE ELV folder")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder")
    parser.add_argument(
        "--commit",
        help="commit the imported code is (when run on an exported tree, e.g. "
        "git archive HEAD src | tar -x -C DIR; PYTHONPATH=DIR/src python ...)",
    )
    args = parser.parse_args(argv)
    official = find_official(args.profiles)
    if official is None:
        print("official data not found: the ELV day references are left as they are")
    args.out.mkdir(parents=True, exist_ok=True)
    files = []
    for stem, arrays in all_outputs(official):
        np.savez_compressed(args.out / f"{stem}.npz", **arrays)
        files.append(f"{stem}.npz")
        print(f"wrote {stem}.npz")
    metadata = {
        "git_commit": args.commit or _git_commit(),
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "command": " ".join(["python", *sys.argv]) if argv is None else " ".join(argv),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "source": str(Path(sys.modules["popdispatch"].__file__).resolve().parent),
        "machine": platform.machine(),
        "cpu": host_cpu(),
        "official_data": official is not None,
        "files": files,
        "synthetic": {**SYNTHETIC, "profile_seed": SYNTHETIC_PROFILE_SEED},
    }
    (args.out / "metadata.json").write_text(json.dumps(metadata, indent=2) + "\n")


def host_cpu() -> str:
    """The CPU numba compiles the kernels for (LLVM's name of the host, ``znver4``): the same
    code can round differently on another, whose instructions (fused multiply-adds, vector
    widths) LLVM picks."""
    import llvmlite.binding

    return llvmlite.binding.get_host_cpu_name()


if __name__ == "__main__":
    main()
