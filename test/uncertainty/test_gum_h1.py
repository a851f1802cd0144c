"""The law of propagation against JCGM 100:2008 Annex H.1 (calibration of an end gauge), through our own code, and
against GTC (the GUM Tree Calculator) as an independent peer.

The example's inputs as the GUM prints them (H.1.3, H.1.4 and Table H.1), model (H.1.2, first order)
l = l_s + d − l_s (δα θ + α_s δθ):
- l_s = 50.000 623 mm, certificate U = 0.075 µm at k = 3 (u = 25 nm), ν = 18;
- d = 215 nm, u(d) = 9.7 nm from u(d̄) = 5.8 nm (ν 24), u(d₁) = 3.9 nm (ν 5), u(d₂) = 6.7 nm (ν 8): ν = 25.6;
- α_s = 11.5 × 10⁻⁶ °C⁻¹ within ±2 × 10⁻⁶ °C⁻¹, rectangular (u = 1.2 × 10⁻⁶ °C⁻¹);
- θ = −0.1 °C, u(θ) = 0.41 °C (from u(θ̄) = 0.2 °C and the U-shaped cycle of 0.5 °C: 0.35 °C);
- δα = 0 within ±1 × 10⁻⁶ °C⁻¹, rectangular (u = 0.58 × 10⁻⁶ °C⁻¹), ν = 50;
- δθ = 0 within ±0.050 °C, rectangular (u = 0.029 °C), ν = 2.
Printed (Table H.1, H.1.6): contributions 25, 9.7, 0, 0, 2.9 and 16.6 nm; u_c = 32 nm; ν_eff = 16;
k = t_95(16) = 2.12; U95 = 2.12 × 32 nm = 0.07 µm (U99 = 2.92 × 32 nm = 93 nm).
"""
from __future__ import annotations

import math

import pytest

from crane_stiffness.uncertainty.budget import RESULT_KEYS, coverage_factor, propagate, welch_satterthwaite
from crane_stiffness.uncertainty.inputs import InputQuantity


def end_gauge_inputs() -> list[InputQuantity]:
    theta_u = math.hypot(0.2, 0.5 / math.sqrt(2.0))  # H.1.3.4: 0.41 °C
    return [InputQuantity.expanded('l_s', 50.000623e-3, 0.075e-6, 3.0, dof=18, unit='m'),
            InputQuantity.normal('d', 215e-9, 9.7e-9, dof=25.6, unit='m'),
            InputQuantity.bounded('alpha_s', 11.5e-6, 2e-6, 'rectangular', unit='1/°C'),
            InputQuantity.normal('theta', -0.1, theta_u, unit='°C'),
            InputQuantity.bounded('delta_alpha', 0.0, 1e-6, 'rectangular', dof=50, unit='1/°C'),
            InputQuantity.bounded('delta_theta', 0.0, 0.050, 'rectangular', dof=2, unit='°C')]


def end_gauge(l_s, d, alpha_s, theta, delta_alpha, delta_theta):
    return l_s + d - l_s * (delta_alpha * theta + alpha_s * delta_theta)


def test_end_gauge_budget_as_printed_in_table_h1():
    result = propagate(end_gauge, end_gauge_inputs())
    rows = {row.name: row for row in result.budget}
    printed_nm = {'l_s': 25, 'd': 9.7, 'alpha_s': 0, 'theta': 0, 'delta_alpha': 2.9, 'delta_theta': 16.6}
    for name, nm in printed_nm.items():  # to the printed digits
        digits = 1 if name in ('d', 'delta_alpha', 'delta_theta') else 0
        assert round(rows[name].contribution * 1e9, digits) == nm, name
    assert rows['l_s'].u == pytest.approx(25e-9, rel=1e-12)
    assert round(rows['alpha_s'].u * 1e6, 1) == 1.2 and round(rows['delta_alpha'].u * 1e6, 2) == 0.58
    assert round(rows['delta_theta'].u, 3) == 0.029 and round(rows['theta'].u, 2) == 0.41
    # sensitivity coefficients of Table H.1: c = 1, 1, 0, 0, -l_s θ, -l_s α_s
    assert rows['l_s'].sensitivity == pytest.approx(1.0, abs=1e-6)
    assert rows['d'].sensitivity == pytest.approx(1.0, abs=1e-6)
    assert rows['alpha_s'].sensitivity == 0.0 and rows['theta'].sensitivity == 0.0
    assert rows['delta_alpha'].sensitivity == pytest.approx(50.000623e-3 * 0.1, rel=1e-6)
    assert rows['delta_theta'].sensitivity == pytest.approx(-50.000623e-3 * 11.5e-6, rel=1e-6)
    assert round(result.u_c * 1e9) == 32 and result.u_c == pytest.approx(31.7e-9, abs=0.05e-9)
    assert math.floor(result.nu_eff) == 16  # W-S gives 16.7; G.4.1 truncates
    assert round(result.k, 2) == 2.12 and result.k == pytest.approx(2.1199, abs=1e-4)
    assert round(result.U * 1e6, 2) == 0.07
    assert result.value == pytest.approx(50.000838e-3, abs=0.5e-9)  # H.1.5: l = 50.000 838 mm
    assert result.interval == pytest.approx((result.value - result.U, result.value + result.U), abs=0)
    assert result.dominant.name == 'l_s'
    # U99 of H.1.6: t_99(16) = 2.92, 93 nm
    assert round(coverage_factor(result.nu_eff, 0.99), 2) == 2.92
    # (the GUM multiplies the rounded values, 2.92 × 32 nm; unrounded 2.9208 × 31.67 nm = 92.5 nm)
    assert round(round(coverage_factor(result.nu_eff, 0.99), 2) * round(result.u_c * 1e9)) == 93
    assert tuple(result.to_dict()) == RESULT_KEYS and result.to_dict()['monte_carlo'] is None


def test_the_dof_of_d_from_its_three_components():
    """H.1.3.2: u(d) = 9.7 nm from 5.8 (ν 24), 3.9 (ν 5) and 6.7 nm (ν 8); W-S with u = 9.7 nm gives ν = 25.6."""
    assert math.sqrt(5.8 ** 2 + 3.9 ** 2 + 6.7 ** 2) == pytest.approx(9.7, abs=0.05)
    assert round(welch_satterthwaite([5.8, 3.9, 6.7], [24, 5, 8], u_c=9.7), 1) == 25.6


def test_analytic_sensitivities_give_the_same_budget():
    inputs = end_gauge_inputs()
    x = [q.value for q in inputs]
    c = [1 - (x[4] * x[3] + x[2] * x[5]), 1.0, -x[0] * x[5], -x[0] * x[4], -x[0] * x[3], -x[0] * x[2]]
    given = propagate(end_gauge, inputs, sensitivity=c)
    fd = propagate(end_gauge, inputs)
    assert given.u_c == pytest.approx(fd.u_c, rel=1e-7) and given.nu_eff == pytest.approx(fd.nu_eff, rel=1e-6)


def test_gtc_agrees_as_an_independent_peer():
    import GTC as gtc  # pinned in requirements-test.txt
    inputs = end_gauge_inputs()
    ureals = [gtc.ureal(q.value, q.u, q.dof, label=q.name) for q in inputs]
    y = end_gauge(*ureals)
    ours = propagate(end_gauge, inputs)
    assert ours.u_c == pytest.approx(gtc.uncertainty(y), rel=1e-6)
    assert ours.nu_eff == pytest.approx(gtc.dof(y), rel=1e-5)
    for q, row in zip(inputs, ours.budget):
        assert row.contribution == pytest.approx(abs(gtc.reporting.u_component(y, ureals[inputs.index(q)])),
                                                 rel=1e-6, abs=1e-18)


def test_correlated_inputs_follow_gum_5_2_2():
    """y = x1 + x2 with r = 0.5: u_c² = u1² + u2² + 2·r·u1·u2 (and r = −1 with equal u gives 0)."""
    x1, x2 = InputQuantity.normal('x1', 1.0, 0.3), InputQuantity.normal('x2', 2.0, 0.4)
    result = propagate(lambda a, b: a + b, [x1, x2], correlations={('x1', 'x2'): 0.5})
    assert result.u_c == pytest.approx(math.sqrt(0.09 + 0.16 + 2 * 0.5 * 0.12), rel=1e-9)
    same = InputQuantity.normal('x2', 2.0, 0.3)
    assert propagate(lambda a, b: a + b, [x1, same], correlations={('x2', 'x1'): -1.0}).u_c == pytest.approx(
        0.0, abs=1e-9)
