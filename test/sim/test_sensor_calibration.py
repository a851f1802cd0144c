"""A sensor's declared calibration (crane_stiffness.sim.calibration) and a simulated sensor's true errors
(crane_stiffness.sim.truth) in the load cell and LVDT models: standard uncertainties per distribution, the spread of
drawn errors over many seeds against the declared u, seeds, bad declarations named, the errors in the readings, and
the default (perfect) sensors reading as before, sample for sample."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from crane_stiffness.errors import ParameterError
from crane_stiffness.sim.calibration import (LOAD_CELL_CALIBRATION_PARAMS, LOAD_CELL_COMPONENTS,
                                             LVDT_CALIBRATION_PARAMS, LVDT_COMPONENTS, POSE_SENSOR_CALIBRATION_PARAMS,
                                             calibration_of)
from crane_stiffness.sim.sensors import (LOAD_CELL_IMPERFECTION_PARAMS, LOAD_CELL_PARAMS, LVDT_IMPERFECTION_PARAMS,
                                         LVDT_PARAMS, LoadCellModel, LvdtModel, load_cell_from_params,
                                         lvdt_from_params)
from crane_stiffness.sim.truth import load_cell_truth, lvdt_truth

SEEDS = 3000


def defaults(*groups) -> dict:
    return {s.name: s.default for group in groups for s in group}


def load_cell_values(**changes) -> dict:
    values = defaults(LOAD_CELL_PARAMS, LOAD_CELL_CALIBRATION_PARAMS, LOAD_CELL_IMPERFECTION_PARAMS)
    values.update({k.replace('__', '.'): v for k, v in changes.items()})
    return values


def lvdt_values(**changes) -> dict:
    values = defaults(LVDT_PARAMS, LVDT_CALIBRATION_PARAMS, LVDT_IMPERFECTION_PARAMS)
    values.update({k.replace('__', '.'): v for k, v in changes.items()})
    return values


@pytest.mark.parametrize('distribution, k, u', [('normal', 2.0, 0.6), ('normal', 3.0, 0.4),
                                                ('rectangular', 2.0, 1.2 / math.sqrt(3.0)),
                                                ('triangular', 2.0, 1.2 / math.sqrt(6.0)),
                                                ('u_shaped', 2.0, 1.2 / math.sqrt(2.0))])
def test_standard_uncertainty_of_each_distribution(distribution, k, u):
    stated = calibration_of(load_cell_values(calibration__sensitivity=[1.2],
                                             calibration__sensitivity_distribution=distribution,
                                             calibration__sensitivity_k=k), LOAD_CELL_COMPONENTS)['sensitivity']
    np.testing.assert_allclose(stated.standard_uncertainty(), [u] * 6, rtol=1e-15)


def test_not_stated_is_none_never_zero():
    stated = calibration_of(lvdt_values(calibration__linearity_distribution='not_stated'), LVDT_COMPONENTS)
    assert stated['linearity'].standard_uncertainty() is None and not stated['linearity'].stated
    assert stated['sensitivity'].standard_uncertainty() == pytest.approx([0.125])  # 0.25 % at k = 2
    assert {s.name for s in POSE_SENSOR_CALIBRATION_PARAMS} == {
        f'calibration.{c}{suffix}' for c in ('position', 'angle') for suffix in ('', '_distribution', '_k')}


@pytest.mark.parametrize('distribution', ['normal', 'rectangular', 'triangular', 'u_shaped'])
def test_drawn_errors_spread_as_declared_over_many_seeds(distribution):
    """The sensitivity errors drawn over 3000 seeds: mean 0 and sample variance u² within the chi-square 99.9 %
    interval (for a flatter distribution than the normal the interval is wider than needed: still a real test)."""
    values = load_cell_values(truth__mode='drawn', calibration__sensitivity=[0.8, 0.8, 0.8, 1.6, 1.6, 1.6],
                              calibration__sensitivity_distribution=distribution,
                              calibration__misalignment=[0.0175], calibration__misalignment_distribution='normal',
                              calibration__misalignment_k=2.0)
    stated = calibration_of(values, LOAD_CELL_COMPONENTS)
    u = stated['sensitivity'].standard_uncertainty() / 100.0
    truths = [load_cell_truth({**values, 'truth.seed': seed}) for seed in range(SEEDS)]
    draws = np.array([t.sensitivity for t in truths])
    angles = np.array([t.misalignment for t in truths])
    low, high = chi2.ppf([0.0005, 0.9995], SEEDS - 1) / (SEEDS - 1)
    ratio = draws.var(axis=0, ddof=1) / u ** 2
    print(distribution, 'var/u² per axis', ratio.round(3).tolist(), f'99.9 %: {low:.3f} .. {high:.3f}')
    assert ((ratio > low) & (ratio < high)).all()
    assert (np.abs(draws.mean(axis=0)) < 3.5 * u / math.sqrt(SEEDS)).all()
    if distribution != 'normal':
        assert (np.abs(draws) <= np.array([0.008] * 3 + [0.016] * 3)).all()  # a half-width bounds its errors
    angle_ratio = angles.var(axis=0, ddof=1) / (0.0175 / 2.0) ** 2
    assert ((angle_ratio > low) & (angle_ratio < high)).all()


def test_same_seed_same_truth_and_the_truth_follows_from_the_parameters():
    values = load_cell_values(truth__mode='drawn', truth__seed=42)
    a, b = load_cell_truth(values), load_cell_truth(dict(values))
    assert np.array_equal(a.sensitivity, b.sensitivity) and np.array_equal(a.misalignment, b.misalignment)
    c = load_cell_truth({**values, 'truth.seed': 43})
    assert not np.array_equal(a.sensitivity, c.sensitivity)
    lv = lvdt_truth(lvdt_values(truth__mode='drawn', truth__seed=42))
    assert lv == lvdt_truth(lvdt_values(truth__mode='drawn', truth__seed=42)) and lv.sensitivity != 0.0
    # not_stated draws nothing
    silent = lvdt_truth(lvdt_values(truth__mode='drawn', calibration__linearity_distribution='not_stated'))
    assert silent.linearity == 0.0


@pytest.mark.parametrize('name, value, rule', [
    ('calibration.sensitivity', [1.0, -0.1, 1.0, 1.0, 1.0, 1.0], '>= 0'),
    ('calibration.crosstalk', [math.nan], 'finite'),
    ('calibration.misalignment', [0.01, 0.01], '3 or 1 numbers'),
    ('calibration.nonlinearity_distribution', 'gaussian', 'must be one of normal, rectangular'),
    ('calibration.sensitivity_k', 0.0, '> 0'),
    ('calibration.zero_drift_k', -2.0, '> 0'),
    ('truth.mode', 'sometimes', 'must be one of perfect, given, drawn'),
    ('truth.sensitivity', [1.0, math.inf, 0.0, 0.0, 0.0, 0.0], 'finite'),
    ('truth.misalignment', [0.0], '3 numbers'),
])
def test_bad_load_cell_declarations_are_refused_naming_the_field(name, value, rule):
    with pytest.raises(ParameterError) as err:
        load_cell_from_params(load_cell_values(**{name.replace('.', '__'): value}))
    assert err.value.field == name and rule in str(err.value)


@pytest.mark.parametrize('name, value, rule', [
    ('calibration.daq_offset', -1e-6, '>= 0'),
    ('calibration.linearity', math.inf, 'finite'),
    ('calibration.daq_gain_distribution', 'flat', 'must be one of'),
    ('truth.linearity', math.nan, 'finite'),
])
def test_bad_lvdt_declarations_are_refused_naming_the_field(name, value, rule):
    with pytest.raises(ParameterError) as err:
        lvdt_from_params(lvdt_values(**{name.replace('.', '__'): value}))
    assert err.value.field == name and rule in str(err.value)


def test_a_linearity_error_needs_a_finite_stroke():
    with pytest.raises(ParameterError) as err:
        lvdt_from_params(lvdt_values(truth__mode='given', truth__linearity=0.5, range_m=[-math.inf, math.inf]))
    assert err.value.field == 'truth.linearity' and 'finite range_m' in str(err.value)


def test_given_load_cell_errors_in_the_readings():
    quiet = dict(noise_std=[0.0] * 6, bias=[0.0] * 6, resolution=[0.0] * 6, seed=1)
    model = load_cell_from_params(load_cell_values(truth__mode='given', truth__sensitivity=[0, 1.0, 0, 0, 0, -2.0],
                                                   **quiet))
    reading, _ = model.measure([0.0, 4.0, 0.0, 0.0, 0.0, 0.5])
    np.testing.assert_allclose(reading, [0.0, 4.04, 0.0, 0.0, 0.0, 0.49], rtol=1e-15, atol=1e-15)
    # 1 deg about z: a load along y shows 1.7 % of itself on x (the sensor reads in its own, turned axes).
    angle = math.radians(1.0)
    turned = load_cell_from_params(load_cell_values(truth__mode='given', truth__misalignment=[0.0, 0.0, angle],
                                                    **quiet))
    reading, _ = turned.measure([0.0, 10.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(reading[:3], [10.0 * math.sin(angle), 10.0 * math.cos(angle), 0.0], atol=1e-12)
    assert reading[0] / 10.0 == pytest.approx(0.01745, abs=1e-5)


def test_given_lvdt_errors_in_the_readings():
    model = lvdt_from_params(lvdt_values(truth__mode='given', truth__sensitivity=0.5, truth__linearity=0.2,
                                         noise_std=0.0, resolution=0.0))
    full_scale = 2.5e-3  # the default stroke's half
    d = np.array([0.0, full_scale / 2, full_scale, -full_scale])
    t3 = 4 * (d / full_scale) ** 3 - 3 * (d / full_scale)  # 0, -1, 1, -1
    np.testing.assert_allclose(model.indicated(d), 1.005 * d + 0.002 * full_scale * t3, rtol=1e-14, atol=1e-18)
    reading, _ = model.measure([0.0, full_scale / 2, 0.0], np.eye(3))
    assert reading == pytest.approx(1.005 * full_scale / 2 - 0.002 * full_scale, rel=1e-12)


def test_default_parameters_read_exactly_as_a_sensor_without_imperfections():
    """The defaults (truth.mode perfect, every noise level 0) change no number: the demo's and the tests' results
    stand."""
    plain = {s.name: s.default for s in LOAD_CELL_PARAMS} | {'seed': 5}
    rng = np.random.default_rng(0)
    wrenches = rng.normal(0, 5, (2000, 6))
    t = np.arange(2000) / 1000.0
    before = LoadCellModel.from_params(plain)
    after = load_cell_from_params(load_cell_values(seed=5))
    assert np.array_equal(before.measure(wrenches, t)[0], after.measure(wrenches, t)[0])
    lvdt_plain = {s.name: s.default for s in LVDT_PARAMS if s.name != 'zero_on_first_pose'} | {'seed': 5}
    u = np.column_stack([np.zeros(2000), rng.normal(0, 1e-3, 2000), np.zeros(2000)])
    q = np.broadcast_to(np.eye(3), (2000, 3, 3))
    assert np.array_equal(LvdtModel.from_params(lvdt_plain).measure(u, q)[0],
                          lvdt_from_params(lvdt_values(seed=5)).measure(u, q, t)[0])


def test_coloured_noise_does_not_change_the_white_noise_stream():
    """The coloured noise draws from a generator of its own: the readings with it are those without it plus it."""
    wrenches = np.zeros((1000, 6))
    t = np.arange(1000) / 1000.0
    white = load_cell_from_params(load_cell_values(seed=9, bias=[0.0] * 6, resolution=[0.0] * 6))
    coloured = load_cell_from_params(load_cell_values(seed=9, bias=[0.0] * 6, resolution=[0.0] * 6,
                                                      noise__mains_amplitude=[0.1] * 6))
    difference = coloured.measure(wrenches, t)[0] - white.measure(wrenches, t)[0]
    spectrum = np.abs(np.fft.rfft(difference, axis=0)) * 2.0 / 1000
    assert np.argmax(spectrum[:, 1]) == 50 and spectrum[50, 1] == pytest.approx(0.1, rel=1e-9)


def test_a_load_cell_and_an_lvdt_drawn_with_one_seed_get_independent_errors():
    """Each kind of sensor draws from its own stream of truth.seed: the errors of the two are uncorrelated over
    seeds (both sensitivities rectangular: from one stream, fx's and the LVDT's would be the same first uniform)."""
    seeds = range(800)
    cell = load_cell_values(truth__mode='drawn', calibration__sensitivity_distribution='rectangular')
    lv = lvdt_values(truth__mode='drawn', calibration__sensitivity_distribution='rectangular',
                     calibration__daq_gain_distribution='not_stated')
    a = np.array([load_cell_truth({**cell, 'truth.seed': s}).sensitivity[0] for s in seeds])
    b = np.array([lvdt_truth({**lv, 'truth.seed': s}).sensitivity for s in seeds])
    r = np.corrcoef(a, b)[0, 1]
    assert abs(r) < 4.0 / math.sqrt(len(a)), r
