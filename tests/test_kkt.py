"""Issue 10: a run claims ``converged`` only at a KKT point of the DC-OPF (item 9), and run
settings are validated before any data is loaded (item 7, library half)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from popdispatch.errors import OptionError
from popdispatch.integrate import Integrator
from popdispatch.online import KktTolerances, RunSettings, kkt_violations, run_day
from popdispatch.opf import solve_opf
from popdispatch.scenarios import elv_problem

TOL = KktTolerances.of(RunSettings(mode="exact").stepping, RunSettings().fitness.gain)
C = RunSettings().fitness.C


@pytest.fixture(scope="module")
def congested():
    return elv_problem(limits=[(505, 666, 28.0)])


def opf_point(problem, minute=566):
    """Clarabel's solution (MW) and its line duals as controller states (up, down; EUR/MW)."""
    opf = solve_opf(problem, minute)
    z = np.concatenate([np.maximum(opf.line_price, 0.0), np.maximum(-opf.line_price, 0.0)])
    return opf.p_kw / 1000.0, z


@pytest.mark.parametrize("limit_kw", [None, 28.0, 30.0])
def test_kkt_check_accepts_the_dc_opf_solution_and_duals(limit_kw):
    problem = elv_problem(limits=[] if limit_kw is None else [(505, 666, limit_kw)])
    p, z = opf_point(problem)
    assert kkt_violations(problem, [566], p, z, TOL, C) == [None]


def test_kkt_check_rejects_a_perturbed_optimum(congested):
    p, z = opf_point(congested)
    g1, g739 = (list(congested.generators).index(g) for g in ("G1", "G739"))
    moved = p.copy()
    moved[g1] += 1e-4  # 0.1 kW from G739 to G1 (both interior): the line is then slack
    moved[g739] -= 1e-4
    [reason] = kkt_violations(congested, [566], moved, z, TOL, C)
    assert reason is not None and "below its limit" in reason  # price on a slack line
    [reason] = kkt_violations(congested, [566], moved, np.zeros_like(z), TOL, C)
    assert reason is not None and "not a KKT point" in reason  # G739 would take more
    [reason] = kkt_violations(congested, [566], p, 2.0 * z, TOL, C)  # wrong line price
    assert reason is not None and "not a KKT point" in reason
    over = p.copy()
    over[g1] -= 1e-4
    over[g739] += 1e-4
    [reason] = kkt_violations(congested, [566], over, z, TOL, C)
    assert reason is not None and "over its limit" in reason


def test_kkt_price_tolerance_is_the_integrators():
    loose = Integrator(method="heun", tol_kw=1e-3, price_atol=1e-2, window=4, dt=0.01)
    tol = KktTolerances.of(loose, 100.0)
    assert tol.power_mw == pytest.approx(1e-6)
    assert tol.flow_gap == pytest.approx(1e-6 / (100.0 * 4 * 0.01))
    assert tol.price == pytest.approx(2e-2)
    # relative to the minute's demand (floor tol_kw) and prices in units of the price scale
    relative = Integrator(method="heun", tol_kw=1e-3, tol_rel=1e-6, price_atol=1e-2, window=4)
    tol = KktTolerances.of(relative, 100.0, demand_mw=8.0, price_scale=4.0)
    assert tol.power_mw == pytest.approx(8e-6)
    assert tol.flow_gap == pytest.approx(8e-6 / (100.0 * 4 * 0.01))
    assert tol.price == pytest.approx(8e-2)


def test_a_day_on_a_ring_lands_on_the_dc_opf_minute_by_minute(congested):
    """Distributed Smith on a ring rested 0.78 kW from the DC-OPF at minute 566 (generators at
    a limit cut the ring) until the relay (docs/agents.md); now every minute is converged,
    KKT-checked and within the run's tolerance of Clarabel's optimum."""
    settings = RunSettings(mode="exact", dynamics="distributed-smith", graph="ring")
    minutes = np.array([565, 566, 567])
    day = run_day(congested, settings, minutes=minutes)
    assert day.status == "converged" and day.converged.all() and not day.stalled.any()
    for row, minute in enumerate(minutes):
        tol_kw = settings.stepping.tol_mw(float(congested.demand[minute - 1])) * 1e3
        opf = solve_opf(congested, int(minute))
        assert np.abs(day.setpoints_kw[row] - opf.p_kw).max() <= 1e-3 + tol_kw


def test_a_rest_point_without_a_proof_is_stalled_not_converged(congested, monkeypatch):
    """The day's bookkeeping of the distance certificate (the certificate itself:
    tests/test_certificate.py): a minute at rest whose end state the certificate does not
    prove within the accuracy is ``stalled`` with its reason, never converged."""
    import popdispatch.online.engine as engine_module

    real = engine_module.certify_minutes

    def unproved_566(problem, minutes, *args, **kwargs):
        found = real(problem, minutes, *args, **kwargs)
        return [replace(c, bound_mw=np.full_like(c.bound_mw, np.inf), reason="no proof here")
                if m == 566 else c for m, c in zip(minutes, found, strict=True)]  # fmt: skip

    monkeypatch.setattr(engine_module, "certify_minutes", unproved_566)
    day = run_day(congested, RunSettings(mode="exact"), minutes=np.array([565, 566, 567]))
    assert day.status == "stalled"
    assert day.stalled.tolist() == [False, True, False]
    assert day.converged.tolist() == [True, False, True]
    assert list(day.stall_reasons) == [566] and "no proof here" in day.stall_reasons[566]
    assert day.distance_bound_kw[1] == np.inf and (day.distance_bound_kw[[0, 2]] <= 1e-3).all()


def test_paper_mode_claims_only_a_rest_point(congested):
    """Paper mode's congestion rest point leaves an overflow (docs/paper-mode.md): it is
    'converged' as a rest of the paper's dynamics, and never checked against the DC-OPF."""
    day = run_day(congested, RunSettings(), minutes=np.array([566]))
    assert day.status == "converged" and day.overflow_kw.max() > 0.1
    assert not day.stalled.any()


# -- run settings (item 7) ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("settings", "option", "named"),
    [
        ({"mode": "exact", "dynamics": "replicator"}, "--mode", "replicator"),
        ({"mode": "exact", "dynamics": "local-replicator"}, "--mode", "local-replicator"),
        ({"graph": "ring"}, "--graph", "ring"),
        ({"dynamics": "replicator", "graph": "path"}, "--graph", "replicator"),
        ({"dynamics": "distributed-smith", "graph": "torus"}, "--graph", "torus"),
        ({"warm_start": "sideways"}, "--warm-start", "sideways"),
        ({"warm_start": "setpoints"}, "--warm-start", "paper"),
        ({"mode": "fast"}, "--mode", "fast"),
        ({"dynamics": "best-response"}, "--dynamics", "best-response"),
        ({"x0": "random"}, "--x0", "random"),
    ],
)
def test_run_settings_reject_bad_options_with_one_line(settings, option, named):
    with pytest.raises(OptionError) as error:
        RunSettings(**settings)
    assert error.value.option == option
    message = str(error.value)
    assert named in message and "\n" not in message


@pytest.mark.parametrize(
    "settings",
    [
        {},
        {"mode": "exact", "warm_start": "setpoints"},
        {"mode": "exact", "warm_start": "shares"},
        {"dynamics": "distributed-smith", "graph": "ring"},
        {"dynamics": "local-replicator", "graph": "star"},
        {"mode": "exact", "dynamics": "distributed-smith", "graph": "path"},
        {"x0": {"G1": 1.0}},
    ],
)
def test_run_settings_accept_good_options(settings):
    RunSettings(**settings)


def test_run_settings_are_checked_without_loading_data(monkeypatch):
    """Construction is cheap: no feeder or profile is read (the CLI validates first)."""
    import popdispatch.cases.builtin as cases

    def fail(*args, **kwargs):
        raise AssertionError("data loaded")

    monkeypatch.setattr(cases, "ieee_elv", fail)
    with pytest.raises(OptionError):
        RunSettings(mode="exact", dynamics="replicator")
