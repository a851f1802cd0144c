"""The model's prediction with its uncertainty for the lab model: the Monte Carlo's mean at the point prediction,
u scaling as the law of propagation says when one input's uncertainty doubles, the budget naming the dominant
input, and the crane's uncertainty file."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from crane_stiffness.model import axis_stiffness, lab_model, rest_pose, tangent_stiffness
from crane_stiffness.uncertainty.budget import RESULT_KEYS
from crane_stiffness.uncertainty.crane_inputs import (crane_inputs, default_uncertainty, input_names,
                                                      load_uncertainty_file)
from crane_stiffness.uncertainty.errors import InputError
from crane_stiffness.uncertainty.prediction import predict_stiffness, stiffness_function

CONFIG = Path(__file__).resolve().parents[2] / 'config'
LAB = lab_model(0.5, 50.0)


@pytest.fixture(scope='module')
def lab_fy():
    return predict_stiffness(LAB, 'fy', seed=1)


def test_the_prediction_is_the_exact_tangent_and_the_monte_carlo_centres_on_it(lab_fy):
    point = axis_stiffness(tangent_stiffness(LAB, rest_pose(LAB)), 'fy')
    assert lab_fy.value == pytest.approx(point, rel=1e-12)
    assert lab_fy.value == pytest.approx(53793.5, abs=0.05)  # as make demo prints it
    mc = lab_fy.monte_carlo
    assert mc is not None and mc['converged'] and mc['trials'] >= 20_000
    # the law of propagation and the Monte Carlo agree on u to a few %; the mean sits within 1 % of u of the
    # prediction (the small shift is the curvature of k in d and E)
    assert mc['u'] == pytest.approx(lab_fy.u_c, rel=0.05)
    assert abs(mc['mean'] - lab_fy.value) < 0.02 * lab_fy.u_c
    assert mc['interval'][0] < lab_fy.value < mc['interval'][1]
    assert tuple(lab_fy.to_dict()) == RESULT_KEYS
    assert set(mc['validation']) == {'d_low', 'd_high', 'delta', 'validated'}
    assert math.isinf(lab_fy.nu_eff) and lab_fy.k == pytest.approx(1.96, abs=1e-3)


def test_the_budget_names_the_wire_modulus_as_dominant_for_the_lab_model(lab_fy):
    rows = sorted(lab_fy.budget, key=lambda r: -r.contribution)
    assert lab_fy.dominant.name == 'youngs_modulus' == rows[0].name
    assert rows[1].name == 'wire_diameter'
    # k_fy of the lab model is nearly all wire elasticity: c_E·E/k ≈ 1 and c_d·d/k ≈ 2 (k ∝ d² E)
    c = {r.name: r.sensitivity for r in lab_fy.budget}
    assert c['youngs_modulus'] * LAB.youngs_modulus / lab_fy.value == pytest.approx(1.0, abs=0.05)
    assert c['wire_diameter'] * LAB.wire_diameter / lab_fy.value == pytest.approx(2.0, abs=0.1)
    assert sum(r.contribution ** 2 for r in lab_fy.budget) == pytest.approx(lab_fy.u_c ** 2, rel=1e-12)


def test_doubling_one_inputs_uncertainty_scales_u_as_the_law_says(lab_fy):
    """u(E) doubled: u_c² grows by 3·(c_E u_E)², in the budget and in the Monte Carlo alike."""
    inputs = crane_inputs(LAB)
    doubled = [q.scaled(2.0) if q.name == 'youngs_modulus' else q for q in inputs]
    again = predict_stiffness(LAB, 'fy', inputs=doubled, seed=1)
    c_e = next(r.contribution for r in lab_fy.budget if r.name == 'youngs_modulus')
    expected = math.sqrt(lab_fy.u_c ** 2 + 3.0 * c_e ** 2)
    assert again.u_c == pytest.approx(expected, rel=1e-3)
    assert again.monte_carlo is not None and lab_fy.monte_carlo is not None
    assert again.monte_carlo['u'] == pytest.approx(expected, rel=0.05)
    assert again.monte_carlo['u'] / lab_fy.monte_carlo['u'] == pytest.approx(expected / lab_fy.u_c, rel=0.05)
    # an input that hardly matters doubled leaves u_c where it was
    weight_doubled = [q.scaled(2.0) if q.name == 'weight' else q for q in inputs]
    assert predict_stiffness(LAB, 'fy', inputs=weight_doubled, monte_carlo_run=False).u_c == pytest.approx(
        lab_fy.u_c, rel=1e-4)


def test_the_same_seed_gives_the_same_prediction():
    a = predict_stiffness(LAB, 'fx', seed=3, trials=2000)
    b = predict_stiffness(LAB, 'fx', seed=3, trials=2000)
    assert a.to_dict() == b.to_dict() and a.monte_carlo is not None and a.monte_carlo['trials'] == 2000


def test_a_moment_axis_and_a_crane_given_by_k():
    crane = LAB.replace(wire_stiffness=LAB.k, wire_diameter=None, youngs_modulus=None)
    assert 'wire_stiffness' in input_names(crane) and 'youngs_modulus' not in input_names(crane)
    result = predict_stiffness(crane, 'mz', monte_carlo_run=False)
    assert result.value == pytest.approx(axis_stiffness(tangent_stiffness(crane, rest_pose(crane)), 'mz'),
                                         rel=1e-12)
    assert result.dominant.name == 'wire_stiffness'


def test_the_function_at_the_estimates_is_the_point_prediction_for_offsets_too():
    crane = LAB.replace(length_offsets=(2e-6, -1e-6, 0.0, 3e-6, 0.0, -2e-6), com_offset=(1e-3, -2e-3, 5e-3))
    names = input_names(crane)
    f = stiffness_function(crane, 'fx', names)
    values = [q.value for q in crane_inputs(crane)]
    assert float(f(*values)[0]) == pytest.approx(axis_stiffness(tangent_stiffness(crane, rest_pose(crane)), 'fx'),
                                                 rel=1e-10)


def test_the_shipped_uncertainty_file_holds_the_defaults():
    entries = load_uncertainty_file(CONFIG / 'uncertainty_lab.yaml')
    defaults = default_uncertainty(LAB)
    assert set(entries) == set(defaults) == set(input_names(LAB))
    from_file = crane_inputs(LAB, entries)
    from_code = crane_inputs(LAB)
    for a, b in zip(from_file, from_code):
        assert (a.name, a.distribution, a.value) == (b.name, b.distribution, b.value)
        assert a.u == pytest.approx(b.u, rel=1e-12)
    assert all(d.source for d in defaults.values())


def test_bad_uncertainty_entries_are_refused_naming_them():
    with pytest.raises(InputError) as info:
        crane_inputs(LAB, {'wire_length': {'u': 1e-3}})
    assert info.value.field == 'uncertainty.wire_length' and 'not an input of this crane' in str(info.value)
    with pytest.raises(InputError) as info:
        crane_inputs(LAB, {'weight': {'value': 49.0, 'u': 0.1}})
    assert info.value.field == 'uncertainty.weight.value'
    with pytest.raises(InputError) as info:
        crane_inputs(LAB, {'weight': {'U': 0.1, 'k': 0}})
    assert info.value.field == 'weight.k'
    with pytest.raises(InputError) as info:
        crane_inputs(LAB, {'a': {'half_width': 1e-3, 'distribution': 'beta'}})
    assert info.value.field == 'a.distribution'
    from crane_stiffness.uncertainty.inputs import InputQuantity
    with pytest.raises(InputError) as info:  # an input the model does not have would silently count for nothing
        predict_stiffness(LAB, 'fy', inputs=[InputQuantity.normal('wire_length', 0.5, 1e-3)])
    assert info.value.field == 'inputs' and info.value.value == 'wire_length'
