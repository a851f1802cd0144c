"""The measured stiffness' budget (crane_stiffness.uncertainty.measurement) against a hand computation: relative
uncertainties in quadrature, sensitivity coefficients +k for the force and −k for the displacement, Welch–Satterthwaite
on the fit's degrees of freedom; components not stated left out and named."""
from __future__ import annotations

import math

import pytest
from scipy import stats

from crane_stiffness.uncertainty.errors import InputError
from crane_stiffness.uncertainty.measurement import SlopeStatistics, measured_stiffness

K, SE, DOF = 50_000.0, 400.0, 4.0
LOAD_CELL = {'full_scale': [40.0, 40.0, 120.0, 2.0, 2.0, 2.0],
             'calibration.sensitivity': [1.0, 2.0, 1.0, 1.0, 1.0, 1.0],
             'calibration.sensitivity_distribution': 'normal',
             'calibration.sensitivity_k': 2.0,
             'calibration.nonlinearity': [0.2] * 6, 'calibration.nonlinearity_distribution': 'rectangular',
             'calibration.nonlinearity_k': 2.0,
             'calibration.misalignment': [0.01, 0.02, 0.03], 'calibration.misalignment_distribution': 'rectangular',
             'calibration.misalignment_k': 2.0}
LVDT = {'range_m': [-2.5e-3, 2.5e-3], 'calibration.sensitivity': 0.3, 'calibration.sensitivity_distribution': 'normal',
        'calibration.sensitivity_k': 3.0, 'calibration.daq_gain': 0.05,
        'calibration.daq_gain_distribution': 'triangular',
        'calibration.daq_gain_k': 2.0, 'calibration.linearity': 0.25, 'calibration.linearity_distribution': 'u_shaped',
        'calibration.linearity_k': 2.0}


def test_budget_matches_the_hand_computation():
    force_span, x_span = 10.0, 10.0 / K
    m = measured_stiffness(SlopeStatistics(K, SE, DOF, 'hold means'), 'fy', load_cell=LOAD_CELL, lvdt=LVDT,
                           force_span=force_span, displacement_span=x_span, cross_load_ratio=0.1)
    # By hand, each relative standard uncertainty (fy: index 1; the tilt of y: the angles about x and z).
    theta = math.hypot(0.01, 0.03)
    relative = {'load_cell_sensitivity': 2.0e-2 / 2.0,
                'load_cell_nonlinearity': 0.2e-2 * 3.0 / math.sqrt(3.0),  # min(40 N / 10 N, 3) x 0.2 %
                'load_cell_misalignment': (1.0 - math.cos(theta)) / math.sqrt(3.0),
                'load_cell_cross_load': 0.1 * math.sin(theta) / math.sqrt(3.0),
                'lvdt_sensitivity': 0.3e-2 / 3.0,
                'lvdt_daq_gain': 0.05e-2 / math.sqrt(6.0),
                'lvdt_linearity': 0.25e-2 * 3.0 / math.sqrt(2.0)}  # min(2.5 mm / 0.19 mm, 3) x 0.25 %
    rows = {row.name: row for row in m.result.budget}
    assert set(rows) == {'stiffness_fit', *relative}
    assert rows['stiffness_fit'].contribution == pytest.approx(SE, rel=1e-9)
    for name, u in relative.items():
        assert rows[name].u == pytest.approx(u, rel=1e-12)
        sign = 1.0 if name.startswith('load_cell') else -1.0
        assert rows[name].sensitivity == pytest.approx(sign * K, rel=1e-6)
        assert rows[name].contribution == pytest.approx(K * u, rel=1e-6)
    u_c = math.sqrt(SE ** 2 + sum((K * u) ** 2 for u in relative.values()))
    assert m.result.value == K
    assert m.result.u_c == pytest.approx(u_c, rel=1e-6)
    nu_eff = u_c ** 4 / (SE ** 4 / DOF)
    assert m.result.nu_eff == pytest.approx(nu_eff, rel=1e-6)
    k = stats.t.ppf(0.975, math.floor(nu_eff))
    assert m.result.k == pytest.approx(k, rel=1e-9)
    assert m.result.U == pytest.approx(k * u_c, rel=1e-6)
    assert not m.statistical_only and m.left_out == ()
    assert m.to_dict()['uncertainty']['U'] == pytest.approx(k * u_c, rel=1e-6)


def test_not_stated_components_are_named_never_zero():
    load_cell = {**LOAD_CELL, 'calibration.nonlinearity_distribution': 'not_stated'}
    m = measured_stiffness(SlopeStatistics(K, SE, DOF, 'samples'), 'fy', load_cell=load_cell, lvdt=None,
                           force_span=10.0, displacement_span=2e-4)
    assert m.left_out == ('load_cell_nonlinearity', 'lvdt_sensitivity', 'lvdt_daq_gain', 'lvdt_linearity')
    assert 'statistical only for load_cell_nonlinearity, lvdt_sensitivity' in m.calibration_statement
    assert 'load_cell_nonlinearity' not in {row.name for row in m.result.budget}


def test_no_declaration_is_statistical_only():
    m = measured_stiffness(SlopeStatistics(K, SE, DOF, 'samples'), 'fy', force_span=10.0, displacement_span=2e-4)
    assert m.statistical_only
    assert m.calibration_statement.startswith('statistical only')
    assert m.result.u_c == pytest.approx(SE)
    assert m.result.k == pytest.approx(stats.t.ppf(0.975, 4))


def test_bad_input_is_named():
    with pytest.raises(InputError, match='cross_load_ratio'):
        measured_stiffness(SlopeStatistics(K, SE, DOF, 'samples'), 'fy', cross_load_ratio=-1.0)
    with pytest.raises(InputError, match='calibration.sensitivity_distribution'):
        measured_stiffness(SlopeStatistics(K, SE, DOF, 'samples'), 'fy',
                           load_cell={**LOAD_CELL, 'calibration.sensitivity_distribution': 'bimodal'})
