"""Input quantities: the GUM's standard uncertainties from certificates and bounds, the flat form, bad input refused
naming the field, and each distribution's draws."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.uncertainty.budget import correlation_matrix
from crane_stiffness.uncertainty.errors import InputError
from crane_stiffness.uncertainty.inputs import (InputQuantity, entries_from_params, input_from_mapping,
                                                inputs_from_mapping)


def test_standard_uncertainty_by_the_gums_rules():
    # GUM 4.3.3: a certificate's U = 0.075 um at k = 3 (the end gauge of H.1) is u = 25 nm.
    assert InputQuantity.expanded('l_s', 0.05, 0.075e-6, 3).u == pytest.approx(25e-9, rel=1e-12)
    # 4.3.7 rectangular a/sqrt(3), 4.3.9 triangular a/sqrt(6), arcsine (U-shaped) a/sqrt(2).
    assert InputQuantity.bounded('x', 0.0, 2e-6, 'rectangular').u == pytest.approx(1.1547005e-6, rel=1e-7)
    assert InputQuantity.bounded('x', 0.0, 0.6, 'triangular').u == pytest.approx(0.6 / 6 ** 0.5, rel=1e-12)
    assert InputQuantity.bounded('x', 0.0, 0.5, 'arcsine').u == pytest.approx(0.35355339, rel=1e-8)
    assert InputQuantity.bounded('x', 0.0, 0.5, 'u-shaped').distribution == 'arcsine'
    q = InputQuantity.normal('w', 50.0, 0.05, dof=9, unit='N')
    assert (q.u, q.dof, q.unit, q.half_width) == (0.05, 9.0, 'N', 0.05)
    assert InputQuantity.bounded('x', 1.0, 0.3).half_width == pytest.approx(0.3, rel=1e-15)
    assert math.isinf(InputQuantity.normal('x', 1.0, 0.1).dof)


def test_the_flat_form_of_parameter_files():
    assert input_from_mapping('d', {'value': 1.08e-3, 'U': 2e-5, 'k': 2}).u == pytest.approx(1e-5, rel=1e-12)
    q = input_from_mapping('h', {'value': 0.5, 'half_width': 5e-4, 'distribution': 'rectangular', 'unit': 'm'})
    assert (q.distribution, q.unit) == ('rectangular', 'm') and q.u == pytest.approx(5e-4 / 3 ** 0.5)
    q = input_from_mapping('w', {'u': 0.05, 'dof': 9}, value=50.0)
    assert (q.value, q.u, q.dof, q.distribution) == (50.0, 0.05, 9.0, 'normal')
    assert math.isinf(input_from_mapping('w', {'value': 1, 'u': 0.1, 'dof': 'inf'}).dof)
    assert input_from_mapping('z', {'value': 1, 'half_width': 0.1}).distribution == 'rectangular'
    # to_dict is the flat form again.
    for q in (InputQuantity.bounded('a', 0.1, 5e-4, 'triangular', dof=12), InputQuantity.normal('b', 2, 0.3)):
        again = input_from_mapping(q.name, q.to_dict())
        assert again == q or (again.u == pytest.approx(q.u, rel=1e-15) and again.distribution == q.distribution)
    assert [q.name for q in inputs_from_mapping({'x': {'value': 1, 'u': 1}, 'y': {'value': 2, 'u': 1}})] == ['x', 'y']


@pytest.mark.parametrize('make, field, words', [
    (lambda: InputQuantity.expanded('d', 1.0, -1e-5, 2), 'd.U', 'must be >= 0'),
    (lambda: InputQuantity.expanded('d', 1.0, 1e-5, 0), 'd.k', 'coverage factor must be > 0'),
    (lambda: InputQuantity.expanded('d', 1.0, 1e-5, -2), 'd.k', 'coverage factor must be > 0'),
    (lambda: InputQuantity.normal('w', 50.0, float('nan')), 'w.u', 'must be finite'),
    (lambda: InputQuantity.normal('w', 50.0, float('inf')), 'w.u', 'must be finite'),
    (lambda: InputQuantity.normal('w', float('nan'), 1.0), 'w.value', 'must be finite'),
    (lambda: InputQuantity.bounded('h', 0.5, -1e-3), 'h.half_width', 'must be >= 0'),
    (lambda: InputQuantity.bounded('h', 0.5, 1e-3, 'lognormal'), 'h.distribution', 'unknown distribution'),
    (lambda: InputQuantity.normal('w', 1.0, 0.1, dof=0), 'w.dof', 'must be > 0'),
    (lambda: input_from_mapping('d', {'value': 1.0, 'U': 1e-5}), 'd.k', 'needs its coverage factor'),
    (lambda: input_from_mapping('d', {'value': 1.0, 'U': 1e-5, 'k': 2, 'u': 1e-5}), 'd', 'exactly one of'),
    (lambda: input_from_mapping('d', {'value': 1.0, 'sigma': 1e-5}), 'd.sigma', 'unknown key'),
    (lambda: input_from_mapping('d', {'U': 1e-5, 'k': 2}), 'd.value', 'is required'),
    (lambda: input_from_mapping('d', {'value': 1, 'u': 1, 'k': 2}), 'd.k', 'goes with U only'),
    (lambda: correlation_matrix([InputQuantity.normal('x', 0, 1), InputQuantity.normal('y', 0, 1)],
                                {('x', 'y'): 1.5}), "correlation[('x', 'y')]", 'must lie in [-1, 1]'),
    (lambda: correlation_matrix([InputQuantity.normal('x', 0, 1)], {('x', 'q'): 0.5}), "correlation[('x', 'q')]",
     'not given'),
])
def test_bad_input_is_refused_naming_the_field_the_value_and_the_rule(make, field, words):
    with pytest.raises(InputError) as info:
        make()
    assert info.value.field == field and words in str(info.value)
    assert str(info.value).startswith(f'{field} = ')
    assert isinstance(info.value, CraneStiffnessError) and isinstance(info.value, ValueError)


@pytest.mark.parametrize('distribution', ['normal', 'rectangular', 'triangular', 'arcsine'])
def test_draws_have_the_stated_mean_and_standard_uncertainty(distribution):
    q = InputQuantity(name='x', value=3.0, u=0.2, distribution=distribution)
    x = q.draws(np.random.default_rng(7), 200_000)
    # standard error of a standard deviation from 2e5 draws is below 0.3 %; of the mean 0.2/447
    assert np.std(x) == pytest.approx(0.2, rel=0.01)
    assert abs(np.mean(x) - 3.0) < 4 * 0.2 / 447
    if distribution != 'normal':
        assert np.all(np.abs(x - 3.0) <= q.half_width)
        assert np.max(np.abs(x - 3.0)) > 0.99 * q.half_width


def test_a_normal_input_with_finite_dof_draws_the_scaled_shifted_t():
    """JCGM 101 6.4.9: t_nu(x, u^2), whose standard deviation is u*sqrt(nu/(nu-2)) (here 5 dof: 1.29 u)."""
    q = InputQuantity.normal('x', 1.0, 0.1, dof=5)
    x = q.draws(np.random.default_rng(3), 400_000)
    assert np.std(x) == pytest.approx(0.1 * math.sqrt(5 / 3), rel=0.03)
    # the t's 97.5 % quantile is 2.571 u from the value (normal: 1.960 u)
    assert np.quantile(x, 0.975) - 1.0 == pytest.approx(0.2571, rel=0.02)


def test_flat_ros_parameters_regroup_into_entries():
    params = {'uncertainty.gain.U': 2e-5, 'uncertainty.gain.k': 2.0, 'uncertainty.offset.half_width': 1e-6,
              'uncertainty.offset.distribution': 'triangular', 'displacement_gain': 0.002}
    entries = entries_from_params(params, 'uncertainty.')
    assert entries == {'gain': {'U': 2e-5, 'k': 2.0}, 'offset': {'half_width': 1e-6, 'distribution': 'triangular'}}
    assert input_from_mapping('gain', entries['gain'], value=0.002).u == pytest.approx(1e-5)
    with pytest.raises(InputError) as info:
        entries_from_params({'uncertainty.gain': 1.0}, 'uncertainty.')
    assert info.value.field == 'uncertainty.gain'
