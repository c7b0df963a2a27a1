"""LinDistFlow voltage sensitivities against finite differences of the AC power flow.

At zero load (every flow 0, every voltage 1 p.u.) LinDistFlow is the first-order expansion of
the AC power flow, so ``d(v_j^2)/d(p_i) = 2 R_ij / Z_base`` must match a central difference of
the AC results to the difference's own error (second order in the step). At minute 566 of
ieee-elv the AC sensitivity differs by the order of the voltage drop (measured 0.5 % of the
largest sensitivity); the bound asserted is the measured one with a margin.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("power_grid_model", reason='the AC check needs pip install "popdispatch[ac]"')

from popdispatch.ac import check_setpoints  # noqa: E402
from popdispatch.ac.lindistflow import shared_path_ohm, voltage_sensitivity  # noqa: E402
from popdispatch.cases import ieee_elv  # noqa: E402
from popdispatch.cases.builtin import elv_snapshot_566_kw  # noqa: E402
from popdispatch.errors import FeederError  # noqa: E402

STEP_KW = 0.5


def finite_difference(feeder, load_kw, base_kw):
    """Central differences of v^2 (p.u.^2 per kW), rows: buses, columns: generators."""
    n = len(feeder.generators)
    shifts = np.vstack([np.eye(n) * STEP_KW, -np.eye(n) * STEP_KW])
    setpoints = base_kw[None, :] + shifts
    loads = np.tile(load_kw, (2 * n, 1))
    day = check_setpoints(feeder, loads, setpoints, tolerance_pu=1e-13)
    v2 = day.flows.v_pu**2
    return ((v2[:n] - v2[n:]) / (2 * STEP_KW)).T


@pytest.fixture(scope="module")
def elv():
    return ieee_elv()


def test_shared_path_resistance_by_hand(elv):
    """Two buses on different branches share only the lines above their junction."""
    r = elv.lines.r_ohm
    path_a = elv.path_lines(1, 817)
    path_b = elv.path_lines(1, 835)
    common = sorted(set(path_a) & set(path_b))
    shared = shared_path_ohm(elv, [817, 835], [835, 817])
    assert shared[0, 1] == pytest.approx(r[path_a].sum())
    assert shared[0, 0] == shared[1, 1] == pytest.approx(r[common].sum())
    assert shared_path_ohm(elv, [1], [835])[0, 0] == 0.0
    with pytest.raises(FeederError, match="unknown bus 9999"):
        shared_path_ohm(elv, [9999], [1])


def test_sensitivity_equals_ac_finite_differences_at_zero_load(elv):
    gens = elv.generators
    base = np.zeros(len(gens))
    fd = finite_difference(elv, np.zeros(len(elv.loads)), base)
    lin = voltage_sensitivity(elv, gens.bus.tolist()).to_numpy()
    scale = np.abs(lin).max()
    assert np.max(np.abs(fd - lin)) < 1e-6 * scale  # measured 9.6e-8 (docs/ac.md)


def test_sensitivity_at_the_peak_minute_is_within_the_voltage_drop(elv):
    gens = elv.generators
    load_kw = elv_snapshot_566_kw().loc[elv.loads.index].to_numpy()
    base = gens.pmax_kw.to_numpy() / gens.pmax_kw.sum() * load_kw.sum()
    fd = finite_difference(elv, load_kw, base)
    lin = voltage_sensitivity(elv, gens.bus.tolist()).to_numpy()
    relative = np.max(np.abs(fd - lin)) / np.abs(lin).max()
    assert relative < 0.01  # measured 5.3e-3 (docs/ac.md)
