"""The 6×6 measurement uncertainty (crane_stiffness.uncertainty.matrix, .calibration6) and the model's 6×6 prediction
(.prediction6): the instrument model inverted exactly, the Type A of the step means against its formula, the law of
propagation against the JCGM 102 Monte Carlo, a declaration missing said, never a silent zero."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.model import lab_model, rest_pose, tangent_stiffness
from crane_stiffness.testing.synthetic_full6 import declared_calibrations, draw_errors
from crane_stiffness.uncertainty.calibration6 import six_axis_inputs
from crane_stiffness.uncertainty.errors import UncertaintyError
from crane_stiffness.uncertainty.matrix import k2_gradient, matrix_uncertainty, step_means_fit
from crane_stiffness.uncertainty.prediction6 import en_matrix, predict_matrix

GEOMETRY = lab_model(0.5, 50.0)
K_TRUE = tangent_stiffness(GEOMETRY, rest_pose(GEOMETRY))
C_TRUE = np.linalg.inv(K_TRUE)
#: 20 held wrenches spread over the six axes, as ± pairs (N, N·m).
_RNG = np.random.default_rng(5)
_HALF = _RNG.uniform(-1.0, 1.0, (10, 6)) * np.array([2.8, 3.3, 24.0, 1.6, 1.4, 0.75])
WRENCHES = np.vstack([_HALF, -_HALF])


def _errors_as_inputs(names: tuple[str, ...], seed: int) -> np.ndarray:
    """The synthetic truth of ``seed`` (testing.synthetic_full6.draw_errors) as one row of input values."""
    e = draw_errors(seed)
    axes, xyz = ('fx', 'fy', 'fz', 'mx', 'my', 'mz'), ('x', 'y', 'z')
    values = {**{f'load_cell_sensitivity_{a}': e.sensitivity[i] for i, a in enumerate(axes)},
              **{f'load_cell_misalignment_{c}': e.misalignment[i] for i, c in enumerate(xyz)},
              **{f'load_cell_nonlinearity_{a}': e.nonlinearity[i] for i, a in enumerate(axes)},
              **{f'pose_sensor_angle_{c}': e.pose_angle[i] for i, c in enumerate(xyz)},
              **{f'load_cell_crosstalk_{axes[i]}_{axes[j]}': e.crosstalk[i, j] for i in range(6) for j in range(6)
                 if i != j}}
    return np.array([[values[n] for n in names]])


def test_correct_inverts_the_instrument_model_the_synthetic_sensors_apply():
    """The readings of the true step means through drawn errors (the synthetic sensors' forward model, written
    apart) corrected with the same errors give the true wrench and deflection back."""
    lc, pose = declared_calibrations()
    cal = six_axis_inputs(lc, pose)
    assert len(cal.inputs) == 6 + 3 + 30 + 6 + 3 and not cal.left_out
    d_true = WRENCHES @ C_TRUE.T
    for seed in range(3):
        e = draw_errors(seed)
        w, d = cal.correct(_errors_as_inputs(cal.names, seed), e.read_wrench(WRENCHES), e.read_deflection(d_true))
        assert np.max(np.abs(w[0] - WRENCHES)) < 1e-9 * np.abs(WRENCHES).max()
        assert np.max(np.abs(d[0] - d_true)) < 1e-12 * np.abs(d_true).max()
        # and the errors matter: uncorrected, the readings are off by far more
        assert np.max(np.abs(e.read_wrench(WRENCHES) - WRENCHES)) > 1e-3


def test_type_a_of_the_step_means_is_the_regression_covariance():
    """Step means with independent noise: C within its intervals, Cov(vec C) = Σ ⊗ (W̃ᵀW̃)⁻¹ whose diagonal matches
    the scatter of C over repeated sessions (400 of them)."""
    rng = np.random.default_rng(1)
    noise = np.array([2e-7] * 3 + [2e-6] * 3)
    fits, ses = [], []
    for _ in range(400):
        d = WRENCHES @ C_TRUE.T + rng.standard_normal(WRENCHES.shape) * noise
        c, cov, sigma, dof = step_means_fit(WRENCHES, d)
        fits.append(c.ravel())
        ses.append(np.sqrt(np.diag(cov)))
    assert dof == WRENCHES.shape[0] - 7
    scatter = np.std(fits, axis=0, ddof=1)
    # the mean standard error (√ of the mean variance) against the scatter of the estimates: 400 sessions know
    # each scatter to 3.5 %, so the 36 ratios spread about ±10 % (a standard error √2 off would fail)
    ratio = np.sqrt(np.mean(np.square(ses), axis=0)) / scatter
    assert 0.85 < ratio.min() and ratio.max() < 1.15 and abs(float(np.mean(ratio)) - 1.0) < 0.03
    assert np.max(np.abs(np.mean(fits, axis=0) - C_TRUE.ravel()) / scatter) < 0.2


def test_law_of_propagation_agrees_with_the_monte_carlo_and_counts_every_declared_component():
    lc, pose = declared_calibrations()
    cal = six_axis_inputs(lc, pose)
    e = draw_errors(0)
    rng = np.random.default_rng(0)
    d = e.read_deflection(WRENCHES @ C_TRUE.T) + rng.standard_normal(WRENCHES.shape) * 1e-7
    r = matrix_uncertainty(e.read_wrench(WRENCHES), d, cal, trials=20_000, seed=3)
    ratio = r.stiffness.mc_u / r.stiffness.u_c
    assert 0.9 < ratio.min() and ratio.max() < 1.15, ratio
    # the Type B dominates the diagonal (the sensitivity alone is 0.5 % of it) and both parts add in quadrature
    assert np.all(np.diag(r.stiffness.u_b) > 0.004 * np.diag(K_TRUE))
    assert np.allclose(r.stiffness.u_c, np.hypot(r.stiffness.u_a, r.stiffness.u_b))
    assert np.allclose(r.stiffness.U, r.stiffness.k * r.stiffness.u_c)
    assert np.all(r.stiffness.k >= 1.959) and np.all(r.stiffness.k < 2.1)
    # K2's u from the covariance of vec K, as any derived quantity
    assert math.isclose(float(r.k2.u_c), r.derived_uncertainty(k2_gradient()), rel_tol=1e-9)
    assert r.stiffness_cov_mc is not None and r.stiffness_cov_mc.shape == (36, 36)
    d = r.to_dict()
    assert set(d['stiffness']) >= {'u_c', 'U', 'k', 'coverage', 'interval', 'statistical_interval'}
    assert len(d['covariance']['stiffness']) == 36 and d['statistical_only'] is False


def test_a_missing_declaration_is_named_never_a_silent_zero():
    lc, pose = declared_calibrations()
    lc = {**lc, 'calibration.crosstalk_distribution': 'not_stated'}
    cal = six_axis_inputs(lc, None)
    assert 'load_cell cross-talk' in cal.left_out and 'pose_sensor angle' in cal.left_out
    assert 'statistical only for' in cal.statement and 'load_cell cross-talk' in cal.statement
    array = six_axis_inputs(lc, None, {'calibration.gain': 0.001})  # the deflection from an LVDT array
    assert any(name.startswith('lvdt_array') for name in array.left_out) and 'lvdt_array' in array.statement
    nothing = six_axis_inputs(None, None)
    assert nothing.statistical_only and nothing.statement.startswith('statistical only')
    d = WRENCHES @ C_TRUE.T + np.random.default_rng(2).standard_normal(WRENCHES.shape) * 1e-7
    r = matrix_uncertainty(WRENCHES, d, nothing, trials=0)
    assert r.statistical_only and np.all(r.stiffness.u_b == 0.0) and np.all(r.stiffness.u_a > 0.0)
    with pytest.raises(UncertaintyError, match='degrees of freedom'):
        matrix_uncertainty(WRENCHES[:7], d[:7], nothing, trials=0)


def test_the_model_prediction_of_every_entry_with_its_monte_carlo():
    p = predict_matrix(GEOMETRY, trials=4000, seed=1)
    assert np.allclose(p.stiffness, K_TRUE)
    diag = np.diag(p.stiffness_u) / np.diag(K_TRUE)
    # E and the wire diameter make ~3 % of every diagonal entry (docs/uncertainty.md: 1675 N/m of 53794 along fy)
    assert np.all((0.025 < diag) & (diag < 0.04))
    ratio = np.diag(p.stiffness_u) / np.diag(p.stiffness_u_linear)
    assert np.all((0.93 < ratio) & (ratio < 1.07))
    assert math.isclose(p.k2, float(K_TRUE.ravel() @ k2_gradient()), rel_tol=1e-12) and p.k2_u > 0.0
    en = en_matrix(K_TRUE * 1.01, 0.005 * np.abs(K_TRUE), p.stiffness, p.stiffness_U)
    assert np.all(np.abs(np.diag(en)) < 1.0)
    assert np.isnan(en_matrix(0.0, 0.0, 0.0, 0.0))
