"""A designed program kept where the response is linear and the load cell reads (crane_stiffness.full6.linearity):
the lack of fit the nonlinear model predicts is the one a session over that model measures; on the lab model the
design is left as it is, on a soft set-up (h = 1.5 m) it is scaled down until the prediction passes, and its peaks
never exceed the load cell's full scale."""
from __future__ import annotations

import numpy as np
import pytest

from crane_stiffness.full6.admissible import axis_peaks, check_steps
from crane_stiffness.full6.design import d_optimal_design
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.full6.identify import identify
from crane_stiffness.full6.linearity import linear_design, predicted_lack_of_fit, program_steps
from crane_stiffness.full6.program import design_program
from crane_stiffness.model.geometry import lab_model
from crane_stiffness.testing.synthetic_full6 import model_responses, synthetic_pairs

FULL_SCALE = 0.9 * np.array([40.0, 40.0, 120.0, 2.0, 2.0, 2.0])  # config/sensors.yaml's load cell, x 0.9


def measured_lack_of_fit(g, design, seeds=range(4)) -> float:
    """The mean lack-of-fit statistic of seeded sessions over the nonlinear model (white sensor noise)."""
    truth = model_responses(g, design_program(design), design.settle_s)
    values = []
    for seed in seeds:
        s = synthetic_pairs(truth, seed=seed)
        values.append(identify(s.wrench, s.deflection, s.step).lack_of_fit)
    return float(np.mean(values))


def test_the_prediction_is_the_lack_of_fit_sessions_over_the_model_measure():
    g = lab_model(1.5, 50.0)
    for fraction, low, high in ((0.15, 1.0, 1.6), (0.3, 2.0, 12.0)):
        design = d_optimal_design(g, fraction * axis_peaks(g, 2.0), n_steps=16, hold_s=2.0, baseline_s=1.0)
        predicted = predicted_lack_of_fit(g, *program_steps(design))
        measured = measured_lack_of_fit(g, design)
        assert low < predicted < high
        # the statistic of pure noise scatters ±0.2 about 1 here (54 degrees of freedom, 4 sessions)
        assert measured == pytest.approx(predicted, abs=0.15 + 0.15 * (predicted - 1.0)), (fraction, predicted)


def test_the_lab_model_s_design_is_kept_and_a_soft_set_up_s_scaled_until_the_prediction_passes():
    lab = lab_model(0.5, 50.0)
    kept = linear_design(lab, 0.98 * axis_peaks(lab, 2.0), full_scale=FULL_SCALE, seed=0)
    assert kept.scale == 1.0 and kept.lack_of_fit < 1.05
    assert np.allclose(kept.design.peaks, 0.98 * axis_peaks(lab, 2.0))  # config/program_full6.yaml's peaks stand
    soft = lab_model(1.5, 50.0)
    peaks = 0.98 * axis_peaks(soft, 2.0)
    assert predicted_lack_of_fit(soft, *program_steps(d_optimal_design(soft, np.minimum(peaks, FULL_SCALE)))) > 5
    scaled = linear_design(soft, peaks, full_scale=FULL_SCALE, seed=0)
    assert 1.0 < scaled.lack_of_fit <= 1.2 and scaled.scale < 0.5
    assert check_steps(soft, scaled.design.steps, 2.0).factor.min() >= 2.0


def test_no_peak_exceeds_the_load_cell_s_full_scale():
    heavy = lab_model(0.5, 100.0)  # its slack margins allow moments of 3.2 N·m: the load cell reads 2
    assert np.any(0.98 * axis_peaks(heavy, 2.0) > FULL_SCALE)
    made = linear_design(heavy, 0.98 * axis_peaks(heavy, 2.0), full_scale=FULL_SCALE, seed=0)
    assert np.all(np.abs(made.design.steps).max(axis=0) <= FULL_SCALE + 1e-12)
    with pytest.raises(Full6InputError, match='max_lack_of_fit'):
        linear_design(heavy, FULL_SCALE, max_lack_of_fit=1.0)
